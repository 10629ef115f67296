"""Run-time monitors: the guarantees' assumptions and the safety bounds, checked on the fly.

Fatal (an event, and the run's exit status becomes 1):
* a UAV's link is lost: no valid message for `link_timeout_s` of mission time;
* a tracking error |position - V_n(t)| at or above rho_c: the guarantees assume less;
* a UAV-UAV distance below 2 x `vehicle.radius` or a UAV-obstacle distance below
  `vehicle.radius`: a collision.

Warnings only (the plan reaches them by design): UAV-UAV below 2 rho_c, UAV-obstacle below
rho_c. A condition is reported when it starts, not at every sample, and again only after it
cleared. Distances are horizontal (docs/outputs.md, run JSON); the sampled checks are the
planner's (`planner.guarantees.check_positions`), so the run, the log report and the plan
measure the same thing.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from planner.guarantees import check_positions
from planner.obstacles import Obstacles
from planner.sight import Sight

#: The plan flies at exactly rho_c from obstacles and 2 rho_c from other UAVs by design, so the
#: flown distance hovers around those bounds: a "near" warning is raised when a bound is crossed
#: and re-armed only once the distance is this much (m) above it again.
NEAR_HYSTERESIS_M = 2.0


@dataclass(frozen=True)
class MonitorEvent:
    """Something a monitor noticed, at mission time `t`."""

    t: float
    level: str  # "warning" | "error"
    kind: str
    text: str
    uav: int | None = None
    fatal: bool = False


@dataclass
class SafetyStats:
    """Running extremes over the whole run."""

    min_uav_uav_m: float = float("inf")
    min_uav_obstacle_m: float = float("inf")
    max_tracking_error_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    max_control_error_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    samples: int = 0
    connected_samples: int = 0
    los_connected_samples: int = 0  # ... connected by line of sight (`planner.sight`)
    last_connected: bool | None = None  # at the last sample with every UAV known

    @property
    def connected_fraction(self) -> float | None:
        return self.connected_samples / self.samples if self.samples else None

    @property
    def los_connected_fraction(self) -> float | None:
        return self.los_connected_samples / self.samples if self.samples else None


class SafetyMonitor:
    """Tracking errors and distances from sampled positions (the paper's D_min,
    docs/design.md 5)."""

    def __init__(
        self,
        *,
        fleet_size: int,
        obstacles: Obstacles,
        base_stations: np.ndarray,
        radio_range: float,
        safety_margin: float,
        vehicle_radius: float,
        sight: Sight | None = None,
    ) -> None:
        self.fleet_size = fleet_size
        self.sight = sight if sight is not None else Sight(obstacles)
        self.obstacles = obstacles
        self.base_stations = np.asarray(base_stations, float).reshape(-1, 2)
        self.radio_range = radio_range
        self.safety_margin = safety_margin
        self.vehicle_radius = vehicle_radius
        self.stats = SafetyStats(
            max_tracking_error_m=np.zeros(fleet_size),
            max_control_error_m=np.zeros(fleet_size),
        )
        self._active: set[tuple] = set()

    def tracking(
        self, t: float, uavs: np.ndarray, errors: np.ndarray, control: np.ndarray
    ) -> list[MonitorEvent]:
        """Tracking errors |position - V_n| (and |position - reference|) of UAVs `uavs` (0-based)."""
        stats = self.stats
        np.maximum.at(stats.max_tracking_error_m, uavs, errors)
        np.maximum.at(stats.max_control_error_m, uavs, control)
        events = []
        for index, error in zip(uavs.tolist(), errors.tolist(), strict=True):
            events += self._condition(
                ("tracking", index),
                error >= self.safety_margin,
                lambda index=index, error=error: MonitorEvent(
                    t,
                    "error",
                    "tracking",
                    f"UAV {index + 1}: tracking error {error:.2f} m >= safety margin "
                    f"{self.safety_margin:g} m (the guarantees no longer hold)",
                    index + 1,
                    fatal=True,
                ),
            )
        return events

    def positions(
        self,
        t: float,
        xy: np.ndarray,
        heights: np.ndarray | None = None,
        excluded: np.ndarray | None = None,
    ) -> list[MonitorEvent]:
        """Distances and connectivity of the fleet at one instant; `xy` (N, 2), NaN = unknown.

        `heights` (N,): some UAV flies in another layer (a relief): UAV-UAV distances and
        links are 3-D. `excluded` (N,) bool: UAVs out of the fleet (relieved and landed),
        neither unknown nor counted."""
        ids = np.arange(1, len(xy) + 1)
        if excluded is not None and excluded.any():
            keep = ~np.asarray(excluded, dtype=bool)
            xy, ids = xy[keep], ids[keep]
            heights = None if heights is None else heights[keep]
        known = np.isfinite(xy).all(axis=1)
        known_count = np.count_nonzero(known)
        if not known_count:
            return []
        everyone = known_count == len(known)
        if heights is not None:
            heights = np.where(np.isfinite(heights), heights, 0.0)[known]
        sample = check_positions(
            (xy if everyone else xy[known])[None],
            self.obstacles,
            self.base_stations,
            self.radio_range,
            None if heights is None else heights[None],
        )
        stats = self.stats
        pair = float(sample.min_uav_uav_m[0])
        obstacle = float(sample.min_uav_obstacle_m[0])
        stats.min_uav_uav_m = min(stats.min_uav_uav_m, pair)
        stats.min_uav_obstacle_m = min(stats.min_uav_obstacle_m, obstacle)
        if everyone:
            stats.samples += 1
            stats.connected_samples += int(sample.connected[0])
            if sample.connected[0]:  # by line of sight too? (a subset of the links)
                sight = check_positions(
                    xy[None], Obstacles(), self.base_stations, self.radio_range,
                    None if heights is None else heights[None], sight=self.sight,
                )  # fmt: skip
                stats.los_connected_samples += int(sight.connected[0])
            stats.last_connected = bool(sample.connected[0])
        events = []
        rho, radius = self.safety_margin, self.vehicle_radius
        if math.isfinite(pair):

            def who() -> str:
                where = xy[known] if heights is None else np.column_stack([xy[known], heights])
                return self._closest_pair(where, ids[known])

            events += self._condition(
                ("uav_collision",),
                pair < 2 * radius,
                lambda: MonitorEvent(
                    t,
                    "error",
                    "collision_uav",
                    f"UAVs {who()}: {pair:.2f} m apart, below 2 x vehicle radius "
                    f"({2 * radius:g} m)",
                    fatal=True,
                ),
            )
            events += self._condition(
                ("uav_near",),
                pair < 2 * rho,
                lambda: MonitorEvent(
                    t, "warning", "near_uav", f"UAVs {who()}: {pair:.2f} m apart (< 2 rho_c)"
                ),
                cleared=pair > 2 * rho + NEAR_HYSTERESIS_M,
            )
        if math.isfinite(obstacle):
            events += self._condition(
                ("obstacle_collision",),
                obstacle < radius,
                lambda: MonitorEvent(
                    t,
                    "error",
                    "collision_obstacle",
                    f"a UAV is {obstacle:.2f} m from an obstacle, below its radius ({radius:g} m)",
                    fatal=True,
                ),
            )
            events += self._condition(
                ("obstacle_near",),
                obstacle < rho,
                lambda: MonitorEvent(
                    t,
                    "warning",
                    "near_obstacle",
                    f"a UAV is {obstacle:.2f} m from an obstacle (< rho_c)",
                ),
                cleared=obstacle > rho + NEAR_HYSTERESIS_M,
            )
        return events

    def _condition(
        self,
        key: tuple,
        active: bool,
        event: Callable[[], MonitorEvent],
        cleared: bool | None = None,
    ) -> list[MonitorEvent]:
        """Report `event()` when the condition starts (the event, its text and who it names are
        only made then); forget it once `cleared` (default: as soon as it is no longer
        active)."""
        if active and key not in self._active:
            self._active.add(key)
            return [event()]
        if (not active) if cleared is None else cleared:
            self._active.discard(key)
        return []

    @staticmethod
    def _closest_pair(xy: np.ndarray, ids: np.ndarray) -> str:
        gap = xy[:, None, :] - xy[None, :, :]
        distance = np.linalg.norm(gap, axis=2)
        np.fill_diagonal(distance, np.inf)
        i, j = np.unravel_index(np.argmin(distance), distance.shape)
        return f"{ids[min(i, j)]} and {ids[max(i, j)]}"


class LinkMonitor:
    """Link loss (docs/outputs.md: alive while any valid message arrives from the system id)."""

    def __init__(self, fleet_size: int, link_timeout_s: float = 3.0) -> None:
        self.link_timeout_s = link_timeout_s
        self.lost = np.zeros(fleet_size, dtype=bool)
        self.ever_lost = np.zeros(fleet_size, dtype=bool)
        self.lost_at = np.full(fleet_size, -np.inf)  # mission time of each UAV's last loss
        # silence (wall s) when a UAV was declared gone; lost until a newer message arrives
        self._forced = np.full(fleet_size, np.inf)

    def check(self, t: float, silent_s: np.ndarray, timeout_s: float) -> list[MonitorEvent]:
        """`silent_s` (N,): seconds (wall) since each UAV's last valid message; `timeout_s` is
        the link timeout on the same clock."""
        events = []
        self._forced[silent_s < self._forced] = np.inf  # a message arrived since
        now_lost = (silent_s > timeout_s) | np.isfinite(self._forced)
        for index in np.flatnonzero(now_lost & ~self.lost):
            events.append(
                MonitorEvent(
                    t,
                    "error",
                    "link_lost",
                    f"UAV {index + 1}: link lost (no valid message for {self.link_timeout_s:g} s)",
                    int(index) + 1,
                    fatal=True,
                )
            )
        for index in np.flatnonzero(~now_lost & self.lost):
            events.append(
                MonitorEvent(
                    t, "warning", "link_back", f"UAV {index + 1}: link back", int(index) + 1
                )
            )
        self.lost_at[now_lost & ~self.lost] = t
        self.ever_lost |= now_lost
        self.lost = now_lost
        return events

    def mark_lost(self, t: float, index: int, why: str, silent_s: float) -> list[MonitorEvent]:
        """A UAV known to be gone (its vehicle process exited) before its link times out;
        `silent_s` is its current silence: it counts as lost until a newer message arrives."""
        self._forced[index] = max(silent_s, 0.0)
        if self.lost[index]:
            return []
        self.lost[index] = True
        self.ever_lost[index] = True
        self.lost_at[index] = t
        return [MonitorEvent(t, "error", "link_lost", f"UAV {index + 1}: {why}", index + 1, True)]
