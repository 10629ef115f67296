"""The driver interface: one UAV's autopilot conversation, one subclass per autopilot family.

Modelled on skybrush's `autopilots/base.py`: the runtime talks to every UAV through `Driver`
and asks *capabilities* (`accepts_acceleration_feedforward`,
`needs_setpoint_stream_before_offboard`, ...) instead of testing "is this PX4?". The family is
chosen once, from `fleet.backend`, in `gcs/drivers/__init__.py` (never from the heartbeat).

Non-blocking state machine. The runtime runs ONE scheduler loop for the whole fleet; it calls

* `on_message(msg, now)` for every valid message its `Link` received from this UAV,
* `step(now)` once per tick: sends the GCS heartbeat, advances the commands in flight
  (`gcs.drivers.commands`: retransmission, refusal reasons, confirmation, back-off), then the
  phase,
* the requests `takeoff(altitude)`, `land()`, `hold()`, `resume()`, `send_setpoint(...)` and
  `send_speed_change(change)`, which only send or queue and return at once.

Nothing here sleeps, waits on a socket or starts a thread. `now` is always the wall clock
(`time.monotonic()` seconds); every delay a driver uses goes through `DriverTiming.wall`, which
divides a vehicle-time delay by the speedup and never goes below a wall-clock floor.

Phases (`Phase`): connecting -> initialising (waiting for a usable position/home) -> ready ->
arming (guided/offboard mode, then arm) -> taking_off -> following (airborne, streaming) <->
holding -> landing -> landed; failed (with `failure_reason`) from anywhere. `takeoff()` may be
called early: it is carried out as soon as the UAV is ready.

Commands and modes. Every command goes through the driver's `CommandTracker`
(`send_command`): retransmitted with exponential back-off until its final COMMAND_ACK, a
refusal explained by the vehicle's STATUSTEXT (WARNING or worse) from just before to just after
the ACK, an ARM or mode change confirmed only when the heartbeat shows it, and a failed try
(refused, unanswered, not shown) followed by a back-off before the same key is sent again. The
pacing is the family's `retry_policy` (`RetryPolicy`, vehicle-time seconds). A mode the driver
asked for (`request_mode`, or guided while arming) is its *mode goal*: asked again, paced,
until a heartbeat shows it; a later change of mode is the vehicle's own decision.

What a family subclass MUST implement
-------------------------------------
* `family` (class attribute): the `fleet.backend` name (`"sim"`, `"ardupilot"`, `"px4"`).
* `mode_command(mode: FlightMode) -> CommandSpec`: the command that selects a logical mode
  (GUIDED/OFFBOARD, HOLD, LAND) on this autopilot.
* `current_mode() -> FlightMode | None`: the logical mode from the last heartbeat.
* `takeoff_command(relative_altitude) -> CommandSpec | None`: `None` means the family takes
  off by following the setpoint stream (PX4 OFFBOARD).

What it MAY override (defaults: a plain, well-behaved autopilot)
----------------------------------------------------------------
* `retry_policy` (class attribute, a `RetryPolicy`): retransmission, back-off after a refusal,
  confirmation time, HOME_POSITION pacing, the window in which a STATUSTEXT explains a refusal.
* Capability properties: `accepts_acceleration_feedforward`,
  `needs_setpoint_stream_before_offboard`, `acks_set_mode`, `setpoints_time_out_on_vehicle`,
  `setpoint_horizon_s`, `honours_speed_change_time`, `home_tolerance_m`.
* `stream_rates_hz` (class attribute): the telemetry streams asked for (or turned off, rate 0)
  by `on_connected(now)`, which runs once, after the first heartbeat.
* `limit_parameters` and `parameter_encoding` (class attributes): the parameters that bound
  what the autopilot's position controller follows (`gcs.drivers.limits`), read once connected
  (the ground station waits for them, or for the reads to be given up, before take-off),
  and how the family encodes integer
  parameters (`gcs.drivers.parameters`). `limits` gives them; `apply_limits` sets them for the
  flight, and they are put back once the UAV has landed.
* `position_ready()`: the position estimate allows arming (ArduPilot adds EKF, pre-arm bit).
* `arm_allowed(now)`: an ARM may be sent now, the guided mode being shown (PX4: pre-arm bit).
* `mode_request(mode)`: the command of a mode request (default `mode_command`; LAND:
  `landing_command()`, default `mode_command(LAND)`, PX4 MAV_CMD_NAV_LAND).
* `mode_request_allowed(mode, now)`: a paced (re)request may go now (default: guided waits
  for the setpoint stream when `needs_setpoint_stream_before_offboard`).
* `on_mode_result(mode, outcome, now)`, `on_arm_result(outcome, now)`: a mode change or an
  ARM ended (default: report a refusal with its reason, or a change never shown).
* `on_mode_changed(previous, now)`: the heartbeat's logical mode changed (default: leaving
  guided flight unasked is a failsafe; `vehicle_mode_phase()` and `describe_mode()` say
  which phase that is and how the mode is called).
* `on_family_message(msg, now)`: messages the base does not handle (EKF_STATUS_REPORT, EVENT).
* `on_heartbeat_sent(now)`: after each GCS heartbeat (periodic family traffic).
* `on_mission_clock_changed(now)`: the mission clock was held back after a GCS stall.
* `command_ack_is_final(pending, ack)`: PX4's double acknowledgement of DO_SET_MODE.
* `_step_<phase>(now)` (`_step_connecting` ... `_step_failed`): advances one phase; `step`
  calls the current phase's.

Helpers a family uses (and the runtime does not): `send_command`, `may_send`, `request_mode`,
`mode_goal`, `mode_since`, `stream_flowing`, `note_vehicle_text`, `report_refusal`,
`last_refusal`, `set_phase`, `emit`, `fail`, `time_boot_ms`. The shared machinery lives here too: STATUSTEXT capture with chunk reassembly,
telemetry in the mission's local ENU frame (through `gcs.geodesy`), the GCS heartbeat, setpoint
encoding, and leader speed requests.
"""

from __future__ import annotations

import enum
import logging
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from fleetwire.messages import (
    MASK_POSITION_VELOCITY,
    MASK_POSITION_VELOCITY_ACCELERATION,
    SPEED_CHANGE_COMMAND,
    SPEED_CHANGE_FRAME,
    decode_speed_change,
    encode_speed_change,
)
from gcs.drivers.commands import (
    REASON_SEVERITY,
    Backoff,
    CommandCallback,
    CommandSpec,
    CommandTracker,
    Outcome,
    Pending,
    RetryPolicy,
    VehicleTexts,
)
from gcs.drivers.limits import ARDUCOPTER, AutopilotLimits, LimitParameters
from gcs.drivers.parameters import Encoding, ParameterTable
from gcs.geodesy import Origin, enu_to_geodetic, geodetic_point_to_enu
from gcs.speed import SpeedChange
from gcs.transport.link import Link, mavutil

__all__ = [
    "AIRBORNE_PHASES",
    "Backoff",
    "CommandSpec",
    "Driver",
    "DriverEvent",
    "DriverTiming",
    "ExternalFleet",
    "Fleet",
    "FleetProblem",
    "FlightMode",
    "LeaderRequest",
    "Outcome",
    "Pending",
    "PendingCommand",
    "Phase",
    "RetryPolicy",
    "Telemetry",
    "UavSpec",
]

