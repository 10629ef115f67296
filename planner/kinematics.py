"""Line-formation kinematics (paper sec. IV-A, eqs. 16-28) and the smoothed reference
(docs/design.md 3.5).

The commanded speed v(t) is piecewise constant (`SpeedProfile`); S(t) is the distance it makes a
non-stopping UAV travel (eq. 19) and Phi(s) its inverse (eqs. 20-22). A `LineFormation` turns a
complete path P_1 = A ... P_K = B, the fleet size N and the spacings dS_c, dS_r (eq. 23) into the
virtual targets V_n(S) of eq. 27.

Indexing of the thresholds (the paper's L_{k,n}, eq. 24 ff.): ``thresholds[n-1, k]`` is L_{k,n}
for k = 0 .. K+1, with K the number of path points:

* k = 0: L_0,n = (n-1)(dS_r - dS_c), UAV n leaves its parking slot;
* k = 1: L_1,n = (n-1) dS_r, it reaches A = P_1 (end of the start row);
* k = 2 .. K: L_k,n = L_1,n + |P_1 P_2| + ... + |P_{k-1} P_k|, it reaches P_k (k = K: B);
* k = K+1: L_{K+1},n = L_K,n + (N-n) dS_c, it reaches its arrival slot.

The paper's L_{K+2} (everyone parked) is the same for all UAVs: `total_distance` (eq. 25).
``segment_directions[k]`` is e_k: e_0 along the start row towards A, e_1 .. e_{K-1} along the
path segments P_k P_{k+1}, e_K along the goal row away from B; between thresholds k and k+1 the
UAV moves along e_k.

Where we differ from the paper's text (see docs/design.md 3.4):

* parking slots carry the dS_c factor that eq. 17 omits (eq. 27 has it);
* eq. 27's sum stops at k = K: its k = K+1 term is the final wait and moves nothing;
* Phi(s) is 0 for s <= 0 unless the profile starts with a zero-speed stretch (then the end of
  that stretch, eq. 20), and +inf for a distance the profile never reaches (a final speed of 0);
* V_n is evaluated through the distance travelled beyond A (the paper's S', fig. 3) on the path
  extended by the two rows; this is eq. 27 rewritten, and the tests compare it with the literal
  sum of ramps.

The smoothed reference (docs/design.md 3.5) is the moving average of V_n(t) over [t - w/2, t + w/2],
computed in closed form (V_n is piecewise linear in t, its average piecewise quadratic), with
velocity and acceleration as its exact derivatives. Its deviation from V_n is bounded by
`smoothing_error_bound`; `safe_speed` and `recommended_window` size speed and window from the
vehicle's acceleration limit and the error budget (the model is in `safe_speed`'s docstring).
Computing the reference at t needs the profile up to t + w/2: speed changes must be announced
at least w/2 ahead (docs/design.md 4).

Monitoring-station formations (`LineFormation.stations`, use case 1): the path is the route
A -> P_1 -> ... -> P_m (no parking row at its end) and UAV n holds at s_n, a distance along the
route from A (s_1 > ... > s_N; consecutive ones between dS_c and dS_r apart and s_N <= dS_r
for the guarantees, not checked here). UAV n's distance beyond A is min(eq. 27's, s_n): the
leaders stop first, the followers close up behind them. So V_n(S) = eq. 27's V_n(min(S, S_n))
with the cap S_n = s_n + (n-1) dS_r, and its thresholds at and beyond the cap collapse onto it
(min(L_{k,n}, S_n)); the jumps stay e_k - e_{k-1}, whose sum over the collapsed ones is minus
the direction UAV n arrives with: the merged group is the stop. Everyone holds from
S_out = max S_n (UAV N's, as the gaps are at most dS_r), for any larger S. The fleet flies home
from M = `return_distance` (set when the return is decided, `with_return`): V_n(S) =
V_n(2 M - S) for S in [M, 2 M], the motion so far played backwards, the thresholds truncated at
M and extended by the mirrored 2 M - L_{k,n} (k descending) with the jumps in reverse order; at
S >= 2 M everyone is parked on its start slot again. A hold played backwards is as long again,
so the ground station stops S at S_out while the fleet holds (speed 0) and returns from
M = S_out (UAV N, nearest A, leaves first); M < S_out is a return before everyone is on station.
S stays monotone in time and the closed forms below apply unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from planner.formation import (
    DISTANCE_TOLERANCE,
    ParkingRows,
    collision_spacing,
    min_radio_range,
    radio_spacing,
)

# Relative margin kept below a pairwise kink distance or a speed limit so that re-deriving a
# window from a returned speed never lands on the wrong side of a step by rounding.
_RELATIVE_MARGIN = 1e-9


def _readonly(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class SpeedProfile:
    """Piecewise-constant commanded speed v(t) (assumption 2, eqs. 19-22).

    `speeds[i]` holds on [times[i], times[i+1]) (the last one forever); `times[0] == 0` is the
    mission start and v(t) = 0 before it.
    """

    times: np.ndarray  # (C,) start of each constant stretch, s
    speeds: np.ndarray  # (C,) m/s, >= 0

    def __post_init__(self) -> None:
        times = np.array(self.times, dtype=float).reshape(-1)
        speeds = np.array(self.speeds, dtype=float).reshape(-1)
        if times.size == 0 or times.shape != speeds.shape:
            raise ValueError("SpeedProfile: times and speeds must be non-empty, of equal length")
        if times[0] != 0.0:
            raise ValueError("SpeedProfile: times[0] must be 0.0 (the mission start)")
        if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
            raise ValueError("SpeedProfile: times must be finite and strictly increasing")
        if not np.all(np.isfinite(speeds)) or np.any(speeds < 0):
            raise ValueError("SpeedProfile: speeds must be finite and >= 0")
        durations = np.diff(times)
        # S and its time integral at the start of each stretch (exact, piecewise).
        starts = np.concatenate([[0.0], np.cumsum(speeds[:-1] * durations)])
        integrals = np.concatenate(
            [[0.0], np.cumsum(starts[:-1] * durations + 0.5 * speeds[:-1] * durations**2)]
        )
        object.__setattr__(self, "times", _readonly(times))
        object.__setattr__(self, "speeds", _readonly(speeds))
        object.__setattr__(self, "_starts", _readonly(starts))
        object.__setattr__(self, "_integrals", _readonly(integrals))

    @classmethod
    def constant(cls, speed: float) -> SpeedProfile:
        """v(t) = speed for all t >= 0 (the no speed-change scenario, eq. 22)."""
        return cls(np.array([0.0]), np.array([float(speed)]))

    @classmethod
    def from_changes(
        cls, initial_speed: float, changes: Sequence[tuple[float, float]]
    ) -> SpeedProfile:
        """Profile from an initial speed and (effective time s, new speed) changes.

        Effective times must be >= 0 and strictly increasing; a change at 0 replaces the
        initial speed.
        """
        profile = cls.constant(initial_speed)
        last = -math.inf
        for effective_s, speed in changes:
            if not effective_s > last:
                raise ValueError("speed changes: effective times must be strictly increasing")
            last = effective_s
            profile = profile.with_change(effective_s, speed)
        return profile

    def with_change(self, effective_s: float, speed: float) -> SpeedProfile:
        """This profile up to `effective_s`, then `speed` forever (later stretches dropped)."""
        if not (math.isfinite(effective_s) and effective_s >= 0):
            raise ValueError(f"speed change: effective time must be >= 0, not {effective_s}")
        keep = self.times < effective_s
        return SpeedProfile(
            np.append(self.times[keep], float(effective_s)),
            np.append(self.speeds[keep], float(speed)),
        )

    def with_pause(self, at_s: float, length_s: float) -> SpeedProfile:
        """This profile with the formation stopped for `length_s` from `at_s` (>= 0): speed 0,
        then the speed it had, every later stretch `length_s` later. The smoothed reference of
        a pause as long as the smoothing window stands still at its middle and then
        accelerates at speed / window (docs/design.md 3.5): a standing start."""
        if not (math.isfinite(at_s) and at_s >= 0 and math.isfinite(length_s) and length_s > 0):
            raise ValueError(f"pause: need at >= 0 and length > 0, not {at_s}, {length_s}")
        keep = self.times < at_s
        later = self.times > at_s
        resume = float(self.speed_at(at_s))
        return SpeedProfile(
            np.concatenate(
                [self.times[keep], [at_s, at_s + length_s], self.times[later] + length_s]
            ),
            np.concatenate([self.speeds[keep], [0.0, resume], self.speeds[later]]),
        )

    @property
    def final_speed(self) -> float:
        """Speed of the last stretch (0 means the formation stops for good)."""
        return float(self.speeds[-1])

    def _stretch(self, t: np.ndarray) -> np.ndarray:
        """Index of the stretch holding time t (stretch 0 for t < 0)."""
        return np.maximum(self.times.searchsorted(t, side="right") - 1, 0)

    def speed_at(self, t) -> np.ndarray:
        """v(t), right-continuous; 0 before the mission start."""
        t = np.asarray(t, dtype=float)
        return np.where(t < 0, 0.0, self.speeds[self._stretch(t)])

    def speed_before(self, t) -> np.ndarray:
        """Left limit v(t-): the speed just before t (0 at and before the mission start)."""
        t = np.asarray(t, dtype=float)
        index = np.searchsorted(self.times, t, side="left") - 1
        return np.where(index < 0, 0.0, self.speeds[np.clip(index, 0, None)])

    def distance(self, t) -> np.ndarray:
        """S(t) = integral of v from 0 to t (eq. 19); 0 for t <= 0, vectorised over t."""
        t = np.asarray(t, dtype=float)
        i = self._stretch(t)
        speed = self.speeds[i]
        with np.errstate(invalid="ignore"):
            travelled = np.where(speed > 0, speed * (t - self.times[i]), 0.0)
        return np.where(t <= 0, 0.0, self._starts[i] + travelled)

    def distance_integral(self, t) -> np.ndarray:
        """J(t) = integral of S from 0 to t (piecewise quadratic); 0 for t <= 0."""
        t = np.asarray(t, dtype=float)
        i = self._stretch(t)
        dt = np.maximum(t - self.times[i], 0.0)
        value = self._integrals[i] + self._starts[i] * dt + 0.5 * self.speeds[i] * dt**2
        return np.where(t <= 0, 0.0, value)

    def time_at_distance(self, s) -> np.ndarray:
        """Phi(s) (eqs. 20-22): the time S reaches s, vectorised over s.

        On a zero-speed stretch at distance s it is the end of that stretch (eq. 20); for
        s < 0 it is 0; for a distance never reached (final speed 0) it is +inf.
        """
        s = np.asarray(s, dtype=float)
        i = np.maximum(self._starts.searchsorted(s, side="right") - 1, 0)
        speed = self.speeds[i]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(speed > 0, self.times[i] + (s - self._starts[i]) / speed, np.inf)
        return np.where(s < 0, 0.0, np.maximum(t, 0.0))


@dataclass(frozen=True, eq=False)
class LineFormation:
    """N virtual UAVs V_n on a complete path with parking rows (eqs. 16-28).

    `fleet_size` is not checked against eq. 28 here (tests may force a fleet too small on
    purpose); `radio_range` must satisfy eq. 9 so that dS_r >= dS_c.

    `stations` (N,) makes it a monitoring-station formation (module docstring): UAV n holds at
    distance s_n beyond A along the path (0 < s_n <= len(P), strictly decreasing; the spacing
    rules of the guarantees are the mission's to check, like eq. 28). `return_distance` (only with
    stations) adds the mirrored flight home. Both at their defaults: the A -> B formation.
    """

    path: np.ndarray  # (K, 2): P_1 = A ... P_K = B
    fleet_size: int
    safety_margin: float
    radio_range: float
    rows: ParkingRows
    stations: np.ndarray | None = None  # (N,) s_n, metres beyond A along the path
    return_distance: float | None = None  # with stations: V_n(S) = V_n(2 M - S) for S >= M
    #: dS of eq. 27, the spacing of flying UAVs along the path: dS_r = rho_R - 2 rho_c unless
    #: given (line of sight: the path's chord reach, `planner.sight.chord_reach`), in
    #: (dS_c, dS_r].
    spacing: float | None = None
    #: Elastic spacing (line of sight, `planner.elastic`): knots (M, 2) of the map G from arc
    #: length along the path (from A) to distance along the formation (from A), increasing,
    #: from (0, 0) to (len(P), G(len(P))), slope at least 1 between knots. V_n is eq. 27 with
    #: G(arc) for the arc length: a UAV flies at v / G' (slower where G is steep, so that the
    #: UAVs behind close up), and UAVs dS apart in formation distance are closer along the
    #: path there. The path gains a vertex at every knot. None: G is the identity.
    warp: np.ndarray | None = None

    def __post_init__(self) -> None:
        path = np.array(self.path, dtype=float)
        if path.ndim != 2 or path.shape[1] != 2 or len(path) < 2:
            raise ValueError("LineFormation: path must be (K, 2) with K >= 2")
        if not np.all(np.isfinite(path)):
            raise ValueError("LineFormation: path must be finite")
        steps = np.diff(path, axis=0)
        lengths = np.hypot(steps[:, 0], steps[:, 1])
        if np.any(lengths <= DISTANCE_TOLERANCE):
            raise ValueError("LineFormation: consecutive path points must be distinct")
        if isinstance(self.fleet_size, bool) or int(self.fleet_size) != self.fleet_size:
            raise ValueError("LineFormation: fleet_size must be an integer")
        fleet_size = int(self.fleet_size)
        if fleet_size < 1:
            raise ValueError("LineFormation: fleet_size must be >= 1")
        if not self.safety_margin > 0:
            raise ValueError("LineFormation: safety_margin must be > 0")
        if self.radio_range < min_radio_range(self.safety_margin) - DISTANCE_TOLERANCE:
            raise ValueError(
                "LineFormation: radio_range must be >= 2(1+sqrt 2) safety_margin (eq. 9)"
            )
        stations = self._checked_stations(fleet_size, float(lengths.sum()))
        path, steps, lengths, formation_lengths = self._warped(path, steps, lengths)
        e0 = np.asarray(self.rows.start_direction, dtype=float)
        ek = np.asarray(self.rows.goal_direction, dtype=float)
        e0 = e0 / np.hypot(*e0)
        ek = ek / np.hypot(*ek)

        # formation distance of P_k beyond A (its arc length unless warped)
        cumulative = np.concatenate([[0.0], np.cumsum(formation_lengths)])
        directions = np.concatenate([e0[None], steps / formation_lengths[:, None], ek[None]])
        spacing_c = collision_spacing(self.safety_margin)
        spacing_r = radio_spacing(self.safety_margin, self.radio_range)
        if self.spacing is not None:
            if not spacing_c + DISTANCE_TOLERANCE < self.spacing <= spacing_r + DISTANCE_TOLERANCE:
                raise ValueError(
                    "LineFormation: spacing must be above dS_c and at most dS_r = rho_R - 2 rho_c"
                )
            spacing_r = float(self.spacing)
        rank = np.arange(fleet_size, dtype=float)  # n - 1
        count = len(path)
        thresholds = np.empty((fleet_size, count + 2))
        thresholds[:, 0] = rank * (spacing_r - spacing_c)
        thresholds[:, 1 : count + 1] = rank[:, None] * spacing_r + cumulative[None, :]
        thresholds[:, count + 1] = thresholds[:, count] + (fleet_size - 1 - rank) * spacing_c
        # Direction of motion after passing m thresholds: 0, e_0, ..., e_K, 0 (index m).
        phase_directions = np.concatenate([np.zeros((1, 2)), directions, np.zeros((1, 2))])
        # eq. 27's, for `_eq27_passed` (a station formation counts through them too)
        object.__setattr__(self, "_departures", _readonly(thresholds[:, 0].copy()))
        object.__setattr__(self, "_arrivals", _readonly(thresholds[:, -1].copy()))
        if stations is not None:
            thresholds, phase_directions = self._station_tables(
                thresholds, phase_directions, stations, rank * spacing_r
            )
        # Velocity jump at each threshold per unit speed: e_k - e_{k-1}; coincident thresholds
        # (n = 1 starts at A, n = N stops at B, a station's collapsed ones) are merged into the
        # first of their group.
        jumps = np.diff(phase_directions, axis=0)  # (K+2, 2); returning (2(K+2), 2)
        prefix_l = np.concatenate(
            [np.zeros((fleet_size, 1, 2)), np.cumsum(thresholds[:, :, None] * jumps, axis=1)],
            axis=1,
        )

        object.__setattr__(self, "path", _readonly(path))
        object.__setattr__(self, "fleet_size", fleet_size)
        object.__setattr__(self, "_lengths", _readonly(lengths))
        object.__setattr__(self, "_arc_length", float(lengths.sum()))
        object.__setattr__(self, "_cumulative", _readonly(cumulative))
        object.__setattr__(self, "_directions", _readonly(directions))
        object.__setattr__(self, "_spacing_c", spacing_c)
        object.__setattr__(self, "_spacing_r", spacing_r)
        object.__setattr__(self, "_rank", _readonly(rank))
        object.__setattr__(self, "_thresholds", _readonly(thresholds))
        object.__setattr__(self, "_phase_directions", _readonly(phase_directions))
        object.__setattr__(self, "_jumps", _readonly(jumps))
        object.__setattr__(self, "_prefix_l", _readonly(prefix_l))
        # what the per-tick evaluations use, computed once
        object.__setattr__(self, "_rank_spacing_r", _readonly(rank * spacing_r))
        object.__setattr__(self, "_lowest_beyond", _readonly(-rank * spacing_c))
        behind = fleet_size - 1 - rank
        highest = float(cumulative[-1]) + behind * spacing_c
        object.__setattr__(self, "_highest_beyond", _readonly(highest))
        # the pieces of the path extended by both rows: start point, arc length at it
        starts = np.concatenate([path[:1], path[:-1], path[-1:]])
        arcs = np.concatenate([[0.0], cumulative[:-1], cumulative[-1:]])
        object.__setattr__(self, "_piece_starts", _readonly(starts))
        object.__setattr__(self, "_piece_arcs", _readonly(arcs))
        start_slots = path[0] - (rank * spacing_c)[:, None] * directions[0]
        object.__setattr__(self, "_start_slots", _readonly(start_slots))
        object.__setattr__(self, "_crossing_cache", None)  # (profile, prefix sums), see below

    def _warped(self, path: np.ndarray, steps: np.ndarray, lengths: np.ndarray):
        """`path`, its steps and their arc lengths with a vertex added at every interior knot
        of `warp` (stored read-only), and each step's length in formation distance (G's
        increase over it; the arc lengths without a warp)."""
        if self.warp is None:
            return path, steps, lengths, lengths
        if self.stations is not None:
            raise ValueError("LineFormation: warp is for A -> B formations (no stations)")
        knots = np.array(self.warp, dtype=float)
        arcs = np.concatenate([[0.0], np.cumsum(lengths)])
        if (
            knots.ndim != 2
            or knots.shape[1] != 2
            or len(knots) < 2
            or not np.all(np.isfinite(knots))
            or np.any(np.abs(knots[0]) > DISTANCE_TOLERANCE)
            or abs(knots[-1, 0] - arcs[-1]) > DISTANCE_TOLERANCE
            or np.any(np.diff(knots[:, 0]) <= DISTANCE_TOLERANCE)
            or np.any(np.diff(knots[:, 1]) < np.diff(knots[:, 0]) - DISTANCE_TOLERANCE)
        ):
            raise ValueError(
                "LineFormation: warp must be (M, 2) knots from (0, 0) to (len(P), G) with "
                "increasing arc lengths and slope >= 1"
            )
        knots[0], knots[-1, 0] = 0.0, arcs[-1]
        object.__setattr__(self, "warp", _readonly(knots))
        inner = knots[1:-1, 0]
        inner = inner[np.min(np.abs(inner[:, None] - arcs[None, :]), axis=1) > DISTANCE_TOLERANCE]
        if len(inner):
            merged = np.sort(np.concatenate([arcs, inner]))
            path = np.column_stack([np.interp(merged, arcs, path[:, k]) for k in (0, 1)])
            arcs = merged
            steps = np.diff(path, axis=0)
            lengths = np.diff(arcs)
        formation = np.interp(arcs, knots[:, 0], knots[:, 1])
        return path, steps, lengths, np.diff(formation)

    def _checked_stations(self, fleet_size: int, path_length: float) -> np.ndarray | None:
        """`stations` validated (and stored read-only, clipped to len(P)), `return_distance`
        checked."""
        mirror = self.return_distance
        if mirror is not None:
            if isinstance(mirror, bool) or not np.isfinite(mirror) or mirror < 0:
                raise ValueError("LineFormation: return_distance must be a finite number >= 0")
            object.__setattr__(self, "return_distance", float(mirror))
        if self.stations is None:
            if mirror is not None:
                raise ValueError(
                    "LineFormation: return_distance needs stations (it mirrors their flight)"
                )
            return None
        try:
            stations = np.array(self.stations, dtype=float)
        except (TypeError, ValueError):
            raise ValueError("LineFormation: stations must be numbers") from None
        if stations.shape != (fleet_size,):
            raise ValueError(
                f"LineFormation: stations must be ({fleet_size},), one per UAV, "
                f"not {stations.shape}"
            )
        if not np.all(np.isfinite(stations)):
            raise ValueError("LineFormation: stations must be finite")
        if np.any(stations <= 0) or np.any(stations > path_length + DISTANCE_TOLERANCE):
            raise ValueError(
                f"LineFormation: stations must lie in (0, len(P) = {path_length:.6g}] m beyond A"
            )
        stations = np.minimum(stations, path_length)
        if np.any(np.diff(stations) >= 0):
            raise ValueError(
                "LineFormation: stations must be strictly decreasing (UAV 1 holds farthest)"
            )
        object.__setattr__(self, "stations", _readonly(stations))
        return stations

    def _station_tables(self, thresholds, phase_directions, stations, rank_spacing_r):
        """Thresholds (N, G) and phase directions (G+1, 2) of a station formation from eq. 27's
        (G = K+2); returning, (N, 2G) and (2G+1, 2). Sets the caps S_n, S_out and the mirror M."""
        caps = stations + rank_spacing_r  # S_n = s_n + (n-1) dS_r, where UAV n stops
        outbound = float(caps.max())  # S_out: UAV N's cap whenever the gaps are <= dS_r
        object.__setattr__(self, "_caps", _readonly(caps))
        object.__setattr__(self, "_outbound", outbound)
        object.__setattr__(self, "_outbound_count", thresholds.shape[1])
        # S_n <= L_K,n (s_n <= len(P)): UAV n is still on the path when it stops. Its later
        # thresholds collapse onto S_n; their jumps add up to minus its direction there.
        capped = np.minimum(thresholds, caps[:, None])
        if self.return_distance is None:
            return capped, phase_directions
        # The return is V_n(2 M - S) from M = `return_distance` on (M >= S_out: from the hold;
        # earlier, the motion so far played backwards): the thresholds beyond M collapse onto
        # it, and each threshold L becomes 2 M - L, in reverse order, and
        # the slope on either side changes sign. Just after the mirrored kink the slope is minus
        # the outbound one just before it, just before it minus the one just after: the jump
        # there is (-e_{k-1}) - (-e_k) = e_k - e_{k-1}, the outbound jump. So the directions go
        # on with the jumps in reverse order, their cumulative sum: -e_{k-1} after the mirror of
        # threshold k, and 0 (parked on the start slot) after the mirror of L_0,n.
        mirror = self.return_distance
        object.__setattr__(self, "_mirror", mirror)
        capped = np.minimum(capped, mirror)
        mirrored = 2.0 * mirror - capped[:, ::-1]
        extended = np.concatenate([phase_directions, -phase_directions[-2::-1]])
        return np.concatenate([capped, mirrored], axis=1), extended

    # ----- geometry -------------------------------------------------------------------------

    @property
    def path_length(self) -> float:
        """len(P) (eq. 12)."""
        return self._arc_length

    @property
    def formation_length(self) -> float:
        """G(len(P)): the formation distance from A to B; len(P) unless `warp`ed."""
        return float(self._cumulative[-1])

    @property
    def collision_spacing(self) -> float:
        """dS_c (eq. 23)."""
        return self._spacing_c

    @property
    def radio_spacing(self) -> float:
        """dS_r (eq. 23), or the `spacing` given instead (line of sight)."""
        return self._spacing_r

    @property
    def segment_directions(self) -> np.ndarray:
        """(K+1, 2): e_0 (start row, towards A), e_1 .. e_{K-1} (path), e_K (goal row): unit
        vectors, dV_n/dS on each piece; shorter (1 / G') on a `warp`ed path's steep pieces."""
        return self._directions

    @property
    def thresholds(self) -> np.ndarray:
        """(N, K+2): L_{k,n} for k = 0 .. K+1 (module docstring), row n-1 for UAV n.

        Station formations: min(L_{k,n}, S_n); returning, (N, 2(K+2)): min(L_{k,n}, S_n, M) followed by their
        mirrors 2 M - min(L_{k,n}, S_n, M), k = K+1 .. 0. Every row is non-decreasing."""
        return self._thresholds

    @property
    def total_distance(self) -> float:
        """L_{K+2} = len(P) + (N-1) dS_r: distance after which everyone is parked (eq. 25).

        Station formations: S_out (everyone on its station), 2 M returning (everyone
        back on its start slot)."""
        if self.stations is None:
            return self.formation_length + (self.fleet_size - 1) * self._spacing_r
        return 2.0 * self._mirror if self.returning else self._outbound

    @property
    def outbound_distance(self) -> float:
        """S_out = max_n s_n + (n-1) dS_r, the S from which every UAV is on its station (the
        hold; UAV N's cap); `total_distance` for an A -> B formation."""
        if self.stations is None:
            return self.total_distance
        return self._outbound

    @property
    def returning(self) -> bool:
        """A station formation with its way home (`return_distance` set)."""
        return self.return_distance is not None

    def with_return(self, distance: float) -> LineFormation:
        """This station formation flying home from formation distance `distance` on (M): the
        same V_n(S) up to M, then V_n(2 M - S). M at or after `outbound_distance` returns from
        the hold; earlier, the flight so far is played backwards."""
        return replace(self, return_distance=float(distance))

    @property
    def flown_polyline(self) -> np.ndarray:
        """(K+2, 2): the polyline the UAVs fly: the start row's far end (UAV N's slot), A ... B,
        the goal row's far end (UAV 1's slot)."""
        row = (self.fleet_size - 1) * self._spacing_c
        return np.vstack(
            [
                self.path[0] - row * self._directions[0],
                self.path,
                self.path[-1] + row * self._directions[-1],
            ]
        )

    @property
    def start_slots(self) -> np.ndarray:
        """(N, 2): P_0,n = A - (n-1) dS_c e_0 (eqs. 17, 27)."""
        return self._start_slots.copy()

    @property
    def goal_slots(self) -> np.ndarray:
        """(N, 2): P_{K+1},n = B + (N-n) dS_c e_K (eq. 17 with the dS_c factor): where each UAV
        ends. Station formations: its station (`station_slots`), its start slot when returning."""
        if self.stations is not None:
            return self._start_slots.copy() if self.returning else self.station_slots
        behind = self.fleet_size - 1 - self._rank
        return self.path[-1] + (behind * self._spacing_c)[:, None] * self._directions[-1]

    @property
    def landing_slots(self) -> np.ndarray:
        """(N, 2): where each UAV lands at the end of the mission: its arrival slot
        (`goal_slots`), or for a station formation its start slot (the fleet comes home),
        whether or not the return is decided yet."""
        return self._start_slots.copy() if self.stations is not None else self.goal_slots

    @property
    def station_slots(self) -> np.ndarray:
        """(N, 2): the points where the UAVs hold, s_n along the path from A; `goal_slots` for
        an A -> B formation."""
        if self.stations is None:
            return self.goal_slots
        return self._point_at(self.stations)

    @property
    def departure_distance(self) -> np.ndarray:
        """(N,): L_0,n, the S at which UAV n leaves its parking slot."""
        return self._thresholds[:, 0]

    @property
    def arrival_distance(self) -> np.ndarray:
        """(N,): L_{K+1},n, the S at which UAV n parks on its arrival slot (for good: station
        formations S_n, on its station; returning, 2 M - L_0,n, back on its start
        slot)."""
        return self._thresholds[:, -1]

    # ----- V_n as a function of S -------------------------------------------------------------

    def distance_beyond_start(self, distance) -> np.ndarray:
        """(..., N): distance travelled beyond A by each UAV (the paper's S', fig. 3).

        Negative on the start row, above len(P) on the goal row. Station formations: at most
        s_n; returning, that of the mirrored distance min(S, 2 M - S).
        """
        s = np.asarray(distance, dtype=float)[..., None]
        if self.stations is not None:
            if self.returning:
                s = np.minimum(s, 2.0 * self._mirror - s)
            beyond = np.maximum(s - self._rank_spacing_r, self._lowest_beyond)
            return np.minimum(beyond, self.stations)
        return np.minimum(
            np.maximum(s - self._rank_spacing_r, self._lowest_beyond), self._highest_beyond
        )

    def positions(self, distance) -> np.ndarray:
        """V_n at formation distances S (eq. 27): shape S.shape + (N, 2)."""
        return self._point_at(self.distance_beyond_start(distance))

    def directions(self, distance) -> np.ndarray:
        """dV_n/dS (right derivative), S.shape + (N, 2): e_k while moving, 0 while parked (or
        holding on a station); -e_k on the way home of a returning formation."""
        return self._phase_directions[self._passed(distance, strict=False)]

    def phases(self, distance) -> np.ndarray:
        """S.shape + (N,) int: 0 parked at start, 1 start row, 2 path, 3 goal row, 4 parked.

        Station formations: 4 is holding on its station (3 never occurs: no goal row); with
        a return, the mirrored phases follow, 2 (path, homewards), 1 (start row), and 0 parked
        on its start slot again. A UAV is in the phase it leaves until S exceeds the
        threshold."""
        count = len(self._cumulative)
        table = np.array([0, 1] + [2] * (count - 1) + [3, 4])
        if self.returning:
            table = np.concatenate([table, table[-2::-1]])
        return table[self._passed(distance, strict=True)]

    def threshold_times(self, profile: SpeedProfile) -> np.ndarray:
        """(N, K+2): Phi(L_{k,n}), the time UAV n passes each threshold (eq. 24)."""
        return profile.time_at_distance(self._thresholds)

    def duration(self, profile: SpeedProfile) -> float:
        """Mission duration T = Phi(len(P) + (N-1) dS_r) (eq. 25); inf if never reached.

        Station formations: Phi(`total_distance`), S_out or 2 S_out (Phi of a distance where the
        profile stops for good is inf, eq. 20: a profile that ends with speed 0 at S_out)."""
        return float(profile.time_at_distance(self.total_distance))

    @property
    def path_arcs(self) -> np.ndarray:
        """(K,): formation distance beyond A of each path point P_k (0 at A; its arc length
        from A, G(arc) on a `warp`ed path, whose points include the knots)."""
        return self._cumulative

    def point_at(self, beyond) -> np.ndarray:
        """Point at formation distance `beyond` from A (arc length unless `warp`ed) on the path
        extended by both rows (negative: on the start row, behind A): beyond.shape + (2,)."""
        return self._point_at(np.asarray(beyond, dtype=float))

    def _point_at(self, beyond: np.ndarray) -> np.ndarray:
        """Point at arc length `beyond` from A on the path extended by both rows.

        Piece j of the extended path starts at `_piece_starts[j]` (arc length `_piece_arcs[j]`)
        and runs along `_directions[j]`: j = 0 the start row (before A), 1 .. K-1 the path's
        segments (the last one up to B included), K the goal row (beyond B)."""
        count = len(self._cumulative)
        piece = np.minimum(self._cumulative.searchsorted(beyond, side="right"), count - 1)
        piece = np.where(beyond > self._cumulative[-1], count, piece)
        along = (beyond - self._piece_arcs[piece])[..., None]
        return self._piece_starts[piece] + along * self._directions[piece]

    def _passed(self, distance, strict: bool) -> np.ndarray:
        """S.shape + (N,): how many thresholds L_{k,n} are below S (strict) or <= S."""
        s = np.asarray(distance, dtype=float)[..., None]
        if self.stations is not None:
            return self._station_passed(s, strict)
        return self._eq27_passed(s, strict)

    def _station_passed(self, s: np.ndarray, strict: bool) -> np.ndarray:
        """`_passed` of a station formation; `s` broadcasts against (N,) (one S per UAV, or
        (..., 1) for all). Counted through eq. 27's thresholds and the caps, exactly the
        comparisons `_eq27_passed` makes: below S_n the capped thresholds below S are eq. 27's;
        past it all G. On the way home (S > S_out, or S >= S_out counting <=) the mirrored
        thresholds 2 S_out - L below S are the outbound L above S' = 2 S_out - S: G minus those
        <= S' (resp. < S')."""
        count = self._outbound_count
        out = self._capped_passed(s, strict)
        if not self.returning:
            return out
        mirror = self._mirror
        back = 2 * count - self._capped_passed(2.0 * mirror - s, not strict)
        home = s > mirror if strict else s >= mirror
        return np.where(home, back, out)

    def _capped_passed(self, s: np.ndarray, strict: bool) -> np.ndarray:
        """How many of min(L_{k,n}, S_n) are below S (strict) or <= S, `s` as `_station_passed`."""
        capped = s > self._caps if strict else s >= self._caps
        return np.where(capped, self._outbound_count, self._eq27_passed(s, strict))

    def _eq27_passed(self, s: np.ndarray, strict: bool) -> np.ndarray:
        """How many of eq. 27's L_{k,n} are below S (strict) or <= S; `s` broadcasts against
        (N,) (the last axis one S per UAV, or 1)."""
        side = "left" if strict else "right"
        below = np.less if strict else np.less_equal
        on_path = self._cumulative.searchsorted(s - self._rank_spacing_r, side=side)
        departed = below(self._departures, s)
        arrived = below(self._arrivals, s)
        # Keep the three comparisons consistent where rounding splits coincident thresholds.
        on_path = np.where(arrived, len(self._cumulative), on_path * departed)
        return on_path + departed + arrived

    def _kinks(self) -> tuple[np.ndarray, np.ndarray]:
        """Kinks of V_n(S): positions (N, G) = thresholds and unit-speed velocity jumps.

        Thresholds that coincide (UAV 1 starts at A, UAV N stops at B, a station's collapsed
        thresholds; returning, UAV N's stop and turn back at M) are merged: the first of
        a group carries the whole jump e_last - e_{first-1}, the others 0.
        """
        thresholds = self._thresholds
        size = thresholds.shape[1]
        index = np.broadcast_to(np.arange(size), thresholds.shape)
        new_group = np.ones(thresholds.shape, dtype=bool)
        new_group[:, 1:] = thresholds[:, 1:] > thresholds[:, :-1]
        ends_group = np.ones(thresholds.shape, dtype=bool)
        ends_group[:, :-1] = new_group[:, 1:]
        last = np.flip(
            np.minimum.accumulate(np.flip(np.where(ends_group, index, size), axis=1), axis=1),
            axis=1,
        )
        jumps = self._phase_directions[last + 1] - self._phase_directions[index]
        return thresholds, np.where(new_group[..., None], jumps, 0.0)


# ----- smoothed reference (docs/design.md 3.5) ---------------------------------------------


@dataclass(frozen=True, eq=False)
class Reference:
    """Smoothed targets with feed-forward, each (T, N, 2): m, m/s, m/s^2."""

    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray


def _crossing_prefix(formation: LineFormation, profile: SpeedProfile) -> np.ndarray:
    """(N, G+1, 2): prefix sums over the thresholds of jump_k (J(phi) - L phi), phi = Phi(L),
    for `_antiderivative`. They depend on the profile only, which changes on a speed change:
    the formation keeps the last profile's (the fast and live loops evaluate every tick)."""
    cached = formation._crossing_cache
    if cached is not None and cached[0] is profile:
        return cached[1]
    thresholds = formation._thresholds
    crossing = profile.time_at_distance(thresholds)  # (N, K+2)
    finite = np.isfinite(crossing)
    safe_crossing = np.where(finite, crossing, 0.0)
    offsets = np.where(
        finite, profile.distance_integral(safe_crossing) - thresholds * safe_crossing, 0.0
    )
    prefix_a = np.concatenate(
        [
            np.zeros((formation.fleet_size, 1, 2)),
            np.cumsum(offsets[:, :, None] * formation._jumps, axis=1),
        ],
        axis=1,
    )
    object.__setattr__(formation, "_crossing_cache", (profile, _readonly(prefix_a)))
    return prefix_a


def _antiderivative(
    formation: LineFormation, profile: SpeedProfile, times: np.ndarray, distance: np.ndarray
):
    """Integral of V_n - P_0,n from -inf to t, (T, N, 2), exact; `distance` is S(times).

    V_n(t) = P_0,n + sum_k jump_k max(S(t) - L_k,n, 0) with jump_k = e_k - e_{k-1} (eq. 27
    regrouped), and the integral of max(S - L, 0) up to t is J(t) - L t - (J(phi) - L phi)
    once t > phi = Phi(L), with J the integral of S. The set of passed thresholds is a prefix,
    so the sums over k are prefix sums gathered at the count of passed thresholds.
    """
    prefix_a = _crossing_prefix(formation, profile)
    passed = formation._passed(distance, strict=True)  # (T, N)
    uav = np.arange(formation.fleet_size)
    integral = profile.distance_integral(times)[:, None, None]
    return (
        integral * formation._phase_directions[passed]
        - times[:, None, None] * formation._prefix_l[uav, passed]
        - prefix_a[uav, passed]
    )


def _velocity(
    formation: LineFormation, profile: SpeedProfile, times: np.ndarray, distance: np.ndarray
) -> np.ndarray:
    """dV_n/dt (right derivative), (T, N, 2); `distance` is S(times)."""
    return profile.speed_at(times)[:, None, None] * formation.directions(distance)


def smoothed_reference(
    formation: LineFormation, profile: SpeedProfile, times, window_s: float
) -> Reference:
    """Moving average of V_n(t) over [t - w/2, t + w/2], with its exact derivatives.

    Closed form, vectorised over times and UAVs. The velocity is (V(t+w/2) - V(t-w/2)) / w and
    the acceleration (V'(t+w/2) - V'(t-w/2)) / w (piecewise constant, right-continuous).
    `window_s == 0` returns V_n itself with its velocity and zero acceleration.
    """
    window_s = float(window_s)
    if not (math.isfinite(window_s) and window_s >= 0):
        raise ValueError(f"window_s must be finite and >= 0, not {window_s}")
    times = np.asarray(times, dtype=float).reshape(-1)
    if window_s == 0:
        distance = profile.distance(times)
        positions = formation.positions(distance)
        velocities = _velocity(formation, profile, times, distance)
        return Reference(positions, velocities, np.zeros_like(velocities))
    # Both window ends in one evaluation: [late..., early...].
    ends = np.concatenate([times + window_s / 2, times - window_s / 2])
    count = len(times)
    distance = profile.distance(ends)
    integral = _antiderivative(formation, profile, ends, distance)
    virtual = formation.positions(distance)
    velocity = _velocity(formation, profile, ends, distance)
    positions = formation._start_slots[None] + (integral[:count] - integral[count:]) / window_s
    velocities = (virtual[:count] - virtual[count:]) / window_s
    accelerations = (velocity[:count] - velocity[count:]) / window_s
    return Reference(positions, velocities, accelerations)


# ----- kink arithmetic shared by the bound, the safe speed and the window ------------------


def _row_searchsorted(rows: np.ndarray, queries: np.ndarray, side: str) -> np.ndarray:
    """np.searchsorted of each row of `queries` (N, Q) in the sorted row of `rows` (N, G)."""
    count, size = rows.shape
    low = min(rows.min(), queries.min())
    band = max(rows.max(), queries.max()) - low + 1.0
    offsets = np.arange(count)[:, None] * band
    flat = (rows - low + offsets).ravel()
    found = np.searchsorted(flat, queries - low + offsets, side=side)
    return np.clip(found - np.arange(count)[:, None] * size, 0, size)


def _bump(offset: np.ndarray, width: float) -> np.ndarray:
    """Moving-average error of a unit velocity kink at `offset` from it: (w/2 - |x|)^2 / 2w."""
    return np.maximum(width / 2 - np.abs(offset), 0.0) ** 2 / (2 * width)


def _neighbours(positions: np.ndarray, radius: float):
    """For each kink, indices (N, G, W) of the kinks within `radius` of it, and a validity mask."""
    low = _row_searchsorted(positions, positions - radius, "left")
    high = _row_searchsorted(positions, positions + radius, "right")
    width = max(int((high - low).max()), 1)
    index = low[..., None] + np.arange(width)
    valid = index < high[..., None]
    return np.minimum(index, positions.shape[1] - 1), valid


def _gather(values: np.ndarray, index: np.ndarray) -> np.ndarray:
    """values (N, G) gathered at index (N, G, W)."""
    count = values.shape[0]
    return np.take_along_axis(values, index.reshape(count, -1), axis=1).reshape(index.shape)


def _max_bump_sum(positions: np.ndarray, weights: np.ndarray, width: float) -> float:
    """max over x of sum_i weights_i bump(x - positions_i): attained at a kink (convexity)."""
    if width <= 0 or positions.size == 0:
        return 0.0
    index, valid = _neighbours(positions, width / 2)
    offset = positions[..., None] - _gather(positions, index)
    total = np.where(valid, _gather(weights, index) * _bump(offset, width), 0.0).sum(axis=-1)
    return float(total.max())


class _JumpSteps:
    """M(lambda): the largest |sum of velocity jumps| of kinks within a path window lambda.

    Built from every contiguous range of kinks (per row) spanning at most `radius`; M is the
    running maximum of the ranges' vector sums sorted by span, a right-continuous step
    function. The reference's acceleration is that sum divided by the window (docs/design.md 3.5).
    """

    def __init__(self, positions: np.ndarray, jumps: np.ndarray, radius: float) -> None:
        count, size = positions.shape
        self.radius = radius
        high = _row_searchsorted(positions, positions + radius, "right")
        width = max(int((high - np.arange(size)).max()), 1)
        index = np.arange(size)[None, :, None] + np.arange(width)
        index = np.broadcast_to(index, (count, size, width))
        valid = index < high[..., None]
        index = np.minimum(index, size - 1)
        cumulative = np.concatenate([np.zeros((count, 1, 2)), np.cumsum(jumps, axis=1)], axis=1)
        flat = (index + 1).reshape(count, -1, 1)
        sums = np.take_along_axis(cumulative, flat, axis=1).reshape(count, size, width, 2)
        sums = sums - cumulative[:, :size, None, :]
        spans = _gather(positions, index) - positions[..., None]
        order = np.argsort(spans[valid], kind="stable")
        self.spans = spans[valid][order]
        self.largest = np.maximum.accumulate(np.hypot(sums[..., 0], sums[..., 1])[valid][order])

    def __call__(self, widths) -> np.ndarray:
        """M at each width (widths must not exceed `radius`)."""
        found = np.searchsorted(self.spans, np.asarray(widths, dtype=float), side="right") - 1
        return self.largest[np.maximum(found, 0)]


def _unit_kinks(formation_or_path) -> tuple[np.ndarray, np.ndarray]:
    """Kinks along S at unit speed: positions (R, G) sorted per row, velocity jumps (R, G, 2).

    A `LineFormation` gives every UAV's kinks (start, row->path bend, path bends, path->row bend,
    stop); a bare (K, 2) path gives its interior bends only.
    """
    if isinstance(formation_or_path, LineFormation):
        return formation_or_path._kinks()
    path = np.asarray(formation_or_path, dtype=float).reshape(-1, 2)
    steps = np.diff(path, axis=0)
    lengths = np.hypot(steps[:, 0], steps[:, 1])
    if np.any(lengths <= DISTANCE_TOLERANCE):
        raise ValueError("path: consecutive points must be distinct")
    units = steps / lengths[:, None]
    return np.cumsum(lengths)[:-1][None], np.diff(units, axis=0)[None]


def smoothing_error_bound(
    formation: LineFormation, profile: SpeedProfile, window_s: float
) -> float:
    """Upper bound of |smoothed reference - V_n(t)| over all t and n, metres (docs/design.md 3.5).

    V_n(t) is piecewise linear in t; the moving average over a window w deviates from it by
    sum_i dv_i g(t - t_i) with dv_i the velocity jump at kink t_i and
    g(x) = (w/2 - |x|)^2 / (2w) (g(0) = w/8). Bounded by sum |dv_i| g(t - t_i), whose maximum is
    at a kink (each g is convex on either side of its peak), so kinks closer than w add up.
    Kinks: each UAV's threshold crossings (bends, start, stop; |dv| = v |e_k - e_{k-1}|) and
    every speed step |v_i - v_{i-1}| while the UAV moves. Coincident kinks are counted
    separately (conservative).

    Station formations hold on purpose at a kink (the formation stops at S_out, UAV N's
    station), where counting the bend at Phi and both speed steps would triple the stop's
    weight: their kinks are the jumps of each UAV's velocity in time, measured
    (`_velocity_jumps`).
    """
    window_s = float(window_s)
    if window_s <= 0:
        return 0.0
    if formation.stations is not None:
        return _worst_bump(*_velocity_jumps(formation, profile), window_s)
    thresholds, jumps = formation._kinks()
    crossing = profile.time_at_distance(thresholds)  # (N, K+2)
    finite = np.isfinite(crossing)
    safe_crossing = np.where(finite, crossing, 0.0)
    speed = np.maximum(profile.speed_at(safe_crossing), profile.speed_before(safe_crossing))
    bend_weights = np.where(finite, speed * np.hypot(jumps[..., 0], jumps[..., 1]), 0.0)
    step_times = profile.times[1:]
    step_sizes = np.abs(np.diff(profile.speeds))
    reached = profile.distance(step_times)[None, :]  # (1, C-1)
    moving = (thresholds[:, :1] < reached) & (reached <= thresholds[:, -1:])
    step_weights = np.where(moving, step_sizes[None, :], 0.0)
    times = np.concatenate(
        [safe_crossing, np.broadcast_to(step_times, (formation.fleet_size, len(step_times)))],
        axis=1,
    )
    weights = np.concatenate([bend_weights, step_weights], axis=1)
    return _worst_bump(times, weights, window_s)


def _worst_bump(times: np.ndarray, weights: np.ndarray, window_s: float) -> float:
    """`_max_bump_sum` of kinks at `times` (N, G) weighing `weights`, in any order. Kinks that
    weigh nothing (unreached, collapsed thresholds, a UAV holding through a speed step) are
    parked far away, each alone, so that they share no window and widen no neighbourhood."""
    far = float(times.max()) + 2 * window_s + 1.0
    spread = far + np.arange(times.shape[1]) * (window_s + 1.0)
    times = np.where(weights > 0, times, spread)
    order = np.argsort(times, axis=1, kind="stable")
    return _max_bump_sum(
        np.take_along_axis(times, order, axis=1),
        np.take_along_axis(weights, order, axis=1),
        window_s,
    )


def _velocity_jumps(formation: LineFormation, profile: SpeedProfile):
    """Every UAV's velocity jumps in time: kink times (N, M) sorted per row, |jump| (N, M).

    dV_n/dt = v(t) dV_n/dS(S(t)) changes only at a speed step or when S crosses a threshold,
    at Phi(L) (a threshold reached at the start of a stop is left at its end, eq. 20; the
    stop's start is a speed step). Between consecutive such instants the velocity is
    constant: it is sampled half-way (right-continuous: at an instant itself when two
    coincide), and each jump is the difference of the velocities on either side (0 before
    the mission start). Unreached thresholds weigh 0 (their time: the last reached one's).
    """
    count = formation.fleet_size
    crossing = profile.time_at_distance(formation._thresholds)  # (N, G)
    steps = np.broadcast_to(profile.times, (count, len(profile.times)))
    times = np.sort(np.concatenate([crossing, steps], axis=1), axis=1)  # inf last
    finite = np.isfinite(times)
    later = np.concatenate([times[:, 1:], np.full((count, 1), np.inf)], axis=1)
    middle = np.where(np.isfinite(later), 0.5 * (times + later), times + 1.0)
    middle = np.where(finite, middle, 0.0)
    distance = profile.distance(middle)  # (N, M), row n for UAV n
    passed = formation._station_passed(distance.T, strict=False).T
    velocity = profile.speed_at(middle)[..., None] * formation._phase_directions[passed]
    before = np.concatenate([np.zeros((count, 1, 2)), velocity[:, :-1]], axis=1)
    jump = velocity - before
    weights = np.where(finite, np.hypot(jump[..., 0], jump[..., 1]), 0.0)
    return np.where(finite, times, float(times[finite].max())), weights


def _smallest_window(positions, jumps, speed: float, max_acceleration: float) -> float:
    """Smallest path window lambda with speed^2 M(lambda) / lambda <= a_max.

    Fixed point from M(0): every lambda below the current iterate needs a larger one, so the
    increasing iteration stops at the smallest admissible window (M only grows with lambda).
    """
    factor = speed**2 / max_acceleration
    radius = factor * float(np.hypot(jumps[..., 0], jumps[..., 1]).max()) * 2.0
    steps = _JumpSteps(positions, jumps, radius)
    window = factor * float(steps(0.0))
    for _ in range(positions.size + 2):
        if window * 1.01 > steps.radius:  # keep ranges near the window clear of rounding
            steps = _JumpSteps(positions, jumps, 2.0 * window)
        needed = factor * float(steps(window))
        if needed <= window * (1 + _RELATIVE_MARGIN):
            break
        window = needed
    return window


def recommended_window(speed: float, max_acceleration: float, formation_or_path=None) -> float:
    """Smallest smoothing window (s) that keeps the reference's acceleration within a_max.

    The reference's acceleration is the vector sum of the velocity jumps inside the window
    divided by the window, so at constant `speed` v a path window lambda = v w must satisfy
    v^2 M(lambda) / lambda <= a_max, M(lambda) the largest |sum of unit jumps e_k - e_{k-1}|
    within lambda of path (a start or stop is 1, a bend of theta 2 sin(theta/2)). Without a
    formation or path: one 90-degree bend (the sharpest a valid path has), w = sqrt(2) v / a_max.
    Size it for v_max: slower speeds and speed steps of at most v_max (each needs v_max / w <=
    a_max, implied by the start kink) then keep the limit too.
    """
    if not max_acceleration > 0:
        raise ValueError("max_acceleration must be > 0")
    if speed <= 0:
        return 0.0
    if formation_or_path is None:
        return math.sqrt(2.0) * speed / max_acceleration
    positions, jumps = _unit_kinks(formation_or_path)
    if positions.size == 0 or not np.any(np.hypot(jumps[..., 0], jumps[..., 1]) > 0):
        return 0.0
    return _smallest_window(positions, jumps, speed, max_acceleration) / speed


def safe_speed(formation_or_path, max_acceleration: float, error_budget: float) -> float:
    """Highest constant formation speed whose smoothed reference meets a_max and the budget, m/s.

    Model (docs/design.md 3.5): the reference is the moving average of V_n over a window w. A
    velocity jump |dv| smoothed over w costs |dv| w / 8 of position error and needs |dv| / w of
    acceleration, so the smallest error under a_max is |dv|^2 / (8 a_max), with
    |dv| = 2 v sin(theta/2) at a bend of theta (90 degrees at 10 m/s with a_max = 5: 5 m) and
    |dv| = v at a start or stop. Kinks closer than the window add up: in the error each
    contributes |dv| (w/2 - |x|)^2 / 2w at distance x (magnitudes added: conservative), in the
    acceleration their vector jumps add (a rectangle's corner is two 45-degree kinks 2 rho_c
    apart). At constant speed both depend on the window's length along the path,
    lambda = v w: the error E(lambda) grows with lambda, and a window is admissible when
    v^2 M(lambda) / lambda <= a_max. So lambda* = the largest lambda with
    E(lambda) <= error_budget, and the answer is sqrt(a_max max(lambda / M(lambda))) over
    lambda <= lambda* (M steps at the spans of kink ranges: those, and lambda*, are the
    candidates).

    A `LineFormation` counts every UAV's kinks, the row->path and path->row bends included; a
    bare (K, 2) path only its interior bends; inf when nothing bends. The result is rounded
    down by 1e-9 (relative) so that `recommended_window` at this speed stays within the budget.
    """
    if not max_acceleration > 0:
        raise ValueError("max_acceleration must be > 0")
    if not error_budget > 0:
        return 0.0
    positions, jumps = _unit_kinks(formation_or_path)
    weights = np.hypot(jumps[..., 0], jumps[..., 1])
    heaviest = float(weights.max()) if weights.size else 0.0
    if heaviest <= 0:
        return math.inf
    # E(lambda) >= heaviest * lambda / 8 (a kink's own bump), so lambda* <= 8 budget / heaviest.
    low, high = 0.0, 8.0 * error_budget / heaviest
    if _max_bump_sum(positions, weights, high) <= error_budget:
        low = high
    while high - low > 1e-12 * high:
        middle = 0.5 * (low + high)
        if _max_bump_sum(positions, weights, middle) <= error_budget:
            low = middle
        else:
            high = middle
    steps = _JumpSteps(positions, jumps, 1.01 * low)
    spans = np.unique(steps.spans)
    candidates = np.concatenate([[low], spans[(spans > 0) & (spans < low)] * (1 - 1e-6)])
    ratio = float(np.max(candidates / steps(candidates)))
    return math.sqrt(max_acceleration * ratio) * (1 - _RELATIVE_MARGIN)
