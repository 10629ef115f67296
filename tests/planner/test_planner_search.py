"""Graph nodes (docs/design.md 3.1), edges (def. 5, docs/design.md 3.2) and the search
(docs/design.md 3.3) on hand-made maps, including the diagnosis when no valid path exists."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from planner import search
from planner.formation import SQRT2, collision_spacing, min_fleet_size, parking_rows
from planner.graph import GOAL, KIND_OBSTACLE, KIND_ROW, START, edge_ok, graph_nodes
from planner.obstacles import Obstacles
from planner.scenarios import city_grid, paper_scenario, random_buildings, scenario_problem
from planner.search import plan_path
from planner.validity import check_path
from tests.planner_maps import REPAIR, RHO, problem, square


def ring_walls(ring):
    return np.stack([ring, np.roll(ring, -1, axis=0)], axis=1)


def assert_valid(plan, pb):
    assert plan.valid, plan.reason
    assert check_path(plan.path, pb, plan.rows).ok
    length = float(np.sum(np.hypot(*np.diff(plan.path, axis=0).T)))
    assert plan.length_m == pytest.approx(length)
    assert plan.min_fleet_size == min_fleet_size(length, pb.safety_margin, pb.radio_range)
    assert plan.fleet_size >= plan.min_fleet_size


# ------------------------------------------------------------------------------ nodes


def test_nodes_of_a_square_corners_merged_and_side_nodes_flat():
    pb = problem(
        (-100.0, 5.0), (100.0, 5.0), Obstacles(polygons=(square(0, 0, 10),)), safety_margin=1.0
    )
    nodes = graph_nodes(pb)
    obstacle = nodes.kind == KIND_OBSTACLE
    # 16 raw nodes (eq. 39): the 4 outer corner pairs merge, 8 side nodes stay.
    assert obstacle.sum() == 12
    assert (nodes.kind == KIND_ROW).sum() == 4
    pts = nodes.points[obstacle]
    outer = {(-1.0, -1.0), (11.0, -1.0), (11.0, 11.0), (-1.0, 11.0)}
    assert outer <= {tuple(np.round(p, 9)) for p in pts}
    corner_dist = pb.obstacles.distance_to_points(nodes.points[obstacle])
    assert np.sum(np.isclose(corner_dist, SQRT2)) == 4  # outer corners: rho sqrt 2
    assert np.sum(np.isclose(corner_dist, 1.0)) == 8  # side nodes hug a side at rho
    assert np.array_equal(nodes.flat[obstacle], np.isclose(corner_dist, 1.0))
    assert nodes.prunable[obstacle].all()
    np.testing.assert_allclose(nodes.points[[START, GOAL]], [[-100.0, 5.0], [100.0, 5.0]])


def test_nodes_of_a_wall_use_d_at_the_d_end_erratum_of_eq_39():
    pb = problem(
        (-100.0, 0.0), (100.0, 50.0), Obstacles(walls=np.array([[[0.0, 0.0], [30.0, 0.0]]]))
    )
    pts = {tuple(np.round(p, 9)) for p in graph_nodes(pb).points}
    assert {(-5.0, -5.0), (-5.0, 5.0), (35.0, -5.0), (35.0, 5.0)} <= pts


def test_nodes_inside_a_margin_are_dropped_and_row_nodes_sit_beside_a_and_b():
    overlapping = Obstacles(polygons=(square(0, 0, 20), square(10, 10, 20)))
    pb = problem((-50.0, 0.0), (80.0, 0.0), overlapping, theta_a=30.0)
    nodes = graph_nodes(pb)
    assert np.all(pb.obstacles.distance_to_points(nodes.points[2:]) >= RHO - 1e-6)
    assert len(nodes) < 2 + 4 + 2 * 16  # the reflex corner's nodes are gone
    rows = nodes.points[nodes.kind == KIND_ROW]
    np.testing.assert_allclose(np.hypot(*(rows[:2] - pb.start).T), RHO * SQRT2)
    e0 = np.array([math.cos(math.radians(30.0)), math.sin(math.radians(30.0))])
    np.testing.assert_allclose((rows[:2] - pb.start) @ e0, 0.0, atol=1e-9)  # perpendicular


# ------------------------------------------------------------------------------ edges


def test_edge_hugging_exactly_rho_is_an_edge_and_closer_is_not():
    pb = problem((-50.0, -20.0), (60.0, -20.0), Obstacles(polygons=(square(0, 0, 10),)))
    rows = parking_rows(pb.start, pb.goal, 0.0, 0.0, 1, RHO)
    starts = np.array([[-5.0, -5.0], [-5.0, -5.0 + 1e-3], [-5.0, -5.0 + 5e-7]])
    ends = np.array([[15.0, -5.0], [15.0, -5.0 + 1e-3], [15.0, -5.0 + 5e-7]])
    assert edge_ok(pb, rows, starts, ends).tolist() == [True, False, True]


def test_row_tests_exempt_edges_leaving_a_or_reaching_b_and_kill_the_a_b_side_nodes():
    pb = problem((0.0, 0.0), (100.0, 0.0))
    rows = parking_rows(pb.start, pb.goal, 0.0, 0.0, 3, RHO)
    # from A along the row's side (exempt from Delta_A) and straight to B (exempt from Delta_B)
    assert edge_ok(pb, rows, [[0.0, 0.0]], [[100.0, 0.0]]).all()
    nodes = graph_nodes(pb)
    side = nodes.points[nodes.kind == KIND_ROW]  # A+, A-, B+, B-
    far = np.array([[50.0, 80.0]] * 4)
    assert not edge_ok(pb, rows, side[:2], far[:2]).any()  # leaving A+-: within 2 rho of Delta_A
    assert not edge_ok(pb, rows, far[2:], side[2:]).any()  # reaching B+-: within 2 rho of Delta_B


def test_departure_and_arrival_angles_admit_exactly_90_degrees():
    pb = problem((0.0, 0.0), (100.0, 0.0))
    rows = parking_rows(pb.start, pb.goal, 0.0, 0.0, 1, RHO)
    assert edge_ok(pb, rows, [[0.0, 0.0]], [[0.0, 50.0]]).all()  # exactly 90 degrees
    assert not edge_ok(pb, rows, [[0.0, 0.0]], [[-0.01, 50.0]]).any()
    assert edge_ok(pb, rows, [[100.0, 50.0]], [[100.0, 0.0]]).all()
    assert not edge_ok(pb, rows, [[100.01, 50.0]], [[100.0, 0.0]]).any()


# ------------------------------------------------------------------------------ search


def test_free_map_gives_the_straight_line():
    pb = problem((0.0, 0.0), (300.0, 400.0))
    plan = plan_path(pb)
    assert_valid(plan, pb)
    np.testing.assert_allclose(plan.path, [[0.0, 0.0], [300.0, 400.0]])
    assert plan.iterations == 1 and plan.level == "taut"
    assert plan.fleet_size == plan.min_fleet_size == 3  # ceil(500 / 210)


def test_round_one_square_hugging_its_corners():
    pb = problem(
        (-20.0, 5.0), (30.0, 5.0), Obstacles(polygons=(square(0, 0, 10),)), safety_margin=1.0
    )
    plan = plan_path(pb)
    assert_valid(plan, pb)
    assert plan.length_m == pytest.approx(2 * math.hypot(19.0, 6.0) + 12.0)
    assert len(plan.path) == 4
    np.testing.assert_allclose(np.abs(plan.path[1:3, 1] - 5.0), [6.0, 6.0])


def test_u_turn_round_a_wall_end_with_exact_rho_and_exact_right_angles():
    wall = Obstacles(walls=np.array([[[0.0, 0.0], [0.0, 100.0]]]))
    pb = problem((-5.0, 50.0), (5.0, 50.0), wall, theta_a=90.0, theta_b=-90.0)
    plan = plan_path(pb)
    assert_valid(plan, pb)
    np.testing.assert_allclose(plan.path, [[-5, 50], [-5, 105], [5, 105], [5, 50]], atol=1e-9)
    assert plan.length_m == pytest.approx(120.0)


def test_arrival_from_beyond_b_needs_a_loop_round_an_obstacle():
    # theta_B = 180: the UAVs must reach B heading back towards A, so the path passes B,
    # turns round the wall beyond it and comes back.
    wall = Obstacles(walls=np.array([[[90.0, -30.0], [90.0, 30.0]]]))
    pb = problem((0.0, 0.0), (40.0, 0.0), wall, theta_b=180.0, radio_range=400.0)
    plan = plan_path(pb)
    assert_valid(plan, pb)
    assert plan.path[:, 0].max() > 90.0  # went round the wall
    last = plan.path[-1] - plan.path[-2]
    assert last @ plan.rows.goal_direction > 0.0  # arrives heading along e_K


def test_walls_are_not_solid_a_start_inside_a_walled_box_is_planned_but_boxed_in():
    box = ring_walls(square(-100, -100, 200))
    pb = problem((0.0, 0.0), (300.0, 0.0), Obstacles(walls=box))
    plan = plan_path(pb)
    assert not plan.valid
    assert plan.reason.startswith("B is unreachable"), plan.reason
    solid = problem((0.0, 0.0), (300.0, 0.0), Obstacles(polygons=(square(-100, -100, 200),)))
    assert "lies inside obstacle 0" in plan_path(solid).reason


def test_goal_enclosed_by_walls_is_unreachable_and_says_so_quickly():
    box = ring_walls(square(180, -20, 40))
    pb = problem((0.0, 0.0), (200.0, 0.0), Obstacles(walls=box))
    plan = plan_path(pb)
    assert not plan.valid and plan.reason.startswith("B is unreachable")
    assert plan.path.shape == (0, 2)
    assert plan.expansions < 1000


@pytest.mark.parametrize(
    ("theta_a", "theta_b", "fragment"),
    [
        (0.0, 180.0, "sharp bend at arrival"),
        (180.0, 0.0, "sharp bend at departure"),
        (180.0, 180.0, "sharp bends at both departure and arrival"),
    ],
)
def test_sharp_departure_or_arrival_on_an_open_map(theta_a, theta_b, fragment):
    # No obstacle corner to turn round: every route turns more than 90 degrees at A or B.
    plan = plan_path(problem((0.0, 0.0), (100.0, 0.0), theta_a=theta_a, theta_b=theta_b))
    assert not plan.valid
    assert fragment in plan.reason


def test_every_route_needing_a_sharp_bend_in_the_middle_is_diagnosed():
    # Only route: into a dead-end slot 8 m wide (too narrow to turn round in) and back.
    walls = np.array([[[0.0, 4.0], [200.0, 4.0]], [[0.0, -4.0], [200.0, -4.0]]])
    obstacles = Obstacles(walls=walls, polygons=(square(60.0, -100.0, 20.0),))
    pb = problem((-20.0, 60.0), (-20.0, -60.0), obstacles, theta_a=-90.0, theta_b=90.0)
    plan = plan_path(pb)
    if plan.valid:  # the map allows it after all: then the path must be valid
        assert_valid(plan, pb)
    else:
        assert plan.reason


def test_cap_counted_in_expansions():
    pb = scenario_problem(city_grid(8, 8), max_expansions=20)
    plan = plan_path(pb)
    assert not plan.valid
    assert "cap of 20 expansions" in plan.reason
    assert plan.expansions <= 21


def test_fleet_size_grows_with_the_path_and_rows_follow():
    # Straight line 100 m: 1 UAV (dS_r = 110 m); the detour makes the path need 2.
    block = Obstacles(polygons=(square(10.0, -40.0, 60.0),))
    pb = problem((0.0, 0.0), (100.0, 0.0), block, radio_range=120.0)
    plan = plan_path(pb)
    assert_valid(plan, pb)
    assert plan.length_m > 110.0
    assert plan.fleet_size == plan.min_fleet_size == 2
    row_length = np.hypot(*(plan.rows.start_row[1] - plan.rows.start_row[0]))
    assert row_length == pytest.approx(collision_spacing(RHO) + RHO)
    fixed = plan_path(problem((0.0, 0.0), (100.0, 0.0), block, radio_range=120.0, fleet_size=4))
    assert fixed.valid and fixed.fleet_size == 4 and fixed.min_fleet_size == 2


def test_growing_rows_that_hit_an_obstacle_are_refused_with_the_reason():
    # the second square sits 12..18 m behind A: clear of a 1-UAV row (5 m), not of 2 (19.1 m)
    block = Obstacles(polygons=(square(10.0, -40.0, 60.0), square(-18.0, -3.0, 6.0)))
    pb = problem((0.0, 0.0), (100.0, 0.0), block, radio_range=120.0)
    plan = plan_path(pb)
    assert not plan.valid
    assert "needs 2 UAVs (eq. 28)" in plan.reason and "eq. 14" in plan.reason


def test_ray_parking_forbids_obstacles_anywhere_behind_a():
    behind = Obstacles(polygons=(square(-500.0, -5.0, 10.0),))
    assert plan_path(problem((0.0, 0.0), (100.0, 0.0), behind)).valid
    ray = plan_path(problem((0.0, 0.0), (100.0, 0.0), behind, parking="ray"))
    assert not ray.valid and "eq. 14" in ray.reason


def test_repair_of_condition_5_finds_the_valid_path():
    pb = problem(**REPAIR, radio_range=400.0)
    plan = plan_path(pb)
    assert_valid(plan, pb)
    assert plan.repairs == 1 and plan.iterations == 2
    assert plan.length_m == pytest.approx(332.38, abs=0.01)
    assert plan.certified


def test_a_walk_bending_at_both_ends_of_a_short_edge_is_never_the_first_walk():
    # The shortest walk meeting (1)-(4) turns round two corners 2.8 m apart, one each way:
    # the segments either side of that edge come within 2 rho_c (condition 5). The walk
    # search knows that much of (5), so its first walk is already the valid path: no repair.
    pb = problem(
        (0.0, 0.0),
        (200.0, 0.0),
        Obstacles(
            polygons=(
                np.array([[120.2, -2.6], [154.1, -2.6], [154.1, 16.2], [120.2, 16.2]]),
                np.array([[58.5, -12.0], [94.1, -12.0], [94.1, 25.1], [58.5, 25.1]]),
                np.array([[34.6, -60.4], [45.6, -60.4], [45.6, -12.5], [34.6, -12.5]]),
            )
        ),
        radio_range=400.0,
    )
    planner = search._Planner(pb)
    rows = search._RowFilter(pb, pb.rows(1), planner.nodes)
    cache = planner.cache("taut")
    walk, _ = search._walk_search(cache, rows, planner.budget)  # (1)-(4) alone
    path, _ = search._walk_points(cache, walk)
    broken = check_path(path, pb, rows.rows).proximity
    segment = np.hypot(*np.diff(path, axis=0).T)
    assert len(broken) and all(
        j == i + 2 and segment[i + 1] < 2 * RHO for i, j in broken[:, :2].astype(int)
    )
    plan = plan_path(pb)
    assert_valid(plan, pb)
    assert plan.repairs == 0 and plan.iterations == 1 and plan.certified
    assert plan.length_m == pytest.approx(211.878, abs=0.001)


def test_taut_path_under_binding_constraints_is_checked_against_the_full_graph():
    # The departure angle only admits a first segment to the flat node above the block's
    # top side; the taut graph's best valid path (358.7 m) is beaten by the full graph's.
    pb = problem(
        (0.0, 0.0),
        (13.5, -12.9),
        Obstacles(
            polygons=(np.array([[-40.0, -113.0], [-1.5, -113.0], [-1.5, -98.6], [-40.0, -98.6]]),),
            walls=np.array([[[86.7, -128.8], [95.1, -77.7]]]),
        ),
        theta_a=20.0,
        theta_b=135.0,
        radio_range=400.0,
    )
    plan = plan_path(pb)
    assert_valid(plan, pb)
    assert plan.level == "full" and plan.certified
    assert plan.length_m == pytest.approx(288.40, abs=0.01)
    np.testing.assert_allclose(plan.path[1], [-35.0, -93.6], atol=1e-9)


def test_a_gap_tolerance_ends_the_certification_once_the_path_is_proven_within_it():
    # 30 random buildings (seed 6): the taut graph's valid path (567.3 m) is 3.4 % longer
    # than the shortest walk that keeps the rows and parking angles (548.9 m, the bound at
    # A); the shortest valid path (550.8 m) takes a search of the full graph.
    pb = scenario_problem(random_buildings(30, seed=6, size=400.0))
    exact = plan_path(pb)
    assert exact.certified and exact.lower_bound_m == exact.length_m
    assert exact.length_m == pytest.approx(550.785, abs=0.01)
    # 5 %: the bound proves the taut path within it; no full-graph search, not certified
    loose = plan_path(replace(pb, gap_tolerance=0.05))
    assert_valid(loose, pb)
    assert not loose.certified and not loose.stopped and loose.gap_tolerance == 0.05
    assert exact.length_m < loose.length_m <= loose.lower_bound_m / 0.95
    assert loose.lower_bound_m <= exact.length_m
    assert loose.expansions < exact.expansions
    # 2 %: the taut path is not within it: the full graph is searched, its path certified
    narrow = plan_path(replace(pb, gap_tolerance=0.02))
    assert narrow.certified and narrow.length_m == pytest.approx(exact.length_m)


def test_a_path_only_the_rows_and_angles_lengthen_is_certified_without_the_full_graph():
    """Table II map, seed 37: the shortest valid path (1222.07 m) is 4.8 % longer than the
    shortest walk with no rule; the parking rows and angles account for all of it. The
    heuristic keeps them (`GoalDistance` over the row filter's edges), so its value at A
    proves the taut path shortest at once: no search of the full graph (the unconstrained
    value left a 4.8 % gap to close that way)."""
    pb = scenario_problem(paper_scenario(seed=37))
    plan = plan_path(pb)
    assert plan.certified and plan.level == "taut"
    assert plan.length_m == pytest.approx(1222.07, abs=0.01)
    planner = search._Planner(pb)
    rows = search._RowFilter(pb, pb.rows(plan.fleet_size), planner.nodes)
    taut = planner.cache("taut")
    free = search.goal_distance(taut, search._Budget(10**9))[START]
    kept = search.goal_distance(taut, search._Budget(10**9), rows)[START]
    assert free < 0.96 * plan.length_m and kept == pytest.approx(plan.length_m)


def test_gap_tolerance_is_a_fraction_below_one():
    with pytest.raises(ValueError, match="gap_tolerance"):
        replace(scenario_problem(paper_scenario()), gap_tolerance=1.0)


def test_taut_graph_falls_back_to_the_full_graph():
    # The departure rule makes the path dip before climbing over the wall end: a bend that
    # does not wrap its corner, which only the full graph has.
    wall = Obstacles(walls=np.array([[[97.5, -26.2], [52.5, -0.9]]]))
    pb = problem((0.0, 0.0), (8.3, -29.2), wall, theta_a=-10.0, theta_b=185.0, radio_range=400.0)
    plan = plan_path(pb)
    assert_valid(plan, pb)
    assert plan.level == "full"


def test_penalty_method_agrees_on_easy_maps_and_is_capped_on_hard_ones():
    sc = paper_scenario()
    exact = plan_path(scenario_problem(sc))
    penalty = plan_path(scenario_problem(sc, method="penalty"))
    assert penalty.valid and penalty.level == "penalty"
    assert penalty.length_m == pytest.approx(exact.length_m)
    wall = Obstacles(walls=np.array([[[90.0, -30.0], [90.0, 30.0]]]))
    pb = problem(
        (0.0, 0.0), (40.0, 0.0), wall, theta_b=180.0, method="penalty", max_penalty_iterations=3
    )
    plan = plan_path(pb)
    if plan.valid:
        assert_valid(plan, pb)
    else:
        assert "penalty loop" in plan.reason and plan.iterations == 3


def test_paper_scenario_path_is_valid_and_bends():
    sc = paper_scenario()
    plan = plan_path(scenario_problem(sc))
    assert_valid(plan, scenario_problem(sc))
    assert len(plan.path) >= 3
    assert plan.fleet_size in (4, 5)  # docs/design.md 6: eq. 28 gives 4-5 UAVs for this map
    assert plan.candidate_edges.shape[1:] == (2, 2) and len(plan.candidate_edges) > 0


def test_a_zero_length_wall_is_still_an_obstacle():
    # GEOS's prepared predicates skip a degenerate line; the planner must not.
    point_wall = Obstacles(walls=np.array([[[50.0, 3.0], [50.0, 3.0]]]))
    pb = problem((0.0, 0.0), (100.0, 0.0), point_wall)
    straight = check_path(np.array([[0.0, 0.0], [100.0, 0.0]]), pb, plan_path(pb).rows)
    assert straight.obstacle[:, 2].tolist() == [3.0]
    plan = plan_path(pb)
    assert_valid(plan, pb)
    assert len(plan.path) > 2


def test_polygons_with_different_vertex_counts_and_a_concave_one():
    triangle = np.array([[40.0, -20.0], [70.0, -20.0], [55.0, 25.0]])
    concave = np.array([[120.0, -30.0], [160.0, -30.0], [160.0, 30.0], [140.0, 0.0], [120.0, 30.0]])
    obstacles = Obstacles(polygons=(triangle, square(80.0, -5.0, 10.0), concave))
    pb = problem((0.0, 0.0), (200.0, 0.0), obstacles)
    plan = plan_path(pb)
    assert_valid(plan, pb)
    assert len(plan.path) > 2
