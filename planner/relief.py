"""Relief of one UAV on a monitoring-station chain (use case 1, paper sec. III-C1;
docs/design.md 7): a UAV about to be discharged goes home while the others keep the chain to A.

The UAVs hold on stations along one route; a UAV cannot fly home along it in the chain's
layer without passing the UAVs between it and A. So, from the hold (every UAV on station):

1. **Climb.** UAV k rises `lane_offset` = dS_c above its station (the vertical twin of the
   parked spacing: no other UAV comes nearer than that).
2. **Close the gap.** The UAVs of k's gap (the stations between the point before k's, or A,
   and the point after, inclusive) re-space evenly without k, along the route: those beyond k
   move back, those before it move forward, so the order never changes and every spacing is
   a mixture of two spacings >= dS_c. k, above its old station, bridges its two neighbours
   while they close in. The gap keeps its point: the UAV that ends on it holds it.
3. **Home.** k flies back above the route, then above the start row, to the free slot of the
   start row the furthest from A, and lands there (the remaining UAVs' return lands them on
   the first slots: they fly home as a formation of one UAV fewer, numbered by rank).

Every move is a rest-to-rest minimum-jerk motion from corner to corner of the route (zero
velocity at the route's corners, so no corner is cut), its speed and acceleration within the
mission's. The relief is refused when the gap would need more than dS_r between stations
without k (`station_layout`'s rule: the gap holds the fewest UAVs already), or when the
sampled manoeuvre breaks a guarantee: UAV-UAV distances (3-D) >= 2 rho_c, every UAV chained
to a base station through links <= dS_r (3-D between UAVs).

Pure: numbers in, numbers out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from fleetline.errors import FleetlineError
from planner.formation import DISTANCE_TOLERANCE, collision_spacing, radio_spacing
from planner.guarantees import _chunk_metrics
from planner.kinematics import LineFormation
from planner.numbers import plural

__all__ = ["Motion", "ReliefLayout", "ReliefPlan", "ReliefRefused", "plan_relief", "relief_layout"]

#: Minimum-jerk peak speed and acceleration, in units of (length / duration) and
#: (length / duration^2): s(u) = 10u^3 - 15u^4 + 6u^5.
_PEAK_SPEED = 1.875
_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)
#: Time step of the manoeuvre's sampled check (s).
CHECK_STEP_S = 0.2


class ReliefRefused(FleetlineError, ValueError):
    """The chain cannot let this UAV go: the message says why."""


@dataclass(frozen=True, eq=False)
class ReliefLayout:
    """The stations after UAV `uav` leaves: `stations` (N,) s_n, NaN for every relieved UAV
    (this one included); `holders` (m,) the UAV on each point; `members` the UAVs still on
    station (1-based), by decreasing station (their rank in the returning formation); `gap`
    the point whose gap `uav` leaves (0-based, visiting order)."""

    uav: int
    stations: np.ndarray
    holders: np.ndarray
    members: np.ndarray
    gap: int


def relief_layout(
    stations: np.ndarray,
    point_distances: np.ndarray,
    uav: int,
    safety_margin: float,
    radio_range: float,
    point_names: tuple[str, ...] | None = None,
) -> ReliefLayout:
    """The stations without UAV `uav` (1-based): its gap's c UAVs become c - 1, evenly spaced
    and ending on the gap's point, as `station_layout` spaces them; the other gaps stay.

    `stations` (N,) are the current s_n (NaN: relieved already). Raises `ReliefRefused` when
    `uav` holds no station, or when c - 1 UAVs would stand more than dS_r apart (the gap has
    the fewest already: fly with a larger `fleet.size` to be able to relieve)."""
    s = np.asarray(stations, dtype=float).reshape(-1)
    d = np.asarray(point_distances, dtype=float).reshape(-1)
    names = point_names or tuple(f"point {i + 1}" for i in range(len(d)))
    if not 1 <= uav <= len(s):
        raise ReliefRefused(f"there is no UAV {uav} (the fleet has UAVs 1 to {len(s)})")
    if not math.isfinite(s[uav - 1]):
        raise ReliefRefused(f"UAV {uav} was relieved already")
    spacing_r = radio_spacing(safety_margin, radio_range)
    # gap i holds the stations in (d_{i-1}, d_i]
    gap_of = np.searchsorted(d + DISTANCE_TOLERANCE, s, side="left")
    gap = int(gap_of[uav - 1])
    start = 0.0 if gap == 0 else float(d[gap - 1])
    length = float(d[gap]) - start
    on_station = np.isfinite(s)
    inside = np.flatnonzero(on_station & (gap_of == gap))
    count = len(inside)
    before = "A" if gap == 0 else f"'{names[gap - 1]}'"
    if count - 1 < 1 or length / (count - 1) > spacing_r + DISTANCE_TOLERANCE:
        spread = "no UAV left on it" if count == 1 else f"{length / (count - 1):.2f} m apart"
        raise ReliefRefused(
            f"UAV {uav} cannot leave: the {plural(count, 'UAV')} between {before} and "
            f"'{names[gap]}' ({length:.2f} m) are the fewest that keep the chain (without it: "
            f"{spread}, more than dS_r = {spacing_r:.2f} m); fly with a larger fleet.size to "
            "relieve UAVs"
        )
    staying = inside[inside != uav - 1]
    staying = staying[np.argsort(-s[staying], kind="stable")]
    after = s.copy()
    after[uav - 1] = np.nan
    after[staying] = d[gap] - length * np.arange(count - 1) / (count - 1)
    members = np.flatnonzero(np.isfinite(after))
    members = members[np.argsort(-after[members], kind="stable")] + 1
    holders = np.array(
        [members[np.argmin(np.abs(after[members - 1] - point))] for point in d], dtype=int
    )
    return ReliefLayout(uav, after, holders, members, gap)


@dataclass(frozen=True, eq=False)
class Motion:
    """Rest-to-rest minimum-jerk legs through `waypoints` (K, 3): leg i runs from waypoint i to
    i + 1 over [starts[i], starts[i] + durations[i]]; between legs (and before the first,
    after the last) the motion stands on its waypoint."""

    waypoints: np.ndarray
    starts: np.ndarray
    durations: np.ndarray

    @classmethod
    def through(cls, waypoints, start_s: float, speed: float, max_acceleration: float) -> Motion:
        """Leg after leg from `start_s`, each as short as `speed` and `max_acceleration`
        allow (peak speed 1.875 L / T, peak acceleration 5.77 L / T^2)."""
        points = _distinct(np.asarray(waypoints, dtype=float).reshape(-1, 3))
        if len(points) < 2:
            return cls(points, np.empty(0), np.empty(0))
        lengths = np.linalg.norm(np.diff(points, axis=0), axis=1)
        durations = np.maximum(
            _PEAK_SPEED * lengths / speed, np.sqrt(_PEAK_ACCELERATION * lengths / max_acceleration)
        )
        starts = start_s + np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        return cls(points, starts, durations)

    @property
    def start_s(self) -> float:
        return float(self.starts[0]) if len(self.starts) else math.inf

    @property
    def end_s(self) -> float:
        return float(self.starts[-1] + self.durations[-1]) if len(self.starts) else -math.inf

    def then(self, other: Motion) -> Motion:
        """This motion, then `other` (which starts where and after this one ends)."""
        if not len(self.starts):
            return other
        if not len(other.starts):
            return self
        return Motion(
            np.vstack([self.waypoints, other.waypoints[1:]]),
            np.concatenate([self.starts, other.starts]),
            np.concatenate([self.durations, other.durations]),
        )

    def state(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration at times `t`: each t.shape + (3,)."""
        t = np.asarray(t, dtype=float)
        if not len(self.starts):
            still = np.broadcast_to(self.waypoints[0], t.shape + (3,)).copy()
            return still, np.zeros_like(still), np.zeros_like(still)
        leg = np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, len(self.starts) - 1)
        duration = self.durations[leg]
        u = np.clip((t - self.starts[leg]) / duration, 0.0, 1.0)[..., None]
        step = (self.waypoints[leg + 1] - self.waypoints[leg]) / duration[..., None]
        s = u**3 * (10.0 - 15.0 * u + 6.0 * u * u)
        ds = 30.0 * u * u * (1.0 - u) ** 2
        dds = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
        position = self.waypoints[leg] + s * step * duration[..., None]
        return position, ds * step, dds * step / duration[..., None]


