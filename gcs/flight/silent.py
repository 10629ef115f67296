"""Where a UAV flies when the ground station no longer hears it: dead reckoning from its last
setpoint, and the tracking error it would reach if the formation held now or a tick later.

A UAV whose link is cut (out of range, jammed, its process stopped) flies on alone: its
autopilot extrapolates the last setpoint it received along its feed-forward for
`OnItsOwn.horizon_s` (ArduCopter's GUID_TIMEOUT integrates the guided target's velocity and
acceleration; our vehicles for at most 1 s), then brakes to a stop at `brake_mps2` (the guided
acceleration, WPNAV_ACCEL, which the run checks is at least the mission's a_max). The ground
station knows what it sent and when it last heard the UAV, so it can tell where the UAV will
stop without hearing it, and time the formation's hold so that the formation's targets stop
near it:

* a UAV left standing (its last setpoint at rest, the formation starting) must be held at
  once: every tick of waiting moves its target on;
* a UAV carrying on an accelerating setpoint overshoots: holding as soon as its telemetry lags
  (the former fixed 1 s rule) stopped the targets short of it (5.5 m in the fast mode, a link
  cut while a UAV joined at 12 m/s); holding later, when the targets would stop where it
  stops, keeps the error smallest.

`hold_errors` gives both sides of that choice; `gcs.flight.hold.HoldPolicy` decides. Pure: no
clocks, sockets or files.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: Mission seconds between the samples of a forecast.
FORECAST_STEP_S = 0.1
#: The longest forecast (mission s): a UAV stopped by then, or the link policy's business.
FORECAST_SPAN_S = 8.0


@dataclass(frozen=True)
class OnItsOwn:
    """What an autopilot does with its last setpoint when the stream stops: it flies the
    setpoint's feed-forward on for `horizon_s`, then brakes horizontally at `brake_mps2`."""

    horizon_s: float
    brake_mps2: float


@dataclass(frozen=True)
class SentSetpoint:
    """A horizontal setpoint the ground station sent at mission time `t` (ENU m, m/s, m/s^2;
    zero acceleration where the autopilot takes none)."""

    t: float
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray

    def stop_time(self, alone: OnItsOwn) -> float:
        """Mission time a UAV flying this setpoint on alone comes to rest."""
        end_velocity = self.velocity + self.acceleration * alone.horizon_s
        return self.t + alone.horizon_s + float(np.hypot(*end_velocity)) / alone.brake_mps2


def dead_reckon(setpoint: SentSetpoint, alone: OnItsOwn, times: np.ndarray) -> np.ndarray:
    """(T, 2) where a UAV whose last setpoint was `setpoint` is at mission `times`: the setpoint
    extrapolated for the horizon, then a straight braking run along its velocity at the brake
    deceleration, then standing."""
    times = np.asarray(times, dtype=float)
    horizon = alone.horizon_s
    tau = np.clip(times - setpoint.t, 0.0, horizon)[:, None]
    p, v, a = setpoint.position, setpoint.velocity, setpoint.acceleration
    positions = p + v * tau + 0.5 * a * tau * tau
    end_position = p + v * horizon + 0.5 * a * horizon * horizon
    end_velocity = v + a * horizon
    speed = float(np.hypot(*end_velocity))
    if speed <= 0.0:
        return positions
    brake = alone.brake_mps2
    braking = np.clip(times - setpoint.t - horizon, 0.0, speed / brake)[:, None]
    run = speed * braking - 0.5 * brake * braking * braking
    after = (times - setpoint.t > horizon)[:, None]
    return np.where(after, end_position + end_velocity / speed * run, positions)


def hold_errors(
    setpoint: SentSetpoint,
    alone: OnItsOwn,
    now: float,
    tick_s: float,
    targets_if_held: Callable[[float, np.ndarray], np.ndarray],
    standing_after_s: float,
) -> tuple[float, float]:
    """The largest distance between a silent UAV (dead reckoned from `setpoint`) and its target
    from `now` on, if the formation holds now and if it holds a tick later.
    `targets_if_held(decided, times)` is the UAV's target (T, 2) at `times` under a hold
    decided at mission time `decided`; the targets stand still `standing_after_s` after it."""
    end = max(setpoint.stop_time(alone), now + tick_s + standing_after_s) + FORECAST_STEP_S
    end = min(end, now + FORECAST_SPAN_S)
    times = np.arange(now, end + FORECAST_STEP_S / 2, FORECAST_STEP_S)
    uav = dead_reckon(setpoint, alone, times)
    errors = []
    for decided in (now, now + tick_s):
        offsets = uav - targets_if_held(decided, times)
        errors.append(float(np.max(np.hypot(offsets[:, 0], offsets[:, 1]))))
    return errors[0], errors[1]
