"""The planner at city scale (issue 13): the goal-distance heuristic, certification inside
the ellipse of the path found, stop requests with the best path so far, lower bounds, and
memory that follows the vertex count."""

from __future__ import annotations

import math

import networkx as nx
import numpy as np
import pytest
import shapely

import planner.graph as graph
import planner.search as search
from planner.formation import ANGLE_TOLERANCE, DISTANCE_TOLERANCE
from planner.graph import GOAL, START, EdgeCache, graph_nodes
from planner.obstacles import Obstacles, _cell_centres_inside
from planner.scenarios import (
    city_grid,
    paper_scenario,
    random_buildings,
    scenario_problem,
    walled_in,
)
from planner.search import SearchProgress, goal_distance, plan_path
from planner.types import PathProblem
from planner.validity import check_path
from tests.planner_maps import REPAIR, problem, square, terraced_rows


def _complete_graph_distances(cache: EdgeCache) -> dict[int, float]:
    """Exact distance to B of every node over all of the cache's edges (networkx)."""
    graph = nx.DiGraph()
    for v in cache.members:
        lo, hi = cache.edges(int(v))
        for e in range(lo, hi):
            graph.add_edge(int(cache.src[e]), int(cache.dst[e]), weight=float(cache.length[e]))
    return nx.single_source_dijkstra_path_length(graph.reverse(), GOAL)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_goal_distance_never_overestimates_and_is_consistent(seed):
    prob = scenario_problem(random_buildings(40, seed=seed, size=800.0))
    nodes = graph_nodes(prob)
    cache = EdgeCache(prob, nodes, taut=True, prune_collinear=True)
    h = goal_distance(cache, search._Budget(10**9))
    exact = _complete_graph_distances(cache)
    reached = np.array(sorted(exact))
    assert np.all(h[reached] <= np.array([exact[v] for v in reached]) + 1e-6)
    assert h[START] == pytest.approx(exact[START])  # A settled: the unconstrained length
    # consistent along every edge: h(v) <= |vw| + h(w)
    size = cache.size
    assert np.all(h[cache.src[:size]] <= cache.length[:size] + h[cache.dst[:size]] + 1e-6)


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_goal_distance_over_the_rows_never_overestimates_and_is_consistent(seed):
    """With a row filter, the heuristic is the exact distance to B over the edges the rows
    and parking angles let through (each edge tested as the segment it is), never below the
    unconstrained one, and consistent along those edges: what the walk and label searches
    relax."""
    world = random_buildings(40, seed=seed, size=800.0)
    prob = scenario_problem(world, start_angle_deg=70.0, goal_angle_deg=110.0)
    nodes = graph_nodes(prob)
    cache = EdgeCache(prob, nodes, taut=True, prune_collinear=True)
    rows = search._RowFilter(prob, prob.rows(4), nodes)
    kept = search.goal_distance(cache, search._Budget(10**9), rows)
    free = goal_distance(cache, search._Budget(10**9))
    graph = nx.DiGraph()
    for v in cache.members:
        lo, hi = cache.edges(int(v))
        for e in lo + np.flatnonzero(rows.mask(cache, int(v))):
            graph.add_edge(int(cache.src[e]), int(cache.dst[e]), weight=float(cache.length[e]))
    exact = nx.single_source_dijkstra_path_length(graph.reverse(), GOAL)
    reached = np.array(sorted(exact))
    truth = np.array([exact[v] for v in reached])
    assert np.all(kept[reached] <= truth + 1e-6)
    assert kept[START] == pytest.approx(exact[START])
    assert np.all(kept >= free - 1e-9) and np.any(kept > free + 1e-6)  # the rows bind
    size = cache.size
    allowed = np.concatenate([rows.mask(cache, int(v)) for v in cache.members])
    src, dst, length = cache.src[:size], cache.dst[:size], cache.length[:size]
    order = np.concatenate([np.arange(*cache.edges(int(v))) for v in cache.members])
    src, dst, length = src[order][allowed], dst[order][allowed], length[order][allowed]
    assert np.all(kept[src] <= length + kept[dst] + 1e-6)


@pytest.mark.parametrize("seed", [1, 2])
def test_goal_distance_run_on_settles_every_node_below_the_key_and_stays_a_lower_bound(seed):
    prob = scenario_problem(random_buildings(40, seed=seed, size=800.0))
    cache = EdgeCache(prob, graph_nodes(prob), taut=True, prune_collinear=True)
    budget = search._Budget(10**9)
    goal = search.heuristic_of(cache, budget)
    first = goal.values.copy()
    unconstrained = float(first[START])
    goal.extend(unconstrained + 300.0, budget)
    h = goal.values
    exact = _complete_graph_distances(cache)
    pts = cache.nodes.points
    to_start = np.hypot(*(pts - pts[START]).T)
    reached = np.array(sorted(set(exact) - {START}))
    truth = np.array([exact[v] for v in reached])
    assert np.all(h >= first - 1e-9)  # running on only tightens it
    assert np.all(h[reached] <= truth + 1e-6)
    below = truth + to_start[reached] < unconstrained + 300.0 - 1e-6
    assert np.count_nonzero(below) > np.count_nonzero(first[reached] == truth)
    assert np.allclose(h[reached[below]], truth[below])  # exact where the key is below
    size = cache.size
    assert np.all(h[cache.src[:size]] <= cache.length[:size] + h[cache.dst[:size]] + 1e-6)


