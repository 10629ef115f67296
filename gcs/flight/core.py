"""The ground-station core: all the flight policy of one mission, with no socket and no clock.

The loop that drives it passes its time `now` (the live loop's monotonic wall clock, the fast
mode's simulated seconds) and what arrived, and the core answers through its drivers (which
write to the links they were given) and its recorder. Two loops drive this one core:
`gcs.flight.live` (selectors over UDP links, the wall clock) and `gcs.sim.fastsim` (the lockstep
vehicles and radio medium in process, in-memory links). The loop calls, in order:

* `receive(now, batches)`: every valid message read from each UAV's link (a stall of the loop
  is noticed here: see below); `fleet_reports(...)`, `operator_request(...)` and
  `operator_command(...)` for what its processes, socket and terminal delivered;
* `connect_step(now, started)` until every UAV is ready (the mission clock is then anchored),
* then `tick(now)` at the mission's setpoint rate (in mission time) until `finished(now)`;
* `result()`: the run's `RunResult`.

At each tick the core:

1. turns speed requests (schedule, operator, leader, Ctrl-C, link loss) into time-stamped
   changes of the formation's speed profile, broadcast to every UAV (docs/design.md 4);
2. takes each UAV off when its departure Phi(L_0,n) approaches (minus the take-off lead),
   lands it when it sits on its arrival slot after Phi(L_{K+1},n);
3. streams one setpoint per UAV in flight, from the smoothed reference of V_n(t) (position,
   velocity, acceleration; docs/design.md 3.5), converted for the whole fleet at once;
4. steps the drivers (handshakes, retransmissions), runs the monitors, records.

Monitoring-station missions (`formation.stations`, use case 1): the formation caps each UAV
on its station, so from the outbound distance S_out on every UAV holds there; nobody lands on
a station, the setpoints keep flowing. The formation then stops (speed 0, `_hold_due`), so
that S stays at S_out: the return plays the flight up to S backwards, and distance run while
holding would be played back as more holding. The return home (`_return_home`, whoever asks:
the mission's `return.at`, the end of every point's `dwell_s`, the operator with `gcs return`
or `return` typed in the live view, or at once when `RunOptions.return_when_on_station` and
nothing else applies) stops S at the effective time t_e (speed 0), plays the flight so far
backwards from M = S(t_e) (`LineFormation.with_return`) and restores the speed one smoothing
window later: the reversal's velocity jump is two steps, each within the smoothing budget.
Each UAV then lands on its start slot when it gets there (the landing rule, with the returning
formation's arrival slots); a UAV the return reached before it left its slot stays down.

If the loop stalls, the setpoints stop and the vehicles' own failsafes see it; once it runs
again the mission clock stands still while the backlog is read, then the mission resumes where
the UAVs stopped (`_resume_after_stall`), so that they are not asked to catch up: the mission
clock never runs backwards and never counts time the formation was not flown. Mission time 0
is when the formation starts moving; the clock is anchored once every UAV is ready, so that
UAV 1 (which leaves at t = 0) takes off at -lead. With `speedup` K the mission clock runs K
times faster than the loop's clock; every delay keeps a floor (`DriverTiming`).

A UAV that is not airborne shortly before its departure freezes the formation (speed 0) until
it is: the virtual targets never leave a UAV behind. A lost link freezes the formation too;
then either the operator decides (interactive) or, after `link_wait_s`, everyone lands where
it is and the run ends with exit status 1. Ctrl-C once freezes, twice lands everyone.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import NamedTuple, Protocol

import numpy as np

from fleetline.errors import FleetlineError
from fleetwire.messages import parse_clock_slipped
from gcs.drivers.base import VEHICLE_REBOOT_JUMP_S, Driver, DriverEvent, Phase
from gcs.drivers.limits import LimitExceeded, exceeded
from gcs.flight import relief as relief_policy
from gcs.flight.answers import AnswerResult, OperatorAnswer, OperatorCommand
from gcs.flight.clock import MissionClock, VehicleClock, paused
from gcs.flight.hold import HoldPolicy, UavState
from gcs.flight.records import (
    MetricsRecord,
    RadioRecord,
    ReliefRecord,
    ReturnRecord,
    SetpointRecord,
    SpeedRecord,
    SpeedRecordKind,
    UavStateRecord,
    run_json_radio,
)
from gcs.flight.rejoin import RejoinPolicy
from gcs.flight.result import (
    PointHeld,
    RunResult,
    StationsResult,
    UavRelieved,
    completion,
    landing_errors,
    setpoint_timing,
)
from gcs.flight.roster import Roster
from gcs.flight.schedule import Schedule, ScheduleDecision, UavProgress
from gcs.flight.silent import OnItsOwn, SentSetpoint, hold_errors
from gcs.flight.stall import Resume, Stall, resume_point
from gcs.flight.stations import StationWatch
from gcs.geodesy import enu_to_geodetic
from gcs.monitors import LinkMonitor, MonitorEvent, SafetyMonitor
from gcs.speed import (
    SpeedBroadcast,
    SpeedChange,
    SpeedChanges,
    SpeedRefused,
)
from gcs.transport.link import mavutil
from planner.formation import DISTANCE_TOLERANCE
from planner.kinematics import (
    Reference,
    SpeedProfile,
    recommended_window,
    smoothed_reference,
    smoothing_error_bound,
)
from planner.relief import ReliefRefused

log = logging.getLogger(__name__)
mavlink = mavutil.mavlink

_SEVERITY_LEVEL = {
    mavlink.MAV_SEVERITY_EMERGENCY: "fatal",
    mavlink.MAV_SEVERITY_ALERT: "error",
    mavlink.MAV_SEVERITY_CRITICAL: "error",
    mavlink.MAV_SEVERITY_ERROR: "error",
    mavlink.MAV_SEVERITY_WARNING: "warning",
    mavlink.MAV_SEVERITY_NOTICE: "info",
    mavlink.MAV_SEVERITY_INFO: "info",
    mavlink.MAV_SEVERITY_DEBUG: "debug",
}


#: Mission seconds a position sample may be carried forward by its velocity (distances).
MAX_EXTRAPOLATION_S = 1.0
#: Mission seconds without a position sample after which a following UAV is dead-reckoned
#: (`gcs.flight.silent`): five telemetry periods, a cut link rather than lost samples. With
#: 0.25 s, 30 % loss each way made 165 holds in 40 fast-mode flights instead of 18, and one
#: broke rho_c (8.77 m): a hold's own braking and restart, for a UAV that was following.
SILENT_AFTER_S = 0.5
#: A tick this late (mission seconds, the vehicles' setpoint timeout) is a stall of the GCS.
STALL_S = 1.0
#: ... and at least this late on the wall clock (the vehicles' timeouts have this floor).
STALL_WALL_FLOOR_S = 0.25
#: After a stall the formation resumes where the following UAVs stand: it waits (the clock
#: still frozen) until each has a position sample at most this many mission seconds old ...
STALL_FRESH_S = 0.3
#: ... for at most this many mission seconds after the wake-up. Resolving at once on samples
#: from before the stall (their telemetry of the stall lost, or a socket buffer that overflowed
#: while the process was stopped) placed the UAVs 1 s behind where they stood: 4.5 m in the
#: fast mode, 5.03 m (past rho_c) in a live flight of the fault tests.
STALL_FRESH_WAIT_S = 1.0
#: After the last landing, how long (wall s) the GCS waits for disarming and commands in flight.
SETTLE_WALL_S = 3.0
#: Why an operator's speed change is refused while a stations mission's fleet holds.
_HOLDING = (
    "every UAV holds its station: the formation stands still until the return (gcs return); "
    "speed changes apply from then on"
)
#: Who brings a stations mission's fleet home (`ReturnRecord.source`), in words.
_RETURN_SOURCES = {
    "schedule": "the mission's return.at",
    "dwell": "once the longest dwell_s is over",
    "on_station": "as soon as every UAV is on station: no return.at, not every point has a "
    "dwell_s, and nobody to ask",
    "operator": "asked by the operator",
}


@dataclass(frozen=True)
class RunOptions:
    """How to fly (command-line options of `gcs mission run`)."""

    speedup: float = 1.0
    setpoint_rate_hz: float = 10.0  # mission time
    link_timeout_s: float = 3.0  # mission time without a valid message = link lost
    link_wall_floor_s: float = 1.0  # ... but never less than this on the wall clock
    link_wait_s: float = 10.0  # mission time to wait for a lost link before landing everyone
    interactive: bool = False  # a terminal operator decides after a link loss
    takeoff_lead_s: float | None = None  # mission time before departure; None: from the climb
    climb_rate_mps: float = 2.5  # assumed for the automatic take-off lead
    landing_tolerance_m: float = 1.0  # over its arrival slot within this -> land
    landing_settle_s: float = 10.0  # land anyway this long after the target stopped
    connect_timeout_s: float = 60.0  # wall: every UAV ready within this
    finish_timeout_s: float = 120.0  # mission time for the landings after an abort
    metrics_period_s: float = 0.0  # mission time between /metrics records (0: every tick)
    #: A mission assuming more than an autopilot's limits (`gcs.drivers.limits`): "refuse"
    #: before take-off, "cap" (re-plan with the autopilot's limits: `replan`), or "apply"
    #: (set the autopilots' limits for the flight, put back after landing).
    autopilot_limits: str = "refuse"
    #: A stations mission with neither `return.at` nor a `dwell_s` on every point returns as
    #: soon as every UAV is on station (the fast mode: nobody to ask); otherwise it holds until
    #: the operator asks (`gcs return`).
    return_when_on_station: bool = False


@dataclass
class UavTrack:
    """What the runtime keeps per UAV."""

    takeoff_sent: bool = False
    land_sent: bool = False
    takeoff_time: float | None = None  # mission time take-off started
    landed_time: float | None = None
    last_position: np.ndarray | None = None  # (3,) ENU
    last_velocity: np.ndarray | None = None
    last_sample_time: float | None = None  # mission time of the last position
    final_xy: np.ndarray | None = None


class ReturnRefused(FleetlineError, ValueError):
    """A return home that cannot be flown (the reason is the message)."""


class View(Protocol):
    """The live view (or nothing): shown while flying, and a source of operator commands."""

    def update(self, run: GroundStation, now: float) -> None: ...

    def commands(self) -> list[str]: ...

    def message(self, level: str, text: str) -> None: ...


class _NoView:
    def update(self, run: GroundStation, now: float) -> None:
        return None

    def commands(self) -> list[str]:
        return []

    def message(self, level: str, text: str) -> None:
        return None


class Recorder(Protocol):
    """What the core records, as typed records (`gcs.flight.records`); `wall` is the loop's
    time of the thing recorded (gcs.recording.recording.FlightRecorder implements it).
    `keeps_samples` False: the per-UAV setpoint and state records would be thrown away, so the
    core does not build them (the fast mode's `NullRecorder`: 60 k records a mission).
    `error`: why the recording stopped (None: it has not); `on_error` is told that once."""

    keeps_samples: bool
    error: str | None
    on_error: Callable[[str], None] | None

    def setpoint(self, record: SetpointRecord, wall: float) -> None: ...

    def state(self, record: UavStateRecord, wall: float) -> None: ...

    def fix(self, uav: int, lat: float, lon: float, alt: float, wall: float) -> None: ...

    def speed(self, record: SpeedRecord, wall: float) -> None: ...

    def metrics(self, record: MetricsRecord, wall: float) -> None: ...

    def fleet(
        self, t: float, positions: np.ndarray, targets: np.ndarray | None, wall: float
    ) -> None: ...

    def event(self, level: str, message: str, wall: float, name: str = "gcs") -> None: ...

    def radio(self, record: RadioRecord, wall: float) -> None: ...

    def return_home(self, record: ReturnRecord, wall: float) -> None: ...

    def relief(self, record: ReliefRecord, wall: float) -> None: ...


def _error_growth(offsets: np.ndarray, target_velocities: np.ndarray, velocities: np.ndarray):
    """(S,) how fast the tracking error of each UAV behind its target grows, m/s: the target's
    velocity relative to the UAV along the UAV's offset from it (`offsets` (S, 2) = UAV -
    target). 0 where the UAV is not behind (a hold slows the target down: it helps a UAV
    behind close, and widens the gap of one ahead, such as a UAV that flew its last setpoints
    on through a stall of the ground station), its velocity is unknown or it sits on its
    target."""
    distance = np.hypot(*offsets.T)
    toward_target = -offsets / np.maximum(distance, 1e-9)[:, None]
    growth = np.einsum("ij,ij->i", target_velocities - velocities, toward_target)
    behind = np.einsum("ij,ij->i", target_velocities, toward_target) > 0.0
    return np.where(np.isfinite(growth) & (distance > 1e-6) & behind, growth, 0.0)


class _Sample(NamedTuple):
    """A position sample received since the last tick: UAV index, mission time taken, xyz,
    true (SIM_STATE) or reported, horizontal velocity (None: not reported)."""

    uav: int
    t: float
    position: np.ndarray
    truth: bool
    velocity: np.ndarray | None


@dataclass(frozen=True, eq=False)
class _Evaluation:
    """The formation evaluated once per tick: at the tick (row 0) and at each position sample
    received since the last tick (rows 1..): `samples` (UAV index, t, xyz, true?), `times`
    (1+S,), `distances` S(t) (1+S,), `virtual` V_n(t) (1+S, N, 2), `reference` the smoothed
    reference with its feed-forward."""

    samples: list[_Sample]
    times: np.ndarray
    distances: np.ndarray
    virtual: np.ndarray
    reference: Reference


class NullRecorder:
    """Records nothing (the fast mode keeps its own time series), so never fails."""

    keeps_samples = False
    error: str | None = None
    on_error: Callable[[str], None] | None = None

    def setpoint(self, record: SetpointRecord, wall: float) -> None:
        return None

    def state(self, record: UavStateRecord, wall: float) -> None:
        return None

    def speed(self, record: SpeedRecord, wall: float) -> None:
        return None

    def metrics(self, record: MetricsRecord, wall: float) -> None:
        return None

    def radio(self, record: RadioRecord, wall: float) -> None:
        return None

    def return_home(self, record: ReturnRecord, wall: float) -> None:
        return None

    def relief(self, record: ReliefRecord, wall: float) -> None:
        return None

    def fix(self, uav: int, lat: float, lon: float, alt: float, wall: float) -> None:
        return None

    def fleet(self, t: float, positions, targets, wall: float) -> None:
        return None

    def event(self, level: str, message: str, wall: float, name: str = "gcs") -> None:
        return None


class GroundStation:
    """One flight of a planned mission (see the module docstring)."""

    def __init__(
        self,
        plan,
        drivers: list[Driver],
        clock: MissionClock,
        recorder: Recorder,
        options: RunOptions,
        *,
        view: View | None = None,
        replan: Callable[[float, float], object] | None = None,
    ) -> None:
        """`replan(max_speed, max_acceleration)`: the mission planned again with these vehicle
        limits (RunOptions.autopilot_limits "cap")."""
        self._replan = replan
        self.limits_refused: list[LimitExceeded] = []
        self._limits_checked = False
        self._limits_applied = False
        self._adopt(plan)
        self.drivers = drivers
        self.clock = clock
        self.recorder = recorder
        self.options = options
        self.view = view or _NoView()
        size = self.formation.fleet_size
        self.size = size
        self.tracks = [UavTrack() for _ in range(size)]
        self._vehicle_clocks = [VehicleClock(VEHICLE_REBOOT_JUMP_S) for _ in range(size)]
        self.links = LinkMonitor(size, options.link_timeout_s)
        self.events: list[MonitorEvent] = []
        self.fatal = False
        self.reason: str | None = None
        self.aborting = False
        self.frozen_by: str | None = None  # "link" | "operator" | "takeoff" | None
        self._resume_speed: float | None = None
        self.rejoin = RejoinPolicy(options.link_wait_s, options.interactive)
        self._takeoff_waits: frozenset[int] = frozenset()  # UAVs late to take off (indices)
        self.interrupts = 0
        self._handled_interrupts = 0
        self._samples: list[_Sample] = []  # received since the last tick
        self._tick_walls: list[float] = []
        self._last_metrics: float | None = None
        self._abort_time: float | None = None
        self._settle_deadline: float | None = None
        self.ticks = 0
        self.radio_report: dict | None = None  # the radio medium's last report
        self._last_awake: float | None = None  # the last tick (or the end of a stall)
        self._last_awake_t: float | None = None  # ... and its mission time
        self._followed_at_tick: list[int] = []  # UAVs following at the last tick (stalls)
        self._pending_stall: float | None = None  # a stall found by `tick`, resumed by `receive`
        self._stall_woke: float | None = None  # raw mission time the pending stall woke up
        self.stalls: list[Stall] = []
        self.tracking_now = np.full(size, np.nan)
        self.error_growth_now = np.zeros(size)  # m/s, the tracking error's growth (hold policy)
        self._heard_t = np.full(size, np.nan)  # mission time of each UAV's last valid message
        self.mission_time = None
        # the hold policy (gcs.flight.hold): the formation stops for a UAV that fell behind
        self.holds = HoldPolicy.for_budget(
            self.mission.safety_margin,
            self.mission.vehicle.tracking_allowance,
            options.link_wait_s,
            self.mission.vehicle.max_acceleration,
        )
        self._hold_speed = 0.0  # the speed the formation resumes with after the hold
        # the setpoints of the last ticks (mission time, UAV indices, horizontal position,
        # velocity, acceleration sent), one per mission instant (25 s at 10 Hz): where a silent
        # UAV flies on (gcs.flight.silent)
        self._sent: deque[tuple[float, np.ndarray, ...]] = deque(maxlen=256)
        self._takes_acceleration = np.array(
            [[float(d.accepts_acceleration_feedforward)] for d in drivers]
        )  # (N, 1): 0 where the autopilot is sent no acceleration
        # stations missions
        self.returned: ReturnRecord | None = None  # the return home, once asked
        self._hold: tuple[float, float] | None = None  # stopped on station: (from t, speed)
        self._planned_return_done = False  # the mission's own return was issued (or refused)
        self.stations_watch = StationWatch(size, self.mission.safety_margin)  # time on station
        self.batteries = relief_policy.BatteryWatch(self.mission.relieve_below_pct)  # (stations)
        if self._station_xy is not None:
            planned = self._planned_return()
            if planned is None:
                log.info("stations mission: the fleet holds its stations until the operator "
                         "asks for the return (gcs return)")  # fmt: skip
            else:
                log.info("stations mission: the fleet returns home by itself (%s)",
                         _RETURN_SOURCES[planned[1]])  # fmt: skip

    def _adopt(self, plan) -> None:
        """Fly `plan`: everything derived from it (at construction, or re-planned before
        take-off with the autopilots' limits)."""
        mission = plan.mission
        self.plan = plan
        self.mission = mission
        self.formation = plan.formation
        self.altitude = mission.altitude
        a_max = mission.vehicle.max_acceleration
        self.window_s = float(recommended_window(plan.speeds.max, a_max, self.formation))
        # The profile starts with the initial speed; every change (scheduled ones included) is
        # added when it is broadcast, always ahead of its effective time.
        self.profile = SpeedProfile.constant(plan.speeds.initial)
        schedule = list(plan.speeds.changes)
        self.speeds = SpeedChanges(
            max_speed=plan.speeds.max, window_s=self.window_s, schedule=schedule
        )
        self._records: list[SpeedBroadcast] = []
        stations = mission.base_station_points
        self.safety = SafetyMonitor(
            fleet_size=plan.formation.fleet_size,
            obstacles=mission.obstacles,
            base_stations=np.array(stations),
            radio_range=mission.radio_range,
            safety_margin=mission.safety_margin,
            vehicle_radius=mission.vehicle.radius,
        )
        self.current_speed = plan.speeds.initial
        # where each UAV holds (stations missions; changed only by a relief)
        stations = self.formation.stations is not None
        self._station_xy = self.formation.station_slots if stations else None
        self.roster = self._roster(plan) if stations else None

    @staticmethod
    def _roster(plan) -> Roster | None:
        """Which UAV flies which row of a stations formation (reliefs, `gcs relieve`)."""
        route, mission = plan.route, plan.mission
        if route is None or route.layout is None:
            return None
        names = tuple(mission.stations[i].name for i in route.order.tolist())
        return Roster(
            plan.formation, route.point_distance, names, np.array(mission.base_station_points)
        )

    # ------------------------------------------------------------------ public
    @property
    def tick_period_wall(self) -> float:
        return 1.0 / (self.options.setpoint_rate_hz * self.options.speedup)

    def takeoff_lead_s(self) -> float:
        """Mission seconds between take-off and departure: arming, climb, margin."""
        if self.options.takeoff_lead_s is not None:
            return self.options.takeoff_lead_s
        climb = self.altitude / self.options.climb_rate_mps
        return 5.0 + 1.5 * climb

    def smoothing_bound(self) -> float:
        """Bound of |smoothed reference - V_n| for the profile flown so far (docs/design.md 3.5)."""
        return float(smoothing_error_bound(self.formation, self.profile, self.window_s))

    def note(self, level: str, kind: str, text: str, now: float) -> None:
        """Something the loop noticed that belongs in the run's events (e.g. lockstep)."""
        t = self.clock.mission_time(now) if self.clock.anchored else 0.0
        self._event(MonitorEvent(t, level, kind, text), now)

    def interrupt(self) -> None:
        """Ctrl-C (from a signal handler: only counts; the next tick acts on it)."""
        self.interrupts += 1

    def land_everyone(self, reason: str, now: float) -> None:
        """Abort: every UAV lands where it is; the run ends with exit status 1."""
        if self.aborting:
            return
        self.aborting = True
        self.reason = self.reason or reason
        self._abort_time = self.clock.mission_time(now) if self.clock.anchored else 0.0
        self.holds.end(self._abort_time, "landed")
        self._event(
            MonitorEvent(self._abort_time, "error", "abort", f"landing everyone: {reason}"), now
        )
        for driver in self.drivers:
            driver.land(now)

    # ------------------------------------------------------------------ what the loop calls
    def connect_step(self, now: float, started: float) -> bool | None:
        """One step of the handshakes (the loop calls it after handing over what arrived):
        True once every UAV is ready (the mission clock is then anchored), False if connecting
        failed (`reason` says why), None while still connecting. `started`: when the loop
        began connecting."""
        for driver in self.drivers:
            driver.step(now)
        self._drain_driver_events(now)
        if self.interrupts:
            self.reason = "interrupted while connecting"
            return False
        failed = [d for d in self.drivers if d.phase == Phase.FAILED]
        if failed:
            self.reason = f"UAV {failed[0].uav_id}: {failed[0].failure_reason}"
            self.fatal = True
            return False
        if self.aborting:
            return False
        if not all(d.phase == Phase.READY for d in self.drivers):
            if now - started > self.options.connect_timeout_s:
                waiting = [d for d in self.drivers if d.phase != Phase.READY]
                self.reason = (
                    f"UAV {waiting[0].uav_id} not ready after "
                    f"{self.options.connect_timeout_s:g} s ({waiting[0].phase.value})"
                )
                self.fatal = True
                return False
            return None
        if not self._limits_checked:
            verdict = self._autopilot_limits(now)
            if verdict is not True:
                return verdict
        self.clock.anchor(now, -self.takeoff_lead_s())
        self._last_awake = now
        self._last_awake_t = -self.takeoff_lead_s()
        bound, budget = self.smoothing_bound(), self.mission.error_budget
        if bound > budget:
            self._event(
                MonitorEvent(
                    -self.takeoff_lead_s(),
                    "warning",
                    "smoothing_budget",
                    f"smoothing error bound {bound:.2f} m exceeds its budget {budget:.2f} m",
                ),
                now,
            )
        for driver in self.drivers:
            driver.set_mission_clock(self.clock.mission_time)
            driver.step(now)
        return True

    def _autopilot_limits(self, now: float) -> bool | None:
        """The mission against what every autopilot allows (`gcs.drivers.limits`), once all
        are READY: True to go on, None to wait (limits being set), False refused (`reason`).
        `options.autopilot_limits` says what a mission assuming more gets: refused, re-planned
        with the lowest limits ("cap"), or the autopilots' limits set for the flight
        ("apply"; a UAV puts its own back once landed)."""
        if not all(d.parameters_settled for d in self.drivers):
            return None  # "apply": the vehicles have not shown the new values yet
        vehicle = self.mission.vehicle
        if not self._limits_applied:  # (once)
            for driver in self.drivers:
                for name in driver.parameters.failed():
                    text = (
                        f"UAV {driver.uav_id}: {name} unread: the autopilot never answered, "
                        "its limits are not checked"
                    )
                    self._event(MonitorEvent(0.0, "warning", "limits_unread", text), now)
        limits = [lim for lim in (d.limits for d in self.drivers) if lim is not None]
        beyond = [
            e for lim in limits for e in exceeded(lim, vehicle.max_speed, vehicle.max_acceleration)
        ]
        policy = self.options.autopilot_limits
        if beyond and policy == "apply" and not self._limits_applied:
            self._limits_applied = True
            for driver in self.drivers:
                driver.apply_limits(vehicle.max_speed, vehicle.max_acceleration, now)
            return None
        if beyond and policy == "cap" and self._replan is not None:
            speed = min(lim.max_speed for lim in limits)
            acceleration = min(lim.max_acceleration for lim in limits)
            plan = self._replan(speed, acceleration)
            if plan.valid and plan.formation.fleet_size == self.size:
                self._adopt(plan)
                text = (
                    f"re-planned within the autopilots' limits: {plan.speeds.max:g} m/s, "
                    f"{plan.mission.vehicle.max_acceleration:g} m/s^2 ({beyond[0].text()})"
                )
                self._event(MonitorEvent(0.0, "warning", "limits_capped", text), now)
                beyond = []
        self._limits_checked = True
        if not beyond:
            return True
        self.limits_refused = beyond
        hint = "raise it on the autopilot, lower the mission's value, or fly with --cap-speed"
        self.reason = f"{beyond[0].text()}: {hint} or vehicle.apply_limits: true"
        self._event(MonitorEvent(0.0, "error", "limits", self.reason), now)
        return False

    def receive(self, now: float, batches: Iterable[tuple[int, list, float]]) -> None:
        """The loop woke up at `now` and hands over what arrived: (UAV index, valid messages,
        time they were read) per link; `batches` may be lazy (read as it is iterated).

        A wake-up long after the previous one is a stall of the ground station (the process
        was stopped or starved of CPU for a setpoint timeout of mission time): the mission clock
        stands still at the last instant the loop ran while the backlog is read, then resumes
        where the formation stands (`_resume_after_stall`)."""
        stalled_since = self._pending_stall
        if stalled_since is None:
            stalled_since = self._stalled_since(now)
        if stalled_since is not None:
            self.clock.freeze(stalled_since)
        latest = now
        for index, messages, received in batches:
            latest = max(latest, received)
            if stalled_since is None:  # the process stopped while it was reading
                stalled_since = self._stalled_since(received)
                if stalled_since is not None:
                    self.clock.freeze(stalled_since)
            driver = self.drivers[index]
            if messages and self.clock.anchored:
                self._heard_t[index] = self.clock.mission_time(received)
            for msg in messages:
                driver.on_message(msg, received)
                kind = msg.get_type()
                if kind == "GLOBAL_POSITION_INT":
                    self._on_reported_position(driver, msg, received)
                if kind == "SIM_STATE" or (
                    kind == "GLOBAL_POSITION_INT" and driver.telemetry.true_time is None
                ):
                    self._on_position(index, driver, kind == "SIM_STATE", received)
        if stalled_since is not None:
            woke = self.clock.raw_mission_time(latest)
            if self._stall_woke is None:
                self._stall_woke = woke
            if self._stale_after_stall(woke) and woke - self._stall_woke < STALL_FRESH_WAIT_S:
                self._pending_stall = stalled_since  # wait for where the UAVs stand now
                return
            self._pending_stall = self._stall_woke = None
            self._resume_after_stall(stalled_since, latest)
        if self.clock.anchored and self._pending_stall is None:
            self._relay_leader_requests(self.clock.mission_time(latest), latest)

    def fleet_reports(self, now: float, problems: Iterable, radio_reports: Iterable[dict]) -> None:
        """What the fleet's processes reported: problems (`FleetProblem`: a vehicle process
        exited) and the radio medium's reports."""
        for report in radio_reports:
            self.radio_report = report
            if self.clock.anchored:
                self.recorder.radio(RadioRecord(self.clock.mission_time(now), report), now)
        for problem in problems:
            t = self.clock.mission_time(now) if self.clock.anchored else 0.0
            if not self.clock.anchored or not problem.uavs:
                self._event(MonitorEvent(t, "error", "vehicle_exit", problem.text, fatal=True), now)
                if not self.clock.anchored:
                    self.aborting = True
                continue
            silences = self._silences(t, now)
            for uav in problem.uavs:
                silent = float(silences[uav - 1])  # as `links.check` will measure it
                for event in self.links.mark_lost(t, uav - 1, problem.text, silent):
                    self._event(event, now)

    def operator_request(
        self, speed: float | None, at: float | None, error: str | None, now: float
    ) -> OperatorAnswer:
        """A request of `gcs speed` (the operator socket): the answer to send back."""
        command = OperatorCommand.SPEED
        refused = self._operator_refusal(command, error, flying=False)
        if refused is not None:
            return refused
        t = self.clock.mission_time(now) if self.clock.anchored else 0.0
        try:
            change = self.speeds.request(speed, t, "operator", at)
        except SpeedRefused as why:
            return OperatorAnswer.refused(command, AnswerResult.REFUSED, str(why))
        self._apply(change, now)
        return OperatorAnswer(
            command,
            AnswerResult.ACCEPTED,
            seq=change.seq,
            effective_s=change.effective_s,
            speed=change.speed,
        )

    def operator_return(self, at: float | None, error: str | None, now: float) -> OperatorAnswer:
        """A request of `gcs return` (the operator socket): the answer to send back (the
        formation distance M it flies home from)."""
        command = OperatorCommand.RETURN
        refused = self._operator_refusal(command, error, flying=True)
        if refused is not None:
            return refused
        try:
            record = self._return_home(self.clock.mission_time(now), now, at, "operator")
        except ReturnRefused as why:
            return OperatorAnswer.refused(command, AnswerResult.REFUSED, str(why))
        return OperatorAnswer(
            command, AnswerResult.ACCEPTED, effective_s=record.effective_s, distance=record.distance
        )

    def operator_relieve(self, uav: int | None, error: str | None, now: float) -> OperatorAnswer:
        """A request of `gcs relieve N` (the operator socket): the answer to send back (where
        the relieved UAV lands)."""
        command = OperatorCommand.RELIEVE
        refused = self._operator_refusal(command, error, flying=True)
        if refused is not None:
            return refused
        try:
            plan = self._relieve(self.clock.mission_time(now), now, uav, "operator")
        except ReliefRefused as why:
            return OperatorAnswer.refused(command, AnswerResult.REFUSED, str(why))
        landing = (float(plan.landing_xy[0]), float(plan.landing_xy[1]))
        return OperatorAnswer(
            command, AnswerResult.ACCEPTED, uav=uav, effective_s=plan.start_s, landing_xy=landing
        )

    def _operator_refusal(
        self, command: OperatorCommand, error: str | None, flying: bool
    ) -> OperatorAnswer | None:
        """The answer refusing an operator request before its own rules are asked: a request
        that could not be read; a return or relief before take-off (`flying`); a speed
        change while the fleet lands or holds its stations."""
        if error:
            return OperatorAnswer.refused(command, AnswerResult.BAD_REQUEST, error)
        if flying:
            if not self.clock.anchored:
                return OperatorAnswer.refused(
                    command, AnswerResult.NOT_FLYING, "the fleet is not flying yet"
                )
            return None
        if self.aborting:
            return OperatorAnswer.refused(
                command, AnswerResult.LANDING, f"the fleet is landing ({self.reason})"
            )
        if self._holding():
            return OperatorAnswer.refused(command, AnswerResult.HOLDING, _HOLDING)
        return None

    def operator_command(self, line: str, now: float) -> None:
        """A line typed in the live view: a speed (m/s) [@T], return [@T], or 'land'."""
        if self.clock.anchored and not self.aborting:
            self._operator_command(line, self.clock.mission_time(now), now)

    def tick(self, now: float) -> None:
        """One tick of the flight (the mission's setpoint rate): requests, take-offs and
        landings, setpoints, drivers, acks, monitors, the link policy."""
        stalled_since = self._stalled_since(now)
        if stalled_since is not None or self._pending_stall is not None:
            # The process stopped after it last read its links: the telemetry of the stall
            # is still queued. Stand still and let the next `receive` read it and resume
            # where the formation stands; flying on now would chase a reference that ran on.
            if self._pending_stall is None:
                self._pending_stall = stalled_since
                self.clock.freeze(stalled_since)
            return
        self.ticks += 1
        self._last_awake = now
        t = self.clock.mission_time(now)
        self._last_awake_t = t
        self._followed_at_tick = [
            i for i, driver in enumerate(self.drivers) if driver.phase == Phase.FOLLOWING
        ]
        self.mission_time = t
        self._handle_interrupts(now)
        self._handle_requests(t, now)
        self._schedule_uavs(t, now)
        if self.roster is not None:
            self._relief_due(t, now)
        evaluation = self._evaluate(t)
        self._stream(t, now, evaluation)
        for driver in self.drivers:
            driver.step(now)
        self._collect_acks(now)
        self._drain_driver_events(now)
        samples = self.safety.stats.samples
        self._monitor(t, now, evaluation)
        if self._station_xy is not None:
            sampled = self.safety.stats.samples > samples
            self._watch_stations(t, now, evaluation, sampled)
        self._hold_policy(t, now)
        self._link_policy(t, now)

    def finished(self, now: float) -> bool:
        """Every UAV is down (or given up on) and settled: the run is over."""
        return self._finished(now)

    def result(self) -> RunResult:
        return self._result()

    def _silences(self, t: float, now: float) -> np.ndarray:
        """(N,) wall seconds since each UAV's last valid message, as the link monitor judges
        them: silence the mission clock did not count is none (lockstep or a stall held it
        back: the world stood still, the UAVs too). A link marked lost (its process exited)
        is back only when a message makes this shorter than it was then, so both must be
        measured alike: a wall-clock silence recorded at the exit, against this one a tick
        later, once read a held-back clock as a message and the link as back."""
        silent = np.array([d.link.silent_for(now) for d in self.drivers])
        heard = np.isfinite(self._heard_t)
        silent[heard] = np.minimum(silent[heard], (t - self._heard_t[heard]) / self.options.speedup)
        return silent

    # ------------------------------------------------------------------ stalls
    def _stalled_since(self, now: float) -> float | None:
        """The time of the last tick (the last setpoints sent), if the loop stalled since (the
        process was stopped or starved of CPU for a setpoint timeout of mission time); else
        None. The gap is counted on the mission clock: in lockstep the simulated world stood
        still with the ground station (the clock held back: `gcs.flight.lockstep`), and a
        stall the world did not fly is none."""
        last = self._last_awake
        if last is None or not self.clock.anchored:
            return None
        gap = now - last
        if gap < STALL_WALL_FLOOR_S:
            return None
        if self._last_awake_t is not None:
            if self.clock.raw_mission_time(now) - self._last_awake_t < STALL_S:
                return None
        elif gap * self.options.speedup < STALL_S:
            return None
        return last

    def _resume_after_stall(self, last: float, now: float) -> None:
        """No setpoint went out from `last` to `now`: each vehicle flew on by itself (its own
        setpoint timeout: carry the last setpoint forward, brake, hold) and the telemetry that
        queued meanwhile has just been read, on a clock frozen at `last`. The mission resumes
        where the formation stands and as fast as the UAVs move (`gcs.flight.stall`): a pause
        inserted at the instant whose virtual targets the following UAVs match, as long as they
        need to be picked up at their speed (a standing start for UAVs that stopped, none for
        UAVs that flew on); at t_last itself when no UAV was following the formation (nothing
        flew it meanwhile). The mission time never runs backwards: the pause holds it, it never
        rewinds. The vehicles' clocks are told at once, and the samples taken after that
        instant map to it."""
        t_last = self.clock.mission_time(last)  # frozen there
        t_now = self.clock.raw_mission_time(now)
        resume = self._where_the_formation_stands(t_last, t_now)
        paused_at = resume.at
        resumed_at = paused_at
        text = (
            f"GCS scheduler stalled {now - last:.2f} s ({t_now - t_last:.1f} s of mission "
            "time): no setpoints meanwhile, the vehicles flew on their own failsafe; "
        )
        moving = paused_at >= 0 and float(self.profile.speed_at(paused_at)) > 0
        if resume.pause_s > 0 and moving:
            self.profile = self.profile.with_pause(paused_at, resume.pause_s)
            resumed_at = resume.clock_at
        held_back = t_now - resumed_at  # negative: the inserted pause is longer than the stall
        self.clock.resume(now, resumed_at)
        self._last_awake = now
        self._last_awake_t = resumed_at
        if abs(held_back) > 1e-3:
            for clock in self._vehicle_clocks:
                clock.pause(resumed_at, held_back)
            stood = t_now - paused_at  # samples taken while the UAVs stood map to the pause
            self._samples = [
                sample._replace(t=paused(sample.t, paused_at, stood)) for sample in self._samples
            ]
            for track in self.tracks:
                if track.last_sample_time is not None:
                    track.last_sample_time = paused(track.last_sample_time, paused_at, stood)
            for driver in self.drivers:
                driver.on_mission_clock_changed(now)
            moved = (
                f"mission clock held back {held_back:.2f} s"
                if held_back > 0
                else f"mission clock set {-held_back:.2f} s ahead"
            )
            text += f"{moved}: the formation resumes where the UAVs stand (t={paused_at:.2f} s)"
        else:
            text += "they kept up with the formation"
        if resumed_at > paused_at:
            speed = 1.0 - resume.pause_s / self.window_s
            text += (
                ", from a standstill"
                if speed <= 0
                else f", at {speed:.0%} of its speed (the UAVs' own)"
            )
        self.stalls.append(Stall(last, now, t_last, paused_at, resumed_at, held_back))
        self._event(MonitorEvent(paused_at, "warning", "stall", text), now)

    def _stale_after_stall(self, t_raw: float) -> bool:
        """A UAV that followed the formation has no position sample of the last
        `STALL_FRESH_S` (raw mission time `t_raw`): where it stands is not known yet."""
        return any(
            self.tracks[i].last_sample_time is not None
            and t_raw - self.tracks[i].last_sample_time > STALL_FRESH_S
            for i in self._following()
        )

    def _following(self) -> list[int]:
        """The UAVs that followed the formation at the last tick, with a known position: a
        stall long enough for their own GCS failsafe (BRAKE) has taken them out of guided
        flight by the time the backlog is read, yet they flew the formation until it stopped,
        and where they stand says where it stands."""
        return [
            i
            for i in self._followed_at_tick
            if self.drivers[i].phase in (Phase.FOLLOWING, Phase.HOLDING)
            and self.tracks[i].last_position is not None
        ]

    def _where_the_formation_stands(self, t_from: float, t_to: float) -> Resume:
        """How the formation resumes (`gcs.flight.stall.resume_point`) at an instant from
        `t_from` to half a smoothing window past `t_to` (UAVs that carried their last setpoint
        on while catching up run a little ahead of the formation), matching the following
        UAVs' latest positions, moved on to `t_to` by their velocities (for at most 0.5 s: a
        UAV not heard lately is placed where it was heading, not where it was last seen; in
        the fast mode, UAV 3 cut off for 2.2 s around a 1 s stall: 3.2 m, against 6.6 m when
        the formation instead restarted from a standstill with that UAV where it was last
        heard); at `t_from` if none is
        following (neither the formation nor the take-offs went on meanwhile), at `t_to` if
        the formation did not move (frozen: nothing to hold back)."""
        following = self._following()
        if not following:
            return Resume(t_from, 0.0, 0.0)
        t_until = t_to + self.window_s / 2
        count = int(np.clip(math.ceil((t_until - t_from) / 0.02) + 1, 3, 5001))
        times = np.linspace(t_from, t_until, count)
        distances = self.profile.distance(times)
        if distances[-1] - distances[0] < 1e-6:
            return Resume(t_to, 0.0, 0.0)
        targets = self._virtual(distances)[:, following]  # (count, k, 2)
        positions, velocities = [], []
        for i in following:
            track = self.tracks[i]
            velocity = np.zeros(2) if track.last_velocity is None else track.last_velocity[:2]
            age = 0.0 if track.last_sample_time is None else t_to - track.last_sample_time
            positions.append(track.last_position[:2] + velocity * float(np.clip(age, 0.0, 0.5)))
            velocities.append(velocity)
        return resume_point(
            times,
            targets,
            np.array(positions),
            np.array(velocities),
            self.window_s,
            self.mission.vehicle.max_acceleration,
        )

    def _handle_interrupts(self, now: float) -> None:
        while self._handled_interrupts < self.interrupts:
            self._handled_interrupts += 1
            t = self.clock.mission_time(now)
            if self._handled_interrupts == 1:
                self._event(
                    MonitorEvent(
                        t,
                        "warning",
                        "interrupt",
                        "Ctrl-C: freezing the formation (Ctrl-C again: land everyone)",
                    ),
                    now,
                )
                self.reason = "interrupted by the operator"
                self._freeze("operator", now)
            else:
                self.land_everyone("interrupted by the operator (Ctrl-C twice)", now)

    def _handle_requests(self, t: float, now: float) -> None:
        if self.aborting:
            return
        for scheduled in self.speeds.due(t):
            if not self._deferred(scheduled.speed, t, "schedule", now):
                at = max(scheduled.at, self.speeds.earliest(t))
                self._issue(scheduled.speed, t, "schedule", now, at=at)
        self._relay_leader_requests(t, now)
        if self._station_xy is not None:
            if not self._planned_return_done:
                self._planned_return_due(t, now)
            if self._hold is None and self.returned is None:
                self._hold_due(t, now)

    def _relay_leader_requests(self, t: float, now: float) -> None:
        """Each leader's request becomes a fleet speed change (or is deferred) as soon as the
        loop reads it, not at the next tick: the wait for a tick (up to 100 ms of mission time
        at 10 Hz) would be most of every UAV's reaction time T_dv."""
        if self.aborting:
            return
        for driver in self.drivers:
            for request in driver.drain_leader_requests():
                source = f"leader:{request.uav_id}"
                if not self._deferred(request.speed, t, source, now):
                    self._issue(request.speed, t, source, now)

    # ------------------------------------------------------------------ stations missions
    def _planned_return(self) -> tuple[float, str] | None:
        """When the mission itself brings the fleet home (the effective time asked, and the
        source), under the profile flown so far; None: when the operator asks."""
        mission = self.mission
        if mission.return_at is not None:
            return float(mission.return_at), "schedule"
        on_station = self._on_station_time()
        dwells = [point.dwell_s for point in mission.stations]
        if dwells and min(dwells) > 0:
            return on_station + max(dwells), "dwell"
        if self.options.return_when_on_station:
            return on_station, "on_station"
        return None

    def _on_station_time(self) -> float:
        """When every UAV is (or will be) on station: Phi(S_out), inf while frozen before."""
        if self._hold is not None:
            return self._hold[0]
        return float(self.profile.time_at_distance(self.formation.outbound_distance))

    def _holding(self) -> bool:
        """The formation stands still with every UAV on its station, waiting for the return."""
        return self._hold is not None and self.returned is None

    def _hold_due(self, t: float, now: float) -> None:
        """The formation stops (speed 0, source "hold") once every UAV is on station, issued
        ahead as a scheduled change: S stays at S_out, so that whenever the return comes it
        starts from there (`with_return(M)` plays back the flight up to M, and the distance
        run while holding would be played back as more holding). The speed it had is the one
        the way home flies at."""
        if self.frozen_by is not None:
            return  # standing still already; resumed, the hold is due again
        at = self._on_station_time()
        if at - self.speeds.lead_s - self.speeds.announce_s > t:  # (inf while frozen)
            return
        speed = float(self.profile.speed_at(at))
        change = self._issue(0.0, t, "hold", now, at=max(at, self.speeds.earliest(t)))
        if change is not None:
            self._hold = (change.effective_s, speed)

    def _planned_return_due(self, t: float, now: float) -> None:
        """Issue the mission's own return ahead of its time, as a scheduled speed change."""
        if self.returned is not None:
            self._planned_return_done = True  # the operator asked first
            return
        if self.roster is not None and self.roster.active is not None:
            return  # a UAV is being relieved: the return comes once it has landed
        planned = self._planned_return()
        if planned is None:
            self._planned_return_done = True
            return
        at, source = planned
        if at - self.speeds.lead_s - self.speeds.announce_s > t:  # (inf while frozen)
            return
        self._planned_return_done = True
        try:
            self._return_home(t, now, at, source)
        except ReturnRefused as refused:
            text = f"{source}: return refused: {refused}"
            self._event(MonitorEvent(t, "warning", "return_refused", text), now)

    def _return_home(self, t: float, now: float, at: float | None, source: str) -> ReturnRecord:
        """The return home of a stations mission, asked at mission time `t` by `source` for
        effective time `at` (None: the earliest): from t_e = max(at, the earliest a speed
        change may take effect) the formation stands still at M = S(t_e) (a speed change to
        0), flies its way out backwards from there (`LineFormation.with_return(M)`), and one
        smoothing window later gets back the speed it had (each UAV's velocity reverses in two
        steps, each within the smoothing budget). Raises `ReturnRefused`."""
        formation = self.formation
        if formation.stations is None:
            raise ReturnRefused(
                "this mission has no stations: the fleet flies from A to B and lands there"
            )
        if self.aborting:
            raise ReturnRefused(f"the fleet is landing ({self.reason})")
        if self.returned is not None:
            returned = self.returned
            raise ReturnRefused(
                f"the fleet is already returning (from t={returned.effective_s:.2f} s, "
                f"{_RETURN_SOURCES[returned.source]})"
            )
        if at is not None and not math.isfinite(at):
            raise ReturnRefused(f"the return time must be a finite mission time, got {at!r}")
        active = None if self.roster is None else self.roster.active
        if active is not None:
            raise ReturnRefused(
                f"UAV {active.index + 1} is being relieved: the fleet returns once it has "
                f"landed (about t={active.plan.home_s:.2f} s)"
            )
        earliest = self.speeds.earliest(t)
        effective = earliest if at is None else max(float(at), earliest)
        # the speed in force before (holding: the one it had when it stopped on station)
        speed = self._hold[1] if self._holding() else float(self.profile.speed_at(effective))
        self._apply(self.speeds.request(0.0, t, "return", effective), now)
        distance = float(self.profile.distance(effective))
        self.formation = formation.with_return(distance)
        record = ReturnRecord(t=t, effective_s=effective, distance=distance, source=source)
        self.returned = record
        if self.frozen_by == "operator" and source == "operator":
            self.frozen_by = None  # the operator decided
        if self.frozen_by is not None:  # the return flies when the formation resumes
            if speed > 0:
                self._resume_speed = speed
        elif speed > 0:
            back = max(effective + self.window_s, self.speeds.earliest(t))
            self._apply(self.speeds.request(speed, t, "return", back), now)
        self.recorder.return_home(record, now)
        text = (
            f"return home ({_RETURN_SOURCES[source]}): from t={effective:.2f} s every UAV flies "
            f"its way out backwards to its start slot (formation distance {distance:.1f} m)"
        )
        self._event(MonitorEvent(t, "info", "return", text), now)
        return record

    def _watch_stations(self, t: float, now: float, evaluation: _Evaluation, sampled: bool):
        """Time on station per UAV (its reported position within rho_c of its station while
        its virtual target holds there), the connectivity while everyone holds, and the event
        when everyone is on station."""
        reported = np.full((self.size, 2), np.nan)
        for index, driver in enumerate(self.drivers):
            position = driver.telemetry.position_enu
            if position is not None and not self.links.lost[index]:
                reported[index] = position[:2]
        reached = self.stations_watch.update(
            t,
            self._station_xy,
            evaluation.virtual[0],
            reported,
            float(evaluation.distances[0]),
            self.formation.outbound_distance,
            None if self.returned is None else self.returned.distance,
            bool(self.safety.stats.last_connected) if sampled else None,
        )
        if reached:
            self._event(MonitorEvent(t, "info", "on_station", self._on_station_text(t)), now)

    def _on_station_text(self, t: float) -> str:
        text = f"every UAV on station at t={t:.2f} s: "
        if self.returned is not None:
            leaves = 2 * self.returned.distance - self.formation.outbound_distance
            at = float(self.profile.time_at_distance(leaves))
            return text + f"the first leaves for home at t={at:.2f} s (the return)"
        planned = self._planned_return()
        if planned is None:
            return text + "holding until the operator asks (gcs return, or type 'return')"
        at, source = planned
        return text + f"holding until t={at:.2f} s ({_RETURN_SOURCES[source]})"

    def _stations_result(self) -> StationsResult | None:
        route = self.plan.route
        if self._station_xy is None or route is None or route.layout is None:
            return None
        holders = route.layout.holders if self.roster is None else self.roster.holders
        points = tuple(
            PointHeld(
                name=self.mission.stations[index].name,
                uav=int(uav),
                on_station_s=float(self.stations_watch.on_station_s[int(uav) - 1]),
            )
            for index, uav in zip(route.order.tolist(), holders.tolist(), strict=True)
        )
        reliefs = () if self.roster is None else self.roster.reliefs
        relieved = tuple(
            UavRelieved(
                uav=relief.index + 1,
                source=relief.source,
                asked_s=relief.asked_s,
                landing=(float(relief.plan.landing_xy[0]), float(relief.plan.landing_xy[1])),
                landed_s=self.tracks[relief.index].landed_time,
                on_station_s=float(self.stations_watch.on_station_s[relief.index]),
            )
            for relief in reliefs
        )
        return StationsResult(
            points=points,
            return_s=None if self.returned is None else self.returned.effective_s,
            held_connected_fraction=self.stations_watch.held_connected_fraction,
            relieved=relieved,
        )

    # ------------------------------------------------------------------ reliefs
    def _relieve(self, t: float, now: float, uav: int | None, source: str):
        """Send UAV `uav` home alone from its station (`planner.relief`), asked at mission
        time `t` by `source`: it climbs above the chain, the UAVs of its gap close up, it flies
        home above the route and lands on the last free slot of the start row; the UAVs left
        on station fly on as a formation of one UAV fewer. Returns the `ReliefPlan`; raises
        `ReliefRefused` with the reason."""
        roster = self.roster
        if roster is None:
            raise ReliefRefused(
                "this mission has no stations: its UAVs fly from A to B together, none alone"
            )
        active = roster.active
        why = relief_policy.refusal(
            uav,
            relief_policy.ReliefState(
                size=self.size,
                landing=self.reason if self.aborting else None,
                returning=self.returned is not None,
                relieved=self._relieved(),
                active=None if active is None else (active.index, active.plan.home_s),
                holding=self._holding() and self.stations_watch.holding,
                frozen_by=self.frozen_by,
                unavailable=self._unavailable(),
            ),
        )
        if why is not None:
            raise ReliefRefused(why)
        assert uav is not None and self._hold is not None  # (refusal: 1..N, holding)
        vehicle = self.mission.vehicle
        plan = roster.plan(
            uav,
            t,
            self._hold[1],
            relief_policy.RELIEF_ACCELERATION_SHARE * vehicle.max_acceleration,
            self.options.climb_rate_mps,
        )
        self.formation = roster.adopt(plan, source, t)
        self._station_xy = roster.station_xy()
        layout = plan.layout
        self.recorder.relief(
            ReliefRecord(
                t=t,
                uav=uav,
                source=source,
                start_s=plan.start_s,
                climbed_s=plan.climbed_s,
                closed_s=plan.closed_s,
                home_s=plan.home_s,
                landing=[float(v) for v in plan.landing_xy],
                lane_offset_m=plan.lane_offset,
                stations=[None if math.isnan(v) else float(v) for v in layout.stations],
                holders=[int(v) for v in layout.holders],
                members=[int(v) for v in layout.members],
            ),
            now,
        )
        moving = sorted(other for other, _ in plan.moves)
        closing = (
            f"UAV {', '.join(map(str, moving))} close the gap by t={plan.closed_s:.2f} s"
            if moving
            else "nobody needs to move"
        )
        x, y = plan.landing_xy
        text = (
            f"UAV {uav} relieved ({relief_policy.RELIEF_SOURCES[source]}): it climbs "
            f"{plan.lane_offset:.1f} m above the chain, {closing}, it flies home above the "
            f"route and lands on the start-row slot ({x:.1f}, {y:.1f}) at about "
            f"t={plan.home_s:.2f} s"
        )
        self._event(MonitorEvent(t, "info", "relief", text, uav), now)
        return plan

    def _relief_due(self, t: float, now: float) -> None:
        """The relieved UAV lands once above its slot; a relief is over once it has landed.
        A UAV on station whose battery is below `stations.relieve_below_pct` is relieved."""
        roster = self.roster
        active = roster.active
        if active is not None:
            index, plan = active.index, active.plan
            driver, track = self.drivers[index], self.tracks[index]
            if not track.land_sent and relief_policy.lands_now(
                t,
                plan.home_s,
                self._slot_offset(index, t),
                self.options.landing_tolerance_m,
                self.options.landing_settle_s,
            ):
                track.land_sent = True
                driver.land(now)
            if driver.phase in (Phase.LANDED, Phase.FAILED):
                roster.active = None
        if roster.active is not None or not (self._holding() and self.stations_watch.holding):
            return
        levels = [driver.telemetry.battery_remaining_pct for driver in self.drivers]
        while (index := self.batteries.due(levels, self._relieved())) is not None:
            try:
                self._relieve(t, now, index + 1, "battery")
                return
            except ReliefRefused as refused:
                text = (
                    f"UAV {index + 1}: battery {levels[index]:g} % below "
                    f"{self.batteries.threshold_pct:g} %, but it stays: {refused}"
                )
                self._event(MonitorEvent(t, "warning", "relief_refused", text, index + 1), now)

    def _relieved(self) -> frozenset[int]:
        """The UAVs (0-based) relieved so far."""
        if self.roster is None:
            return frozenset()
        return frozenset(int(i) for i in np.flatnonzero(self.roster.relieved))

    def _deferred(self, speed: float, t: float, source: str, now: float) -> bool:
        """While the formation is frozen, a scheduled or leader change is not flown: it becomes
        the speed the formation resumes with (only the operator unfreezes it). While every UAV
        holds its station, it becomes the speed of the way home. While the formation holds
        for a UAV behind, it becomes the speed the hold resumes with."""
        if self._holding():
            self._hold = (self._hold[0], speed)
            why = "every UAV holds its station; the fleet flies home at that speed"
        elif self.holds.holding:
            self._hold_speed = speed
            why = "the formation holds for a UAV behind; it resumes at that speed"
        elif self.frozen_by is not None:
            self._resume_speed = speed
            why = f"the formation is frozen ({self.frozen_by}); it resumes at that speed"
        else:
            return False
        text = f"{source}: {speed:g} m/s deferred, {why}"
        self._event(MonitorEvent(t, "warning", "speed_deferred", text), now)
        return True

    def _operator_command(self, line: str, t: float, now: float) -> None:
        words = line.strip().lower().split()
        if not words:
            return
        if words[0] == "land":
            self.land_everyone("the operator asked everyone to land", now)
            return
        usage = f"type a speed (m/s) [@T], return [@T], relieve N, or land; not {line.strip()!r}"
        if words[0] == "relieve":
            if len(words) != 2 or not words[1].isdigit():
                self.view.message("warning", usage)
                return
            try:
                self._relieve(t, now, int(words[1]), "operator")
            except ReliefRefused as refused:
                self.view.message("warning", f"relief refused: {refused}")
            return
        try:
            at = float(words[1].lstrip("@")) if len(words) > 1 else None
            speed = None if words[0] == "return" else float(words[0])
        except ValueError:
            self.view.message("warning", usage)
            return
        if speed is None:
            try:
                self._return_home(t, now, at, "operator")
            except ReturnRefused as refused:
                self.view.message("warning", f"return refused: {refused}")
            return
        if self._holding():
            self.view.message("warning", _HOLDING)
            return
        try:
            change = self.speeds.request(speed, t, "operator", at)
        except SpeedRefused as refused:
            self.view.message("warning", str(refused))
            return
        self._apply(change, now)

    def _issue(self, speed: float, t: float, source: str, now: float, at: float | None = None):
        try:
            change = self.speeds.request(speed, t, source, at)
        except SpeedRefused as refused:
            self._event(MonitorEvent(t, "warning", "speed_refused", f"{source}: {refused}"), now)
            return None
        self._apply(change, now)
        return change

    def _apply(self, change: SpeedChange, now: float) -> None:
        """The formation takes the change at its effective time; broadcast it to every UAV."""
        if self.holds.holding and not change.source.startswith("freeze:"):
            t = self.clock.mission_time(now)
            self._hold_ended(t, "operator" if change.source == "operator" else "superseded", now)
        self.profile = self.profile.with_change(change.effective_s, change.speed)
        record = self.speeds.record(change, now)
        for driver in self.drivers:
            if driver.phase not in (Phase.CONNECTING, Phase.FAILED):
                driver.send_speed_change(change, now)
        self.recorder.speed(
            SpeedRecord(
                t=change.requested_s,
                kind=SpeedRecordKind.REQUEST,
                seq=change.seq,
                effective_s=change.effective_s,
                speed=change.speed,
                source=change.source,
            ),
            now,
        )
        text = (
            f"speed change {change.seq}: {change.speed:g} m/s at t={change.effective_s:.2f} s "
            f"({change.source})"
        )
        self.recorder.event("info", text, now)
        log.info("%s", text)
        self._records.append(record)
        if change.source == "operator" and change.speed > 0 and self.frozen_by is not None:
            self.frozen_by = None  # the operator decided
            self.rejoin.operator_decided()

    def _freeze(self, why: str, now: float) -> None:
        """Speed 0 at the earliest effective time (the formation holds its shape)."""
        if self.frozen_by is not None or self.aborting:
            self.frozen_by = self.frozen_by or why
            return
        t = self.clock.mission_time(now)
        self._resume_speed = float(self.profile.speed_at(self.speeds.earliest(t)))
        if self.holds.holding:  # the freeze takes over: it resumes at the hold's speed
            self._resume_speed = self._hold_speed
            self._hold_ended(t, "superseded", now)
        self.frozen_by = why
        self._issue(0.0, t, f"freeze:{why}", now)

    def _resume(self, now: float) -> None:
        t = self.clock.mission_time(now)
        speed = self._resume_speed if self._resume_speed is not None else self.plan.speeds.initial
        self.frozen_by = None
        self._issue(speed, t, "resume", now)

    def _schedule_uavs(self, t: float, now: float) -> None:
        formation = self.formation
        roster = self.roster
        departures = self.profile.time_at_distance(formation.departure_distance)
        arrivals = self.profile.time_at_distance(formation.arrival_distance)
        relieved = np.zeros(self.size, dtype=bool)
        if roster is not None and roster.reshaped:  # rows -> UAVs; a relieved UAV: its own
            departures = roster.expand(departures, math.inf)
            arrivals = roster.expand(arrivals, math.inf)
            relieved = roster.relieved
        lead = self.takeoff_lead_s()
        horizon = t + self.speeds.lead_s + 2 * self.tick_period_wall * self.options.speedup
        # a stations formation holds its UAVs on their stations until it returns
        lands = formation.stations is None or formation.returning
        # returning before a UAV left its slot: it never leaves it
        stays = (
            formation.departure_distance >= formation.return_distance - DISTANCE_TOLERANCE
            if formation.returning
            else np.zeros(formation.fleet_size, dtype=bool)
        )
        if roster is not None and roster.reshaped:
            stays = roster.expand(stays, False)
        decision = ScheduleDecision()
        if not self.aborting:
            uavs = [
                UavProgress(
                    relieved=bool(relieved[index]),
                    stays=bool(stays[index]),
                    not_up=driver.phase in (Phase.READY, Phase.ARMING, Phase.TAKING_OFF),
                    following=driver.phase == Phase.FOLLOWING,
                    takeoff_sent=track.takeoff_sent,
                    land_sent=track.land_sent,
                )
                for index, (driver, track) in enumerate(zip(self.drivers, self.tracks, strict=True))
            ]
            schedule = Schedule(
                lead, self.options.landing_tolerance_m, self.options.landing_settle_s
            )
            decision = schedule.decide(
                t, uavs, departures, arrivals, horizon, self.window_s, lands,
                lambda index: self._slot_offset(index, t),
                frozen_for=self._takeoff_waits if self.frozen_by == "takeoff" else frozenset(),
            )  # fmt: skip
        stay, takeoff, land = set(decision.stay), set(decision.takeoff), set(decision.land)
        for index, driver in enumerate(self.drivers):  # per UAV, in the order of its actions
            track = self.tracks[index]
            if index in stay:
                track.land_sent = True
                driver.land(now)
                text = (
                    f"UAV {index + 1} lands back on its start slot: the return came before "
                    "it left it"
                    if track.takeoff_sent
                    else f"UAV {index + 1} stays on its start slot: the return came first"
                )
                self._event(MonitorEvent(t, "info", "stays", text, index + 1), now)
                continue
            if index in takeoff:
                track.takeoff_sent = True
                track.takeoff_time = t
                driver.takeoff(self.altitude, now)
            if index in land:
                track.land_sent = True
                driver.land(now)
        late = list(decision.late)
        self._takeoff_waits = frozenset(uav - 1 for uav in late)
        if late and self.frozen_by is None:
            self._event(
                MonitorEvent(
                    t,
                    "warning",
                    "late_takeoff",
                    f"waiting for UAV {', '.join(map(str, late))} to take off: formation frozen",
                ),
                now,
            )
            self._freeze("takeoff", now)
        elif not late and self.frozen_by == "takeoff":
            self._resume(now)

    def _slot_offset(self, index: int, t: float) -> float:
        track = self.tracks[index]
        if track.last_position is None:
            return math.inf
        slot = self._goal_slots()[index]
        return float(np.hypot(*(track.last_position[:2] - slot)))

    def _evaluate(self, t: float) -> _Evaluation:
        """The formation at the tick and at the samples that arrived since the last one, in
        one vectorised evaluation (the profile is final for these instants: a change always
        takes effect later than half the smoothing window ahead)."""
        samples, self._samples = self._samples, []
        times = np.array([t] + [sample.t for sample in samples])
        distances = self.profile.distance(times)
        virtual = self.formation.positions(distances)
        reference = smoothed_reference(self.formation, self.profile, times, self.window_s)
        roster = self.roster
        if roster is not None and roster.reshaped:  # rows -> UAVs, and the relief's motions
            virtual = roster.expand(virtual, np.nan, axis=-2)
            reference = Reference(
                roster.expand(reference.positions, np.nan, axis=-2),
                roster.expand(reference.velocities, 0.0, axis=-2),
                roster.expand(reference.accelerations, 0.0, axis=-2),
            )
            virtual, reference = roster.overlay(times, virtual, reference)
        return _Evaluation(samples, times, distances, virtual, reference)

    def _virtual(self, distances: np.ndarray) -> np.ndarray:
        """V_n at formation distances, one column per UAV (a relieved UAV: its landing
        slot)."""
        virtual = self.formation.positions(distances)
        if self.roster is None or not self.roster.reshaped:
            return virtual
        landing = self.roster.landing_xy()[self.roster.relieved]
        return self.roster.expand(virtual, landing, axis=-2)

    def virtual_targets(self, t: float) -> np.ndarray:
        """(N, 2): V_n at mission time `t` per UAV, a relief's motions included (the fast
        mode's tracking errors)."""
        times = np.array([float(t)])
        virtual = self._virtual(self.profile.distance(times))
        if self.roster is not None:
            virtual = self.roster.overlay_positions(times, virtual)
        return virtual[0]

    def out_of_fleet(self) -> np.ndarray:
        """(N,) bool: UAVs relieved and landed, no longer part of the chain."""
        if self.roster is None or not self.roster.reshaped:
            return np.zeros(self.size, dtype=bool)
        landed = np.array([d.phase == Phase.LANDED for d in self.drivers])
        return self.roster.relieved & landed

    def _goal_slots(self) -> np.ndarray:
        """(N, 2) where each UAV ends: its row's goal slot, a relieved UAV its landing slot."""
        slots = self.formation.goal_slots
        if self.roster is None or not self.roster.reshaped:
            return slots
        landing = self.roster.landing_xy()[self.roster.relieved]
        return self.roster.expand(slots, landing, axis=-2)

    def _stream(self, t: float, now: float, evaluation: _Evaluation) -> None:
        streaming = [
            i for i, d in enumerate(self.drivers) if d.wants_setpoints and not self.aborting
        ]
        if not streaming:
            return
        self._tick_walls.append(now)
        reference = evaluation.reference
        idx = np.array(streaming)
        xy = reference.positions[0, idx]
        vxy = reference.velocities[0, idx]
        count = len(idx)
        vertical = np.zeros((count, 3))  # height above the mission altitude, rate, acceleration
        if self.roster is not None and self.roster.active is not None:
            vertical = self.roster.heights(t)[idx]
        up = float(self.altitude) + vertical[:, 0]
        geodetic = enu_to_geodetic(xy[:, 0], xy[:, 1], up, self.mission.origin).reshape(count, 3)
        virtual = evaluation.virtual[0, idx]
        speed = float(self.profile.speed_at(t))
        distance = float(evaluation.distances[0])
        self.current_speed = float(self.profile.speed_at(max(t, 0.0)))  # commanded, for the view
        position = np.column_stack([xy, up])
        velocity = np.column_stack([vxy, vertical[:, 1]])
        axy = reference.accelerations[0, idx]
        acceleration = np.column_stack([axy, vertical[:, 2]])
        sent_acceleration = axy * self._takes_acceleration[idx]
        if self._sent and self._sent[-1][0] >= t:
            self._sent.pop()  # the clock stood still (held for the world): one per instant
        self._sent.append((t, idx, xy, vxy, sent_acceleration))  # (indexed: copies)
        # Python lists once per tick: the per-UAV loop below is the hot path.
        positions, velocities = position.tolist(), velocity.tolist()
        accelerations, virtuals, geo = acceleration.tolist(), virtual.tolist(), geodetic.tolist()
        keep = self.recorder.keeps_samples
        for k, index in enumerate(streaming):
            driver = self.drivers[index]
            driver.send_setpoint(positions[k], velocities[k], accelerations[k], t, now, geo[k])
            if not keep:
                continue
            lat, lon, alt = geo[k]
            self.recorder.setpoint(
                SetpointRecord(
                    t=t,
                    uav=driver.uav_id,
                    position=positions[k],
                    velocity=velocities[k],
                    acceleration=accelerations[k],
                    virtual_target=virtuals[k],
                    formation_speed=speed,
                    distance=distance,
                    latitude=lat,
                    longitude=lon,
                    altitude=alt,
                    relative_altitude=alt - driver.home_altitude_amsl,
                ),
                now,
            )

    def _on_reported_position(self, driver: Driver, msg, now: float) -> None:
        """A position the vehicle reports (with its navigation noise): the Map panel's fix."""
        self.recorder.fix(driver.uav_id, msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3, now)

    def _on_position(self, index: int, driver: Driver, truth: bool, now: float) -> None:
        """A position sample for the metrics: the true one from a simulator (SIM_STATE), else
        the reported one (docs/outputs.md: distances and tracking error use true positions)."""
        tel = driver.telemetry
        position = tel.true_position_enu if truth else tel.position_enu
        velocity = tel.true_velocity_enu if truth else tel.velocity_enu
        vehicle_s = tel.true_vehicle_time_s if truth else tel.position_vehicle_time_s
        if position is None:
            return
        track = self.tracks[index]
        track.last_position = position
        track.last_velocity = velocity
        if self.clock.anchored:
            # the raw time: while a stall is being resolved the clock stands still, but the
            # samples keep the time they were taken (mapped onto the pause afterwards)
            received = self.clock.raw_mission_time(now)
            t = self._vehicle_clocks[index].mission_time(vehicle_s, received)
            track.last_sample_time = t
            self._samples.append(
                _Sample(
                    index, t, position.copy(), truth, None if velocity is None else velocity[:2]
                )
            )
        else:
            self.recorder.state(
                UavStateRecord(
                    t=None,
                    uav=driver.uav_id,
                    phase=driver.phase.value,
                    position=_list(tel.position_enu),
                    true_position=_list(tel.true_position_enu),
                    armed=tel.armed,
                    mode=tel.custom_mode,
                    landed_state=int(tel.landed_state),
                ),
                now,
            )

    def _monitor(self, t: float, now: float, evaluation: _Evaluation) -> None:
        events: list[MonitorEvent] = []
        samples = evaluation.samples
        if samples:
            uavs = np.array([s.uav for s in samples])
            times = evaluation.times[1:]
            sampled = np.array([s.position for s in samples])
            xy = sampled[:, :2]
            truths = [s.truth for s in samples]
            rows = np.arange(len(uavs))
            virtual = evaluation.virtual[1:][rows, uavs]
            smooth = evaluation.reference.positions[1:][rows, uavs]
            errors = np.hypot(*(xy - virtual).T)
            control = np.hypot(*(xy - smooth).T)
            self.tracking_now[uavs] = errors
            self.error_growth_now[uavs] = _error_growth(
                xy - virtual,
                evaluation.reference.velocities[1:][rows, uavs],
                np.array([(np.nan, np.nan) if s.velocity is None else s.velocity for s in samples]),
            )
            if not self.aborting:  # landing where they are: V_n no longer applies
                events += self.safety.tracking(t, uavs, errors, control)
            for k, index in enumerate(uavs.tolist() if self.recorder.keeps_samples else ()):
                driver = self.drivers[index]
                tel = driver.telemetry
                # the position of this sample (the one its tracking error is computed from);
                # the other one is the latest of its kind
                sample = sampled[k].tolist()
                self.recorder.state(
                    UavStateRecord(
                        t=float(times[k]),
                        uav=driver.uav_id,
                        phase=driver.phase.value,
                        position=_list(tel.position_enu) if truths[k] else sample,
                        true_position=sample if truths[k] else _list(tel.true_position_enu),
                        armed=tel.armed,
                        mode=tel.custom_mode,
                        landed_state=int(tel.landed_state),
                        velocity=_list(tel.velocity_enu),
                        virtual_target=virtual[k].tolist(),
                        tracking_error_m=float(errors[k]),
                    ),
                    now,
                )
        # The fleet now: each UAV's last sample moved on by its velocity (samples are up to a
        # telemetry period old); a UAV silent for longer than that is unknown, not guessed.
        fleet = np.full((self.size, 3), np.nan)  # x, y extrapolated; z as last reported
        for index, track in enumerate(self.tracks):
            if track.last_position is None or track.last_sample_time is None:
                continue
            age = t - track.last_sample_time
            if age > MAX_EXTRAPOLATION_S or self.links.lost[index]:
                continue
            xy = track.last_position[:2]
            if track.last_velocity is not None:
                xy = xy + track.last_velocity[:2] * max(age, 0.0)
            fleet[index, :2] = xy
            fleet[index, 2] = track.last_position[2]
        positions = fleet[:, :2]
        heights = excluded = None
        roster = self.roster
        if roster is not None and roster.reshaped:
            excluded = self.out_of_fleet()
            if roster.active is not None and not excluded[roster.active.index]:
                heights = fleet[:, 2]  # one UAV flies home above the chain
        events += self.safety.positions(t, positions, heights, excluded)
        # what `gcs log report` checks again: with the heights while a UAV flies above the
        # chain, and who is out of the fleet since a relief
        recorded = positions if heights is None else fleet
        out_of_fleet = None if excluded is None else [int(i) + 1 for i in np.flatnonzero(excluded)]
        self.recorder.fleet(t, fleet, evaluation.virtual[0], now)
        silent = self._silences(t, now)
        timeout = max(
            self.options.link_timeout_s / self.options.speedup, self.options.link_wall_floor_s
        )
        active = np.array([d.phase not in (Phase.LANDED, Phase.FAILED) for d in self.drivers])
        silent = np.where(active, silent, 0.0)
        events += self.links.check(t, silent, timeout)
        for event in events:
            self._event(event, now)
        if self._last_metrics is None or t - self._last_metrics >= self.options.metrics_period_s:
            self._last_metrics = t
            stats = self.safety.stats
            self.recorder.metrics(
                MetricsRecord(
                    t=t,
                    formation_speed=float(self.profile.speed_at(t)),
                    distance=float(self.profile.distance(t)),
                    min_uav_uav_m=_finite(stats.min_uav_uav_m),
                    min_uav_obstacle_m=_finite(stats.min_uav_obstacle_m),
                    max_tracking_error_m=_finite(
                        float(np.max(stats.max_tracking_error_m, initial=0.0))
                    ),
                    tracking_error_m=[_finite(e) for e in self.tracking_now.tolist()],
                    connected=stats.last_connected,
                    # the sample the monitors checked: `gcs log report` re-checks it
                    positions=[None if math.isnan(p[0]) else p for p in recorded.tolist()],
                    out_of_fleet=out_of_fleet,
                    holding=list(self.holds.current.uavs) if self.holds.holding else None,
                    world_held_s=self.clock.held_back_s or None,
                ),
                now,
            )

    # ------------------------------------------------------------------ holds
    def _uav_states(self) -> list[UavState]:
        """What the hold policy reads of each UAV now (a UAV whose link is lost is the link
        policy's, not following here)."""
        lost = self.links.lost
        return [
            UavState(
                index=i,
                following=driver.phase == Phase.FOLLOWING and not lost[i],
                tracking_error_m=float(self.tracking_now[i]),
                sample_time=self.tracks[i].last_sample_time,
                error_growth_mps=float(self.error_growth_now[i]),
            )
            for i, driver in enumerate(self.drivers)
        ]

    def _hold_policy(self, t: float, now: float) -> None:
        """Hold the formation for a UAV behind, resume once everyone is back, land everyone
        when the hold does not restore the budget (`gcs.flight.hold`)."""
        policy = self.holds
        states = self._uav_states()
        if self.aborting or self._holding():
            return  # landing, or a stations fleet standing on its stations
        if policy.holding and self._unavailable():
            return  # a UAV lost or gone its own way: the link policy's freeze takes over
        if policy.holding:
            if policy.back(t, states):
                self._hold_ended(t, "resumed", now)
            elif policy.overdue(t):
                behind = policy.behind(t, states)
                text = "; ".join(f"UAV {u}: {why}" for u, why in behind) or policy.current.text()
                self.land_everyone(
                    f"the formation held {policy.held_s(t):.1f} s and the "
                    f"error budget was not restored ({text})",
                    now,
                )
            return
        if self.frozen_by is not None:
            return  # already frozen: the freeze's cause owns the formation
        states = [
            replace(state, silent_errors_m=self._silent_forecast(t, state.index))
            if state.following
            else state
            for state in states
        ]
        behind = policy.behind(t, states)
        if not behind:
            return
        # the window's leading edge: no jump in the reference (the profile starts at 0)
        stop = max(t + self.window_s / 2, 0.0)
        self._hold_speed = float(self.profile.speeds[-1])  # every change announced so far
        self.profile = self.profile.with_change(stop, 0.0)
        hold = policy.start(t, stop, stop + self.window_s / 2, behind)
        text = (
            f"formation holds: {hold.text()}; every UAV stops on its target by "
            f"t={hold.standing_s:.2f} s and waits until every UAV is back within "
            f"{policy.resume_m:.2f} m"
        )
        self._event(MonitorEvent(t, "warning", "hold", text, hold.uavs[0]), now)

    def _silent_forecast(self, t: float, index: int) -> tuple[float, float] | None:
        """For a UAV not heard for `SILENT_AFTER_S`: the largest tracking error it reaches
        flying its last setpoint on alone, if the formation holds now and a tick later
        (`gcs.flight.silent`); None for a UAV heard lately."""
        heard = self.tracks[index].last_sample_time
        if heard is None or t - heard <= SILENT_AFTER_S:
            return None
        setpoint = self._last_sent(index, heard)
        if setpoint is None:
            return None
        alone = OnItsOwn(
            self.drivers[index].setpoint_horizon_s, self.mission.vehicle.max_acceleration
        )
        half = self.window_s / 2

        def targets(decided: float, times: np.ndarray) -> np.ndarray:
            profile = self.profile.with_change(max(decided + half, 0.0), 0.0)
            return self._virtual(profile.distance(times))[:, index]

        tick_s = 1.0 / self.options.setpoint_rate_hz
        return hold_errors(setpoint, alone, t, tick_s, targets, self.window_s)

    def _last_sent(self, index: int, heard: float) -> SentSetpoint | None:
        """The last setpoint `index` was sent at or before mission time `heard` (None: not
        among the ticks kept)."""
        for sent_t, uavs, xy, vxy, axy in reversed(self._sent):
            if sent_t > heard:
                continue
            k = int(np.searchsorted(uavs, index))
            if k < len(uavs) and uavs[k] == index:
                return SentSetpoint(sent_t, xy[k], vxy[k], axy[k])
        return None

    def _hold_ended(self, t: float, outcome: str, now: float) -> None:
        """End the hold in progress: resumed (the speed it had, or a deferred one, from the
        window's leading edge), or taken over by an operator's change or another freeze."""
        hold = self.holds.end(t, outcome)
        if hold is None:
            return
        if outcome == "resumed":
            self.profile = self.profile.with_change(
                max(t + self.window_s / 2, hold.stop_s), self._hold_speed
            )
            text = (
                f"formation resumes at {self._hold_speed:g} m/s after holding "
                f"{hold.duration_s:.1f} s: every UAV is back within {self.holds.resume_m:.2f} m"
            )
        else:
            text = f"the hold ends after {hold.duration_s:.1f} s: {outcome}"
        self._event(MonitorEvent(t, "info", "hold_end", text), now)

    def _unavailable(self) -> dict[int, str]:
        """The UAVs the formation cannot fly on without, index -> why: a lost link, or a
        vehicle that left guided flight by itself (its own failsafe: holding or landing)."""
        out = {}
        for index, driver in enumerate(self.drivers):
            if self.links.lost[index]:
                out[index] = "link lost"
            elif (
                driver.phase in (Phase.HOLDING, Phase.LANDING) and not self.tracks[index].land_sent
            ):
                out[index] = f"left the formation by itself ({driver.phase.value})"
        return out

    def _link_policy(self, t: float, now: float) -> None:
        """A UAV lost (link, or its own failsafe) freezes the formation; it resumes once every
        such UAV has rejoined its target, else everyone lands (`gcs.flight.rejoin` decides,
        this applies)."""
        if self.aborting:
            return
        unavailable = self._unavailable()
        decision = self.rejoin.decide(
            t,
            unavailable,
            holding=frozenset(
                i
                for i in unavailable
                if self.drivers[i].phase == Phase.HOLDING and not self.links.lost[i]
            ),
            landing=frozenset(i for i in unavailable if self.drivers[i].phase == Phase.LANDING),
            tracking_now=self.tracking_now,
            tolerance_m=self.mission.vehicle.tracking_allowance,
            frozen_by=self.frozen_by,
        )
        for index in decision.guided:
            self.drivers[index].resume(now)  # its link is back: guided flight again
            self._event(
                MonitorEvent(
                    t, "warning", "rejoin", f"UAV {index + 1}: back to guided flight, rejoining",
                    index + 1,
                ),
                now,
            )  # fmt: skip
        if decision.freeze:
            if self.frozen_by is None:
                self._freeze("link", now)
            self.frozen_by = "link"
        if decision.ask_operator:
            self.view.message(
                "error", "link lost: formation frozen. Type a speed to resume, or 'land'."
            )
        if decision.land is not None:
            self.land_everyone(decision.land, now)
        elif decision.resume:
            self._resume(now)

    def _collect_acks(self, now: float) -> None:
        speedup = self.options.speedup
        for record in self._records:
            seq = record.change.seq
            for driver in self.drivers:
                uav = driver.uav_id
                if uav in record.acks or uav in record.refused:
                    continue
                if seq not in driver.speed_results:
                    continue  # still in flight
                result = driver.speed_results[seq]
                reaction = None
                if result == mavlink.MAV_RESULT_ACCEPTED and seq in driver.speed_acks:
                    reaction = (driver.speed_acks[seq] - record.broadcast_wall) * speedup
                    # (a link lost since the broadcast: the delay is the outage's)
                    outage = self.links.lost[uav - 1] or (
                        self.links.lost_at[uav - 1] >= record.change.requested_s
                    )
                    self.speeds.acknowledge(record, uav, reaction, sets_lead=not outage)
                    kind = SpeedRecordKind.ACK
                elif result is None:
                    record.refused[uav] = "no answer"
                    kind = SpeedRecordKind.UNANSWERED
                else:
                    record.refused[uav] = str(result)
                    kind = SpeedRecordKind.REFUSED
                self.recorder.speed(
                    SpeedRecord(
                        t=self.clock.mission_time(now),
                        kind=kind,
                        seq=seq,
                        uav=uav,
                        reaction_s=reaction,
                    ),
                    now,
                )

    def _drain_driver_events(self, now: float) -> None:
        for driver in self.drivers:
            for event in driver.drain_events():
                self._driver_event(driver, event, now)
            if driver.phase == Phase.LANDED:
                track = self.tracks[driver.uav_id - 1]
                if track.landed_time is None and self.clock.anchored:
                    track.landed_time = self.clock.mission_time(now)
                    if track.last_position is not None:
                        track.final_xy = track.last_position[:2].copy()

    def _driver_event(self, driver: Driver, event: DriverEvent, now: float) -> None:
        level = _SEVERITY_LEVEL.get(event.severity, "info")
        if event.kind == "statustext" and (slip := parse_clock_slipped(event.text)) is not None:
            self._vehicle_clocks[driver.uav_id - 1].slipped(slip)
        self.recorder.event(
            level, f"UAV {driver.uav_id}: {event.text}", now, name=f"uav{driver.uav_id}"
        )
        if event.kind in ("phase", "failed") and level in ("error", "fatal"):
            self.view.message(level, f"UAV {driver.uav_id}: {event.text}")
        if driver.phase == Phase.FAILED and self.clock.anchored and not self.aborting:
            self.fatal = True
            self.land_everyone(f"UAV {driver.uav_id} failed: {driver.failure_reason}", now)

    def _event(self, event: MonitorEvent, now: float) -> None:
        self.events.append(event)
        if event.fatal:
            self.fatal = True
            self.reason = self.reason or event.text
        self.recorder.event(event.level, event.text, now)
        self.view.message(event.level, event.text)
        (log.warning if event.level != "info" else log.info)("t=%.2f %s", event.t, event.text)

    def _finished(self, now: float) -> bool:
        lost = self.links.lost
        done = [
            d.phase in (Phase.LANDED, Phase.FAILED) or (self.aborting and lost[i])
            for i, d in enumerate(self.drivers)
        ]
        if all(done):
            return self._settled(now)
        if self.aborting and self._abort_time is not None:
            t = self.clock.mission_time(now)
            if t - self._abort_time > self.options.finish_timeout_s:
                self._event(
                    MonitorEvent(t, "error", "abort_timeout", "gave up waiting for the landings"),
                    now,
                )
                return True
        return False

    def _settled(self, now: float) -> bool:
        """Every UAV is down: keep stepping the landed ones while they are still armed or have
        commands in flight (ArduPilot disarms itself ~0.5 s after touchdown; PX4 must be
        disarmed, and a refused DISARM is retried), for at most `SETTLE_WALL_S` of wall time."""
        if not any(
            d.phase is Phase.LANDED and (d.pending_commands or d.telemetry.armed)
            for d in self.drivers
        ):
            return True
        if self._settle_deadline is None:
            self._settle_deadline = now + SETTLE_WALL_S
        return now >= self._settle_deadline

    # ------------------------------------------------------------------ result
    def _result(self) -> RunResult:
        stats = self.safety.stats
        takeoffs = [tr.takeoff_time for tr in self.tracks if tr.takeoff_time is not None]
        landings = [tr.landed_time for tr in self.tracks if tr.landed_time is not None]
        landing_error = landing_errors([tr.final_xy for tr in self.tracks], self._goal_slots())
        completed, why_not = completion(
            aborting=self.aborting,
            started=self.clock.anchored,
            all_landed=all(d.phase == Phase.LANDED for d in self.drivers),
            all_told_to_land=all(tr.land_sent for tr in self.tracks),
            landing_error_m=landing_error,
            safety_margin=self.mission.safety_margin,
        )
        if not completed and self.reason is None:
            self.reason = why_not
        completed = completed and not self.fatal
        sampled = stats.samples > 0 or np.any(stats.max_tracking_error_m > 0)
        nominal = self.tick_period_wall
        timing = setpoint_timing(self._tick_walls, nominal, self.options.speedup)
        noise = getattr(getattr(self.mission.sim, "noise", None), "position_m", None)
        return RunResult(
            completed=completed,
            reason=None if completed else self.reason,
            fleet_size=self.size,
            duration_s=(max(landings) - min(takeoffs)) if takeoffs and landings else None,
            min_uav_uav_m=_finite(stats.min_uav_uav_m),
            min_uav_obstacle_m=_finite(stats.min_uav_obstacle_m),
            max_tracking_error_m=float(stats.max_tracking_error_m.max()) if sampled else None,
            tracking_error_m=[float(e) for e in stats.max_tracking_error_m]
            if sampled
            else [None] * self.size,
            control_error_m=[float(e) for e in stats.max_control_error_m]
            if sampled
            else [None] * self.size,
            landing_error_m=landing_error,
            connected_fraction=stats.connected_fraction,
            los_connected_fraction=stats.los_connected_fraction,
            speed_changes=self.speeds.as_json(),
            events=list(self.events),
            phases=[d.phase.value for d in self.drivers],
            smoothing_window_s=self.window_s,
            smoothing_error_m=self.smoothing_bound(),
            noise_m=noise,
            setpoints_sent=sum(d.setpoints_sent for d in self.drivers),
            setpoint_rate_hz=timing.rate_hz,
            setpoint_jitter_p99_ms=timing.jitter_p99_ms,
            setpoint_period_ms=nominal * 1000,
            setpoint_max_gap_ms=timing.max_gap_ms,
            ticks=self.ticks,
            interrupted=self.interrupts,
            fatal=self.fatal,
            radio=run_json_radio(self.radio_report),
            stalls=list(self.stalls),
            telemetry_shed=sum(getattr(d.link.counters, "stale", 0) for d in self.drivers),
            limits_refused=list(self.limits_refused),
            stations=self._stations_result(),
            holds=self.holds.all_holds(),
        )


def _list(array: np.ndarray | None) -> list | None:
    return None if array is None else array.tolist()


def _finite(value: float | None) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None