def _distinct(points: np.ndarray) -> np.ndarray:
    """Waypoints without consecutive repeats (at least the first)."""
    keep = np.concatenate([[True], np.linalg.norm(np.diff(points, axis=0), axis=1) > 1e-9])
    return points[keep]


@dataclass(frozen=True, eq=False)
class ReliefPlan:
    """How UAV `layout.uav` goes home (module docstring): `relieved` its motion (x, y, height
    above the mission altitude), `moves` (UAV id, motion) of the UAVs closing the gap, the
    instants the climb ends (`climbed_s`), the gap is closed (`closed_s`) and it stands above
    its landing slot (`home_s`); `landing_xy` that slot; `min_separation_m` and
    `min_separation_m` the closest two UAVs came in its sampled check (virtual positions,
    3-D)."""

    layout: ReliefLayout
    relieved: Motion
    moves: tuple[tuple[int, Motion], ...]
    lane_offset: float
    start_s: float
    climbed_s: float
    closed_s: float
    home_s: float
    landing_xy: np.ndarray
    landing_rank: int
    min_separation_m: float

    def positions(self, t, stations_xy: np.ndarray) -> np.ndarray:
        """(..., N, 3) virtual positions (height above the mission altitude) at times `t`:
        the UAVs that hold stand on `stations_xy` (N, 2), the moving ones follow their
        motion, the relieved one its own."""
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape + (len(stations_xy), 3))
        out[..., :2] = stations_xy
        for uav, motion in self.moves:
            out[..., uav - 1, :] = motion.state(t)[0]
        out[..., self.layout.uav - 1, :] = self.relieved.state(t)[0]
        return out


