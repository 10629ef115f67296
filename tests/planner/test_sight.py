"""Line of sight (`planner.sight`) against plain shapely, one chord and one obstacle at a time,
on random maps (hypothesis): rectangles, concave polygons, polygons of more than
`Obstacles.LARGE_POLYGON` vertices, walls (a walled courtyard stands for a footprint with a
hole), in 2-D with and without a margin, and in 3-D with roof heights."""

from __future__ import annotations

import numpy as np
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planner.obstacles import Obstacles
from planner.sight import Sight
from tests.sight_checks import brute_connected, shapely_blocked

SETTINGS = dict(
    derandomize=True,
    deadline=None,
    database=None,
    max_examples=30,
    suppress_health_check=[HealthCheck.too_slow],
)


def random_map(rng: np.random.Generator) -> tuple[list[np.ndarray], np.ndarray]:
    polygons = []
    for _ in range(int(rng.integers(1, 8))):
        centre = rng.uniform(0, 400, 2)
        kind = rng.integers(0, 3)
        if kind == 0:  # a rectangle
            w, h = rng.uniform(5, 60, 2)
            ring = centre + np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2
        else:  # a star: concave, and with kind 2 more vertices than LARGE_POLYGON
            count = 7 if kind == 1 else 90
            angle = np.sort(rng.uniform(0, 2 * np.pi, count))
            radius = rng.uniform(8, 40) * rng.uniform(0.4, 1.0, count)
            ring = centre + np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
        polygons.append(ring)
    # a walled courtyard (four walls with a gap): chords inside it are clear
    c = rng.uniform(100, 300, 2)
    square = c + np.array([[-30, -30], [30, -30], [30, 30], [-30, 30]])
    walls = np.array([[square[0], square[1]], [square[1], square[2]], [square[2], square[3]],
                      [square[3], square[0] + [0, 10]]])  # fmt: skip
    return polygons, walls


def chords(rng: np.random.Generator, count: int = 400) -> tuple[np.ndarray, np.ndarray]:
    starts = rng.uniform(-20, 420, (count, 2))
    ends = starts + rng.normal(0, 80, (count, 2))
    return starts, ends


@settings(**SETTINGS)
@given(seed=st.integers(0, 2**32 - 1), margin=st.sampled_from([0.0, 5.0]))
def test_a_chord_is_clear_exactly_when_shapely_finds_it_clear(seed, margin):
    rng = np.random.default_rng(seed)
    polygons, walls = random_map(rng)
    starts, ends = chords(rng)
    sight = Sight(Obstacles(polygons=polygons, walls=walls))
    clear = sight.clear(starts, ends, margin)
    expected = [
        not shapely_blocked(polygons, walls, s, e, margin)
        for s, e in zip(starts, ends, strict=True)
    ]
    assert clear.tolist() == expected
    assert 0.05 < clear.mean() < 0.95  # both answers are exercised


def shapely_blocked_3d(polygons, heights, walls, start, end) -> bool:
    """Independently: the part of the chord below a roof (its height is linear along it) is
    a sub-segment; the roof blocks when that sub-segment meets the footprint in 2-D."""
    line = shapely.LineString([start[:2], end[:2]])
    if any(line.intersects(shapely.LineString(w)) for w in walls):
        return True
    for ring, roof in zip(polygons, heights, strict=True):
        polygon = shapely.Polygon(ring)
        if np.isinf(roof):
            below = (0.0, 1.0)
        elif start[2] == end[2]:
            below = (0.0, 1.0) if start[2] < roof else None
        else:
            t = (roof - start[2]) / (end[2] - start[2])  # where the chord crosses the roof
            below = (0.0, t) if end[2] > start[2] else (t, 1.0)  # where z(t) < roof
            below = (max(below[0], 0.0), min(below[1], 1.0))
            if below[0] >= below[1]:
                below = None
        if below is None:
            continue
        a = start[:2] + below[0] * (end[:2] - start[:2])
        b = start[:2] + below[1] * (end[:2] - start[:2])
        if shapely.LineString([a, b]).intersects(polygon):
            return True
    return False


@settings(**SETTINGS)
@given(seed=st.integers(0, 2**32 - 1))
def test_a_chord_over_a_lower_roof_is_clear_in_3d(seed):
    rng = np.random.default_rng(seed)
    polygons, walls = random_map(rng)
    heights = rng.uniform(5, 40, len(polygons))
    heights[rng.uniform(size=len(polygons)) < 0.2] = np.inf  # no height known
    starts, ends = chords(rng)
    starts = np.column_stack([starts, rng.choice([0.0, 20.0, 30.0], len(starts))])
    ends = np.column_stack([ends, rng.choice([0.0, 20.0, 30.0], len(ends))])
    sight = Sight(Obstacles(polygons=polygons, walls=walls), heights)
    clear = sight.clear_3d(starts, ends)
    expected = [
        not shapely_blocked_3d(polygons, heights, walls, s, e)
        for s, e in zip(starts, ends, strict=True)
    ]
    assert clear.tolist() == expected
    # with every roof infinitely high, 3-D is 2-D
    tall = Sight(Obstacles(polygons=polygons, walls=walls))
    assert tall.clear_3d(starts, ends).tolist() == tall.clear(starts, ends).tolist()