def test_nodes_out_of_b_s_reach_get_an_infinite_distance():
    """B walled in: once the reverse search has settled every node that reaches B, the
    others (A among them) reach it in no way, and say so (infinite, not the last key); the
    walk search then finds no walk at once instead of taking them for near ones."""
    prob = scenario_problem(walled_in(paper_scenario(), 80.0))
    cache = EdgeCache(prob, graph_nodes(prob), taut=True, prune_collinear=True)
    goal = search.heuristic_of(cache, search._Budget(10**9))
    exact = _complete_graph_distances(cache)
    inside = np.array(sorted(exact))
    assert not goal.open and np.isinf(goal.values[START])
    assert np.allclose(goal.values[inside], [exact[v] for v in inside])
    outside = np.setdiff1d(cache.members, inside)
    assert len(outside) > 40 and np.all(np.isinf(goal.values[outside]))
    rows = search._RowFilter(prob, prob.rows(1), cache.nodes)
    kept = search.heuristic_of(cache, search._Budget(10**9), rows)  # the rows' own bound
    assert not kept.open and np.isinf(kept.values[START])
    budget = search._Budget(10**9)
    walk, status = search._walk_search(cache, rows, budget)
    assert walk is None and status == "exhausted" and budget.used == 1  # A's edges only


@pytest.mark.parametrize("seed", [1, 2])
def test_an_ellipse_too_small_for_any_path_stops_the_reverse_search_at_its_size(seed):
    """Inside an ellipse |Av| + |vB| < L with no path as short as L, the heuristic's reverse
    search stops once its keys reach L instead of settling A: A keeps the bound L (what
    the ellipse search needs to know), and every value stays a lower bound."""
    prob = scenario_problem(random_buildings(40, seed=seed, size=800.0))
    nodes = graph_nodes(prob)
    straight = float(np.hypot(*(prob.goal - prob.start)))
    wide = EdgeCache(prob, nodes, taut=True, prune_collinear=True, within=3.0 * straight)
    shortest = goal_distance(wide, search._Budget(10**9))[START]
    size = shortest - 1.0  # no path is this short
    cache = EdgeCache(prob, nodes, taut=True, prune_collinear=True, within=size)
    goal = search.heuristic_of(cache, search._Budget(10**9))
    h = goal.values
    exact = _complete_graph_distances(cache)
    reached = np.array(sorted(exact))
    distance = np.array([exact[v] for v in reached])
    key = distance + np.hypot(*(nodes.points[reached] - prob.start).T)
    assert goal.settled <= np.count_nonzero(key < size + 1e-6)  # A (key >= L) not settled
    assert h[START] >= size  # ... but bounded by L
    assert np.all(h[reached] <= distance + 1e-6)


def test_b_sees_every_node_that_sees_it_on_a_radius_limited_map():
    """The heuristic's backward search follows B's out-edges: B's candidates are complete
    (like A's). B in open country far from the district, where only the nearest targets of
    each octant would be its candidates, must still see every node that sees it."""
    world = random_buildings(400, seed=1, size=1500.0)
    prob = scenario_problem(world, goal=np.array([3500.0, 1400.0]))
    cache = EdgeCache(
        prob, graph_nodes(prob), taut=True, prune_collinear=True, local_candidates=250
    )
    assert cache.radius is not None
    for v in cache.members:
        cache.edges(int(v))
    size = cache.size
    into_goal = set(cache.src[:size][cache.dst[:size] == GOAL].tolist()) - {START}
    lo, hi = cache.edges(GOAL)
    assert into_goal and into_goal <= set(cache.dst[lo:hi].tolist())


@pytest.mark.parametrize(
    "world, goes_on",
    [
        (lambda: city_grid(12, 10, block=40.0, street=16.0), True),
        (lambda: random_buildings(200), False),
    ],
    ids=["grid", "random"],
)
def test_collinear_pruning_goes_on_only_where_nodes_line_up(monkeypatch, world, goes_on):
    """A grid lines nodes up (many edges pass through a nearer node on the same ray and are
    dropped); scattered footprints do not, and the test stops after its trial. Either way
    every node's distance to B is what it is with every collinear edge kept."""
    prob = scenario_problem(world())
    nodes = graph_nodes(prob)

    def distances(cache: EdgeCache) -> np.ndarray:
        for v in cache.members:
            cache.edges(int(v))
        return goal_distance(cache, search._Budget(10**9))

    monkeypatch.setattr(graph, "COLLINEAR_TRIAL", 5000)
    cache = EdgeCache(prob, nodes, taut=True, prune_collinear=True)
    pruned = distances(cache)
    kept = distances(EdgeCache(prob, nodes, taut=True, prune_collinear=False))
    assert np.allclose(pruned, kept)
    share = cache.collinear_dropped / cache.collinear_tested
    if goes_on:
        assert share > 0.1 and cache.collinear_tested > 10 * graph.COLLINEAR_TRIAL
    else:
        assert share < graph.COLLINEAR_SHARE
        assert cache.collinear_tested < 2 * graph.COLLINEAR_TRIAL < cache.examined / 10