def _route_waypoints(formation: LineFormation, arc_from: float, arc_to: float) -> np.ndarray:
    """(K, 2) points along the route (extended by the start row) from arc `arc_from` to
    `arc_to`, through every corner in between."""
    arcs = formation.path_arcs
    low, high = sorted((arc_from, arc_to))
    inner = arcs[(arcs > low + DISTANCE_TOLERANCE) & (arcs < high - DISTANCE_TOLERANCE)]
    inner = inner if arc_to >= arc_from else inner[::-1]
    return formation.point_at(np.concatenate([[arc_from], inner, [arc_to]]))


def plan_relief(
    formation: LineFormation,
    stations: np.ndarray,
    point_distances: np.ndarray,
    uav: int,
    start_s: float,
    speed: float,
    max_acceleration: float,
    base_stations: np.ndarray,
    relieved_before: int = 0,
    point_names: tuple[str, ...] | None = None,
    climb_speed: float | None = None,
) -> ReliefPlan:
    """The relief of UAV `uav` (1-based) from mission time `start_s`, every UAV holding on
    `stations` (N,) (NaN: relieved already, `relieved_before` of them) of the outbound station
    `formation`; `speed` and `max_acceleration` bound every move (`climb_speed`, default
    `speed`, the climb); `base_stations` (B, 2) as for `check_positions`. Raises `ReliefRefused` (the layout's rule, or a sampled guarantee
    the manoeuvre would break, with its instant)."""
    rho = formation.safety_margin
    layout = relief_layout(stations, point_distances, uav, rho, formation.radio_range, point_names)
    if not (speed > 0 and max_acceleration > 0):
        raise ValueError("speed and max_acceleration must be positive")
    lane = collision_spacing(rho)
    before = np.asarray(stations, dtype=float)
    size = len(before)
    own = float(before[uav - 1])
    station_xy = formation.point_at(own)
    # 1. climb
    climb = Motion.through(
        [[*station_xy, 0.0], [*station_xy, lane]],
        start_s,
        speed if climb_speed is None else min(speed, climb_speed),
        max_acceleration,
    )
    climbed = climb.end_s
    # 2. close the gap
    moves = []
    for other in np.flatnonzero(np.isfinite(layout.stations)):
        a, b = float(before[other]), float(layout.stations[other])
        if abs(a - b) <= DISTANCE_TOLERANCE:
            continue
        points = _route_waypoints(formation, a, b)
        path = np.column_stack([points, np.zeros(len(points))])
        moves.append((int(other) + 1, Motion.through(path, climbed, speed, max_acceleration)))
    closed = max([climbed] + [motion.end_s for _, motion in moves])
    # 3. home, above the route and the start row, to the free slot furthest from A
    rank = size - 1 - relieved_before
    landing_arc = -rank * formation.collision_spacing
    points = _route_waypoints(formation, own, landing_arc)
    home = Motion.through(
        np.column_stack([points, np.full(len(points), lane)]), closed, speed, max_acceleration
    )
    landing_xy = formation.point_at(landing_arc)
    base = np.asarray(base_stations, dtype=float).reshape(-1, 2)
    reach = float(np.linalg.norm(base - landing_xy, axis=1).min())
    if reach > radio_spacing(rho, formation.radio_range) + DISTANCE_TOLERANCE:
        raise ReliefRefused(
            f"UAV {uav} would land out of the chain's reach: the free slot for it, the last of "
            f"the start row ({landing_xy[0]:.1f}, {landing_xy[1]:.1f}), is {reach:.2f} m from "
            f"the base station, more than dS_r = "
            f"{radio_spacing(rho, formation.radio_range):.2f} m"
        )
    relieved = climb.then(home) if home.end_s > home.start_s else climb
    plan = ReliefPlan(
        layout=layout,
        relieved=relieved,
        moves=tuple(moves),
        lane_offset=lane,
        start_s=float(start_s),
        climbed_s=float(climbed),
        closed_s=float(closed),
        home_s=float(max(relieved.end_s, closed)),
        landing_xy=landing_xy,
        landing_rank=rank,
        min_separation_m=math.inf,
    )
    return _checked(plan, formation, before, base_stations)


