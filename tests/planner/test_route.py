"""Routes through monitoring stations (docs/design.md 7): one path meeting definition 4 as a whole,
stations for the fewest UAVs, refusals naming the point. Checked by an independent checker of
definition 4 written here (numpy and shapely distances, not the planner's own check)."""

from __future__ import annotations

import math

import numpy as np
import shapely
from hypothesis import HealthCheck, assume, event, given, note, settings

from planner.formation import (
    DISTANCE_TOLERANCE,
    collision_spacing,
    radio_spacing,
    row_direction,
)
from planner.obstacles import Obstacles
from planner.route import RouteProblem, plan_route
from planner.stations import route_length, visit_order, visit_orders
from tests.planner_maps import RHO, route_maps, square

TOL = 1e-6


def route_problem(points, obstacles=None, start=(0.0, 0.0), **kw) -> RouteProblem:
    return RouteProblem(
        start=np.array(start, float),
        points=np.array(points, float),
        start_angle_deg=kw.pop("theta_a", 0.0),
        safety_margin=kw.pop("safety_margin", RHO),
        radio_range=kw.pop("radio_range", 100.0),
        obstacles=obstacles if obstacles is not None else Obstacles(),
        **kw,
    )


def independent_violations(problem: RouteProblem, plan) -> list[str]:
    """Definition 4 for the whole route A .. P_m with the parking row Delta_A behind A."""
    path = plan.path
    rho = problem.safety_margin
    found = []
    segs = shapely.linestrings(np.stack([path[:-1], path[1:]], axis=1))
    vec = np.diff(path, axis=0)
    first_point = problem.points[plan.order[0]]
    e0 = row_direction(problem.start, first_point, problem.start_angle_deg)
    row_length = (plan.fleet_size - 1) * collision_spacing(rho) + rho
    row = shapely.LineString([problem.start, problem.start - row_length * e0])
    if len(problem.obstacles):
        clearance = np.min(
            shapely.distance(segs[:, None], problem.obstacles.geometries[None, :]), axis=1
        )
        if np.any(clearance < rho - TOL):
            found.append(f"obstacle clearance {clearance.min():.6f}")
    if len(segs) > 1 and np.any(shapely.distance(segs[1:], row) < 2 * rho - TOL):
        found.append("a segment after the first comes within 2 rho_c of Delta_A")
    if vec[0] @ e0 < -1e-9 * np.hypot(*vec[0]):
        found.append("the first segment turns more than 90 degrees from e_0")
    dots = np.sum(vec[:-1] * vec[1:], axis=1)
    if np.any(dots < -1e-9 * np.hypot(*vec[:-1].T) * np.hypot(*vec[1:].T)):
        found.append("a bend over 90 degrees")
    count = len(segs)
    for i in range(count):
        for j in range(i + 2, count):
            if shapely.distance(segs[i], segs[j]) < 2 * rho - TOL:
                found.append(f"segments {i} and {j} closer than 2 rho_c")
    visited = problem.points[plan.order]
    for point, index in zip(visited, plan.point_index, strict=True):
        if np.any(np.abs(path[index] - point) > TOL):
            found.append(f"point {point} is not on the route at {index}")
    if np.any(np.diff(plan.point_index) <= 0):
        found.append("points not visited in order")
    return found


def check_layout(problem: RouteProblem, plan) -> None:
    rho, radio = problem.safety_margin, problem.radio_range
    stations = plan.layout.stations
    gaps = -np.diff(np.concatenate([stations, [0.0]]))
    assert np.all(gaps >= collision_spacing(rho) - TOL)
    assert np.all(gaps <= radio_spacing(rho, radio) + TOL)
    held = stations[plan.layout.holders - 1]
    np.testing.assert_allclose(held, plan.point_distance, atol=TOL)
    assert plan.fleet_size == len(stations)
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(plan.path, axis=0).T))])
    np.testing.assert_allclose(along[plan.point_index], plan.point_distance, atol=TOL)


def test_open_map_route_passes_every_point_in_order_with_the_fewest_uavs():
    problem = route_problem([[200, 0], [200, 150], [50, 150]], order="given")
    plan = plan_route(problem)
    assert plan.valid, plan.reason
    assert independent_violations(problem, plan) == []
    np.testing.assert_array_equal(plan.order, [0, 1, 2])
    # straight legs: 200 + 150 + 150 m, each point a corner of 90 degrees at most
    assert math.isclose(plan.length_m, 500.0, abs_tol=1e-6)
    check_layout(problem, plan)
    spacing = radio_spacing(RHO, 100.0)  # 90 m
    assert plan.fleet_size == 3 + 2 + 2  # ceil(200/90) + ceil(150/90) + ceil(150/90)
    assert plan.layout.holders.tolist() == [5, 3, 1]
    assert plan.layout.stations[-1] <= spacing


def test_a_sharp_turn_at_a_point_is_rounded_by_the_next_leg():
    # P2 lies behind P1 and beside the first leg: the second leg may not turn more than
    # 90 degrees at P1 and must keep 2 rho_c from the first leg.
    problem = route_problem([[200, 0], [60, 30]], order="given")
    plan = plan_route(problem)
    assert plan.valid, plan.reason
    assert independent_violations(problem, plan) == []
    assert len(plan.path) > 3  # not the straight U-turn