def test_certified_where_complete_candidates_agree():
    prob = scenario_problem(city_grid(12, 10, block=40.0, street=16.0))
    plan = plan_path(prob)
    assert plan.valid and plan.certified and plan.lower_bound_m == plan.length_m
    # the same map with complete candidate sets everywhere gives the same length
    old = search.LOCAL_CANDIDATES, search.LOCAL_CANDIDATES_FULL
    try:
        search.LOCAL_CANDIDATES = search.LOCAL_CANDIDATES_FULL = 10**6
        complete = plan_path(prob)
    finally:
        search.LOCAL_CANDIDATES, search.LOCAL_CANDIDATES_FULL = old
    assert complete.valid
    assert plan.length_m == pytest.approx(complete.length_m, abs=1e-6)


def _all_edges(cache: EdgeCache) -> set[tuple[int, int]]:
    for v in cache.members:
        cache.edges(int(v))
    return set(zip(cache.src[: cache.size].tolist(), cache.dst[: cache.size].tolist(), strict=True))


#: 4 x 3 blocks of 6 touching houses (merged into 12 occluders), A and B clear of them.
TERRACED = problem(
    (-40.0, -30.0), (230.0, 150.0), Obstacles(polygons=terraced_rows(rows=4, houses=6, columns=3))
)


@pytest.mark.parametrize("taut", [True, False])
@pytest.mark.parametrize(
    "world",
    [random_buildings(60, seed=4, size=600.0), city_grid(6, 5, block=40.0, street=16.0), None],
    ids=["random", "grid", "terraced"],
)
def test_sector_reach_finds_every_edge_that_testing_every_pair_finds(monkeypatch, world, taut):
    """Complete candidate sets found through each node's sector reach (what a sector's
    nearest spanning occluder hides, and the corner cone's sectors in the taut graph) give
    exactly the edges of testing every pair; the terraced rows' occluders are merged."""
    prob = TERRACED if world is None else scenario_problem(world)
    nodes = graph_nodes(prob)
    straight = float(np.hypot(*(prob.goal - prob.start)))
    made = {}
    for threshold in (10**9, 0):
        monkeypatch.setattr(graph, "_SECTOR_REACH_TARGETS", threshold)
        # (no collinear pruning: once it stops, which edges it dropped depends on the order
        # the pairs come in)
        cache = EdgeCache(prob, nodes, taut=taut, prune_collinear=False, within=1.3 * straight)
        assert cache.uses_sector_reach == (threshold == 0)
        made[threshold] = _all_edges(cache)
    assert len(made[0]) > 100
    assert made[0] == made[10**9]


def test_a_grown_ellipse_reuses_the_clearance_verdicts_and_finds_the_same_edges():
    """Ellipse caches of one problem share their pairs' clearance verdicts: the grown
    ellipse has exactly the edges it has alone, and tests in detail only the pairs the first
    one did not."""
    prob = TERRACED
    nodes = graph_nodes(prob)
    straight = float(np.hypot(*(prob.goal - prob.start)))
    shared = graph.Occlusion(nodes, prob.obstacles, prob.safety_margin)
    tested = prob.obstacles._tested
    made, cost = {}, {}
    for name, occlusion, within in (
        ("first", shared, 1.1 * straight),
        ("grown", shared, 1.3 * straight),
        ("alone", graph.Occlusion(nodes, prob.obstacles, prob.safety_margin), 1.3 * straight),
    ):
        before = tested[0]
        cache = EdgeCache(
            prob, nodes, taut=False, prune_collinear=True, within=within, occlusion=occlusion
        )
        made[name], cost[name] = _all_edges(cache), tested[0] - before
    assert made["grown"] == made["alone"] and len(made["first"]) < len(made["alone"])
    assert cost["grown"] < cost["alone"] - cost["first"] / 2


def test_touching_footprints_merge_into_one_occluder_that_stays_within_the_gap():
    """`Obstacles.merged`: each row of touching houses is one polygon that holds the row and
    stays within half the gap of it (a segment meeting it comes that close to a house, less
    than rho_c); rows farther apart than the gap, and lone footprints, stay as they are."""
    houses = Obstacles(polygons=terraced_rows())  # 3 rows of 8, 20 m apart
    lone = square(200.0, 200.0, 10.0)
    merged = Obstacles(polygons=[*houses.polygons, lone]).merged(1.0)
    assert len(merged) == 4  # one per row, and the lone square
    assert any(len(p) == 4 and np.allclose(p, lone) for p in merged.polygons)
    union = shapely.union_all(houses.geometries)
    assert shapely.contains(shapely.union_all(merged.geometries), union)
    assert np.all(houses.distance_to_points(merged.vertices[0][4:]) <= 0.5 + 1e-9)  # lone first
    # a gap of 1 cm (coordinates rounded through longitude and latitude) still merges
    shifted = [h + [0.01 * k, 0.0] for k, h in enumerate(terraced_rows(rows=1))]
    assert len(Obstacles(polygons=shifted).merged(1.0)) == 1