log = logging.getLogger(__name__)

mavlink = mavutil.mavlink

#: SYS_STATUS health bit the autopilots set when pre-arm checks pass.
PREARM_CHECK_BIT = mavlink.MAV_SYS_STATUS_PREARM_CHECK

#: A command waiting for its outcome (the name the interface used before `Pending`).
PendingCommand = Pending


class Phase(enum.Enum):
    """Where one UAV is in its mission (what the live view and the run JSON show)."""

    CONNECTING = "connecting"  # no heartbeat yet
    INITIALISING = "initialising"  # heartbeat seen; waiting for position / EKF / home
    READY = "ready"  # can arm
    ARMING = "arming"  # selecting guided/offboard mode, arming
    TAKING_OFF = "taking_off"  # climbing above its parking slot
    FOLLOWING = "following"  # airborne, following the setpoint stream
    HOLDING = "holding"  # airborne, holding position in the autopilot's hold mode
    LANDING = "landing"
    LANDED = "landed"  # on the ground (after a flight, or never took off after land())
    FAILED = "failed"  # see Driver.failure_reason


#: Phases in which the vehicle is expected to be in its guided/offboard mode.
GUIDED_PHASES = frozenset({Phase.TAKING_OFF, Phase.FOLLOWING})
#: Take-offs armed again when the autopilot disarms on the ground before the climb.
MAX_TAKEOFF_REARMS = 3

#: Vehicle seconds the vehicle's clock (time_boot_ms) may step back before it counts as a
#: reboot; a smaller step is a datagram overtaken on the way (a network reordering them).
VEHICLE_REBOOT_JUMP_S = 2.0


def overtaken(vehicle_s: float, latest: float | None) -> bool:
    """A vehicle time a little earlier than the `latest` heard (None: none yet): a datagram a
    later one overtook on the way, not the clock going back (a jump back of more than
    `VEHICLE_REBOOT_JUMP_S` is a reboot)."""
    return latest is not None and latest - VEHICLE_REBOOT_JUMP_S <= vehicle_s < latest


#: Phases in which the vehicle is (or may be) in the air.
AIRBORNE_PHASES = frozenset({Phase.TAKING_OFF, Phase.FOLLOWING, Phase.HOLDING, Phase.LANDING})


class FlightMode(enum.Enum):
    """Logical flight modes; each family maps them to its own mode numbers."""

    GUIDED = "guided"  # ArduPilot GUIDED, PX4 OFFBOARD: follows the GCS's setpoints
    HOLD = "hold"  # hold position (BRAKE/LOITER, PX4 AUTO.LOITER)
    LAND = "land"


@dataclass(frozen=True)
class DriverTiming:
    """Delays of the vehicles' clock turned into wall-clock delays (`--speedup K`).

    A delay `s` in vehicle time lasts `s / speedup` wall seconds, but never less than
    `wall_floor_s`, so that a busy machine does not trip timeouts at high speedup.
    """

    speedup: float = 1.0
    wall_floor_s: float = 0.25

    def wall(self, seconds: float, floor: float | None = None) -> float:
        """Wall-clock seconds for `seconds` of vehicle time, at least the floor."""
        return max(seconds / self.speedup, self.wall_floor_s if floor is None else floor)


@dataclass(frozen=True, eq=False)
class UavSpec:
    """What a driver is told about its UAV.

    `uav_id` is 1..N in formation order; `start_slot` / `goal_slot` are the parking slots
    (local x, y in metres) where its home must be and where it lands; `altitude` is the cruise
    altitude above the origin (docs/mission-file.md).
    """

    uav_id: int
    system_id: int
    url: str
    origin: Origin
    start_slot: np.ndarray
    goal_slot: np.ndarray
    altitude: float


@dataclass(frozen=True)
class DriverEvent:
    """Something worth logging: a phase change, a STATUSTEXT, a refusal, a timeout."""

    time: float  # wall clock
    uav_id: int
    kind: str  # "phase" | "statustext" | "command" | "failed" | "leader_request" | ...
    text: str
    severity: int = mavlink.MAV_SEVERITY_INFO


@dataclass(frozen=True)
class LeaderRequest:
    """A speed change asked for by a UAV acting as leader (docs/outputs.md: x = 0, y = its seq)."""

    uav_id: int
    seq: int | None
    speed: float
    received: float  # wall clock


@dataclass
class Telemetry:
    """The latest state reported by one UAV, positions in the mission's local ENU frame."""

    position_enu: np.ndarray | None = None  # (3,) from GLOBAL_POSITION_INT
    velocity_enu: np.ndarray | None = None  # (3,)
    relative_altitude: float | None = None  # m above home
    position_time: float | None = None  # wall clock of the last position
    home_enu: np.ndarray | None = None  # (3,) from HOME_POSITION
    armed: bool = False
    base_mode: int = 0
    custom_mode: int | None = None
    system_status: int = 0
    landed_state: int = mavlink.MAV_LANDED_STATE_UNDEFINED
    prearm_ok: bool | None = None
    battery_remaining_pct: float | None = None  # SYS_STATUS battery_remaining; None: unknown
    heartbeat_time: float | None = None
    autopilot: int | None = None
    vehicle_type: int | None = None
    # Simulators only (SIM_STATE: the true, noise-free state), for the run's metrics
    true_position_enu: np.ndarray | None = None
    true_velocity_enu: np.ndarray | None = None
    true_time: float | None = None
    # The vehicle's own clock (the latest time_boot_ms heard, seconds; a datagram overtaken by
    # a later one does not move it back, a reboot does) and when it was heard (receiver clock);
    # a sample's time on it does not suffer from the ground station's receive delays.
    vehicle_time_s: float | None = None
    vehicle_time_heard: float | None = None
    position_vehicle_time_s: float | None = None  # GLOBAL_POSITION_INT's own time_boot_ms
    # SIM_STATE carries no time: when it was taken, on the vehicle's clock (`_on_sim_state`)
    true_vehicle_time_s: float | None = None
    navigation_noise_m: float | None = None  # the simulator's navigation noise (1 sigma)


