"""The hold policy: the formation stops before a UAV that fell behind breaks the error budget.

A UAV following the formation is *behind* when (checked every tick, on mission time):

* its tracking error |position - V_n(t)| will reach `hold_threshold_m` = rho_c minus the
  vehicle's tracking allowance before the UAV can close the gap: the share of the margin the
  smoothed reference may use is spent, what is left is the allowance the UAV needs to stop
  within rho_c. "Will reach": the latest error, grown at its rate g since that sample was
  taken (a lossy link leaves the ground station blind for a few ticks), plus what it grows
  while the UAV matches its target's speed at its acceleration limit (g^2 / 2 a_max). A UAV
  that lost a few setpoints while the formation accelerated lags a target already faster than
  it: measured in the fast mode with 30 % of packets lost, the error grew 6 m/s at 2 m; a hold
  decided on the error alone came at 3.9 m and the error peaked at 5.1 m, past rho_c, before
  the stopping reference let it close. Only a UAV behind its target counts its growth: one
  ahead (it flew its last setpoints on through a stall of the ground station) closes on a
  target that keeps moving, and a hold would widen its gap (measured after a 1 s stall while a
  UAV joined at 8 m/s: 5.5 m with the hold, 2.9 m without);
* it has not been heard for a while (`UavState.silent_errors_m`, the core's dead reckoning
  of it, `gcs.flight.silent`): waiting a tick would not bring the formation's targets closer
  to where it stops flying its last setpoint on alone, and the wait would break the threshold
  or its latest sample is more than `lag_s` mission seconds old;
* otherwise, its latest position sample is more than `lag_s` mission seconds older than the
  mission clock (its telemetry, or its process's clock, lags the mission: the ground station
  is steering it blind).

A setpoint timeout the UAV reports is not a cause of its own: measured in the fast mode (a UAV
starved of setpoints for 1.5 s and 2 s at 8 m/s, its telemetry still arriving, with the
vehicles' former 3 m/s^2 brake), holding on the report raised the worst tracking error from
1.49 m to 4.19 m and from 1.66 m to 6.23 m. The ground station still hears where such a UAV
is: one that stays stopped shows as a growing tracking error, the first cause above.

Then the formation *holds*: the speed profile drops to 0 at the earliest instant the smoothed
reference can take it without a jump (t + w/2, the leading edge of the smoothing window), so every
UAV decelerates within a_max and holds its current target; the mission clock runs on, the
formation distance S stands still. It resumes (the speed it had, from t + w/2 again) once
every following UAV is back within `resume_m` of its target (the tracking allowance), its
telemetry current. A hold that has not restored the budget
after `give_up_s` mission seconds of holding (the link-loss policy's `link_wait_s`) lands
everyone where they are, as a lost link does. Holds that follow each other within that time
(stop and go) count as one: their held seconds add up, the flight between them does not (two
faults 6 s apart, holding 1.5 s and 2 s, once counted as 10 s held and landed the fleet). Scheduled and leader speed changes that fall due while holding
become the speed the formation resumes with; an operator's change, or a freeze of another
cause (link, take-off, Ctrl-C), takes the formation over from the hold.

This module decides; `gcs.flight.core.GroundStation` reads its decisions each tick and applies
them to the profile, the events, `/metrics` and the run JSON's `holds`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

#: Mission seconds a following UAV's latest sample may lag the mission clock (the vehicles'
#: setpoint timeout: a UAV heard from less often is flying on its own).
HOLD_LAG_S = 1.0


@dataclass(frozen=True)
class Hold:
    """One hold of the formation, mission times: decided at `since`, the profile stopping at
    `stop_s`, the reference standing still from `standing_s` (half a window later);
    `held_before_s`: the seconds held by the earlier holds of its episode (a hold that starts
    within `give_up_s` of the end of the previous one continues its episode: stop and go
    counts as one hold). Ended at
    `until` (None: still holding when the run ended) because of `outcome`: "resumed",
    "landed", "operator" (an operator's speed change) or "superseded" (a freeze of another
    cause took over). `reasons`: the UAVs (1-based) behind when it started, and why."""

    since: float
    stop_s: float
    standing_s: float
    reasons: tuple[tuple[int, str], ...]
    held_before_s: float
    until: float | None = None
    outcome: str | None = None

    @property
    def uavs(self) -> tuple[int, ...]:
        return tuple(uav for uav, _ in self.reasons)

    @property
    def duration_s(self) -> float | None:
        return None if self.until is None else self.until - self.since

    def text(self) -> str:
        return "; ".join(f"UAV {uav}: {why}" for uav, why in self.reasons)

    def to_json(self) -> dict:
        return {
            "since_s": self.since,
            "until_s": self.until,
            "duration_s": self.duration_s,
            "uavs": list(self.uavs),
            "reason": self.text(),
            "outcome": self.outcome,
        }


@dataclass(frozen=True)
class UavState:
    """What the policy reads of one UAV at a tick: its index (0-based), whether it follows the
    formation now, its latest tracking error (NaN: none yet), the mission time of its latest
    sample (None: none) and how fast that error grows while the UAV is behind its target (m/s,
    negative: closing; 0 for a UAV ahead, whose gap a hold would only widen)."""

    index: int
    following: bool
    tracking_error_m: float
    sample_time: float | None
    error_growth_mps: float = 0.0
    #: for a UAV not heard lately: the largest tracking error it reaches flying its last
    #: setpoint on alone if the formation holds now, and if it holds a tick later
    #: (`gcs.flight.silent`); None for a UAV heard lately
    silent_errors_m: tuple[float, float] | None = None


@dataclass
class HoldPolicy:
    """Decides when the formation holds and resumes (see the module docstring). Holds nothing
    but its thresholds, the hold in progress and the finished ones."""

    hold_threshold_m: float
    resume_m: float
    give_up_s: float
    max_acceleration: float = math.inf  # m/s^2: how fast a UAV can match its target's speed
    lag_s: float = HOLD_LAG_S
    current: Hold | None = None
    finished: list[Hold] = field(default_factory=list)

    @classmethod
    def for_budget(
        cls,
        safety_margin: float,
        tracking_allowance: float,
        give_up_s: float,
        max_acceleration: float,
    ) -> HoldPolicy:
        """The thresholds from the error budget: hold at rho_c - allowance, resume within the
        allowance (never above the hold threshold); UAVs accelerate at `max_acceleration`."""
        threshold = max(safety_margin - tracking_allowance, 0.5 * safety_margin)
        return cls(threshold, min(tracking_allowance, threshold), give_up_s, max_acceleration)

    def reach_m(self, t: float, uav: UavState) -> float:
        """The tracking error `uav` reaches before it matches its target's speed: its latest
        error, grown at its rate g since that sample was taken (at most `lag_s`), plus
        g^2 / 2 a_max while it closes (NaN: no error known)."""
        growth = max(uav.error_growth_mps, 0.0)
        age = 0.0 if uav.sample_time is None else min(max(t - uav.sample_time, 0.0), self.lag_s)
        return uav.tracking_error_m + growth * age + growth * growth / (2.0 * self.max_acceleration)

    @property
    def holding(self) -> bool:
        return self.current is not None

    def behind(self, t: float, uavs: list[UavState]) -> list[tuple[int, str]]:
        """The following UAVs that fell behind at mission time `t`, (1-based UAV, why)."""
        out = []
        for uav in uavs:
            if not uav.following:
                continue
            reach = self.reach_m(t, uav)
            if uav.tracking_error_m >= self.hold_threshold_m:
                why = (
                    f"tracking error {uav.tracking_error_m:.2f} m >= "
                    f"{self.hold_threshold_m:.2f} m (rho_c less the tracking allowance)"
                )
            elif reach >= self.hold_threshold_m:
                why = (
                    f"tracking error {uav.tracking_error_m:.2f} m growing "
                    f"{uav.error_growth_mps:.1f} m/s reaches {reach:.2f} m >= "
                    f"{self.hold_threshold_m:.2f} m (rho_c less the tracking allowance) "
                    "before it can close"
                )
            elif uav.silent_errors_m is not None and uav.sample_time is not None:
                if not self._silent_due(t, uav):
                    continue
                now_m, next_m = uav.silent_errors_m
                why = (
                    f"its telemetry lags mission time by {t - uav.sample_time:.1f} s; flying "
                    f"its last setpoint on alone it would be {next_m:.2f} m from its target "
                    f"if the formation held a tick later, {now_m:.2f} m if it holds now"
                )
            elif uav.sample_time is not None and t - uav.sample_time > self.lag_s:
                why = f"its telemetry lags mission time by {t - uav.sample_time:.1f} s"
            else:
                continue
            out.append((uav.index + 1, why))
        return out

    def _silent_due(self, t: float, uav: UavState) -> bool:
        """Hold for a silent UAV now: waiting a tick would not bring the formation's targets
        closer to where it stops, and waiting would break the threshold or it has been silent
        longer than `lag_s` (a UAV carrying an accelerating setpoint on is held later, when
        the targets would stop where it stops)."""
        assert uav.silent_errors_m is not None and uav.sample_time is not None
        now_m, next_m = uav.silent_errors_m
        if now_m > next_m:
            return False
        return next_m >= self.hold_threshold_m or t - uav.sample_time > self.lag_s

    def back(self, t: float, uavs: list[UavState]) -> bool:
        """The reference stands still and every following UAV is back within `resume_m` of its
        target and not drifting away (`reach_m`), its telemetry current (a UAV that stopped
        following is judged where the formation stopped, not while it slows down)."""
        if self.current is not None and t < self.current.standing_s:
            return False
        return all(
            not uav.following
            or (
                self.reach_m(t, uav) <= self.resume_m
                and uav.sample_time is not None
                and t - uav.sample_time <= self.lag_s
            )
            for uav in uavs
        )

    def start(
        self, t: float, stop_s: float, standing_s: float, reasons: list[tuple[int, str]]
    ) -> Hold:
        before = 0.0
        if self.finished:
            last = self.finished[-1]
            assert last.until is not None and last.duration_s is not None  # finished: ended
            if t - last.until < self.give_up_s:
                before = last.held_before_s + last.duration_s
        self.current = Hold(t, stop_s, standing_s, tuple(reasons), before)
        return self.current

    def held_s(self, t: float) -> float:
        """Mission seconds the episode of the hold in progress has held by `t` (0: none)."""
        if self.current is None:
            return 0.0
        return self.current.held_before_s + t - self.current.since

    def overdue(self, t: float) -> bool:
        """The hold's episode has held `give_up_s` without restoring the budget."""
        return self.current is not None and self.held_s(t) >= self.give_up_s

    def end(self, t: float, outcome: str) -> Hold | None:
        """End the hold in progress (if any) at `t`; returns it, finished."""
        if self.current is None:
            return None
        hold = self.current
        done = replace(hold, until=t, outcome=outcome)
        self.finished.append(done)
        self.current = None
        return done

    def all_holds(self) -> list[Hold]:
        """Every hold of the run, the one in progress last (not ended)."""
        return self.finished + ([self.current] if self.current is not None else [])