def test_a_row_of_touching_houses_hides_what_lies_behind_a_party_wall():
    """Seen from A in the street, the ray along the wall two houses share bounds each
    house's angular span (neither hides what lies behind it alone) and lies strictly inside
    the row's: the merged occluder hides the point beyond the row."""
    row = Obstacles(polygons=terraced_rows(rows=1, houses=16))  # x 0..128, y 0..12
    prob = problem((64.0, -8.0), (64.0, -100.0), row)
    nodes = graph_nodes(prob)
    behind = np.array([64.0, 90.0])  # straight beyond the party wall at x = 64
    d = behind - nodes.points[START]
    angle, length = np.array([math.atan2(d[1], d[0])]), np.array([math.hypot(*d)])
    merged = graph.Occlusion(nodes, prob.obstacles, prob.safety_margin)
    merged.ensure(np.array([START]))
    assert merged.in_shadow(np.array([START]), angle, length)[0]
    alone = graph.Occlusion(nodes, prob.obstacles, prob.safety_margin)
    alone.occluders = prob.obstacles  # the houses one by one
    alone.ensure(np.array([START]))
    assert not alone.in_shadow(np.array([START]), angle, length)[0]


@pytest.mark.parametrize("world", ["random", "terraced"])
def test_what_a_shadow_hides_is_blocked_seen_from_either_end(world):
    """`Occlusion.in_shadow` is a culling before the exact test, so it must never hide a
    clear segment: every node pair it blocks, seen from the source (angle in [-pi, pi]) or
    from the far end (the reverse angle, up to 2 pi, wrapped by one turn), comes within
    rho_c of an obstacle. It also blocks a fair share of the pairs, so the check bites."""
    random = random_buildings(120, seed=9, size=800.0)
    prob = TERRACED if world == "terraced" else scenario_problem(random)
    nodes = graph_nodes(prob)
    occlusion = graph.Occlusion(nodes, prob.obstacles, prob.safety_margin)
    rng = np.random.default_rng(12)
    src = rng.integers(0, len(nodes), 40_000)
    dst = rng.integers(0, len(nodes), 40_000)
    keep = src != dst
    src, dst = src[keep], dst[keep]
    occlusion.ensure(np.unique(np.concatenate([src, dst])))
    d = nodes.points[dst] - nodes.points[src]
    angle, length = np.arctan2(d[:, 1], d[:, 0]), np.hypot(d[:, 0], d[:, 1])
    ahead = occlusion.in_shadow(src, angle, length)
    back = occlusion.in_shadow(dst, angle + math.pi, length)
    segments = np.stack([nodes.points[src], nodes.points[dst]], axis=1)
    close = prob.obstacles.segments_within(segments, prob.safety_margin - DISTANCE_TOLERANCE)
    assert np.all(close[ahead | back])
    assert np.count_nonzero(ahead) > 0.2 * len(src) and np.count_nonzero(back) > 0.2 * len(src)
    assert np.count_nonzero(back & ~ahead) > 0  # the far end's view adds its own
    for node, toward, shadowed in ((src, angle, ahead), (dst, angle + math.pi, back)):
        ref, low, high, far = np.moveaxis(occlusion.shadow[node], -1, 0)  # the definition:
        rel = np.mod(toward[:, None] - ref + math.pi, 2.0 * math.pi) - math.pi  # [-pi, pi)
        inside = (rel > low + ANGLE_TOLERANCE) & (rel < high - ANGLE_TOLERANCE)
        inside &= length[:, None] > far + DISTANCE_TOLERANCE
        assert np.array_equal(shadowed, inside.any(axis=1))  # no angle lost to the wrap


