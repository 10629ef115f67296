"""Mission -> MissionPlan: the planned path, the line formation, the speed profile, safe speed.

The glue between the mission file and the pure planner. It also makes the refusals that need
the plan (docs/mission-file.md), each naming its key: a fixed `fleet.size` below the minimum of
eq. 28, a `leader` outside 1..N, a number of `fleet.connections` or of `sim.battery_mah` different
from N, parking rows too close to an obstacle or to each other (eqs. 14-15), and a `speed.max` above
the highest formation speed the path's bends allow (docs/design.md 3.5) unless capping is asked for.

Safe speed (docs/design.md 3.5): the virtual targets turn corners instantly; a vehicle with
acceleration limit `vehicle.max_acceleration` following a smoothed reference deviates at a bend
by a smoothing error that grows with the speed. The error budget for that smoothing is
`safety_margin - vehicle.tracking_allowance` (the allowance, by default 30 % of the margin, is
kept for tracking error and navigation noise); `safe_speed_mps` is the highest speed whose
smoothing error stays within it. Leader requests are planned as taking effect at their `at`
(the run adds the relay lead time and records the profile it actually flew).

Planning time is measured here (the planner itself has no clock).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gcs.errors import InputError, RowsRefused
from gcs.mission import Mission, SpeedSchedule
from planner.elastic import ElasticWarp, elastic_warp
from planner.formation import (
    DISTANCE_TOLERANCE,
    ParkingRows,
    collision_spacing,
    min_fleet_size,
    parking_rows,
    radio_spacing,
)
from planner.guarantees import planned_connected_fraction
from planner.kinematics import (
    LineFormation,
    SpeedProfile,
    recommended_window,
    safe_speed,
    smoothing_error_bound,
)
from planner.numbers import fmt_against, plural
from planner.relief import ReliefRefused, relief_layout
from planner.route import RoutePlan, RouteProblem, first_leg, plan_route
from planner.search import SearchProgress, plan_path
from planner.sight import Sight, chord_reach
from planner.types import PathPlan, PathProblem
from planner.validity import check_path, row_refusal

#: Tolerance when comparing a requested speed with the safe speed, m/s.
SPEED_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Connectivity:
    """How the plan stands under both connectivity rules (plan JSON `connectivity`): the
    mission's `rule`; eq. 28's fleet size; the path's line-of-sight chord reach and the rigid
    formation's fleet size at that spacing (`planner.sight.chord_reach`); the formation's
    spacing dS; the share of the planned flight during which every UAV reaches a base
    station by line of sight (`planner.guarantees.planned_connected_fraction`)."""

    rule: str
    eq28_fleet_size: int
    los_reach_m: float
    rigid_los_fleet_size: int | None  # None: no line-of-sight formation (reach <= dS_c)
    spacing_m: float
    corner_margin_m: float  # the clearance the path's corners were planned with (rho_c: none)
    los_connected_fraction: float
    #: the elastic line-of-sight formation on this path (`planner.elastic`); None: none exists
    elastic_los_fleet_size: int | None = None
    #: the flown formation's warp knots (arc from A, formation distance from A); None: rigid
    warp: np.ndarray | None = None

    @property
    def spacing(self) -> str:
        """How the flying UAVs are spaced: `elastic` (a warp) or `rigid` (eq. 27's dS)."""
        return "elastic" if self.warp is not None else "rigid"

    def to_json(self, fleet_size: int) -> dict[str, Any]:
        return {
            "rule": self.rule,
            "fleet_size": fleet_size,
            "eq28_fleet_size": self.eq28_fleet_size,
            "rigid_los_fleet_size": self.rigid_los_fleet_size,
            "elastic_los_fleet_size": self.elastic_los_fleet_size,
            "los_reach_m": self.los_reach_m,
            "spacing": self.spacing,
            "spacing_m": self.spacing_m,
            "warp_m": None if self.warp is None else _points(self.warp),
            "corner_margin_m": self.corner_margin_m,
            "los_connected_fraction": self.los_connected_fraction,
        }

    def warning(self) -> str | None:
        """One line when a disk plan's links pass through buildings."""
        if self.rule != "disk" or self.los_connected_fraction >= 1.0:
            return None
        sizes = [n for n in (self.rigid_los_fleet_size, self.elastic_los_fleet_size) if n]
        need = (
            f"a line-of-sight formation on this path needs {plural(min(sizes), 'UAV')}"
            if sizes
            else "no line-of-sight formation exists on this path"
        )
        need += " (`connectivity.rule: line_of_sight` also takes its corners wider, for fewer)"
        return (
            f"connected by line of sight {100 * self.los_connected_fraction:.1f} % of the "
            f"flight (radio links through buildings); {need}"
        )


@dataclass(frozen=True, eq=False)
class MissionPlan:
    """Everything the GCS needs to fly a mission, and what `plan_json` reports.

    `formation` is None when no valid path exists (`path_plan.reason` says why). `speeds` is
    the schedule actually flown: the mission's, or capped to `safe_speed_mps` when asked.
    """

    mission: Mission
    path_plan: PathPlan
    formation: LineFormation | None
    speeds: SpeedSchedule
    profile: SpeedProfile
    safe_speed_mps: float | None
    speed_capped: bool
    duration_s: float | None
    error_budget_m: float
    smoothing_window_s: float | None
    smoothing_error_m: float | None
    planning_time_s: float
    route: RoutePlan | None = None  # stations missions (docs/design.md 7)
    connectivity: Connectivity | None = None  # A -> B missions with a formation

    @property
    def valid(self) -> bool:
        return bool(self.path_plan.valid)

    @property
    def reason(self) -> str | None:
        return self.path_plan.reason

    @property
    def fleet_size(self) -> int:
        return int(self.path_plan.fleet_size)


def mission_problem(
    mission: Mission, method: str = "exact", gap_tolerance: float = 0.0
) -> PathProblem:
    """The planner's problem for `mission`: A, B, angles, margins, obstacles, parking mode,
    fixed fleet size (None with `fleet.size: auto`) and the certification's relative gap
    tolerance. For a stations mission, its first leg (A -> the first point visited, with
    Delta_A): what its row refusals are about."""
    if mission.stations:
        return first_leg(route_problem(mission, method, gap_tolerance), mission.fleet.size or 1)
    return PathProblem(
        start=mission.start.xy,
        goal=mission.goal.xy,
        start_angle_deg=mission.start.theta_deg,
        goal_angle_deg=mission.goal.theta_deg,
        safety_margin=mission.safety_margin,
        radio_range=mission.radio_range,
        obstacles=mission.obstacles,
        parking=mission.parking,
        fleet_size=mission.fleet.size,
        method=method,
        gap_tolerance=gap_tolerance,
    )


#: `plan_mission` passes the search's progress on at most this often (the search asks
#: whether to stop at every expansion).
PROGRESS_INTERVAL_S = 0.1


def plan_mission(
    mission: Mission,
    *,
    cap_speed: bool = False,
    connections: tuple[str, ...] | None = None,
    method: str = "exact",
    time_limit_s: float | None = None,
    gap_tolerance: float = 0.0,
    on_progress: Callable[[SearchProgress, float], None] | None = None,
    clock: Callable[[], float] = time.perf_counter,
) -> MissionPlan:
    """Plan `mission`; raise `InputError` for the plan-dependent refusals (exit 2).

    `cap_speed` (or the mission's `speed.cap_to_safe`) caps every speed to the safe speed
    instead of refusing; `connections` overrides `fleet.connections` (e.g. `--connect`).
    A mission without a valid path is returned with `valid == False` and the reason.
    The path search stops after `time_limit_s` seconds of `clock` (the plan is then the best
    valid path found so far, `path_plan.stopped`); `on_progress(progress, elapsed_s)` is
    called as it goes. `gap_tolerance` (relative) ends the certification of an A -> B path
    once it is proven within that fraction of the shortest (`PathProblem.gap_tolerance`).
    """
    conns = mission.fleet.connections if connections is None else tuple(connections)
    conn_key = "fleet.connections" if connections is None else "--connect"
    began = clock()
    next_report = [0.0]

    def progress(state: SearchProgress) -> bool:
        elapsed = clock() - began
        if on_progress is not None and elapsed >= next_report[0]:
            next_report[0] = elapsed + PROGRESS_INTERVAL_S
            on_progress(state, elapsed)
        return time_limit_s is not None and elapsed >= time_limit_s

    if mission.stations:
        if mission.connectivity_rule != "disk":
            raise InputError(
                mission.source,
                "connectivity.rule",
                "disk with stations (line of sight is planned for A -> B missions so far), "
                f"got {mission.connectivity_rule}",
            )
        return _plan_stations(
            mission, cap_speed, conns, conn_key, method, gap_tolerance, progress, clock
        )
    lower = min_fleet_size(
        float(np.linalg.norm(mission.goal.xy - mission.start.xy)),
        mission.safety_margin,
        mission.radio_range,
    )
    fixed = mission.fleet.size
    if fixed is not None:
        _check_fleet_size(mission, fixed, lower, "the straight line A->B")
        _check_fleet(mission, fixed, conns, conn_key)
    first_rows = parking_rows(
        mission.start.xy,
        mission.goal.xy,
        mission.start.theta_deg,
        mission.goal.theta_deg,
        fixed or lower,
        mission.safety_margin,
        mission.parking,
    )
    problem = mission_problem(mission, method, gap_tolerance)
    check_rows(mission, problem, first_rows, fixed or lower)
    began = clock()
    path_plan = plan_path(problem, progress)
    planning_time = clock() - began

    invalid = _unflown(mission, path_plan, planning_time)
    if path_plan.rows is not None:
        check_rows(mission, problem, path_plan.rows, int(path_plan.fleet_size))
    if not path_plan.valid:
        return invalid

    size = int(path_plan.fleet_size)
    if fixed is not None:
        _check_fleet_size(mission, fixed, int(path_plan.min_fleet_size), "the planned path")
    spacing, corner_margin, sight = None, mission.safety_margin, None
    if mission.connectivity_rule == "line_of_sight":
        sight = _sight_spacing(mission, problem, path_plan, fixed, progress)
        path_plan, size, spacing = sight.path_plan, sight.fleet_size, sight.spacing
        corner_margin = sight.corner_margin
        invalid = replace(invalid, path_plan=path_plan, planning_time_s=clock() - began)
        check_rows(mission, problem, path_plan.rows, size)
    _check_fleet(mission, size, conns, conn_key)

    formation = _formation(mission, path_plan, size, spacing, sight.warp if sight else None)
    flown = _flown(invalid, formation, cap_speed)
    return replace(flown, connectivity=_connectivity(mission, formation, corner_margin, sight))


#: Line of sight: the fleet is sized and the path planned again at most this many times
#: (more UAVs lengthen the parking rows, whose chords may shorten the reach).
SIGHT_ROUNDS = 4
#: Line of sight, wider corners: the path is also planned keeping these multiples of rho_c
#: from every obstacle (the formation still keeps rho_c), and the plan with the fewest UAVs
#: wins, then the shortest. A corner hugged at clearance c lets chords about 4 c long round
#: it: city-blocks needs 64 UAVs at rho_c and 12 at 6 rho_c, for 13 % more path.
CORNER_FACTORS = (1.0, 2.0, 3.0, 4.0, 6.0, 8.0)
#: ... each such search stops after this many expansions (or four times the first plan's).
WIDER_EXPANSIONS = 2_000
#: ... and is certified only to within this relative gap (its path is no shortest path).
WIDER_GAP = 0.01
#: ... and kept only while its path is at most this many times the shortest one; the
#: ladder stops at the first wider plan that fails or is longer (wider ones would be too):
#: Helsinki's 4 rho_c plan (18 UAVs instead of 19) flew a path 51 % longer.
WIDER_LENGTH = 1.25


def _formation(
    mission: Mission,
    path_plan: PathPlan,
    size: int,
    spacing: float | None = None,
    warp: ElasticWarp | None = None,
) -> LineFormation:
    """The A -> B line formation of `size` UAVs on `path_plan` (dS = `spacing`, or dS_r;
    elastic with `warp`)."""
    return LineFormation(
        path=path_plan.path,
        fleet_size=size,
        safety_margin=mission.safety_margin,
        radio_range=mission.radio_range,
        rows=path_plan.rows,
        spacing=spacing,
        warp=None if warp is None else warp.knots,
    )


@dataclass(frozen=True)
class _SightOptions:
    """Both line-of-sight formations on one formation's path: the chord reach and the rigid
    fleet at it (None: reach not above dS_c), and the elastic warp (None: none exists)."""

    reach: float
    rigid_fleet_size: int | None
    warp: ElasticWarp | None

    @classmethod
    def of(cls, mission: Mission, formation: LineFormation) -> _SightOptions:
        rho = mission.safety_margin
        limit = radio_spacing(rho, mission.radio_range)
        spacing_c = collision_spacing(rho)
        polyline = formation.flown_polyline
        sight = Sight(mission.obstacles)
        reach = chord_reach(polyline, sight, limit)
        rigid = None
        if reach > spacing_c + DISTANCE_TOLERANCE:
            rigid = max(1, math.ceil(formation.path_length / reach - DISTANCE_TOLERANCE))
        row = (formation.fleet_size - 1) * spacing_c
        warp = elastic_warp(polyline, sight, row, row + formation.path_length, limit, spacing_c)
        return cls(reach, rigid, warp)

    def best(self, mission: Mission) -> tuple[int, float, float | None, ElasticWarp | None] | None:
        """The formation with the fewest UAVs, (fleet, eq. 25's total distance, spacing or
        None for dS_r, warp), ties to the shorter flight; None when neither exists."""
        limit = radio_spacing(mission.safety_margin, mission.radio_range)
        options = []
        if self.rigid_fleet_size is not None:
            spacing = min(self.reach, limit)
            total = self.rigid_fleet_size * spacing  # len(P) + (N - 1) dS, up to rounding
            options.append(
                (self.rigid_fleet_size, total, spacing if spacing < limit else None, None)
            )
        if self.warp is not None:
            size = self.warp.fleet_size
            options.append((size, self.warp.formation_length + (size - 1) * limit, None, self.warp))
        if not options:
            return None
        return min(options, key=lambda option: option[:2])


@dataclass(frozen=True)
class _SightPlan:
    """One line-of-sight candidate: its path plan (rows for `fleet_size` at rho_c), the fleet
    size, the spacing (None: dS_r), the elastic warp (None: rigid) and the clearance its
    corners were planned with."""

    path_plan: PathPlan
    fleet_size: int
    spacing: float | None
    warp: ElasticWarp | None
    corner_margin: float
    options: _SightOptions  # both formations on the path, reported in `connectivity`
    total_distance: float  # eq. 25's: the flight's length in formation distance


def _sight_spacing(
    mission: Mission,
    problem: PathProblem,
    path_plan: PathPlan,
    fixed: int | None,
    progress: Callable[[SearchProgress], bool],
) -> _SightPlan:
    """`connectivity.rule: line_of_sight`: on each path, the rigid formation (dS the path's
    chord reach: every chord between two UAVs at most dS apart along it is clear; the fleet
    eq. 28 with dS) or the elastic one (`planner.elastic`: dS_r in formation distance, the
    UAVs closing up at the corners), whichever needs fewer UAVs; the path planned with its
    corners taken wider as well (`CORNER_FACTORS`, while such a path exists, is at most
    `WIDER_LENGTH` times the shortest and needs fewer UAVs than the one before it), the
    fewest UAVs winning, then the shorter flight.
    Refused (InputError) when no path has either, or a fixed fleet is smaller than the
    fewest."""
    rho = mission.safety_margin
    best: _SightPlan | None = None
    previous: int | None = None  # the fleet of the last candidate
    why = ""  # why the shortest path has no line-of-sight formation
    for factor in CORNER_FACTORS:
        start = fixed or int(path_plan.fleet_size)
        if factor == 1.0:
            candidate = _sight_plan(mission, problem, path_plan, start, progress, replan=True)
        else:
            wide = _wider(mission, problem, path_plan, factor, start, progress)
            if wide is None or wide.length_m > WIDER_LENGTH * path_plan.length_m:
                break
            candidate = _sight_plan(mission, problem, wide, start, progress, replan=False)
        if isinstance(candidate, str):
            why = why or candidate
            continue
        candidate = replace(candidate, corner_margin=factor * rho)
        key = (candidate.fleet_size, candidate.total_distance)
        if best is None or key < (best.fleet_size, best.total_distance):
            best = candidate
        if best.fleet_size <= int(path_plan.min_fleet_size):
            break  # eq. 28's fleet for the shortest path: no wider corner needs fewer
        if previous is not None and candidate.fleet_size >= previous:
            break  # wider corners stopped paying: the next would need as many, or more
        previous = candidate.fleet_size
    if best is None:
        raise InputError(
            mission.source,
            "connectivity.rule",
            f"disk for this path: no line-of-sight formation exists ({why}; its corners taken "
            "wider did not help)",
        )
    if fixed is not None and best.fleet_size > fixed:
        how = (
            "its UAVs closing up at the corners (elastic spacing)"
            if best.warp is not None
            else f"the path's chords are clear "
            f"{best.spacing or radio_spacing(rho, mission.radio_range):g} m apart along it"
        )
        raise InputError(
            mission.source,
            "fleet.size",
            f"auto or at least {plural(best.fleet_size, 'UAV')} for line of sight ({how}; "
            f"eq. 28 needs {plural(int(path_plan.min_fleet_size), 'UAV')}), got {fixed}",
        )
    return best


def _wider(
    mission: Mission,
    problem: PathProblem,
    path_plan: PathPlan,
    factor: float,
    size: int,
    progress: Callable[[SearchProgress], bool],
) -> PathPlan | None:
    """The path planned keeping `factor` rho_c from every obstacle, as a plan of the mission
    (rows at rho_c for `size` UAVs; not certified: the shortest path is `path_plan`'s), or
    None when there is no such path or it breaks definition 4 at rho_c."""
    margin = factor * mission.safety_margin
    wide = replace(
        problem,
        safety_margin=margin,
        radio_range=max(problem.radio_range, 2.0 * (1.0 + math.sqrt(2.0)) * margin + 1e-6),
        fleet_size=None,
        max_expansions=max(WIDER_EXPANSIONS, 4 * int(path_plan.expansions)),
        gap_tolerance=max(problem.gap_tolerance, WIDER_GAP),
    )
    planned = plan_path(wide, progress)
    if not planned.valid:
        return None
    rows = problem.rows(size)
    if row_refusal(problem, rows) is not None or not check_path(planned.path, problem, rows).ok:
        return None
    return replace(
        planned,
        fleet_size=size,
        min_fleet_size=min_fleet_size(planned.length_m, mission.safety_margin, mission.radio_range),
        rows=rows,
        certified=False,
        lower_bound_m=path_plan.lower_bound_m,
        gap_tolerance=problem.gap_tolerance,
        expansions=path_plan.expansions + planned.expansions,
    )


def _sight_plan(
    mission: Mission,
    problem: PathProblem,
    path_plan: PathPlan,
    size: int,
    progress: Callable[[SearchProgress], bool],
    replan: bool,
) -> _SightPlan | str:
    """The line-of-sight formation on `path_plan`'s path with the fewest UAVs, rigid or
    elastic (`_SightOptions`), the fleet grown with its rows until it suffices (the path
    planned again for longer rows when `replan`, else dropped when they break it); else why
    not, as the end of a sentence."""
    spacing_c = collision_spacing(mission.safety_margin)
    for _ in range(SIGHT_ROUNDS):
        options = _SightOptions.of(mission, _formation(mission, path_plan, size))
        best = options.best(mission)
        if best is None:
            return (
                f"somewhere along it, parking rows included, its chords stay clear of the "
                f"buildings only up to about the parking spacing dS_c = {spacing_c:.3g} m "
                f"apart along it"
            )
        need, total, spacing, warp = best
        if need <= size:
            total += (size - need) * (
                spacing or radio_spacing(mission.safety_margin, mission.radio_range)
            )
            return _SightPlan(path_plan, size, spacing, warp, 0.0, options, total)
        size = need
        grown = problem.rows(size)
        if row_refusal(problem, grown) is None and check_path(path_plan.path, problem, grown).ok:
            # longer rows only remove edges: a path still valid with them is still shortest
            path_plan = replace(path_plan, fleet_size=size, rows=grown)
            continue
        refusal = row_refusal(problem, grown)
        if refusal is not None:  # the rows depend on A, B and the angles only: no path helps
            return f"it needs {plural(size, 'UAV')}, and for them {refusal.message}"
        if not replan:
            return f"it needs {plural(size, 'UAV')}, whose parking rows cut its path"
        path_plan = plan_path(replace(problem, fleet_size=size), progress)
        if not path_plan.valid:
            return (
                f"it needs {plural(size, 'UAV')}, and with their parking rows "
                f"{path_plan.reason or 'no path is valid'}"
            )
    return f"its fleet kept growing with its parking rows ({plural(size, 'UAV')} and more)"


def _connectivity(
    mission: Mission, formation: LineFormation, corner_margin: float, sight: _SightPlan | None
) -> Connectivity:
    """How the plan stands under both rules; `sight`: the line-of-sight plan flown (its
    options already computed for this path and fleet), else they are computed here."""
    options = sight.options if sight is not None else _SightOptions.of(mission, formation)
    return Connectivity(
        rule=mission.connectivity_rule,
        eq28_fleet_size=min_fleet_size(
            formation.path_length, mission.safety_margin, mission.radio_range
        ),
        los_reach_m=options.reach,
        rigid_los_fleet_size=options.rigid_fleet_size,
        elastic_los_fleet_size=None if options.warp is None else options.warp.fleet_size,
        warp=formation.warp,
        spacing_m=formation.radio_spacing,
        corner_margin_m=corner_margin,
        los_connected_fraction=planned_connected_fraction(
            formation, mission.base_station_points, mission.radio_range, Sight(mission.obstacles)
        ),
    )


def _unflown(
    mission: Mission, path_plan: PathPlan, planning_time: float, route: RoutePlan | None = None
) -> MissionPlan:
    """The plan before anything needs a formation: the mission's speeds, no formation yet."""
    return MissionPlan(
        mission=mission,
        path_plan=path_plan,
        formation=None,
        speeds=mission.speed,
        profile=_profile(mission.speed),
        safe_speed_mps=None,
        speed_capped=False,
        duration_s=None,
        error_budget_m=mission.error_budget,
        smoothing_window_s=None,
        smoothing_error_m=None,
        planning_time_s=planning_time,
        route=route,
    )


def _flown(invalid: MissionPlan, formation: LineFormation, cap_speed: bool) -> MissionPlan:
    """`invalid` completed for `formation`: the safe speed (refused above it unless capping),
    the duration, the smoothing window and its error bound (docs/design.md 3.5)."""
    mission, speeds, profile = invalid.mission, invalid.speeds, invalid.profile
    safe = float(safe_speed(formation, mission.vehicle.max_acceleration, mission.error_budget))
    capped = False
    if speeds.max > safe + SPEED_TOLERANCE:
        if not (cap_speed or speeds.cap_to_safe):
            raise InputError(
                mission.source,
                "speed.max",
                f"at most the safe formation speed {fmt_against(safe, speeds.max)} m/s that the "
                "path's bends allow "
                f"with vehicle.max_acceleration {mission.vehicle.max_acceleration:g} m/s^2 and "
                f"a smoothing budget of {mission.error_budget:.3g} m (docs/design.md 3.5), got "
                f"{fmt_against(speeds.max, safe, 6)}; lower it, raise vehicle.max_acceleration, or set "
                "speed.cap_to_safe: true (--cap-speed)",
            )
        speeds = _cap(speeds, safe)
        capped = True
        profile = _profile(speeds)
    duration = float(formation.duration(profile))
    window = float(recommended_window(speeds.max, mission.vehicle.max_acceleration, formation))
    smoothing = float(smoothing_error_bound(formation, profile, window))
    return replace(
        invalid,
        formation=formation,
        speeds=speeds,
        profile=profile,
        safe_speed_mps=safe,
        speed_capped=capped,
        duration_s=duration,
        smoothing_window_s=window,
        smoothing_error_m=smoothing,
    )


def route_problem(
    mission: Mission, method: str = "exact", gap_tolerance: float = 0.0
) -> RouteProblem:
    """The planner's route problem for a stations mission (docs/design.md 7); `gap_tolerance` ends
    each leg's certification as `PathProblem.gap_tolerance` does."""
    return RouteProblem(
        start=mission.start.xy,
        points=np.array([point.xy for point in mission.stations]),
        start_angle_deg=mission.start.theta_deg,
        safety_margin=mission.safety_margin,
        radio_range=mission.radio_range,
        obstacles=mission.obstacles,
        names=tuple(point.name for point in mission.stations),
        order=mission.station_order,
        parking=mission.parking,
        fleet_size=mission.fleet.size,
        method=method,
        gap_tolerance=gap_tolerance,
    )


def _plan_stations(
    mission: Mission,
    cap_speed: bool,
    conns: tuple[str, ...],
    conn_key: str,
    method: str,
    gap_tolerance: float,
    progress: Callable[[SearchProgress], bool],
    clock: Callable[[], float],
) -> MissionPlan:
    """A stations mission: the route, its stations and the formation capped on them.
    An unreachable point is an input error naming it (unless the time limit stopped the
    search); a fixed `fleet.size` below the stations' minimum is refused."""
    problem = route_problem(mission, method, gap_tolerance)
    fixed = mission.fleet.size
    size = fixed or 1
    first = first_leg(problem, size)
    check_rows(mission, first, first.rows(size), size)
    began = clock()
    route = plan_route(problem, progress)
    planning_time = clock() - began
    invalid = _unflown(mission, route.path_plan(), planning_time, route)
    if not route.valid:
        if route.failed_point is not None and not route.stopped:
            name = mission.stations[route.failed_point].name
            raise InputError(
                mission.source,
                f"stations.points[{route.failed_point}]",
                f"a point the fleet can reach; {name!r} cannot be: {route.reason}",
            )
        return invalid
    if fixed is not None:
        _check_fleet_size(mission, fixed, route.layout.minimum, "the stations of the route")
    _check_fleet(mission, route.fleet_size, conns, conn_key)
    formation = LineFormation(
        path=route.path,
        fleet_size=route.fleet_size,
        safety_margin=mission.safety_margin,
        radio_range=mission.radio_range,
        rows=route.rows,
        stations=route.layout.stations,
    )
    return _flown(invalid, formation, cap_speed)


def check_rows(mission: Mission, problem: PathProblem, rows: ParkingRows, fleet_size: int) -> None:
    """Eqs. 14-15 through the planner's check, as an input error naming the key at fault."""
    refusal = row_refusal(problem, rows)
    if refusal is None:
        return
    rho = mission.safety_margin
    length = (fleet_size - 1) * collision_spacing(rho) + rho
    size = "" if mission.parking == "ray" else f", {length:.4g} m for {plural(fleet_size, 'UAV')}"
    if refusal.subject == "rows":
        raise RowsRefused(
            mission.source,
            "goal.theta_deg",
            f"parking rows at least 2 x safety_margin = {fmt_against(2 * rho, refusal.distance, 6)} "
            f"m apart (eq. 15); the rows behind start and beyond goal{size} are "
            f"{fmt_against(refusal.distance, 2 * rho)} m apart",
            fleet_size,
        )
    key, where = {
        "start_row": ("start", "behind start"),
        "goal_row": ("goal", "beyond goal"),
    }[refusal.subject]
    raise RowsRefused(
        mission.source,
        f"{key}.theta_deg",
        f"a parking row ({where}{size}) at least safety_margin = "
        f"{fmt_against(rho, refusal.distance, 6)} m from every obstacle (eq. 14); "
        f"{mission.obstacle_keys[refusal.obstacle]} is {fmt_against(refusal.distance, rho)} m "
        "from it",
        fleet_size,
    )


def plan_json(plan: MissionPlan) -> dict[str, Any]:
    """The plan JSON of docs/outputs.md (full precision), plus diagnostics; strict JSON values."""
    pp = plan.path_plan
    mission = plan.mission
    rows = pp.rows
    out: dict[str, Any] = {
        "name": mission.name,
        "valid": plan.valid,
        "reason": plan.reason,
        "path": _points(pp.path),
        "length_m": _number(pp.length_m),
        "fleet_size": _integer(pp.fleet_size),
        "min_fleet_size": _integer(pp.min_fleet_size),
        "duration_s": _number(plan.duration_s),
        "safe_speed_mps": _number(plan.safe_speed_mps),
        "max_speed_mps": _number(plan.speeds.max),
        "speed_capped": plan.speed_capped,
        "parking_rows": {
            "A": _points(rows.start_row) if rows is not None else [],
            "B": _points(rows.goal_row) if rows is not None else [],
        },
        "parking_slots": {
            "A": _points(plan.formation.start_slots) if plan.formation else [],
            "B": _points(plan.formation.goal_slots) if plan.formation else [],
        },
        "certified": bool(pp.certified),
        "lower_bound_m": _number(pp.lower_bound_m),
        "gap_m": _number(pp.length_m - pp.lower_bound_m) if plan.valid else None,
        "gap_tolerance": _number(pp.gap_tolerance),
        "graph": pp.level or None,
        "stopped": bool(pp.stopped),
        "iterations": _integer(pp.iterations),
        "expansions": _integer(pp.expansions),
        "node_count": _integer(pp.node_count),
        "edges_examined": _integer(pp.edges_examined),
        "planning_time_s": plan.planning_time_s,
        "error_budget_m": plan.error_budget_m,
        "smoothing_window_s": _number(plan.smoothing_window_s),
        "smoothing_error_m": _number(plan.smoothing_error_m),
        "speed_changes": [
            {"at": c.at, "speed": c.speed, "leader": c.leader} for c in plan.speeds.changes
        ],
        "initial_speed_mps": plan.speeds.initial,
        "safety_margin_m": mission.safety_margin,
        "radio_range_m": mission.radio_range,
        "altitude_m": mission.altitude,
        "origin": {"lat": mission.origin.lat, "lon": mission.origin.lon, "alt": mission.origin.alt},
    }
    if plan.connectivity is not None:
        out["connectivity"] = plan.connectivity.to_json(plan.fleet_size)
    from gcs.mission.footprints import map_json  # the footprint files' reports (docs/outputs.md)

    out["map"] = map_json(mission.footprints)
    if plan.route is not None:
        out["parking_rows"]["B"] = []
        out["parking_slots"]["B"] = []
        out["stations"] = stations_json(plan)
    return out


def stations_json(plan: MissionPlan) -> dict[str, Any]:
    """The `stations` block of a stations mission's plan JSON (docs/outputs.md): the visiting
    order, each point's distance along the route and the UAV that holds it, every UAV's
    station, the time the last one reaches it, and when the fleet returns."""
    route, mission = plan.route, plan.mission
    layout = route.layout
    points = []
    for k, index in enumerate(route.order.tolist()):
        station = mission.stations[index]
        points.append(
            {
                "name": station.name,
                "xy": [station.x, station.y],
                "distance_m": _number(route.point_distance[k]) if route.valid else None,
                "uav": int(layout.holders[k]) if layout is not None else None,
                "dwell_s": station.dwell_s,
            }
        )
    formation = plan.formation
    slots = formation.station_slots if formation is not None else None
    return {
        "order": mission.station_order,
        "orders_tried": route.orders_tried,
        "points": points,
        "uav_stations_m": [float(s) for s in layout.stations] if layout is not None else [],
        "uav_station_xy": _points(slots),
        "relays": [int(n) for n in np.flatnonzero(layout.relays) + 1] if layout else [],
        "on_station_s": _number(plan.duration_s),
        "return_at_s": mission.return_at,
        "failed_point": route.failed_point,
        "relievable": _relievable(plan),
        "relieve_below_pct": mission.relieve_below_pct,
    }


def _relievable(plan: MissionPlan) -> list[int]:
    """The UAVs whose gap could close up without them (`planner.relief.relief_layout`): the
    ones `gcs relieve` may send home (the manoeuvre's own check may still refuse one)."""
    layout, route = plan.route.layout, plan.route
    if layout is None or not route.valid:
        return []
    mission = plan.mission
    out = []
    for uav in range(1, layout.fleet_size + 1):
        try:
            relief_layout(
                layout.stations, route.point_distance, uav, mission.safety_margin,
                mission.radio_range,
            )  # fmt: skip
        except ReliefRefused:
            continue
        out.append(uav)
    return out


def plan_within_limits(
    plan: MissionPlan,
    max_speed: float,
    max_acceleration: float,
    *,
    connections: tuple[str, ...] | None = None,
    method: str = "exact",
) -> MissionPlan:
    """`plan`'s mission planned again for vehicles that allow no more than `max_speed` and
    `max_acceleration` (an autopilot's own limits): speeds capped to `max_speed`, then to the
    safe formation speed these allow (as `--cap-speed`)."""
    mission = plan.mission
    vehicle = replace(
        mission.vehicle,
        max_speed=min(mission.vehicle.max_speed, max_speed),
        max_acceleration=min(mission.vehicle.max_acceleration, max_acceleration),
    )
    speeds = mission.speed
    if speeds.max > vehicle.max_speed:
        speeds = _cap(speeds, vehicle.max_speed)
    limited = replace(mission, vehicle=vehicle, speed=speeds)
    return plan_mission(limited, cap_speed=True, connections=connections, method=method)


def _profile(speeds: SpeedSchedule) -> SpeedProfile:
    return SpeedProfile.from_changes(speeds.initial, [(c.at, c.speed) for c in speeds.changes])


def _cap(speeds: SpeedSchedule, limit: float) -> SpeedSchedule:
    changes = tuple(replace(c, speed=min(c.speed, limit)) for c in speeds.changes)
    return replace(speeds, max=limit, initial=min(speeds.initial, limit), changes=changes)


def _check_fleet_size(mission: Mission, fixed: int, minimum: int, what: str) -> None:
    if fixed < minimum:
        raise InputError(
            mission.source,
            "fleet.size",
            f"auto or at least {plural(minimum, 'UAV')}, the minimum of eq. 28 for {what}, "
            f"got {fixed}",
        )


def _check_fleet(mission: Mission, size: int, conns: tuple[str, ...], conn_key: str) -> None:
    for i, change in enumerate(mission.speed.changes):
        if change.leader is not None and change.leader > size:
            raise InputError(
                mission.source,
                f"speed.changes[{i}].leader",
                f"a UAV number in 1..{size} (the fleet size), got {change.leader}",
            )
    battery = mission.sim.battery_mah
    if isinstance(battery, tuple) and len(battery) != size:
        raise InputError(
            mission.source,
            "sim.battery_mah",
            f"a number > 0 (mAh) for every UAV, or a list with one per UAV ({size}), "
            f"got {plural(len(battery), 'number')}",
        )
    needs = mission.fleet.backend != "sim" or len(conns) > 0
    if needs and len(conns) != size:
        raise InputError(
            mission.source if conn_key == "fleet.connections" else None,
            conn_key,
            f"one MAVLink connection string per UAV ({size} for backend "
            f"{mission.fleet.backend}), got {len(conns)}",
        )


def _points(array: Any) -> list[list[float]]:
    if array is None:
        return []
    return [[float(x), float(y)] for x, y in np.asarray(array, float).reshape(-1, 2)]


def _number(value: Any) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def _integer(value: Any) -> int | None:
    return None if value is None else int(value)
