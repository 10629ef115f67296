"""One route through monitoring stations (docs/design.md 7, the paper's use case 1, sec. III-C1).

The fleet leaves its parking row at A and visits static points P_1 .. P_m in the order of
`planner.stations.visit_order`; the route A -> P_1 -> ... -> P_m is ONE path that meets
definition 4 as a whole: every bend at most 90 degrees (at the points too) and condition (5)
between any two non-consecutive segments, of the same leg or not. That is what the paper's
"add the path being used as supplementary obstacles" is for; we do it exactly:

* leg j (P_{j-1} -> P_j) is a `PathProblem` whose start row is the route flown so far, from
  P_{j-1} back to A and on along the parking row Delta_A (`PathProblem.start_tail`), with
  e_0 the direction of the previous leg's last segment and no row at its end (`open_goal`).
  The row rules of definition 5 then say exactly what definition 4 asks of the whole route:
  the leg's first segment turns at most 90 degrees from the previous one (the departure
  angle) and keeps 2 rho_c from the rest of the route (`ParkingRows.start_rest`); every later
  segment keeps 2 rho_c from all of it. The directed-edge search and its repair of (5) do the
  rest, as for A -> B.
* the stations s_n of `planner.stations.station_layout` give the fleet size N; the parking
  row sized for N is part of every leg's tail, so the legs are planned again while N grows
  (N only grows, as for A -> B, docs/design.md 3.2).

Each leg is the shortest valid one given the route before it (`certified` says so for every
leg); the route as a whole is not proven shortest (a shorter leg now may force a longer one
later), and a leg that no route before it allows is refused naming its point.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from planner.formation import DISTANCE_TOLERANCE, ParkingRows, radio_spacing
from planner.obstacles import Obstacles
from planner.search import MAX_FLEET_ROUNDS, SearchProgress, plan_path
from planner.stations import (
    StationError,
    StationLayout,
    station_layout,
    visit_order,
    visit_orders,
)
from planner.types import PathPlan, PathProblem
from planner.validity import check_path

__all__ = ["RoutePlan", "RouteProblem", "first_leg", "plan_route"]

#: Visiting orders tried, shortest first, when the shortest one breaks at a point (tsp, at
#: most `planner.stations.EXACT_POINTS` points).
RETRY_ORDERS = 12


@dataclass(frozen=True, eq=False)
class RouteProblem:
    """A: `start`, theta_A (`start_angle_deg`, counter-clockwise from the direction A -> the
    first point visited); `points` (m, 2) and their `names` (for messages); `order` "tsp" or
    "given"; rho_c, rho_R, obstacles, parking mode, a fixed fleet size (None = the fewest the
    stations need), method, caps and `gap_tolerance` as in `PathProblem` (they apply per leg:
    each leg's certification ends once it is proven within the tolerance)."""

    start: np.ndarray
    points: np.ndarray
    start_angle_deg: float
    safety_margin: float
    radio_range: float
    obstacles: Obstacles
    names: tuple[str, ...] = ()
    order: str = "tsp"
    parking: str = "segment"
    fleet_size: int | None = None
    method: str = "exact"
    max_expansions: int = 2_000_000
    gap_tolerance: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", np.asarray(self.start, float).reshape(2))
        points = np.asarray(self.points, float).reshape(-1, 2)
        if len(points) == 0:
            raise ValueError("a route needs at least one point")
        object.__setattr__(self, "points", points)
        if not self.names:
            names = tuple(f"P{i + 1}" for i in range(len(points)))
            object.__setattr__(self, "names", names)
        if len(self.names) != len(points):
            raise ValueError("names must name every point")


@dataclass(frozen=True, eq=False)
class RoutePlan:
    """The planner's answer for a route. `order` lists the points (indices into
    `RouteProblem.points`) in visiting order; `path` (K, 2) is the whole route, A first;
    `point_index` (m,) the index in `path` of each visited point and `point_distance` (m,)
    its distance along the route (both in visiting order); `layout` the stations (UAV n holds
    `layout.stations[n-1]`); `legs` the plan of each leg. `rows` holds Delta_A for
    `fleet_size` UAVs (no row at the end). When `valid` is False, `reason` says why and
    `failed_point` which point (index into `RouteProblem.points`) is at fault, if one is."""

    valid: bool
    reason: str | None
    order: np.ndarray
    path: np.ndarray
    point_index: np.ndarray
    point_distance: np.ndarray
    layout: StationLayout | None
    legs: tuple[PathPlan, ...]
    rows: ParkingRows | None
    fleet_size: int
    length_m: float
    failed_point: int | None = None
    fleet_rounds: int = 1
    stopped: bool = False
    orders_tried: int = 1  # visiting orders planned (> 1: the shorter ones broke at a point)

    @property
    def certified(self) -> bool:
        """Every leg is proven the shortest valid one given the route before it."""
        return bool(self.legs) and all(leg.certified for leg in self.legs)

    @property
    def within_gap(self) -> bool:
        """Not `certified`, but every leg is certified or proven within its gap tolerance."""
        legs = self.legs
        return (
            not self.certified
            and bool(legs)
            and all(leg.certified or (leg.within_gap and not leg.stopped) for leg in legs)
        )

    def path_plan(self) -> PathPlan:
        """The route as one `PathPlan` (level "route"), for what reports a path: the sums
        over the legs, and as lower bound the straight polyline through the points in
        visiting order (each leg's own bound holds only given the route before it)."""
        legs = self.legs
        size = self.fleet_size or (self.layout.fleet_size if self.layout else 1)
        rows = self.rows if self.rows is not None else _empty_rows()
        straight = math.nan
        if self.valid:
            visited = self.path[np.concatenate([[0], self.point_index])]
            straight = float(np.sum(np.hypot(*np.diff(visited, axis=0).T)))
        found = [leg.candidate_edges for leg in legs]
        return PathPlan(
            valid=self.valid,
            reason=self.reason,
            path=self.path,
            length_m=self.length_m,
            fleet_size=size,
            min_fleet_size=self.layout.minimum if self.layout else size,
            rows=rows,
            iterations=sum(leg.iterations for leg in legs),
            expansions=sum(leg.expansions for leg in legs),
            node_count=max((leg.node_count for leg in legs), default=0),
            edges_examined=sum(leg.edges_examined for leg in legs),
            candidate_edges=np.concatenate(found) if found else np.zeros((0, 2, 2)),
            certified=self.certified,
            level="route",
            repairs=sum(leg.repairs for leg in legs),
            fleet_rounds=self.fleet_rounds,
            edge_count=sum(leg.edge_count for leg in legs),
            lower_bound_m=straight,
            stopped=self.stopped,
            gap_tolerance=max((leg.gap_tolerance for leg in legs), default=0.0),
        )


def _empty_rows() -> ParkingRows:
    nowhere = np.zeros((2, 2))
    return ParkingRows(nowhere, nowhere, np.array([1.0, 0.0]), np.array([1.0, 0.0]), True)


def first_leg(problem: RouteProblem, fleet_size: int) -> PathProblem:
    """The first leg, A -> the first point visited, with Delta_A for `fleet_size` UAVs (its
    rows are the route's: eqs. 14-15 are checked on them before planning)."""
    order = visit_order(problem.start, problem.points, problem.order)
    first = problem.points[order[0]]
    return _leg_problem(problem, problem.start, first, _heading_a(problem, order), None, fleet_size)


def _heading_a(problem: RouteProblem, shortest: np.ndarray) -> float:
    """e_0's absolute direction (degrees): theta_A from A -> the first point of `shortest`,
    the shortest visiting order (or the given one)."""
    reference = problem.points[shortest[0]]
    return _direction_deg(reference - problem.start) + problem.start_angle_deg


def _direction_deg(vector: np.ndarray) -> float:
    return math.degrees(math.atan2(vector[1], vector[0]))


def plan_route(
    problem: RouteProblem, progress: Callable[[SearchProgress], bool] | None = None
) -> RoutePlan:
    """Plan the route through every point (docs/design.md 7), or say which point cannot be reached
    and why. `progress` is passed to every leg's search (see `plan_path`).

    With `order="tsp"` and at most `EXACT_POINTS` points, a visiting order whose route breaks
    at a point (a leg that the route before it leaves no way to, a gap the stations cannot
    split) gives way to the next shortest orders, up to `RETRY_ORDERS` of them, legs shared
    by their prefix planned once; the refusal is then the shortest order's. theta_A stays
    relative to A -> the first point of the shortest order."""
    orders = visit_orders(problem.start, problem.points, problem.order, RETRY_ORDERS)
    heading_a = _heading_a(problem, orders[0])
    legs: dict[tuple, tuple[PathPlan, list]] = {}
    first = None
    for tried, order in enumerate(orders, start=1):
        plan = _plan_in_order(problem, order, heading_a, progress, legs)
        if plan.valid or plan.failed_point is None or plan.stopped or not plan.legs[-1].expansions:
            # (a leg refused before any search: the point itself, whatever the order)
            return replace(plan, orders_tried=tried) if first is not None else plan
        first = first or plan
    return replace(first, orders_tried=len(orders))


def _plan_in_order(
    problem: RouteProblem,
    order: np.ndarray,
    heading_a: float,
    progress: Callable[[SearchProgress], bool] | None,
    planned: dict[tuple, tuple[PathPlan, list]],
) -> RoutePlan:
    """The route in one visiting order (legs looked up in `planned` by their prefix and the
    fleet size the parking row is sized for)."""
    points = problem.points[order]
    rho, radio = problem.safety_margin, problem.radio_range
    spacing = radio_spacing(rho, radio)
    if spacing <= 0:
        return _refused(problem, order, "radio_range must exceed 2 * safety_margin")
    straight = np.hypot(*np.diff(np.vstack([problem.start, points]), axis=0).T)
    size = max(problem.fleet_size or 1, int(np.sum(np.ceil(straight / spacing - 1e-9))))
    for fleet_round in range(1, MAX_FLEET_ROUNDS + 1):
        first = _leg_problem(problem, problem.start, points[0], heading_a, None, size)
        rows = _grown(first, size, points[-1])
        route = [problem.start]
        legs: list[PathPlan] = []
        for j, point in enumerate(points):
            key = (tuple(order[: j + 1].tolist()), size)
            if key not in planned:
                leg = first
                if j:
                    behind = np.array(route[::-1])
                    tail = np.vstack([behind, rows.start_row[1:]])
                    heading = _direction_deg(behind[0] - behind[1])
                    leg = _leg_problem(problem, behind[0], point, heading, tail, size)
                plan = plan_path(leg, progress)
                planned[key] = (plan, list(plan.path[1:]))
            plan, extension = planned[key]
            legs.append(plan)
            if not plan.valid:
                name = problem.names[order[j]]
                where = "A" if j == 0 else f"{problem.names[order[j - 1]]!r}"
                reason = (
                    f"no valid leg from {where} to station {name!r} (its A and B below): "
                    f"{plan.reason}"
                )
                return _refused(problem, order, reason, int(order[j]), legs, fleet_round)
            route.extend(extension)
        path = np.array(route)
        steps = np.hypot(*np.diff(path, axis=0).T)
        along = np.concatenate([[0.0], np.cumsum(steps)])
        point_index = _point_index(path, points)
        distance = along[point_index]
        try:
            layout = station_layout(distance, rho, radio, problem.fleet_size)
        except StationError as error:
            return _refused(problem, order, str(error), int(order[error.point]), legs, fleet_round)
        except ValueError as error:  # more UAVs than the route can space
            return _refused(problem, order, str(error), None, legs, fleet_round)
        need = layout.fleet_size
        final_rows = _grown(first, need, points[-1])
        whole = _leg_problem(problem, problem.start, points[-1], heading_a, None, need)
        violations = check_path(path, whole, final_rows)
        if not violations.ok and need <= size:  # cannot happen: each leg kept the route valid
            reason = f"the route breaks definition 4: {violations.describe()}"
            return _refused(problem, order, reason, None, legs, fleet_round)
        if violations.ok:  # (with rows grown for `need` UAVs too, when it needs more)
            return RoutePlan(
                valid=True,
                reason=None,
                order=order,
                path=path,
                point_index=point_index,
                point_distance=distance,
                layout=layout,
                legs=tuple(legs),
                rows=final_rows,
                fleet_size=need,
                length_m=float(along[-1]),
                fleet_rounds=fleet_round,
                stopped=any(leg.stopped for leg in legs),
            )
        size = need
    reason = f"the fleet size kept growing with the route for {MAX_FLEET_ROUNDS} rounds"
    return _refused(problem, order, reason)


def _leg_problem(
    problem: RouteProblem,
    start: np.ndarray,
    goal: np.ndarray,
    heading_deg: float,
    tail: np.ndarray | None,
    size: int,
) -> PathProblem:
    """Leg start -> goal: e_0 at `heading_deg` (absolute), the route behind it as its start
    row (`tail`; None for the first leg, whose row is Delta_A), no row at its end."""
    return PathProblem(
        start=start,
        goal=goal,
        start_angle_deg=heading_deg - _direction_deg(goal - start),
        goal_angle_deg=0.0,
        safety_margin=problem.safety_margin,
        radio_range=problem.radio_range,
        obstacles=problem.obstacles,
        parking=problem.parking,
        fleet_size=size,
        method=problem.method,
        max_expansions=problem.max_expansions,
        gap_tolerance=problem.gap_tolerance,
        start_tail=tail,
        open_goal=True,
    )


def _grown(first: PathProblem, size: int, last: np.ndarray) -> ParkingRows:
    """Delta_A sized for `size` UAVs, open at the route's end."""
    return replace(first.rows(size), goal_row=np.array([last, last]))


def _point_index(path: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Index in `path` of each point in visiting order (the first match after the previous
    one: legs end exactly on their points)."""
    index = np.zeros(len(points), np.int64)
    at = 0
    for j, point in enumerate(points):
        hits = np.flatnonzero(np.all(np.abs(path[at:] - point) <= DISTANCE_TOLERANCE, axis=1))
        at += int(hits[0])
        index[j] = at
    return index


def _refused(
    problem: RouteProblem,
    order: np.ndarray,
    reason: str,
    failed_point: int | None = None,
    legs: list[PathPlan] | None = None,
    fleet_round: int = 1,
) -> RoutePlan:
    return RoutePlan(
        valid=False,
        reason=reason,
        order=order,
        path=np.zeros((0, 2)),
        point_index=np.zeros(0, np.int64),
        point_distance=np.zeros(0),
        layout=None,
        legs=tuple(legs or ()),
        rows=None,
        fleet_size=problem.fleet_size or 0,
        length_m=math.nan,
        failed_point=failed_point,
        fleet_rounds=fleet_round,
        stopped=any(leg.stopped for leg in legs or ()),
    )