@pytest.mark.parametrize(
    "world, local, on_rays",
    [
        (lambda: random_buildings(400, seed=1, size=1500.0), 250, False),
        (lambda: city_grid(14, 12, block=40.0, street=16.0), 40, True),
    ],
    ids=["random", "grid"],
)
def test_octant_completion_picks_the_nearest_targets_beyond_the_radius(world, local, on_rays):
    """On a radius-limited graph each (node, octant) short of targets within the radius gets
    its `_OCTANT_MIN` nearest targets in that octant beyond the radius, ties (a grid's)
    going to the lower target number, whatever the search reach, targets on the octant's
    bounding rays included: the same picks as sorting every target by distance."""
    prob = scenario_problem(world())
    cache = EdgeCache(
        prob, graph_nodes(prob), taut=True, prune_collinear=True, local_candidates=local
    )
    assert cache.radius is not None
    pts = cache.nodes.points
    rng = np.random.default_rng(4)
    apex = np.repeat(rng.choice(cache.members, 60, replace=False), 8)
    octant = np.tile(np.arange(8), 60)
    s, t = cache._wedge_targets(apex, octant)
    got = {(int(v), int(o)): set() for v, o in zip(apex, octant, strict=True)}
    for v, w in zip(s.tolist(), t.tolist(), strict=True):
        got[(v, int(graph._octant((pts[w] - pts[v])[None])[0]))].add(w)
    on_ray = 0
    for v, o in zip(apex.tolist(), octant.tolist(), strict=True):
        d = pts[cache.targets] - pts[v]
        dist = np.hypot(d[:, 0], d[:, 1])
        inside = (graph._octant(d) == o) & (dist > cache.radius)
        targets, dist = cache.targets[inside], dist[inside]
        order = np.lexsort((targets, dist))[: graph._OCTANT_MIN]
        assert got[(v, o)] == set(targets[order].tolist())
        turns = np.arctan2(*(pts[targets[order]] - pts[v]).T[::-1]) / (math.pi / 4.0)
        on_ray += int(np.count_nonzero(np.abs(turns - np.round(turns)) < 1e-9))
    assert sum(len(p) for p in got.values()) > 100
    assert on_ray > 0 or not on_rays  # a grid's targets on an octant's bounding ray


@pytest.fixture(scope="module")
def dense():
    """A map whose taut graph is radius-limited (> 4 x 250 targets)."""
    prob = scenario_problem(random_buildings(400, seed=1, size=1500.0))
    cache = EdgeCache(
        prob, graph_nodes(prob), taut=True, prune_collinear=True, local_candidates=250
    )
    assert cache.radius is not None
    return prob


def test_certified_inside_the_ellipse_on_a_radius_limited_map(dense):
    plan = plan_path(dense)
    assert plan.valid and plan.certified and plan.lower_bound_m == plan.length_m


def test_without_room_to_certify_the_bound_is_the_straight_line(dense):
    old = search.CERTIFY_NODES
    try:
        search.CERTIFY_NODES = 10
        plan = plan_path(dense)
    finally:
        search.CERTIFY_NODES = old
    assert plan.valid and not plan.certified
    straight = float(np.hypot(*(dense.goal - dense.start)))
    assert plan.lower_bound_m == pytest.approx(straight)
    assert plan.lower_bound_m < plan.length_m


def _record_ellipses(monkeypatch) -> list[tuple[float, bool]]:
    """Every ellipse cache the planner builds from now on, as (L, taut), in order."""
    made: list[tuple[float, bool]] = []
    original = search._Planner.certify_cache

    def certify_cache(self, length, taut=False):
        made.append((length, taut))
        return original(self, length, taut)

    monkeypatch.setattr(search._Planner, "certify_cache", certify_cache)
    return made


def test_where_the_taut_graph_lacks_a_bend_the_full_graph_is_searched_at_the_same_bound(
    dense, monkeypatch
):
    """On a radius-limited map, when the taut graph has no valid path inside the ellipse
    (here: it may bend nowhere but at A and B), the full graph is searched with the same
    bound and its path is certified as a taut one would be. Before, the ellipse grew until
    it outgrew CERTIFY_NODES and the path found came uncertified from the radius-limited
    graphs (a Vienna street: 47 s instead of 4 s)."""
    expected = plan_path(dense)
    monkeypatch.setattr(search, "wraps_corner", lambda d_in, dirs, *_: np.zeros(len(dirs), bool))
    ellipses = _record_ellipses(monkeypatch)
    monkeypatch.setattr(search, "_POLL_EVERY", 1)
    bounds: list[float] = []
    plan = plan_path(dense, lambda state: bounds.append(state.lower_bound_m) or False)
    assert plan.valid and plan.level == "full" and plan.certified
    assert plan.length_m == pytest.approx(expected.length_m, abs=1e-6)
    straight = float(np.hypot(*(dense.goal - dense.start)))
    assert max(length for length, _ in ellipses) < 1.5 * straight  # it did not grow far
    # the taut walks searched in vain went past 1.15 |AB|, the answer is shorter: the
    # progress reports only bounds proven for every valid path
    assert bounds and max(bounds) <= plan.length_m + 1e-6


@pytest.mark.parametrize("seed", [24, 39, 42, 45, 48])
def test_a_certified_path_is_the_shortest_of_the_full_graph(seed):
    """The taut graph's unconstrained length is no lower bound on the full graph's paths: on
    maps 24 and 39 the full graph's shortest path bends at a node on the margin of one
    footprint as it passes another, where the taut graph may not bend, and the taut path
    (844.4 m, 822.9 m) was certified although valid paths 17 m and 29 m shorter exist.
    Certification now asks the full graph of definition 5 (the exact search over all its
    pairs here); the other seeds are drawn maps where the two agreed."""
    prob = scenario_problem(random_buildings(60, seed=seed, size=600.0))
    plan = plan_path(prob)
    assert plan.valid and plan.certified
    assert plan.length_m == pytest.approx(_shortest_over_every_pair(prob, plan), abs=1e-6)