def test_a_point_on_the_route_behind_is_refused_naming_it():
    problem = route_problem([[200, 0], [100, 0]], order="given", names=("far", "middle"))
    plan = plan_route(problem)
    assert not plan.valid
    assert plan.failed_point == 1
    assert "'middle'" in plan.reason and "from 'far'" in plan.reason


def test_an_enclosed_point_is_refused_naming_it():
    # a closed courtyard: four walls round (150, 0), the point inside it
    ring = np.array(shapely.Polygon(square(90, -60, 120)).exterior.coords)
    walls = Obstacles(walls=np.stack([ring[:-1], ring[1:]], axis=1))
    problem = route_problem([[300, 0], [150, 0]], walls, order="given", names=("out", "yard"))
    plan = plan_route(problem)
    assert not plan.valid
    assert plan.failed_point == 1 and "'yard'" in plan.reason


def test_tsp_order_visits_the_near_point_first():
    problem = route_problem([[400, 0], [100, 0]])
    plan = plan_route(problem)
    assert plan.valid, plan.reason
    assert plan.order.tolist() == [1, 0]
    assert independent_violations(problem, plan) == []


def test_a_fixed_fleet_size_keeps_the_extra_uavs_as_relays():
    problem = route_problem([[200, 0]], fleet_size=5)
    plan = plan_route(problem)
    assert plan.valid, plan.reason
    assert plan.fleet_size == 5 and len(plan.layout.stations) == 5
    check_layout(problem, plan)


@settings(
    max_examples=80,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow],
)
@given(route_maps())
def test_every_planned_route_meets_definition_4_as_a_whole(problem):
    points = problem.points
    apart = np.hypot(*(points[:, None] - points[None]).T)
    np.fill_diagonal(apart, np.inf)
    assume(apart.min() > 2 * collision_spacing(problem.safety_margin))
    assume(
        np.all(np.hypot(*(points - problem.start).T) > 2 * collision_spacing(problem.safety_margin))
    )
    if len(problem.obstacles):
        assume(
            np.all(
                problem.obstacles.distance_to_points(points)
                > problem.safety_margin + DISTANCE_TOLERANCE
            )
        )
    plan = plan_route(problem)
    note(plan.reason)
    event("valid" if plan.valid else "refused")
    event(f"orders tried: {plan.orders_tried}")
    if not plan.valid:
        assert plan.reason
        return
    assert independent_violations(problem, plan) == []
    check_layout(problem, plan)


def test_when_the_shortest_order_breaks_at_a_point_the_next_orders_are_tried():
    rectangles = [
        [[122.5, 216.5], [161.9, 248.4], [149.1, 264.3], [109.7, 232.3]],
        [[194.7, 21.0], [244.9, 56.4], [231.9, 74.8], [181.7, 39.4]],
        [[269.1, 100.6], [272.6, 151.5], [181.6, 157.8], [178.1, 106.8]],
        [[121.6, 173.4], [180.4, 173.5], [180.3, 215.7], [121.5, 215.6]],
        [[404.8, 44.0], [424.2, 69.5], [338.2, 135.0], [318.8, 109.6]],
        [[230.1, 192.1], [240.2, 198.8], [191.5, 271.9], [181.4, 265.1]],
        [[82.1, 157.7], [123.4, 220.6], [96.0, 238.6], [54.7, 175.7]],
    ]
    obstacles = Obstacles(polygons=tuple(np.array(r) for r in rectangles))
    points = [[154.4, 222.5], [302.8, 65.6], [340.5, 197.3]]
    problem = route_problem(points, obstacles, start=(10.0, 150.0))
    shortest = visit_orders(problem.start, problem.points, "tsp", 2)
    for order in shortest:  # the two shortest orders break at a point ...
        given = route_problem(
            np.array(points)[order], obstacles, start=(10.0, 150.0), order="given"
        )
        assert not plan_route(given).valid
    plan = plan_route(problem)  # ... the third is flown
    assert plan.valid, plan.reason
    assert plan.orders_tried == 3
    assert independent_violations(problem, plan) == []
    check_layout(problem, plan)
    # a fixed order is never changed
    fixed = route_problem(points, obstacles, start=(10.0, 150.0), order="given")
    assert plan_route(fixed).orders_tried == 1


def test_visit_orders_lists_the_shortest_orders_first():
    points = np.array([[100.0, 0.0], [0.0, 100.0], [100.0, 100.0], [50.0, 40.0]])
    orders = visit_orders(np.zeros(2), points, "tsp", 5)
    assert len(orders) == 5 and len({tuple(o) for o in orders}) == 5
    lengths = [route_length(np.zeros(2), points, o) for o in orders]
    assert lengths == sorted(lengths)
    np.testing.assert_array_equal(orders[0], visit_order(np.zeros(2), points, "tsp"))
    assert len(visit_orders(np.zeros(2), points, "given", 5)) == 1