class Driver(ABC):
    """One UAV behind one `Link`; see the module docstring for what a family implements."""

    family: ClassVar[str] = ""

    #: Seconds (vehicle time) the UAV may take to send its first heartbeat; wall floor below.
    connect_timeout_s: ClassVar[float] = 30.0
    connect_wall_floor_s: ClassVar[float] = 15.0
    #: Seconds (vehicle time) from the first heartbeat to a usable position (ArduPilot: ~40 s).
    initialise_timeout_s: ClassVar[float] = 60.0
    #: Seconds (vehicle time) allowed for guided mode + arming, and for the climb.
    arming_timeout_s: ClassVar[float] = 20.0
    takeoff_timeout_s: ClassVar[float] = 60.0
    #: The climb is over when the UAV is this close (m) to the take-off altitude.
    takeoff_altitude_tolerance_m: ClassVar[float] = 1.0
    #: Period (vehicle time) of the GCS heartbeat sent to the UAV.
    heartbeat_period_s: ClassVar[float] = 1.0
    #: Message id -> rate (Hz, vehicle time) asked for once connected (0: turned off).
    stream_rates_hz: ClassVar[dict[int, float]] = {}
    #: Pacing of commands, refusals, confirmations (see `RetryPolicy`).
    retry_policy: ClassVar[RetryPolicy] = RetryPolicy()
    #: The parameters bounding horizontal tracking (None: not read) and their encoding.
    limit_parameters: ClassVar[LimitParameters | None] = ARDUCOPTER
    parameter_encoding: ClassVar[Encoding] = Encoding.C_CAST
    #: Setpoints flowing without a gap for this long (vehicle time) make a stream...
    stream_established_s: ClassVar[float] = 0.5
    #: ... and a gap longer than this (vehicle time) starts a new one.
    stream_gap_s: ClassVar[float] = 0.5

    def __init__(self, spec: UavSpec, link: Link, timing: DriverTiming | None = None) -> None:
        self.spec = spec
        self.link = link
        self.timing = timing or DriverTiming()
        self.telemetry = Telemetry()
        self.phase = Phase.CONNECTING
        self.failure_reason: str | None = None
        self.phase_since: float | None = None
        #: Wall time the heartbeat's logical mode last changed (None before a heartbeat).
        self.mode_since: float | None = None
        #: (wall time, reason) of the last refused ARM or mode change.
        self.last_refusal: tuple[float, str] | None = None
        self.texts = VehicleTexts()
        #: (wall time, severity, text) of every STATUSTEXT, chunks joined.
        self.statustexts: list[tuple[float, int, str]] = self.texts.entries
        self.commands = CommandTracker(
            self.retry_policy, self.timing.wall, self._transmit, self.command_ack_is_final,
            self.texts,
        )  # fmt: skip
        self.failsafes: list[tuple[float, str]] = []  # (wall time, what the vehicle did)
        self.speed_acks: dict[int, float] = {}  # seq -> wall time of its COMMAND_ACK
        self.speed_results: dict[int, int | None] = {}  # seq -> MAV_RESULT (None: unanswered)
        self.setpoints_sent = 0
        self._events: deque[DriverEvent] = deque()
        self._leader_requests: deque[LeaderRequest] = deque()
        self._leader_seqs: set[int] = set()
        self._takeoff_altitude: float | None = None
        self._last_heartbeat_sent: float | None = None
        self._started: float | None = None
        self._mode_goal: FlightMode | None = None
        self._takeoff_sent = False
        self._rearms = 0  # take-offs armed again after the autopilot disarmed on the ground
        self._stream_since: float | None = None  # start of the current setpoint streak
        self._last_setpoint: float | None = None
        #: Mission time at a wall time, once the runtime anchored its clock (None before).
        self.mission_clock: Callable[[float], float | None] = lambda now: None
        pacing = Backoff(self.timing.wall(1.0, floor=0.25), 1.5, self.timing.wall(3.0, floor=1))
        self.parameters = ParameterTable(self.parameter_encoding, retry=pacing)
        self._limits_before: dict[str, tuple[float, int]] = {}  # set for the flight: originals

    # ------------------------------------------------------------------ family hooks
    @abstractmethod
    def mode_command(self, mode: FlightMode) -> CommandSpec:
        """The command that selects `mode` on this autopilot."""

    @abstractmethod
    def current_mode(self) -> FlightMode | None:
        """The logical mode of the last heartbeat (None: another mode, or none seen)."""

    @abstractmethod
    def takeoff_command(self, relative_altitude: float) -> CommandSpec | None:
        """The take-off command to `relative_altitude` m above home (None: by setpoints)."""

    def landing_command(self) -> CommandSpec:
        """The command that lands where the UAV is."""
        return self.mode_command(FlightMode.LAND)

    def mode_request(self, mode: FlightMode) -> CommandSpec:
        """The command sent to put the vehicle in `mode` (LAND: `landing_command`)."""
        return self.landing_command() if mode == FlightMode.LAND else self.mode_command(mode)

    def mode_request_allowed(self, mode: FlightMode, now: float) -> bool:
        """Whether a paced (re)request of `mode` may be sent now: guided waits for the setpoint
        stream on families that `needs_setpoint_stream_before_offboard`."""
        if mode == FlightMode.GUIDED and self.needs_setpoint_stream_before_offboard:
            return self.stream_flowing(now)
        return True

    def arm_allowed(self, now: float) -> bool:
        """Whether an ARM may be sent now (the heartbeat already shows the guided mode)."""
        return True

    def on_connected(self, now: float) -> None:
        """Called once, after the first heartbeat: asks for the family's `stream_rates_hz`
        (MAV_CMD_SET_MESSAGE_INTERVAL; rate 0 turns a stream off) and reads its
        `limit_parameters`."""
        if self.limit_parameters is not None:
            self.parameters.read(*self.limit_parameters.names)
        for message_id, rate in self.stream_rates_hz.items():
            entry = mavlink.mavlink_map.get(message_id)
            name = entry.msgname if entry is not None else str(message_id)
            self.send_command(
                CommandSpec(
                    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                    (message_id, 1e6 / rate if rate > 0 else -1, 0, 0, 0, 0, 0),
                    label=f"{name} at {rate:g} Hz" if rate > 0 else f"{name} off",
                    key=("interval", message_id),
                ),
                now,
                lambda outcome, when, what=name: self._on_interval_result(what, outcome, when),
            )

    def _on_interval_result(self, what: str, outcome: Outcome, now: float) -> None:
        if outcome.refused:
            text = f"stream {what}: {outcome.describe()}"
            self.emit("command", text, now, mavlink.MAV_SEVERITY_WARNING)

    @property
    def limits(self) -> AutopilotLimits | None:
        """What the autopilot allows, once its limit parameters were read (None: not read,
        or the autopilot never answered for one of them)."""
        p = self.limit_parameters
        if p is None:
            return None
        speed, acceleration = (
            self.parameters.value(p.speed.name),
            self.parameters.value(p.acceleration.name),
        )
        if speed is None or acceleration is None:
            return None
        return AutopilotLimits(self.uav_id, p, speed, acceleration)

    def apply_limits(self, max_speed: float, max_acceleration: float, now: float) -> None:
        """Raise the autopilot's limits to `max_speed` / `max_acceleration` (SI) for the flight
        (PARAM_SET, confirmed by PARAM_VALUE); they are put back once the UAV has landed."""
        p = self.limit_parameters
        if p is None:
            return
        for parameter, value in ((p.speed, max_speed), (p.acceleration, max_acceleration)):
            before = self.parameters.value(parameter.name)
            param_type = self.parameters.param_type(parameter.name)
            if before is None or param_type is None or parameter.si(before) >= value:
                continue
            self._limits_before.setdefault(parameter.name, (before, param_type))
            self.parameters.set(parameter.name, parameter.from_si(value), param_type)
            self.emit(
                "parameter",
                f"{parameter.name} {before:g} -> {parameter.from_si(value):g} {parameter.unit} "
                "for the flight",
                now,
            )
        self._send_parameter_requests(now)

    @property
    def parameters_settled(self) -> bool:
        """No parameter read or set is still waiting for the vehicle's answer."""
        return self.parameters.settled()

    def _restore_limits(self, now: float) -> None:
        for name, (value, param_type) in self._limits_before.items():
            self.parameters.set(name, value, param_type)
            self.emit("parameter", f"{name} put back to {value:g}", now)
        self._limits_before = {}

    def _send_parameter_requests(self, now: float) -> None:
        target = self.spec.system_id
        for request in self.parameters.due(now):
            name = request[1].encode()
            if request[0] == "read":
                message = self.link.mav.param_request_read_encode(target, 1, name, -1)
            else:
                message = self.link.mav.param_set_encode(target, 1, name, request[2], request[3])
            self.link.send(message, now)

    def _on_param_value(self, msg, now: float) -> None:
        self.parameters.on_param_value(msg)

    def position_ready(self) -> bool:
        """True when the autopilot's position estimate allows arming."""
        return self.telemetry.position_enu is not None and self.telemetry.home_enu is not None

    def on_family_message(self, msg, now: float) -> None:
        """Messages the base class does not interpret."""
        return None

    def on_mission_clock_changed(self, now: float) -> None:
        """The runtime held the mission clock back (a stall): a family that tells its vehicles
        the mission time tells them again now."""
        return None

    def on_heartbeat_sent(self, now: float) -> None:
        """Called after each GCS heartbeat (periodic family traffic, e.g. the sim's clock)."""
        return None

    def on_mode_changed(self, previous: FlightMode | None, now: float) -> None:
        """The heartbeat's logical mode changed from `previous` to `current_mode()`; called
        before the mode goal is checked (`mode_goal` is still what the driver asked for).

        Leaving guided flight without being asked (no mode goal) while the GCS expects it is a
        failsafe of the vehicle's own (a GCS, offboard-loss or battery failsafe): a `failsafe`
        event and the phase of the vehicle's new mode (`vehicle_mode_phase`), so that the
        ground station sees it at once.

        A UAV landing that leaves LAND without being asked (a report of LAND that its next
        heartbeats contradict, a pilot's switch) is asked for LAND again: the ground station
        wanted it down, and a vehicle in GUIDED without setpoints would only hover."""
        if (
            self.phase == Phase.LANDING
            and previous == FlightMode.LAND
            and self.current_mode() != FlightMode.LAND
            and self.mode_goal is None
        ):
            what = f"the vehicle left LAND: mode {self.describe_mode()}; asking for LAND again"
            self.emit("failsafe", what, now, mavlink.MAV_SEVERITY_WARNING)
            self.request_mode(FlightMode.LAND, now)
            return
        if previous != FlightMode.GUIDED or self.phase not in GUIDED_PHASES:
            return
        if self.mode_goal is not None:
            return  # our own request
        what = f"the vehicle left guided flight by itself: mode {self.describe_mode()}"
        self.failsafes.append((now, what))
        self.emit("failsafe", what, now, mavlink.MAV_SEVERITY_CRITICAL)
        self.set_phase(self.vehicle_mode_phase(), now, "failsafe")

    def vehicle_mode_phase(self) -> Phase:
        """The phase to take when the vehicle leaves guided flight by itself."""
        return Phase.LANDING if self.current_mode() == FlightMode.LAND else Phase.HOLDING

    def describe_mode(self) -> str:
        """The vehicle's current mode, for messages."""
        return str(self.telemetry.custom_mode)

    def on_mode_result(self, mode: FlightMode, outcome: Outcome, now: float) -> None:
        """A mode request ended; report a refusal (with the vehicle's reason) or a change the
        heartbeat never showed. The mode goal is retried after the back-off either way."""
        if outcome.refused:
            severity = mavlink.MAV_SEVERITY_ERROR if mode == FlightMode.LAND else None
            self.report_refusal(f"mode {mode.value} refused", outcome, now, severity)
        elif outcome.result is not None and not outcome.confirmed:
            self.emit(
                "command",
                f"mode {mode.value}: accepted, but the heartbeat did not show it",
                now,
                mavlink.MAV_SEVERITY_WARNING,
            )

    def on_arm_result(self, outcome: Outcome, now: float) -> None:
        """An ARM ended; report a refusal or an arming the heartbeat never showed. Arming is
        tried again after the back-off, until the arming timeout."""
        if outcome.refused:
            self.report_refusal("arming refused", outcome, now)
        elif outcome.result is not None and not outcome.confirmed:
            self.emit(
                "command",
                "arming: accepted, but the heartbeat did not show the vehicle armed",
                now,
                mavlink.MAV_SEVERITY_WARNING,
            )

    def command_ack_is_final(self, pending: Pending, ack) -> bool:
        """Whether `ack` ends `pending` (PX4 sends two acks for DO_SET_MODE)."""
        if ack.result == mavlink.MAV_RESULT_ACCEPTED:
            return pending.acks >= pending.spec.acks_needed
        return ack.result != mavlink.MAV_RESULT_IN_PROGRESS

    # ------------------------------------------------------------------ capabilities
    @property
    def accepts_acceleration_feedforward(self) -> bool:
        """Whether setpoints may carry acceleration (otherwise mask 3520: position+velocity)."""
        return False

    @property
    def needs_setpoint_stream_before_offboard(self) -> bool:
        """Whether setpoints must already flow before the guided/offboard mode is selected."""
        return False

    @property
    def acks_set_mode(self) -> bool:
        """Whether a mode change is acknowledged (MAV_CMD_DO_SET_MODE) rather than only
        visible in the next heartbeat."""
        return True

    @property
    def setpoints_time_out_on_vehicle(self) -> bool:
        """Whether the vehicle itself holds when setpoints stop (ArduPilot GUIDED does not)."""
        return True

    @property
    def setpoint_horizon_s(self) -> float:
        """How long the vehicle flies its last setpoint's feed-forward on when the stream
        stops, before it brakes (PX4 waits COM_OF_LOSS_T, 1 s by default): what
        `gcs.flight.silent` dead-reckons a silent UAV with."""
        return 1.0

    @property
    def honours_speed_change_time(self) -> bool:
        """Whether DO_CHANGE_SPEED's `x` (effective time) and `y` (seq) are used by the vehicle;
        real autopilots ack at once and ignore them."""
        return False

    @property
    def home_tolerance_m(self) -> float:
        """How far (horizontally) the vehicle's home may be from its parking slot."""
        return 1.0

    # ------------------------------------------------------------------ runtime interface
    @property
    def uav_id(self) -> int:
        return self.spec.uav_id

    @property
    def wants_setpoints(self) -> bool:
        """Whether the scheduler should stream setpoints to this UAV now."""
        if self.phase == Phase.FOLLOWING:
            return True
        if self.phase == Phase.LANDING:
            # until a heartbeat shows LAND the vehicle may still fly guided (the request, or
            # its ack, lost): it follows the stream, not the feed-forward of the last setpoint
            # it heard carried on (a braking one flies it back along the path: 10.3 m with 40 %
            # of packets lost); the autopilot ignores setpoints once it lands
            return self._mode_goal == FlightMode.LAND and self.current_mode() == FlightMode.GUIDED
        if self.phase in (Phase.ARMING, Phase.TAKING_OFF):
            return self.needs_setpoint_stream_before_offboard or not self._takes_off_by_command
        return False

    @property
    def airborne(self) -> bool:
        return self.phase in AIRBORNE_PHASES

    def on_message(self, msg, now: float) -> None:
        """Take one valid message from this UAV into account."""
        kind = msg.get_type()
        boot_ms = getattr(msg, "time_boot_ms", None)
        if boot_ms is not None:
            self._heard_vehicle_time(boot_ms / 1000.0, now)
        handler = _HANDLERS.get(kind)
        if handler is not None:
            getattr(self, handler)(msg, now)
        else:
            self.on_family_message(msg, now)

    def _heard_vehicle_time(self, vehicle_s: float, now: float) -> None:
        """The vehicle's clock moves on, or starts over after a reboot; a datagram `overtaken`
        on the way does not move it back."""
        t = self.telemetry
        if not overtaken(vehicle_s, t.vehicle_time_s):
            t.vehicle_time_s = vehicle_s
            t.vehicle_time_heard = now

    def step(self, now: float) -> None:
        """Advance the state machine: heartbeat, commands in flight, the phase, the mode goal."""
        if self._started is None:
            self._started = now
            self.phase_since = now
        if self._last_heartbeat_sent is None or now - self._last_heartbeat_sent >= self.timing.wall(
            self.heartbeat_period_s, floor=0.02
        ):
            self._send_heartbeat(now)
        for severity, text in self.texts.flush(now, self.timing.wall(0.5, floor=0.5)):
            self._on_vehicle_text(severity, text, now)
        self.commands.step(now)
        if not self.parameters.settled():
            self._send_parameter_requests(now)
        getattr(self, f"_step_{self.phase.value}")(now)
        self._pursue_mode_goal(now)

    def takeoff(self, altitude: float, now: float) -> None:
        """Arm and climb above the parking slot to `altitude` (m above the mission origin).

        Safe to call before the UAV is ready: it starts as soon as it is.
        """
        self._takeoff_altitude = altitude
        if self.phase == Phase.READY:
            self._begin_arming(now)

    def land(self, now: float) -> None:
        """Land where the UAV is (the runtime brings it over its arrival slot first). A UAV
        already landing by itself (its own failsafe, as it reported) is asked all the same,
        until its heartbeats show LAND: one report is no landing confirmed."""
        if self.phase in (Phase.LANDED, Phase.FAILED):
            return
        if self.phase == Phase.LANDING:
            if self.mode_goal is None:
                self.request_mode(FlightMode.LAND, now)
            return
        self._takeoff_altitude = None
        if not self.telemetry.armed and self.phase not in AIRBORNE_PHASES:
            self.set_phase(Phase.LANDED, now, "never took off")
            return
        self.commands.cancel(lambda spec: spec.command != mavlink.MAV_CMD_DO_CHANGE_SPEED)
        self.request_mode(FlightMode.LAND, now)
        self.set_phase(Phase.LANDING, now)

    def hold(self, now: float) -> None:
        """Hold position in the autopilot's own hold mode (the stream stops)."""
        if self.phase in (Phase.FOLLOWING, Phase.TAKING_OFF):
            self.request_mode(FlightMode.HOLD, now)
            self.set_phase(Phase.HOLDING, now)

    def resume(self, now: float) -> None:
        """Back from hold to following the setpoint stream."""
        if self.phase == Phase.HOLDING:
            self.request_mode(FlightMode.GUIDED, now)
            self.set_phase(Phase.FOLLOWING, now)

    def send_setpoint(
        self,
        position_enu: np.ndarray,
        velocity_enu: np.ndarray,
        acceleration_enu: np.ndarray | None,
        mission_time: float,
        now: float,
        geodetic: np.ndarray | None = None,
    ) -> None:
        """Send one SET_POSITION_TARGET_GLOBAL_INT (frame 6, altitude relative to home).

        Positions are local ENU metres (z above the origin); `geodetic` (lat, lon, alt AMSL),
        when the caller converted a whole fleet at once, saves the per-UAV conversion.
        Velocities and accelerations are turned into NED as MAVLink wants them.
        """
        if geodetic is None:
            geodetic = enu_to_geodetic(*position_enu, self.spec.origin)
        lat, lon, alt_amsl = geodetic
        use_acc = acceleration_enu is not None and self.accepts_acceleration_feedforward
        mask = MASK_POSITION_VELOCITY_ACCELERATION if use_acc else MASK_POSITION_VELOCITY
        acc = acceleration_enu if use_acc else (0.0, 0.0, 0.0)
        msg = self.link.mav.set_position_target_global_int_encode(
            self.time_boot_ms(now),
            self.spec.system_id,
            1,
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            mask,
            int(round(lat * 1e7)),
            int(round(lon * 1e7)),
            float(alt_amsl - self.home_altitude_amsl),
            float(velocity_enu[1]),
            float(velocity_enu[0]),
            float(-velocity_enu[2]),
            float(acc[1]),
            float(acc[0]),
            float(-acc[2]),
            0.0,
            0.0,
        )
        self.link.send(msg, now)
        self.setpoints_sent += 1
        gap = self.timing.wall(self.stream_gap_s, floor=0.3)
        if self._last_setpoint is None or now - self._last_setpoint > gap:
            self._stream_since = now  # a new streak
        self._last_setpoint = now

    def send_speed_change(self, change: SpeedChange, now: float) -> None:
        """Broadcast leg for this UAV: COMMAND_INT DO_CHANGE_SPEED (docs/outputs.md, MAVLink),
        retransmitted until its COMMAND_ACK; the ack time lands in `speed_acks[seq]`."""
        spec = CommandSpec(
            SPEED_CHANGE_COMMAND,
            encode_speed_change(change.speed, int(round(change.effective_s * 1000)), change.seq),
            use_int=True,
            frame=SPEED_CHANGE_FRAME,
            label=f"speed change {change.seq}",
            retry=Backoff(0.2, growth=1.0, max_s=0.2),  # time-critical: never slower
            max_attempts=None,
            key=("speed", change.seq),
        )

        def done(outcome: Outcome, when: float, seq: int = change.seq) -> None:
            self.speed_results[seq] = outcome.result
            if outcome.result is not None:
                self.speed_acks.setdefault(seq, outcome.answered_at or when)

        self.send_command(spec, now, done)

    def set_mission_clock(self, clock: Callable[[float], float | None]) -> None:
        """The runtime anchored its mission clock: `clock(wall)` gives the mission time. The
        next step sends a heartbeat (and whatever the family sends with it) at once."""
        self.mission_clock = clock
        self._last_heartbeat_sent = None

    def drain_events(self) -> list[DriverEvent]:
        """Events since the last call (phase changes, STATUSTEXT, refusals)."""
        events = list(self._events)
        self._events.clear()
        return events

    def drain_leader_requests(self) -> list[LeaderRequest]:
        """Speed changes this UAV asked for as leader since the last call."""
        requests = list(self._leader_requests)
        self._leader_requests.clear()
        return requests

    def close(self) -> None:
        """Forget pending commands (the link is closed by its owner)."""
        self.commands.clear()

    @property
    def home_altitude_amsl(self) -> float:
        """Home altitude (m AMSL): relative altitudes are measured from it."""
        home = self.telemetry.home_enu
        return self.spec.origin.alt + (0.0 if home is None else float(home[2]))

    @property
    def pending_commands(self) -> list[Pending]:
        return self.commands.pending

    # ------------------------------------------------------------------ helpers for families
    def send_command(
        self,
        spec: CommandSpec,
        now: float,
        on_result: CommandCallback | None = None,
        confirm: Callable[[], bool] | None = None,
    ) -> None:
        """Send `spec` now through the command tracker (`gcs.drivers.commands`).

        A newer command with the same key replaces a pending one. `on_result(outcome, now)` is
        called once; `confirm()`, if given, must hold within the confirmation time after an
        ACCEPTED ack for the outcome to be `accepted`.
        """

        def done(outcome: Outcome, when: float) -> None:
            if outcome.result is None:
                self.emit(
                    "command",
                    f"{spec.name}: no COMMAND_ACK after {outcome.attempts} attempts",
                    when,
                    mavlink.MAV_SEVERITY_WARNING,
                )
            if on_result is not None:
                on_result(outcome, when)

        self.commands.send(spec, now, done, confirm)

    def may_send(self, key: object, now: float) -> bool:
        """No command with this key is in flight and its back-off after a failure is over."""
        return self.commands.may_send(key, now)

    @property
    def mode_goal(self) -> FlightMode | None:
        """The mode the driver asked for and no heartbeat has shown yet (None: none)."""
        return self._mode_goal

    def request_mode(self, mode: FlightMode, now: float) -> None:
        """Ask for `mode` now, and keep asking (paced, see `mode_request_allowed`) until a
        heartbeat shows it."""
        self._want_mode(mode)
        self._send_mode_request(mode, now)

    def stream_flowing(self, now: float) -> bool:
        """Setpoints have been flowing without a gap for `stream_established_s`."""
        if self._stream_since is None or self._last_setpoint is None:
            return False
        recent = now - self._last_setpoint <= self.timing.wall(0.3, floor=0.3)
        return recent and now - self._stream_since >= self.timing.wall(
            self.stream_established_s, floor=0.1
        )

    def note_vehicle_text(self, text: str, severity: int, now: float) -> None:
        """A text from the vehicle (a family decoding e.g. PX4's EVENT adds its texts here):
        logged as a `statustext` event, and a candidate reason for a refusal."""
        entry = self.texts.note(severity, text, now)
        if entry is not None:
            self._on_vehicle_text(*entry, now)

    def report_refusal(
        self, what: str, outcome: Outcome, now: float, severity: int | None = None
    ) -> None:
        """Report a refused command with the vehicle's reason (remembered in `last_refusal`)."""
        reason = outcome.describe()
        self.last_refusal = (now, reason)
        self.emit("command", f"{what}: {reason}", now, severity or mavlink.MAV_SEVERITY_WARNING)

    def emit(self, kind: str, text: str, now: float, severity: int = mavlink.MAV_SEVERITY_INFO):
        """Queue an event for the runtime (and log it)."""
        self._events.append(DriverEvent(now, self.uav_id, kind, text, severity))
        log.log(
            logging.WARNING if severity <= mavlink.MAV_SEVERITY_WARNING else logging.INFO,
            "UAV %d: %s",
            self.uav_id,
            text,
        )

    def refuse_position(self, what: str, now: float) -> None:
        """A position that is not a position (NaN, infinite, off the globe): the sample is
        refused, the UAV is faulty (the ground station cannot watch it): it is told to land
        where it is (no position needed) and the driver fails (the runtime then lands
        everyone). Its last valid true position is forgotten so that no stale sample is used."""
        if self.phase == Phase.FAILED:
            return
        self.emit("invalid_position", f"{what} is not valid: sample refused", now,
                  mavlink.MAV_SEVERITY_ERROR)  # fmt: skip
        self.telemetry.true_position_enu = None
        if self.phase in AIRBORNE_PHASES:
            self.send_command(replace(self.landing_command(), key="mode"), now)
        self.fail(f"reports an invalid {what}", now)

    def fail(self, reason: str, now: float) -> None:
        """Give up on this UAV with a reason (a pending ARM is not sent again)."""
        self.commands.discard("arm")
        self.failure_reason = reason
        self.set_phase(Phase.FAILED, now, reason, severity=mavlink.MAV_SEVERITY_ERROR)

    def last_statustext(
        self, since: float | None = None, max_severity: int = mavlink.MAV_SEVERITY_DEBUG
    ) -> str | None:
        """The last STATUSTEXT received (after `since`, wall clock) of severity
        `max_severity` or worse, if any."""
        return self.texts.last(since, max_severity)

    def set_phase(
        self, phase: Phase, now: float, why: str | None = None, severity=mavlink.MAV_SEVERITY_INFO
    ) -> None:
        """Enter `phase` (an event says why); landed and failed end any mode goal."""
        if phase == self.phase:
            return
        previous = self.phase
        self.phase = phase
        self.phase_since = now
        if phase in (Phase.LANDED, Phase.FAILED):
            self._mode_goal = None
        if phase == Phase.LANDED and self._limits_before:
            self._restore_limits(now)
        text = f"{previous.value} -> {phase.value}" + (f" ({why})" if why else "")
        self.emit("phase", text, now, severity)

    def time_boot_ms(self, now: float) -> int:
        """`time_boot_ms` of what we send: wall-clock ms since this driver started."""
        return int(max(now - (self._started or now), 0.0) * 1000) & 0xFFFFFFFF

    # ------------------------------------------------------------------ internals
    def _transmit(self, spec: CommandSpec, now: float) -> None:
        target = (self.spec.system_id, 1)
        p = spec.params
        if spec.use_int:
            msg = self.link.mav.command_int_encode(
                *target,
                spec.frame,
                spec.command,
                0,
                0,
                p[0],
                p[1],
                p[2],
                p[3],
                int(p[4]),
                int(p[5]),
                p[6],
            )
        else:
            confirmation = 0
            msg = self.link.mav.command_long_encode(*target, spec.command, confirmation, *p)
        self.link.send(msg, now)

    def _send_heartbeat(self, now: float) -> None:
        self._last_heartbeat_sent = now
        msg = self.link.mav.heartbeat_encode(
            mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE
        )
        self.link.send(msg, now)
        self.on_heartbeat_sent(now)

    def _send_mode_request(self, mode: FlightMode, now: float) -> None:
        spec = replace(self.mode_request(mode), key="mode")
        self.send_command(
            spec,
            now,
            lambda outcome, when, m=mode: self.on_mode_result(m, outcome, when),
            confirm=lambda m=mode: self.current_mode() == m,
        )

    def _want_mode(self, mode: FlightMode) -> None:
        """Make `mode` the goal; a new goal starts its back-off afresh."""
        if mode != self._mode_goal:
            self.commands.forget_failures("mode")
        self._mode_goal = mode

    def _pursue_mode_goal(self, now: float) -> None:
        """Ask again for the mode goal, once its back-off is over and the family allows it."""
        goal = self._mode_goal
        if goal is None:
            return
        if self.current_mode() == goal:
            self._mode_goal = None
            return
        if self.may_send("mode", now) and self.mode_request_allowed(goal, now):
            self._send_mode_request(goal, now)

    def _arming_failure_reason(self) -> str | None:
        """Why arming failed: the last refusal while arming, else the last warning text."""
        if self.last_refusal is not None and self.last_refusal[0] >= self.phase_since:
            return self.last_refusal[1]
        return self.last_statustext(since=self.phase_since, max_severity=REASON_SEVERITY)

    @property
    def _takes_off_by_command(self) -> bool:
        return self.takeoff_command(0.0) is not None

    # ------------------------------------------------------------------ phase steps
    # `step` calls `_step_<phase>(now)` of the current phase: a family overrides the ones it
    # needs (calling the base's where it extends it).
    def _step_connecting(self, now: float) -> None:
        strangers = self.link.seen_system_ids - {self.spec.system_id}
        if strangers and self.telemetry.heartbeat_time is None:
            self.fail(
                f"{self.link.url}: heard system id {min(strangers)}, expected {self.spec.system_id}",
                now,
            )
            return
        if now - self._started > self.timing.wall(
            self.connect_timeout_s, floor=self.connect_wall_floor_s
        ):
            self.fail(f"no heartbeat from system {self.spec.system_id} on {self.link.url}", now)

    def _step_initialising(self, now: float) -> None:
        if self.telemetry.home_enu is None and self.may_send("home", now):
            # An autopilot without a home yet acknowledges and sends nothing (ArduPilot before
            # its EKF origin): wait for the message, then ask again later and later.
            pacing = self.retry_policy.home_request
            self.send_command(
                CommandSpec(
                    mavlink.MAV_CMD_REQUEST_MESSAGE,
                    (mavlink.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0),
                    label="request HOME_POSITION",
                    key="home",
                    max_attempts=None,
                    retry=pacing,
                    backoff=pacing,
                    confirm_s=pacing.first_s,
                ),
                now,
                confirm=lambda: self.telemetry.home_enu is not None,
            )
        if self.position_ready():
            home = self.telemetry.home_enu
            offset = float(np.hypot(*(home[:2] - self.spec.start_slot)))
            if offset > self.home_tolerance_m:
                self.fail(
                    f"home is {offset:.1f} m from its parking slot "
                    f"({self.spec.start_slot[0]:.1f}, {self.spec.start_slot[1]:.1f})",
                    now,
                )
                return
            self.commands.discard("home")
            self.set_phase(Phase.READY, now)
            if self._takeoff_altitude is not None:
                self._begin_arming(now)
            return
        if now - self.phase_since > self.timing.wall(self.initialise_timeout_s):
            self.fail("no usable position estimate", now)

    def _step_ready(self, now: float) -> None:
        return None  # `takeoff()` starts arming

    def _begin_arming(self, now: float) -> None:
        self._takeoff_sent = False
        self.set_phase(Phase.ARMING, now)
        self._step_arming(now)

    def _step_arming(self, now: float) -> None:
        if now - self.phase_since > self.timing.wall(self.arming_timeout_s):
            reason = self._arming_failure_reason()
            self.fail("could not arm" + (f": {reason}" if reason else ""), now)
            return
        if self.current_mode() != FlightMode.GUIDED:
            self._want_mode(FlightMode.GUIDED)
            self._pursue_mode_goal(now)  # paced: only when nothing is pending or backing off
            return
        if self.telemetry.armed:
            self.set_phase(Phase.TAKING_OFF, now)
            self._step_taking_off(now)
            return
        if self.may_send("arm", now) and self.arm_allowed(now):
            self.send_command(
                CommandSpec(
                    mavlink.MAV_CMD_COMPONENT_ARM_DISARM,
                    (1, 0, 0, 0, 0, 0, 0),
                    label="arm",
                    key="arm",
                ),
                now,
                self.on_arm_result,
                confirm=lambda: self.telemetry.armed,
            )

    def _step_taking_off(self, now: float) -> None:
        target = self._takeoff_altitude
        if target is None:
            return
        relative = target + self.spec.origin.alt - self.home_altitude_amsl
        if not self._takeoff_sent:
            self._takeoff_sent = True
            command = self.takeoff_command(relative)
            if command is not None:
                self.send_command(replace(command, key="takeoff"), now, self._on_takeoff_result)
        altitude = self.telemetry.relative_altitude
        if altitude is not None and altitude >= relative - self.takeoff_altitude_tolerance_m:
            self.set_phase(Phase.FOLLOWING, now, f"at {altitude:.1f} m")
            return
        if self.telemetry.armed is False and self._rearms < MAX_TAKEOFF_REARMS:
            # Disarmed on the ground before the take-off took (every try of it lost on a
            # lossy link, then the autopilot's own disarm delay): arm and take off again.
            self._rearms += 1
            self.emit("command", "disarmed on the ground before the take-off took (the "
                      "autopilot's disarm delay): arming again", now,
                      mavlink.MAV_SEVERITY_WARNING)  # fmt: skip
            self._begin_arming(now)
            return
        if now - self.phase_since > self.timing.wall(self.takeoff_timeout_s):
            self.fail(f"take-off did not reach {relative:.1f} m", now)

    def _step_following(self, now: float) -> None:
        return None  # the runtime streams; the mode goal (after `resume`) is pursued by `step`

    def _step_holding(self, now: float) -> None:
        return None

    def _step_landing(self, now: float) -> None:
        t = self.telemetry
        if t.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND or (
            not t.armed and t.heartbeat_time is not None and t.heartbeat_time > self.phase_since
        ):
            self.set_phase(Phase.LANDED, now)
            self._step_landed(now)  # at once: the runtime may stop stepping a landed fleet

    def _step_landed(self, now: float) -> None:
        return None

    def _step_failed(self, now: float) -> None:
        return None

    # ------------------------------------------------------------------ command results
    def _on_takeoff_result(self, outcome: Outcome, now: float) -> None:
        if outcome.accepted or self.phase != Phase.TAKING_OFF:
            return
        if outcome.attempts > 1 or outcome.result is None:
            # on a lossy link an earlier try may have been obeyed and its ACK lost (a repeat is
            # then refused: "already flying"): the climb decides, within the take-off timeout
            self.emit("command", f"take-off: {outcome.describe()} after {outcome.attempts} "
                      "tries: waiting for the climb", now, mavlink.MAV_SEVERITY_WARNING)  # fmt: skip
            return
        self.fail(f"take-off refused: {outcome.describe()}", now)

    def _on_vehicle_text(self, severity: int, text: str, now: float) -> None:
        self.emit("statustext", text, now, severity)
        self.commands.on_text(severity, now)

    # ------------------------------------------------------------------ message handlers
    def _on_heartbeat(self, msg, now: float) -> None:
        if msg.type == mavlink.MAV_TYPE_GCS or msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID:
            return  # another ground station or a companion, not the autopilot
        previous = self.current_mode()
        t = self.telemetry
        t.heartbeat_time = now
        t.base_mode = msg.base_mode
        t.custom_mode = msg.custom_mode
        t.system_status = msg.system_status
        t.autopilot = msg.autopilot
        t.vehicle_type = msg.type
        t.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        if self.phase == Phase.CONNECTING:
            self.set_phase(Phase.INITIALISING, now)
            self.on_connected(now)
        current = self.current_mode()
        if self.mode_since is None or current != previous:
            self.mode_since = now
        if current != previous:
            self.on_mode_changed(previous, now)
        if self._mode_goal is not None and current == self._mode_goal:
            self._mode_goal = None
        self.commands.confirm(now)

    def _on_global_position(self, msg, now: float) -> None:
        if msg.lat == 0 and msg.lon == 0:
            return  # ArduPilot streams zeros until it has a position
        if abs(msg.lat) > 900_000_000 or abs(msg.lon) > 1_800_000_000:
            self.refuse_position("reported position (GLOBAL_POSITION_INT)", now)
            return
        t = self.telemetry
        sample_s = msg.time_boot_ms / 1000.0
        if overtaken(sample_s, t.position_vehicle_time_s):
            return  # older than the position we have
        t.position_enu = geodetic_point_to_enu(
            msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3, self.spec.origin
        )
        t.velocity_enu = np.array([msg.vy, msg.vx, -msg.vz], float) * 0.01
        t.relative_altitude = msg.relative_alt * 1e-3
        t.position_time = now
        t.position_vehicle_time_s = sample_s

    def _on_sim_state(self, msg, now: float) -> None:
        """SIM_STATE (simulators): the true position, what the run's metrics measure."""
        lat = msg.lat_int * 1e-7 if msg.lat_int else msg.lat
        lon = msg.lon_int * 1e-7 if msg.lon_int else msg.lon
        values = np.array([lat, lon, msg.alt, msg.ve, msg.vn, msg.vd], float)
        if not np.isfinite(values).all() or abs(lat) > 90.0 or abs(lon) > 180.0:
            self.refuse_position("true position (SIM_STATE)", now)
            return
        t = self.telemetry
        t.true_position_enu = geodetic_point_to_enu(lat, lon, msg.alt, self.spec.origin)
        t.true_velocity_enu = np.array([msg.ve, msg.vn, -msg.vd], float)
        t.true_time = now
        # SIM_STATE has no time of its own, and the timed messages of its tick may have been
        # lost: it was taken at least as much later than the last vehicle time heard as it
        # arrived after it (the vehicle's clock runs at the speed-up). With 30 % loss, the
        # last time heard alone dated samples ticks early: 5.36 m read for a true 0.34 m.
        if t.vehicle_time_s is not None and t.vehicle_time_heard is not None:
            since = max(now - t.vehicle_time_heard, 0.0) * self.timing.speedup
            t.true_vehicle_time_s = t.vehicle_time_s + since
        else:
            t.true_vehicle_time_s = None
        t.navigation_noise_m = float(msg.std_dev_horz)

    def _on_home_position(self, msg, now: float) -> None:
        self.telemetry.home_enu = geodetic_point_to_enu(
            msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3, self.spec.origin
        )

    def _on_extended_sys_state(self, msg, now: float) -> None:
        self.telemetry.landed_state = msg.landed_state

    def _on_sys_status(self, msg, now: float) -> None:
        if msg.onboard_control_sensors_present & PREARM_CHECK_BIT:
            self.telemetry.prearm_ok = bool(msg.onboard_control_sensors_health & PREARM_CHECK_BIT)
        # battery_remaining, % (-1: unknown). As recorded (tests/sitl): ArduCopter 4.7 SITL
        # sends 100 at boot, draining in flight (85 after 110 s), and no BATTERY_STATUS; PX4
        # SIH sends 99-100, draining once armed to a floor of 51 (its simulated battery stops
        # at 50 %), recharging once landed, with a BATTERY_STATUS of the same value. The
        # simulated vehicles send their battery model's charge (vehicles/telemetry.py).
        remaining = msg.battery_remaining
        self.telemetry.battery_remaining_pct = None if remaining < 0 else float(remaining)

    def _on_statustext(self, msg, now: float) -> None:
        entry = self.texts.add(msg, now)
        if entry is not None:
            self._on_vehicle_text(*entry, now)

    def _on_command_ack(self, msg, now: float) -> None:
        if msg.target_system not in (0, self.link.mav.srcSystem):
            return
        self.commands.on_ack(msg, now)

    def _on_command(self, msg, now: float) -> None:
        """A command sent TO the ground station: a leader's speed request (docs/outputs.md)."""
        if msg.target_system not in (0, self.link.mav.srcSystem):
            return
        change = decode_speed_change(msg)
        if change is None:
            result = mavlink.MAV_RESULT_UNSUPPORTED
        else:
            result = mavlink.MAV_RESULT_ACCEPTED
            seq = change.seq  # None: COMMAND_LONG, never deduplicated
            if seq is None or seq not in self._leader_seqs:
                if seq is not None:
                    self._leader_seqs.add(seq)
                request = LeaderRequest(self.uav_id, seq, change.speed, now)
                self._leader_requests.append(request)
                self.emit("leader_request", f"leader asks for {change.speed:g} m/s", now)
        seq = int(msg.y) if msg.get_type() == "COMMAND_INT" else 0
        ack = self.link.mav.command_ack_encode(
            msg.command, result, 0, seq, msg.get_srcSystem(), msg.get_srcComponent()
        )
        self.link.send(ack, now)