def _shortest_over_every_pair(prob: PathProblem, plan) -> float:
    """The shortest valid path over the full graph of definition 5 with every node pair
    examined (the exhaustive search a certified plan must agree with), for `plan`'s rows."""
    nodes = graph_nodes(prob)
    every_pair = EdgeCache(prob, nodes, taut=False, prune_collinear=True)
    rows = search._RowFilter(prob, plan.rows, nodes)
    shortest = search._exact_level(prob, every_pair, rows, search._Budget(10**8))
    assert every_pair.radius is None and shortest.status == "found"
    return search._length(shortest.path)


def test_a_grown_ellipse_is_searched_in_the_full_graph_and_its_path_comes_back_proven(
    monkeypatch,
):
    """A wall across the middle makes every route 30 % longer than the straight line, so the
    first ellipse (1.15 |AB|, taut graph) holds none. The grown one is searched in the full
    graph of definition 5 at once, and its path is the full graph's shortest (the exhaustive
    search over every pair agrees): no taut search of the grown ellipse, no third ellipse
    to certify it."""
    monkeypatch.setattr(search, "LOCAL_CANDIDATES", 40)  # radius-limited: ellipses first
    monkeypatch.setattr(search, "LOCAL_CANDIDATES_FULL", 40)
    base = random_buildings(80, seed=3, size=900.0)
    middle = (base.start + base.goal) / 2.0
    along = (base.goal - base.start) / np.hypot(*(base.goal - base.start))
    across = np.array([-along[1], along[0]])
    wall = np.array([[middle - 420.0 * across, middle + 420.0 * across]])
    prob = problem(base.start, base.goal, Obstacles(polygons=base.obstacles.polygons, walls=wall))
    ellipses = _record_ellipses(monkeypatch)
    plan = plan_path(prob)
    straight = float(np.hypot(*(prob.goal - prob.start)))
    assert plan.valid and plan.certified and plan.level == "full"
    assert plan.length_m > search.ELLIPSE_START * straight
    assert [taut for _, taut in ellipses] == [True, False]
    assert plan.length_m == pytest.approx(_shortest_over_every_pair(prob, plan), abs=1e-6)


def _dead_end_bay() -> PathProblem:
    """400 random buildings over 1.5 km (radius-limited graphs), and B in a bay 38 m wide
    and 54 m deep, open to the east, with its row leaving east: every route enters heading
    west, and the last segment must head within 90 degrees of east. A U-turn in the bay
    needs a corner to bend at, and it has none."""
    scenario = random_buildings(400, seed=1, size=1500.0)
    bay = shapely.box(1380.0, 1400.0, 1440.0, 1450.0).difference(
        shapely.box(1386.0, 1406.0, 1450.0, 1444.0)
    )
    around = shapely.box(1340.0, 1340.0, 1500.0, 1500.0)
    rings = scenario.obstacles.polygons
    shapes = scenario.obstacles.geometries[: len(rings)]
    polygons = [
        ring for ring, shape in zip(rings, shapes, strict=True) if not shape.intersects(around)
    ]
    polygons.append(shapely.get_coordinates(bay.exterior)[:-1])
    return problem(scenario.start, (1425.0, 1425.0), Obstacles(polygons=polygons), theta_b=-45.0)


def test_b_in_a_dead_end_is_proven_walled_in_after_the_first_ellipse():
    """B in a dead end whose way out needs a sharp bend: the first ellipse holds no valid
    path, and the walk search from B back to A over complete candidate sets runs dry at
    once. Before, the ellipses grew to 12,000 nodes and the radius-limited graphs were
    searched to the end: the same reason after 363,558 expansions (a Vienna street: no
    answer in 60 s)."""
    plan = plan_path(_dead_end_bay())
    assert not plan.valid
    assert plan.reason.startswith("every route needs a sharp bend at arrival")
    assert plan.expansions < 60_000


def test_b_in_a_box_is_proven_walled_in_when_the_full_graph_is_radius_limited():
    """A map whose taut graph has complete candidate sets and whose full graph does not: when
    the taut graph has no walk, the search from B back to A over complete candidate sets
    proves B walled in, where the radius-limited full graph, searched to the end (61,428
    expansions), proved nothing: it lacks the long edges."""
    prob = scenario_problem(walled_in(random_buildings(200), 40.0, gap=25.0))
    plan = plan_path(prob)
    assert not plan.valid
    assert plan.reason.startswith("every route from A to B needs a bend sharper than 90")
    assert plan.expansions < 10_000


def _a_in_a_box() -> PathProblem:
    """The box round B of `walled_in`, with A and B swapped: A in a box open towards its
    row's direction, so every way out turns more than 90 degrees somewhere."""
    box = walled_in(random_buildings(200), 40.0, gap=25.0)
    return scenario_problem(box, start=box.goal, goal=box.start)