def test_a_roof_blocks_only_the_chords_that_pass_below_it():
    building = Sight(Obstacles(polygons=[np.array([[40, -10], [60, -10], [60, 10], [40, 10]])]),
                     np.array([15.0]))  # fmt: skip
    a, b = [0.0, 0.0], [100.0, 0.0]
    cases = {  # start height, end height -> clear
        (20.0, 20.0): True,  # over the roof
        (10.0, 10.0): False,  # through the building
        (0.0, 30.0): False,  # rising: 12 m over the near wall (x=40), below the roof
        (0.0, 40.0): True,  # rising: 16 m there, above it
        (40.0, 0.0): True,  # falling: 16 m over the far wall (x=60), above the roof
        (30.0, 0.0): False,  # falling: 12 m there, below it
    }
    starts = np.array([[*a, h0] for h0, _ in cases])
    ends = np.array([[*b, h1] for _, h1 in cases])
    assert building.clear_3d(starts, ends).tolist() == list(cases.values())


# --------------------------------------------------------------------- connectivity by sight
@settings(**{**SETTINGS, "max_examples": 15})
@given(seed=st.integers(0, 2**32 - 1))
def test_connectivity_by_sight_is_what_shapely_and_networkx_find(seed):
    from planner.guarantees import check_positions

    rng = np.random.default_rng(seed)
    polygons, walls = random_map(rng)
    obstacles = Obstacles(polygons=polygons, walls=walls)
    stations = rng.uniform(0, 400, (2, 2))
    positions = rng.uniform(0, 400, (40, 6, 2))
    checked = check_positions(positions, obstacles, stations, 150.0, sight=Sight(obstacles))
    disk = check_positions(positions, obstacles, stations, 150.0)
    expected = [brute_connected(xy, stations, polygons, walls, 150.0) for xy in positions]
    assert checked.connected.tolist() == expected
    assert not np.any(checked.connected & ~disk.connected)  # sight only removes links


def test_every_chord_within_the_reach_is_clear_and_the_reach_is_nearly_tight():
    """`chord_reach` on a path round a block: chords between random points at most the reach
    apart along the path are all clear (shapely, one at a time), and some chord four samples
    longer is not (the sampling's margin costs 3-4 m at a corner)."""
    from planner.sight import REACH_STEP_M, chord_reach

    block = np.array([[20.0, 20.0], [80.0, 20.0], [80.0, 80.0], [20.0, 80.0]])
    path = np.array([[14.0, 0.0], [14.0, 86.0], [86.0, 86.0], [86.0, 0.0]])  # 6 m off it
    sight = Sight(Obstacles(polygons=[block]))
    reach = chord_reach(path, sight, 500.0)
    arcs = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])

    def at(s):
        return np.column_stack([np.interp(s, arcs, path[:, 0]), np.interp(s, arcs, path[:, 1])])

    rng = np.random.default_rng(3)
    s = rng.uniform(0, arcs[-1], 4000)
    gap = rng.uniform(0, reach, 4000)
    keep = s + gap <= arcs[-1]
    a, b = at(s[keep]), at(s[keep] + gap[keep])
    polygon = shapely.Polygon(block)
    assert not any(
        shapely.LineString([p, q]).intersects(polygon) for p, q in zip(a, b, strict=True)
    )
    longer = reach + 4 * REACH_STEP_M
    s = np.linspace(0, arcs[-1] - longer, 2000)
    a, b = at(s), at(s + longer)
    assert any(shapely.LineString([p, q]).intersects(polygon) for p, q in zip(a, b, strict=True))
    assert 10.0 < reach < 60.0  # round a corner 6 m off a block: a few tens of metres


def test_a_straight_path_is_trusted_only_where_it_clears_the_buildings_itself():
    """Pairs on one straight piece are skipped only when the piece keeps the margin: a
    straight path through a block has no reach; one 6 m beside it reaches the limit."""
    from planner.sight import chord_reach

    block = np.array([[20.0, 20.0], [80.0, 20.0], [80.0, 80.0], [20.0, 80.0]])
    sight = Sight(Obstacles(polygons=[block]))
    assert chord_reach(np.array([[0.0, 50.0], [100.0, 50.0]]), sight, 60.0) == 0.0
    beside = np.array([[0.0, 14.0], [50.0, 14.0], [100.0, 14.0]])
    assert chord_reach(beside, sight, 60.0) == 60.0