#: Message type -> the `Driver` method that handles it (others go to `on_family_message`).
_HANDLERS: dict[str, str] = {
    "HEARTBEAT": "_on_heartbeat",
    "GLOBAL_POSITION_INT": "_on_global_position",
    "HOME_POSITION": "_on_home_position",
    "SIM_STATE": "_on_sim_state",
    "EXTENDED_SYS_STATE": "_on_extended_sys_state",
    "SYS_STATUS": "_on_sys_status",
    "STATUSTEXT": "_on_statustext",
    "COMMAND_ACK": "_on_command_ack",
    "COMMAND_INT": "_on_command",
    "COMMAND_LONG": "_on_command",
    "PARAM_VALUE": "_on_param_value",
}


@dataclass(frozen=True)
class FleetProblem:
    """Something wrong with the vehicles themselves (e.g. a simulator process exited)."""

    text: str
    uavs: tuple[int, ...] = ()  # the UAV ids (1-based) it affects


class Fleet(ABC):
    """Where the UAVs' links come from: a backend that starts vehicles (sim) or fixed URLs.

    A context manager: leaving it always stops whatever it started (even on Ctrl-C).
    """

    @abstractmethod
    def start(self) -> list[str]:
        """Start (or locate) the vehicles; return one MAVLink connection string per UAV."""

    def poll(self) -> list[FleetProblem]:
        """Problems noticed since the last call (e.g. a vehicle process that exited)."""
        return []

    def close(self) -> None:
        """Stop whatever `start` started (idempotent)."""
        return None

    def __enter__(self) -> Fleet:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class ExternalFleet(Fleet):
    """Vehicles started by someone else (SITL, real UAVs): the connection strings are given."""

    def __init__(self, urls: list[str]) -> None:
        self.urls = list(urls)

    def start(self) -> list[str]:
        return list(self.urls)