def test_a_in_a_box_is_proven_walled_in_when_the_radius_limited_graphs_run_dry():
    """The forward searches run dry on radius-limited graphs, which proves nothing; the walk
    search from A over complete candidate sets then runs dry too, which does."""
    plan = plan_path(_a_in_a_box())
    assert not plan.valid
    assert plan.reason == search._explain(_a_in_a_box(), "bends")


def test_a_dry_radius_limited_search_says_it_proves_nothing(monkeypatch):
    monkeypatch.setattr(search._Planner, "_pocket", lambda *args, **kwargs: None)
    plan = plan_path(_a_in_a_box())
    assert not plan.valid
    assert plan.reason.endswith(search._RADIUS_LIMITED)
    assert plan.reason.startswith("every route from A to B needs a bend sharper than 90")


def test_b_in_the_open_is_no_pocket(dense):
    planner = search._Planner(dense)
    straight = float(np.hypot(*(dense.goal - dense.start)))
    ellipse = planner.certify_cache(search.ELLIPSE_START * straight, taut=True)
    assert planner._pocket(dense.rows(3), GOAL, ellipse) is None
    assert planner.budget.used <= 2 * search.END_EXPANSIONS


def _stop_after(polls: int):
    seen: list[SearchProgress] = []

    def progress(state: SearchProgress) -> bool:
        seen.append(state)
        return len(seen) >= polls

    return progress, seen


def test_a_stop_request_before_any_path_gives_an_invalid_plan_that_says_so():
    prob = scenario_problem(city_grid(12, 10, block=40.0, street=16.0))
    progress, seen = _stop_after(1)
    plan = plan_path(prob, progress)
    assert not plan.valid and plan.stopped
    assert "stopped" in plan.reason and "time limit" in plan.reason
    assert math.isnan(seen[0].best_length_m)


def test_a_stop_request_after_a_path_returns_it_marked_not_certified(monkeypatch):
    # The shortest walk breaks condition (5): the quick (weighted) repair finds a valid path,
    # then the exact repair runs. Asked at every expansion, stop once a path is known.
    bound = problem(**REPAIR, radio_range=400.0)
    full = plan_path(bound)
    assert full.valid and full.certified and full.repairs == 1
    monkeypatch.setattr(search, "_POLL_EVERY", 1)
    plan = plan_path(bound, lambda state: not math.isnan(state.best_length_m))
    assert plan.valid and plan.stopped and not plan.certified
    assert check_path(plan.path, bound, plan.rows).ok
    assert plan.lower_bound_m <= full.length_m + 1e-6 <= plan.length_m + 1e-6


def test_progress_reports_grow_and_bound_the_answer():
    prob = scenario_problem(random_buildings(60, seed=4, size=1000.0))
    seen: list[SearchProgress] = []
    plan = plan_path(prob, lambda s: seen.append(s) or False)
    assert plan.valid and not plan.stopped and seen
    expansions = [s.expansions for s in seen]
    assert expansions == sorted(expansions)
    assert all(s.lower_bound_m <= plan.length_m + 1e-6 for s in seen)


def test_vertices_are_stored_flat_whatever_the_largest_polygon():
    ring = np.column_stack([np.cos(np.linspace(0, 2 * math.pi, 400, endpoint=False))] * 2)
    ring[:, 1] = np.sin(np.linspace(0, 2 * math.pi, 400, endpoint=False))
    big = 100.0 * ring + [500.0, 500.0]
    small = [square(20.0 * k, -100.0, 5.0) for k in range(50)]
    obstacles = Obstacles(polygons=(big, *small))
    points, offsets = obstacles.vertices
    assert points.shape == (400 + 50 * 4, 2)
    assert offsets[-1] == len(points) and np.all(np.diff(offsets) == [400] + [4] * 50)
    prob = problem([300.0, 300.0], [700.0, 700.0], obstacles)
    plan = plan_path(prob)
    assert plan.valid and check_path(plan.path, prob, plan.rows).ok


def _donut_and_blocks() -> tuple[Obstacles, shapely.Polygon]:
    """A courtyard building (a polygon with a hole), blocks, a wall and a point-like wall."""
    outer = square(0.0, 0.0, 120.0)
    court = shapely.Polygon(outer, [square(30.0, 30.0, 60.0)[::-1]])
    blocks = [square(200.0 + 45.0 * k, 20.0 + 13.0 * k, 25.0) for k in range(5)]
    return Obstacles(
        polygons=(*blocks,),
        walls=np.array([[[-60.0, 200.0], [150.0, 260.0]], [[300.0, 300.0], [300.0, 300.0]]]),
    ), court