def _checked(
    plan: ReliefPlan, formation: LineFormation, before: np.ndarray, base_stations: np.ndarray
) -> ReliefPlan:
    """`plan` with the figures of its sampled check, or `ReliefRefused` at the first instant
    that breaks a guarantee (virtual positions, every `CHECK_STEP_S` and at every leg's end)."""
    rho = formation.safety_margin
    spacing_r = radio_spacing(rho, formation.radio_range)
    flying = np.flatnonzero(np.isfinite(before))
    stations_xy = np.zeros((len(before), 2))
    stations_xy[flying] = formation.point_at(before[flying])
    legs = [plan.relieved] + [motion for _, motion in plan.moves]
    times = np.unique(
        np.concatenate(
            [np.arange(plan.start_s, plan.home_s, CHECK_STEP_S), [plan.home_s]]
            + [np.concatenate([m.starts, m.starts + m.durations]) for m in legs]
        )
    )
    # the relieved UAV counts until it stands above its slot (it then lands, out of the chain)
    positions = plan.positions(times, stations_xy)[:, flying]
    closest, hops = _chunk_metrics(
        positions[..., :2],
        np.asarray(base_stations, dtype=float).reshape(-1, 2),
        spacing_r,
        positions[..., 2],
    )
    bad = np.flatnonzero(closest < 2 * rho - DISTANCE_TOLERANCE)
    if len(bad):
        at = int(bad[0])
        raise ReliefRefused(
            f"relieving UAV {plan.layout.uav} would bring two UAVs {closest[at]:.2f} m apart "
            f"(< 2 rho_c = {2 * rho:g} m) at t={times[at]:.2f} s"
        )
    cut = np.flatnonzero((hops < 0).any(axis=1))
    if len(cut):
        at = int(cut[0])
        lost = flying[hops[at] < 0] + 1
        raise ReliefRefused(
            f"relieving UAV {plan.layout.uav} would cut UAV {', '.join(map(str, lost))} off "
            f"the chain to the base station at t={times[at]:.2f} s (links above dS_r = "
            f"{spacing_r:.2f} m)"
        )
    return replace(plan, min_separation_m=float(closest.min(initial=math.inf)))
