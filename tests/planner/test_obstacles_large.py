"""Large polygons (more than `Obstacles.LARGE_POLYGON` vertices) are queried through their
prepared geometry and their edges instead of one STRtree entry each, so that node building
and clearance tests stay near-linear in the vertices: every query answers exactly as the
one-entry path does, on random maps of large and small polygons and walls, points and
segments inside, on and across them. (The time it saves is measured by `bench polygon`.)"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planner.graph import graph_nodes
from planner.obstacles import Obstacles
from planner.scenarios import fine_polygon, scenario_problem

SETTINGS = dict(
    derandomize=True,
    deadline=None,
    database=None,
    max_examples=25,
    suppress_health_check=[HealthCheck.too_slow],
)


def lobed(rng: np.random.Generator, vertices: int, centre, radius: float) -> np.ndarray:
    angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, vertices))
    r = radius * (1.0 + 0.3 * np.sin(rng.integers(2, 9) * angle)) * rng.uniform(0.9, 1.0, vertices)
    return np.column_stack([centre[0] + r * np.cos(angle), centre[1] + r * np.sin(angle)])


def both_ways(polygons, walls) -> tuple[Obstacles, Obstacles]:
    """The same obstacles queried the large way and the one-entry way."""
    split = Obstacles(polygons=polygons, walls=walls)
    whole = Obstacles(polygons=polygons, walls=walls)
    object.__setattr__(whole, "LARGE_POLYGON", 10**9)  # (an instance's own limit)
    assert split._large is not None and whole._large is None
    return split, whole


@settings(**SETTINGS)
@given(seed=st.integers(0, 2**32 - 1), large=st.integers(1, 3), small=st.integers(0, 6))
def test_large_polygons_answer_every_query_as_one_entry_does(seed, large, small):
    rng = np.random.default_rng(seed)
    polygons = [lobed(rng, int(rng.integers(65, 400)), rng.uniform(0, 300, 2), 40.0)]
    polygons += [lobed(rng, int(rng.integers(65, 400)), rng.uniform(0, 300, 2), 30.0)
                 for _ in range(large - 1)]  # fmt: skip
    polygons += [lobed(rng, 5, rng.uniform(0, 300, 2), 8.0) for _ in range(small)]
    walls = rng.uniform(0, 300, (3, 2, 2))
    walls[2, 1] = walls[2, 0]  # a zero-length wall
    split, whole = both_ways(polygons, walls)

    points = rng.uniform(-20, 320, (3000, 2))
    points[:40] = polygons[0][rng.integers(0, len(polygons[0]), 40)]  # on the boundary
    points[40:60] = np.asarray(polygons[0]).mean(axis=0) + rng.normal(0, 3, (20, 2))  # inside
    starts = rng.uniform(-20, 320, (3000, 2))
    ends = starts + rng.normal(0, 40, (3000, 2))
    ends[:20] = starts[:20] = points[40:60]  # wholly inside a large polygon (zero length)
    ends[20:40] = points[40:60] + 1.0
    segments = np.stack([starts, ends], axis=1)
    owner = rng.integers(0, len(whole), len(points))
    for distance in (0.0, 5.0):
        assert np.array_equal(
            split.points_within(points, distance), whole.points_within(points, distance)
        )
        assert np.array_equal(
            split.near_own(points, owner, distance), whole.near_own(points, owner, distance)
        )
    np.testing.assert_allclose(split.distance_to_points(points), whole.distance_to_points(points))
    np.testing.assert_allclose(
        split.distance_to_segments(segments), whole.distance_to_segments(segments)
    )
    for obstacles in (split, whole):  # the STRtree way, not the prepared union
        object.__setattr__(obstacles, "UNION_VERTICES", 0)
    clear = whole.segments_within(segments, 5.0)
    assert np.array_equal(split.segments_within(segments, 5.0), clear)
    assert clear[:40].all() and 0.05 < clear.mean() < 0.95  # the cases are not all alike


@pytest.mark.parametrize("vertices", [500, 3000])
def test_a_fine_polygon_gets_the_same_nodes_either_way(vertices):
    problem = scenario_problem(fine_polygon(vertices))
    split, whole = both_ways(problem.obstacles.polygons, problem.obstacles.walls)
    nodes = graph_nodes(problem)
    same = graph_nodes(scenario_problem(fine_polygon(vertices), obstacles=whole))
    assert split._large is not None
    assert len(nodes) == len(same) > vertices // 2
    for field in ("points", "kind", "prunable", "flat"):
        assert np.array_equal(getattr(nodes, field), getattr(same, field)), field