def test_a_scanline_fill_finds_the_cell_centres_inside_polygons_with_holes():
    """One geometry or many that overlap (the buffered footprints, not merged first: a
    union of a city costs seconds), holes and a polygon in another's hole included."""
    obstacles, court = _donut_and_blocks()
    parts = [court, *shapely.buffer(obstacles.geometries, 3.0, quad_segs=4)]
    parts += [shapely.box(100.0, 50.0, 160.0, 70.0), shapely.box(40.0, 40.0, 50.0, 50.0)]
    parts += [shapely.box(205.0, 25.0, 240.0, 60.0)]  # across the first block
    area = shapely.union_all(parts)
    origin, cell, shape = np.array([-80.0, -40.0]), 1.7, (300, 220)
    xs = origin[0] + cell * (np.arange(shape[0]) + 0.5)
    ys = origin[1] + cell * (np.arange(shape[1]) + 0.5)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    expected = shapely.contains_xy(area, gx.ravel(), gy.ravel()).reshape(shape)
    assert (
        expected.sum() > 1000
        and not expected[(xs > 55) & (xs < 85)][:, (ys > 55) & (ys < 85)].any()
        and expected[(xs > 41) & (xs < 49)][:, (ys > 41) & (ys < 49)].all()
    )
    overlap = shapely.area(shapely.intersection(np.array(parts)[:, None], parts))
    assert np.count_nonzero(np.triu(overlap, 1) > 1.0) >= 2  # the polygons do overlap
    assert np.array_equal(_cell_centres_inside(area, origin, cell, shape), expected)
    assert np.array_equal(_cell_centres_inside(np.array(parts), origin, cell, shape), expected)


def test_the_core_grid_blocks_only_segments_that_come_too_close_and_most_that_cross():
    obstacles, court = _donut_and_blocks()
    obstacles = Obstacles(polygons=(*obstacles.polygons, np.asarray(court.exterior.coords)[:-1]))
    rng = np.random.default_rng(13)
    starts = rng.uniform(-100.0, 500.0, (20000, 2))
    ends = starts + rng.normal(0.0, 150.0, (20000, 2))
    grid = obstacles.core_grid((-100.0, -100.0, 500.0, 500.0), 5.0)
    blocked = grid.blocks(starts, ends)
    close = obstacles.segments_within(np.stack([starts, ends], axis=1), 5.0)
    crossing = shapely.intersects(
        shapely.union_all(obstacles.geometries), shapely.linestrings(np.stack([starts, ends], 1))
    )
    assert not np.any(blocked & ~close)  # sound: never blocks a clear segment
    inside_grid = np.all((starts > -100) & (starts < 500) & (ends > -100) & (ends < 500), axis=1)
    assert np.all(blocked[crossing & inside_grid])  # every crossing inside the grid is caught
    assert blocked.sum() > 0.5 * close.sum()


def test_segments_are_tested_alike_before_and_after_the_prepared_union(monkeypatch):
    """The first segments go to the STRtree (a city's union costs seconds to build), the
    later ones to the prepared union: both give every segment the same answer, solids
    (a segment wholly inside one), walls and a zero-length wall included."""
    obstacles, court = _donut_and_blocks()
    rng = np.random.default_rng(5)
    starts = rng.uniform(-100.0, 500.0, (6000, 2))
    ends = starts + rng.normal(0.0, 60.0, (6000, 2))
    inside = rng.uniform([205.0, 25.0], [218.0, 38.0], (50, 2))  # in the first block
    starts[:50], ends[:50] = inside, inside + 2.0
    segments = np.stack([starts, ends], axis=1)
    monkeypatch.setattr(Obstacles, "UNION_VERTICES", 0)  # as for a city of footprints
    fresh = Obstacles(polygons=obstacles.polygons, walls=obstacles.walls)
    tree = fresh.segments_within(segments, 5.0)
    assert "_prepared_union" not in fresh.__dict__
    monkeypatch.setattr(Obstacles, "UNION_AFTER", 0)
    union = obstacles.segments_within(segments, 5.0)
    assert "_prepared_union" in obstacles.__dict__
    assert tree[:50].all() and 0.05 < tree.mean() < 0.9
    assert np.array_equal(tree, union)


def test_the_verdict_table_answers_as_a_dict_would():
    """Pair verdicts are stored a whole array at a time (`graph._KeyTable`): through growth,
    keys given twice in one call and keys stored before (which keep their first value), it
    answers every look-up as a dict filled the same way would."""
    rng = np.random.default_rng(8)
    table, truth = graph._KeyTable(), {}
    for batch in range(120):
        keys = rng.integers(0, 50_000 if batch % 2 else 2**40, int(rng.integers(0, 4000)))
        values = rng.integers(0, 2, len(keys)).astype(np.int8)
        asked = np.concatenate([rng.integers(0, 50_000, 2000), keys[:50]])
        expected = np.array([truth.get(int(k), -1) for k in asked], np.int8)
        assert np.array_equal(table.get(asked), expected)
        table.put(keys, values)
        given: dict[int, set[int]] = {}
        for k, v in zip(keys.tolist(), values.tolist(), strict=True):
            if k not in truth:
                given.setdefault(k, set()).add(v)
        stored = table.get(np.array(list(given), np.int64))
        assert all(int(s) in given[k] for k, s in zip(given, stored, strict=True))
        truth.update(zip(given, stored.tolist(), strict=True))
    assert len(truth) > 100_000 and table._count >= len(truth)
    everything = np.array(list(truth), np.int64)
    assert np.array_equal(table.get(everything), np.array(list(truth.values()), np.int8))
