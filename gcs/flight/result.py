"""What a flight reports (the run JSON's source, `gcs.summary`): `RunResult` and the stations'
`StationsResult`, and the pure arithmetic of the result: whether the flight completed, each
UAV's landing error, and the setpoint stream's achieved rate and jitter. The core gathers the
flight's facts; this module judges them. Pure: no clocks, sockets or files.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gcs.drivers.limits import LimitExceeded
from gcs.flight.hold import Hold
from gcs.flight.stall import Stall
from gcs.monitors import MonitorEvent


@dataclass(frozen=True)
class PointHeld:
    """One monitoring point of a stations mission (visiting order): the UAV that holds it
    and the mission seconds its reported position was within rho_c of the point while its
    virtual target held there."""

    name: str
    uav: int
    on_station_s: float


@dataclass(frozen=True)
class UavRelieved:
    """A UAV relieved from its station (`gcs relieve`, or its battery): asked at mission time
    `asked_s` by `source`, landed on the start-row slot `landing` (at `landed_s`; None if it
    had not landed), after `on_station_s` mission seconds on station."""

    uav: int
    source: str
    asked_s: float
    landing: tuple[float, float]
    landed_s: float | None
    on_station_s: float


@dataclass(frozen=True)
class StationsResult:
    """What a stations mission reports: its points, the effective mission time of the return
    (None: never returned), and the fraction of the connectivity samples taken while every
    virtual target held its station (from S_out until the first UAV leaves for home, one
    smoothing window after the return) at which every UAV was chained to a base station
    (None: no such sample)."""

    points: tuple[PointHeld, ...]
    return_s: float | None
    held_connected_fraction: float | None
    relieved: tuple[UavRelieved, ...] = ()


@dataclass
class RunResult:
    """Everything the summary reports."""

    completed: bool
    reason: str | None
    fleet_size: int
    duration_s: float | None
    min_uav_uav_m: float | None
    min_uav_obstacle_m: float | None
    max_tracking_error_m: float | None
    tracking_error_m: list[float | None]
    control_error_m: list[float | None]
    landing_error_m: list[float | None]
    connected_fraction: float | None
    speed_changes: list[dict]
    #: ... by line of sight: every hop's chord clear of the buildings (docs/outputs.md)
    los_connected_fraction: float | None
    events: list[MonitorEvent]
    phases: list[str]
    smoothing_window_s: float
    smoothing_error_m: float
    noise_m: float | None
    setpoints_sent: int
    setpoint_rate_hz: float | None
    setpoint_jitter_p99_ms: float | None
    setpoint_period_ms: float
    setpoint_max_gap_ms: float | None
    ticks: int
    interrupted: int
    fatal: bool
    radio: dict | None = None  # the radio medium's run JSON `radio` object, if one ran
    stalls: list[Stall] = field(default_factory=list)  # stalls of the loop, held back or not
    telemetry_shed: int = 0  # stale telemetry datagrams of backlogs, not decoded
    #: The mission assumed more than an autopilot allows and was refused before take-off.
    limits_refused: list[LimitExceeded] = field(default_factory=list)
    stations: StationsResult | None = None  # stations missions only
    holds: list[Hold] = field(default_factory=list)  # the formation held for a UAV behind


@dataclass(frozen=True)
class SetpointTiming:
    """The setpoint stream as achieved: mean rate (Hz of mission time), the 99th percentile
    of |period - nominal| (ms) and the longest gap between ticks (ms); None: under 3 ticks."""

    rate_hz: float | None
    jitter_p99_ms: float | None
    max_gap_ms: float | None


def setpoint_timing(tick_walls: list[float], nominal_s: float, speedup: float) -> SetpointTiming:
    """From the loop's time of each tick that streamed and the nominal period (loop s)."""
    walls = np.array(tick_walls)
    periods = np.diff(walls) if len(walls) > 2 else np.zeros(0)
    if not periods.size:
        return SetpointTiming(None, None, None)
    return SetpointTiming(
        rate_hz=float(1.0 / periods.mean() / speedup),
        jitter_p99_ms=float(np.percentile(np.abs(periods - nominal_s), 99) * 1000),
        max_gap_ms=float(periods.max() * 1000),
    )


def landing_errors(final_xy: list[np.ndarray | None], slots: np.ndarray) -> list[float | None]:
    """Each UAV's horizontal distance from its landing slot where it ended (None: unknown)."""
    return [
        None if xy is None else float(np.hypot(*(xy - slot)))
        for xy, slot in zip(final_xy, slots, strict=True)
    ]


def completion(
    *,
    aborting: bool,
    started: bool,
    all_landed: bool,
    all_told_to_land: bool,
    landing_error_m: list[float | None],
    safety_margin: float,
) -> tuple[bool, str | None]:
    """Whether the flight completed: started, not aborted, every UAV told to land and landed
    within rho_c of its slot; else the reason to give when the flight has none of its own."""
    on_slots = all(e is not None and e < safety_margin for e in landing_error_m)
    if not aborting and started and all_landed and all_told_to_land and on_slots:
        return True, None
    if not on_slots and all_landed:
        return False, "a UAV landed off its arrival slot"
    return False, "the mission did not complete"
