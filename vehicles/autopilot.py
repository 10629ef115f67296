"""ArduCopter-compatible MAVLink behaviour of one simulated vehicle (no sockets, no clocks).

The sim hands each decoded message to :meth:`Autopilot.handle` and calls :meth:`Autopilot.tick`
at the control rate with the current :class:`Stamp` (simulated and wall-clock seconds); the
autopilot writes references into the shared :class:`~vehicles.dynamics.FleetDynamics` and
appends the messages to send to ``outbox``.

Identity and modes follow ArduCopter (``../shared/sitl/README.md``): HEARTBEAT type 2
(quadrotor), autopilot 3 (ArduPilotMega), custom_mode = Copter mode number (STABILIZE 0,
GUIDED 4, LOITER 5, RTL 6, LAND 9, BRAKE 17); ``MAV_CMD_DO_SET_MODE`` is acknowledged,
``SET_MODE`` is not; an unknown mode gets STATUSTEXT ``No such mode N``; arming is refused
outside GUIDED and LOITER with ``Arm: ...`` and ACK FAILED; ``MAV_CMD_NAV_TAKEOFF`` needs GUIDED,
armed and landed; landing ends in an automatic disarm; position targets outside GUIDED are
ignored silently. Differences from ArduCopter, on purpose: refusals always carry a STATUSTEXT
reason; in GUIDED a stream of ``SET_POSITION_TARGET_*`` that stops for ``setpoint_timeout_s``
makes the vehicle brake and hold (PX4's offboard-loss behaviour; it stays in GUIDED and follows
again when setpoints resume); losing the GCS (no valid message from its system id) makes
it hold (BRAKE), then LAND.

Timeouts count simulated time and never fire before a wall-clock floor (``wall_floor_s``), so a
busy machine at a high speedup does not trip them. See :mod:`vehicles.fleet_speed` for the
mission clock, speed changes and leader requests.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.messages import (
    GCS_SYSTEM_ID,
    SPEED_CHANGE_COMMAND,
    SPEED_CHANGE_FRAME,
    decode_mission_time,
    decode_speed_change,
    encode_speed_change,
)
from fleetwire.modes import COPTER_MODE
from vehicles import telemetry
from vehicles.dynamics import FleetDynamics
from vehicles.fleet_speed import LeaderRequest, LeaderSchedule, MissionClock, SpeedBook, SpeedChange
from vehicles.frames import GeodeticOrigin, ned_to_enu, rotate_body_to_ned
from vehicles.telemetry import FleetSnapshot, TelemetryRates, TelemetrySchedule

log = logging.getLogger(__name__)

AUTOPILOT_COMPONENT = 1  # MAV_COMP_ID_AUTOPILOT1
FORCE_ARM_MAGIC = 2989
FORCE_DISARM_MAGIC = 21196
MAX_EXTRAPOLATION_S = 1.0  # a setpoint's feed-forward is extrapolated for at most this long


#: ArduCopter flight modes the simulation implements (custom_mode numbers, pymavlink's).
Mode = IntEnum(
    "Mode",
    {name: COPTER_MODE[name] for name in ("STABILIZE", "GUIDED", "LOITER", "RTL", "LAND", "BRAKE")},
    module=__name__,
)


ARMABLE_MODES = (Mode.GUIDED, Mode.LOITER)


class Guided(IntEnum):
    """What GUIDED is doing."""

    IDLE = 0  # on the ground (armed or not), waiting for a takeoff
    TAKEOFF = 1
    HOLD = 2  # holding a point (after takeoff, on entry, after a setpoint timeout)
    SETPOINTS = 3  # following SET_POSITION_TARGET_* (subject to the setpoint timeout)
    GOTO = 4  # flying to a point given by DO_REPOSITION / guided mission item (no timeout)


@dataclass(frozen=True)
class Stamp:
    """A moment: simulated seconds since the start and wall-clock (monotonic) seconds."""

    sim_s: float
    wall_s: float


@dataclass(frozen=True)
class FailsafeConfig:
    """Failsafe timings (simulated seconds) and the wall-clock floor of every timeout."""

    setpoint_timeout_s: float = 1.0
    gcs_timeout_s: float = 5.0
    gcs_hold_s: float = 5.0  # hold this long after the GCS is lost, then land
    wall_floor_s: float = 0.25
    gcs_system: int = GCS_SYSTEM_ID


@dataclass(frozen=True)
class AutopilotConfig:
    """Behaviour parameters (ArduCopter parameter names in comments)."""

    failsafe: FailsafeConfig = field(default_factory=FailsafeConfig)
    telemetry: TelemetryRates = field(default_factory=TelemetryRates)
    boot_time_s: float = 1.0
    disarm_delay_s: float = 10.0  # DISARM_DELAY: landed and armed this long -> disarm
    land_detect_s: float = 1.0
    land_speed_mps: float = 0.5  # LAND_SPEED
    land_speed_high_mps: float = 1.5  # LAND_SPEED_HIGH / WPNAV_SPEED_DN
    land_slow_below_m: float = 10.0
    takeoff_speed_mps: float = 2.5  # PILOT_SPEED_UP / WPNAV_SPEED_UP
    waypoint_speed_mps: float = 10.0  # WPNAV_SPEED
    rtl_altitude_m: float = 15.0  # RTL_ALT
    max_altitude_m: float = 1000.0  # takeoff / setpoint altitude above home
    max_range_m: float = 50_000.0  # setpoint distance from the origin
    max_setpoint_speed_mps: float = 100.0
    max_setpoint_acceleration_mps2: float = 50.0
    refusal_text_interval_s: float = 2.0  # at most one STATUSTEXT per refusal kind per interval
    leader_retry_s: float = 1.0
    leader_max_tries: int = 10


@dataclass(frozen=True)
class BatteryState:
    voltage_v: float
    current_a: float
    remaining_fraction: float
    consumed_mah: float
    consumed_j: float
    time_remaining_s: float


@dataclass(frozen=True)
class _Command:
    """COMMAND_LONG or COMMAND_INT, normalised (params 5-7: x, y, z for COMMAND_INT)."""

    command: int
    params: tuple[float, ...]  # param1..param7
    frame: int | None  # COMMAND_INT only
    x: int | None
    y: int | None
    source_system: int
    source_component: int
    message: mavlink.MAVLink_message | None = None  # as received


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def _text(value: object) -> str:
    if isinstance(value, bytes | bytearray):
        return value.split(b"\x00", 1)[0].decode("ascii", "replace")
    return str(value).split("\x00", 1)[0]


class Autopilot:
    """One vehicle's MAVLink behaviour: modes, arming, commands, setpoints, failsafes, telemetry."""

    def __init__(
        self,
        *,
        sysid: int,
        index: int,
        count: int,
        config: AutopilotConfig,
        dynamics: FleetDynamics,
        origin: GeodeticOrigin,
        leader_requests: tuple[LeaderRequest, ...] = (),
    ) -> None:
        self.sysid = sysid
        self.index = index
        self.config = config
        self.dynamics = dynamics
        self.origin = origin
        self.outbox: list[mavlink.MAVLink_message] = []
        self.mode = Mode.STABILIZE
        self.armed = False
        self.landed = True
        self.guided = Guided.IDLE
        self.ekf_origin_enu = dynamics.position[index].copy()
        self.home_enu = dynamics.position[index].copy()
        self.comm_errors = 0
        self.mission_clock = MissionClock()
        self.speeds = SpeedBook()
        self.leader = LeaderSchedule(
            leader_requests, config.leader_retry_s, config.leader_max_tries
        )
        self.telemetry = TelemetrySchedule(
            config.telemetry.intervals(), phase=telemetry.phase_of(index, count)
        )
        self.gcs_failsafe: str | None = None  # None, "hold" or "land"
        self._gcs_last: Stamp | None = None
        self._gcs_failsafe_since: Stamp | None = None
        self._last_setpoint: Stamp | None = None
        self._setpoint_timed_out = False
        self._grounded_since: float | None = None
        self._landed_since: float | None = None
        self._takeoff_target_z = 0.0
        self._takeoff_started = 0.0
        self._rtl_phase = ""
        self._refusal_last: dict[str, float] = {}
        self._booted_announced = False
        self._previous_attitude: tuple[float, float, float, float] | None = None
        self.idle_on_ground()
        self._handlers: dict[str, Callable[[mavlink.MAVLink_message, Stamp], None]] = {
            "SET_MODE": self._on_set_mode,
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "COMMAND_ACK": self._on_command_ack,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_position_target_local,
            "SET_POSITION_TARGET_GLOBAL_INT": self._on_position_target_global,
            "NAMED_VALUE_INT": self._on_named_value_int,
            "TIMESYNC": self._on_timesync,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
            "MISSION_REQUEST_LIST": self._on_mission_request_list,
            "MISSION_COUNT": self._on_mission_count,
            "MISSION_CLEAR_ALL": self._on_mission_clear_all,
            "MISSION_ITEM_INT": self._on_mission_item,
            "MISSION_ITEM": self._on_mission_item,
        }
        self._commands: dict[int, Callable[[_Command, Stamp], int]] = {
            mavlink.MAV_CMD_DO_SET_MODE: self._cmd_set_mode,
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm_disarm,
            mavlink.MAV_CMD_NAV_TAKEOFF: self._cmd_takeoff,
            mavlink.MAV_CMD_NAV_LAND: self._cmd_land,
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: self._cmd_rtl,
            mavlink.MAV_CMD_DO_CHANGE_SPEED: self._cmd_change_speed,
            mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_set_message_interval,
            mavlink.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_message_interval,
            mavlink.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_request_autopilot_capabilities,
            mavlink.MAV_CMD_DO_REPOSITION: self._cmd_reposition,
        }

    # ------------------------------------------------------------------ state ----------
    def booting(self, stamp: Stamp) -> bool:
        return stamp.sim_s < self.config.boot_time_s

    def prearm_ok(self, stamp: Stamp) -> bool:
        return not self.booting(stamp) and self.battery().remaining_fraction > 0.1

    def airborne(self) -> bool:
        return self.armed and not self.landed

    def base_mode(self, stamp: Stamp) -> int:
        base = (
            mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
            | mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        )
        if self.mode != Mode.STABILIZE or self.booting(stamp):
            base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
        if self.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        return base

    def system_status(self, stamp: Stamp) -> int:
        if self.booting(stamp):
            return mavlink.MAV_STATE_BOOT
        if self.armed and self.gcs_failsafe is not None:
            return mavlink.MAV_STATE_CRITICAL
        if self.airborne():
            return mavlink.MAV_STATE_ACTIVE
        return mavlink.MAV_STATE_STANDBY

    def landed_state(self) -> int:
        if not self.airborne():
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self.mode == Mode.GUIDED and self.guided == Guided.TAKEOFF:
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if self.mode == Mode.LAND or (self.mode == Mode.RTL and self._rtl_phase == "land"):
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    def battery(self) -> BatteryState:
        airframe = self.dynamics.config.airframe
        used_j = float(self.dynamics.energy_used_j[self.index])
        nominal_v = 3.7 * airframe.battery_cells
        capacity_j = airframe.battery_capacity_mah * 3.6 * nominal_v
        remaining = max(0.0, 1.0 - used_j / capacity_j)
        voltage = airframe.battery_cells * (3.5 + 0.7 * remaining)
        power = float(self.dynamics.power_w[self.index])
        return BatteryState(
            voltage_v=voltage,
            current_a=power / voltage,
            remaining_fraction=remaining,
            consumed_mah=used_j / nominal_v / 3.6,
            consumed_j=used_j,
            time_remaining_s=remaining * capacity_j / max(power, 1e-3),
        )

    def fleet_speed(self, stamp: Stamp) -> float | None:
        return self.speeds.fleet_speed(stamp.sim_s, self.mission_clock)

    def attitude_rates(
        self, roll: float, pitch: float, yaw: float, stamp: Stamp
    ) -> tuple[float, float, float]:
        previous = self._previous_attitude
        self._previous_attitude = (stamp.sim_s, roll, pitch, yaw)
        if previous is None or stamp.sim_s <= previous[0]:
            return 0.0, 0.0, 0.0
        dt = stamp.sim_s - previous[0]
        dyaw = math.remainder(yaw - previous[3], 2 * math.pi)
        return (roll - previous[1]) / dt, (pitch - previous[2]) / dt, dyaw / dt

    # ------------------------------------------------------------------ output ---------
    def send(self, message: mavlink.MAVLink_message) -> None:
        self.outbox.append(message)

    def status_text(self, severity: int, text: str) -> None:
        log.info("sysid %d: %s", self.sysid, text)
        self.send(
            mavlink.MAVLink_statustext_message(severity, text[:50].encode("ascii", "replace"))
        )

    def _refuse(self, key: str, text: str, stamp: Stamp) -> None:
        """A rate-limited STATUSTEXT for refusals that can arrive at stream rate."""
        last = self._refusal_last.get(key)
        if last is None or stamp.sim_s - last >= self.config.refusal_text_interval_s:
            self._refusal_last[key] = stamp.sim_s
            self.status_text(mavlink.MAV_SEVERITY_WARNING, text)

    def _ack(self, cmd: _Command, result: int, result_param2: int = 0) -> None:
        self.send(
            mavlink.MAVLink_command_ack_message(
                cmd.command, result, 0, result_param2, cmd.source_system, cmd.source_component
            )
        )

    def emit(self, msg_id: int, snapshot: FleetSnapshot, stamp: Stamp) -> bool:
        """Build and queue message ``msg_id`` now; False if it cannot be produced."""
        builder = telemetry.BUILDERS.get(msg_id)
        if builder is None:
            return False
        message = builder(self, snapshot, stamp)
        if message is not None:
            self.send(message)
        return True

    def _expired(self, since: Stamp, timeout_s: float, now: Stamp) -> bool:
        floor = min(self.config.failsafe.wall_floor_s, timeout_s)
        return now.sim_s - since.sim_s >= timeout_s and now.wall_s - since.wall_s >= floor

    # ------------------------------------------------------------------ references -----
    def _set_limits(
        self, speed: float | None = None, climb: float | None = None, descent: float | None = None
    ) -> None:
        airframe = self.dynamics.config.airframe
        self.dynamics.set_limits(
            self.index,
            airframe.max_speed_mps if speed is None else speed,
            airframe.max_climb_mps if climb is None else climb,
            airframe.max_descent_mps if descent is None else descent,
        )

    def idle_on_ground(self) -> None:
        """On the ground: push down (motors at idle when armed), no yaw target."""
        point = self.dynamics.position[self.index].copy()
        point[2] = self.dynamics.ground_z[self.index] - 1.0
        self._set_limits(descent=self.config.land_speed_mps)
        self.dynamics.hold(self.index, point)
        self.dynamics.yaw_target[self.index] = np.nan

    def hold_here(self) -> None:
        """Brake to the stopping point and hold it."""
        self._set_limits()
        self.dynamics.hold(self.index, self.dynamics.stopping_point(self.index))
        self.dynamics.yaw_target[self.index] = self.dynamics.yaw[self.index]

    def _start_landing(self) -> None:
        point = self.dynamics.stopping_point(self.index)
        point[2] = self.dynamics.ground_z[self.index] - 1.0
        self._set_limits(descent=self._land_descent_rate())
        self.dynamics.hold(self.index, point)

    def _land_descent_rate(self) -> float:
        height = self.dynamics.estimated(self.index)[2] - self.dynamics.ground_z[self.index]
        if height > self.config.land_slow_below_m:
            return self.config.land_speed_high_mps
        return self.config.land_speed_mps

    # ------------------------------------------------------------------ modes ----------
    def set_mode(self, mode: int, stamp: Stamp) -> tuple[bool, str | None]:
        """Switch to ``mode``; (accepted, reason when refused)."""
        if mode not in Mode._value2member_map_:
            return False, f"No such mode {mode}"
        mode = Mode(mode)
        if mode == Mode.STABILIZE and self.airborne():
            return False, "Mode change failed: STABILIZE needs RC input"
        if mode == self.mode:
            return True, None
        self.mode = mode
        self._rtl_phase = ""
        if not self.airborne():
            if mode == Mode.GUIDED:
                self.guided = Guided.IDLE
            self.idle_on_ground()
            return True, None
        if mode == Mode.GUIDED:
            self.guided = Guided.HOLD
            self._last_setpoint = None
            self.hold_here()
        elif mode in (Mode.LOITER, Mode.BRAKE):
            self.hold_here()
        elif mode == Mode.LAND:
            self._start_landing()
        elif mode == Mode.RTL:
            self._rtl_phase = "climb"
            point = self.dynamics.stopping_point(self.index)
            point[2] = max(point[2], self.home_enu[2] + self.config.rtl_altitude_m)
            self._set_limits()
            self.dynamics.hold(self.index, point)
        return True, None

    def _arm(self, stamp: Stamp, force: bool) -> tuple[int, str | None]:
        if self.armed:
            return mavlink.MAV_RESULT_ACCEPTED, None
        if self.booting(stamp):
            return mavlink.MAV_RESULT_FAILED, "Arm: System not initialised"
        if not force:
            if self.mode not in ARMABLE_MODES:
                return mavlink.MAV_RESULT_FAILED, "Arm: Mode not armable"
            if self.battery().remaining_fraction <= 0.1:
                return mavlink.MAV_RESULT_FAILED, "Arm: Battery below minimum"
        self.armed = True
        self.landed = True
        self._landed_since = stamp.sim_s
        self.dynamics.motors_on[self.index] = True
        self.home_enu = self.dynamics.estimated(self.index)
        self.guided = Guided.IDLE
        self.idle_on_ground()
        self.status_text(mavlink.MAV_SEVERITY_INFO, "Arming motors")
        self.send(telemetry.home_position(self, FleetSnapshot(self.dynamics, self.origin), stamp))
        return mavlink.MAV_RESULT_ACCEPTED, None

    def disarm(self, stamp: Stamp, reason: str = "Disarming motors") -> None:
        if not self.armed:
            return
        self.armed = False
        self.dynamics.motors_on[self.index] = False
        self.guided = Guided.IDLE
        self._last_setpoint = None
        self.status_text(mavlink.MAV_SEVERITY_INFO, reason)

    # ------------------------------------------------------------------ tick -----------
    def tick(self, stamp: Stamp, snapshot: FleetSnapshot) -> None:
        """Advance the state machine to ``stamp`` and queue the telemetry that is due."""
        self.update(stamp)
        for msg_id in self.telemetry.due(stamp.sim_s):
            self.emit(msg_id, snapshot, stamp)

    def update(self, stamp: Stamp) -> None:
        """Advance the state machine (boot, ground contact, modes, failsafes, leader) to ``stamp``."""
        if not self._booted_announced and not self.booting(stamp):
            self._booted_announced = True
            self.status_text(mavlink.MAV_SEVERITY_INFO, "ArduPilot Ready")
            snapshot = FleetSnapshot(self.dynamics, self.origin)
            self.emit(mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, snapshot, stamp)
            self.emit(mavlink.MAVLINK_MSG_ID_HOME_POSITION, snapshot, stamp)
        self._update_ground_state(stamp)
        if self.armed and not self.landed:
            self._update_mode(stamp)
            self._update_setpoint_timeout(stamp)
        self._update_gcs_failsafe(stamp)
        if self.leader.active():
            self._update_leader(stamp)

    def clock_slipped(self, seconds: float, stamp: Stamp) -> None:
        """The simulation could not keep up and its clock slipped (the sim rate-limits this)."""
        self.status_text(
            mavlink.MAV_SEVERITY_WARNING, f"Sim: clock slipped {seconds:.2f} s (CPU overload)"
        )

    def _update_ground_state(self, stamp: Stamp) -> None:
        i = self.index
        grounded = bool(self.dynamics.grounded[i])
        if grounded:
            if self._grounded_since is None:
                self._grounded_since = stamp.sim_s
        else:
            self._grounded_since = None
        if not self.armed:
            self.landed = True
            return
        if self.landed:
            if not grounded and self.dynamics.position[i, 2] > self.dynamics.ground_z[i] + 0.2:
                self.landed = False
                self._landed_since = None
            elif self._landed_since is not None:
                waited = stamp.sim_s - self._landed_since
                delay = self.config.disarm_delay_s
                if self.mode in (Mode.LAND, Mode.RTL) or (delay > 0 and waited >= delay):
                    self.disarm(stamp)
            return
        taking_off = self.mode == Mode.GUIDED and self.guided == Guided.TAKEOFF
        if (
            self._grounded_since is not None
            and stamp.sim_s - self._grounded_since >= self.config.land_detect_s
            and not (taking_off and stamp.sim_s - self._takeoff_started < 3.0)
        ):
            self.landed = True
            self._landed_since = stamp.sim_s
            if self.mode == Mode.GUIDED:
                self.guided = Guided.IDLE
            self.idle_on_ground()
            if self.mode in (Mode.LAND, Mode.RTL):
                self.disarm(stamp, "Disarming motors")

    def _update_mode(self, stamp: Stamp) -> None:
        if not self.airborne():
            return
        i = self.index
        if self.mode == Mode.LAND or (self.mode == Mode.RTL and self._rtl_phase == "land"):
            self._set_limits(descent=self._land_descent_rate())
        elif self.mode == Mode.GUIDED and self.guided == Guided.TAKEOFF:
            if self.dynamics.estimated(i)[2] >= self._takeoff_target_z - 0.5:
                self.guided = Guided.HOLD
                self._set_limits()
        elif self.mode == Mode.RTL:
            est = self.dynamics.estimated(i)
            target = self.dynamics.reference_position[i]
            if self._rtl_phase == "climb" and abs(est[2] - target[2]) < 0.5:
                self._rtl_phase = "return"
                point = self.home_enu.copy()
                point[2] = target[2]
                self._set_limits(speed=self.config.waypoint_speed_mps)
                self.dynamics.hold(i, point)
            elif self._rtl_phase == "return":
                distance = float(np.hypot(*(est[:2] - self.home_enu[:2])))
                speed = float(np.hypot(*self.dynamics.velocity[i, :2]))
                if distance < 1.0 and speed < 0.5:
                    self._rtl_phase = "land"
                    self._start_landing()

    def _update_setpoint_timeout(self, stamp: Stamp) -> None:
        if (
            self.mode != Mode.GUIDED
            or self.guided != Guided.SETPOINTS
            or self._last_setpoint is None
        ):
            return
        timeout = self.config.failsafe.setpoint_timeout_s
        if self._expired(self._last_setpoint, timeout, stamp):
            self.guided = Guided.HOLD
            self._setpoint_timed_out = True
            self.hold_here()
            self.status_text(
                mavlink.MAV_SEVERITY_WARNING, f"Guided: no setpoint for {timeout:g} s, holding"
            )

    def _update_gcs_failsafe(self, stamp: Stamp) -> None:
        fs = self.config.failsafe
        if self._gcs_last is None or not self.armed:
            self.gcs_failsafe = None if not self.armed else self.gcs_failsafe
            return
        if not self._expired(self._gcs_last, fs.gcs_timeout_s, stamp):
            return
        if self.gcs_failsafe is None:
            self._gcs_failsafe_since = stamp
            if self.landed:
                self.gcs_failsafe = "land"
                self.disarm(stamp, "GCS Failsafe: disarming")
                return
            if self.mode in (Mode.LAND, Mode.RTL):  # already on its way down: carry on
                self.gcs_failsafe = "land"
                self.status_text(
                    mavlink.MAV_SEVERITY_CRITICAL, "GCS Failsafe: no heartbeat, landing"
                )
                return
            self.gcs_failsafe = "hold"
            self.set_mode(Mode.BRAKE, stamp)
            self.status_text(
                mavlink.MAV_SEVERITY_CRITICAL,
                f"GCS Failsafe: no heartbeat for {fs.gcs_timeout_s:g} s, holding",
            )
        elif self.gcs_failsafe == "hold" and self._gcs_failsafe_since is not None:
            if self._expired(self._gcs_failsafe_since, fs.gcs_hold_s, stamp):
                self.gcs_failsafe = "land"
                self.set_mode(Mode.LAND, stamp)
                self.status_text(mavlink.MAV_SEVERITY_CRITICAL, "GCS Failsafe: landing")

    def _update_leader(self, stamp: Stamp) -> None:
        now = self.mission_clock.now(stamp.sim_s)
        for sequence, speed in self.leader.due(now):
            self.status_text(
                mavlink.MAV_SEVERITY_INFO, f"Leader: requesting {speed:g} m/s (seq {sequence})"
            )
            self._send_leader_request(sequence, speed, stamp)
        again, given_up = self.leader.resend_due(
            stamp.sim_s, stamp.wall_s, self.config.failsafe.wall_floor_s
        )
        for entry in again:
            self._send_leader_request(entry.sequence, entry.speed_mps, stamp)
        for sequence in given_up:
            self.status_text(
                mavlink.MAV_SEVERITY_WARNING, f"Leader: speed request {sequence} not acknowledged"
            )

    def _send_leader_request(self, sequence: int, speed: float, stamp: Stamp) -> None:
        self.send(
            mavlink.MAVLink_command_int_message(
                self.config.failsafe.gcs_system,
                0,
                SPEED_CHANGE_FRAME,
                SPEED_CHANGE_COMMAND,
                0,
                0,
                *encode_speed_change(speed, 0, sequence),
            )
        )
        self.leader.sent(sequence, speed, stamp.sim_s, stamp.wall_s)

    # ------------------------------------------------------------------ input ----------
    def handle(self, message: mavlink.MAVLink_message, stamp: Stamp) -> None:
        """React to one decoded message (already known to be valid MAVLink)."""
        if message.get_srcSystem() == self.config.failsafe.gcs_system and (
            self._gcs_last is not None or message.get_type() == "HEARTBEAT"
        ):
            self._gcs_alive(stamp)
        handler = self._handlers.get(message.get_type())
        if handler is None:
            return
        if message.get_srcSystem() == self.sysid:
            return  # our own echo
        target = getattr(message, "target_system", 0)
        if target not in (0, self.sysid):
            return
        component = getattr(message, "target_component", 0)
        if component not in (0, AUTOPILOT_COMPONENT):
            return
        handler(message, stamp)

    def _gcs_alive(self, stamp: Stamp) -> None:
        """The GCS failsafe is armed by the GCS's first HEARTBEAT; from then on any valid
        message from its system id proves it alive (CONTRACTS.md, MAVLink), so that on a lossy
        link its 10 Hz setpoints keep the failsafe off when five 1 Hz heartbeats are lost."""
        self._gcs_last = stamp
        if self.gcs_failsafe is not None:
            self.gcs_failsafe = None
            self._gcs_failsafe_since = None
            if self.armed:
                self.status_text(mavlink.MAV_SEVERITY_INFO, "GCS Failsafe Cleared")

    def _on_set_mode(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        if not msg.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return
        accepted, reason = self.set_mode(int(msg.custom_mode), stamp)
        if not accepted and reason:
            self.status_text(mavlink.MAV_SEVERITY_WARNING, reason)

    def _on_named_value_int(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        if msg.get_srcSystem() != self.config.failsafe.gcs_system:
            return
        mission_time = decode_mission_time(msg)
        if mission_time is not None:
            self.mission_clock.sync(mission_time, stamp.sim_s)

    def _on_timesync(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        if msg.tc1 == 0:
            self.send(mavlink.MAVLink_timesync_message(int(stamp.sim_s * 1e9), msg.ts1))

    def _on_command_ack(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        if msg.get_srcSystem() != self.config.failsafe.gcs_system:
            return
        if msg.command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            self.leader.acknowledge(int(msg.result_param2))

    # -- parameters and missions: the little a GCS needs to connect -------------------------
    def parameters(self) -> list[tuple[str, float, int]]:
        fs = self.config.failsafe
        cfg = self.config
        airframe = self.dynamics.config.airframe
        real, integer = mavlink.MAV_PARAM_TYPE_REAL32, mavlink.MAV_PARAM_TYPE_INT32
        return [
            ("SYSID_THISMAV", self.sysid, integer),
            ("SYSID_MYGCS", fs.gcs_system, integer),
            ("FRAME_CLASS", 1, integer),
            ("FRAME_TYPE", 1, integer),
            ("FS_GCS_ENABLE", 5, integer),
            ("FS_GCS_TIMEOUT", fs.gcs_timeout_s, real),
            ("GUID_TIMEOUT", fs.setpoint_timeout_s, real),
            ("DISARM_DELAY", cfg.disarm_delay_s, integer),
            ("WPNAV_SPEED", cfg.waypoint_speed_mps * 100, real),
            ("WPNAV_SPEED_UP", cfg.takeoff_speed_mps * 100, real),
            ("WPNAV_SPEED_DN", cfg.land_speed_high_mps * 100, real),
            ("WPNAV_ACCEL", airframe.max_acceleration_mps2 * 100, real),
            ("LAND_SPEED", cfg.land_speed_mps * 100, real),
            ("RTL_ALT", cfg.rtl_altitude_m * 100, real),
            ("BATT_CAPACITY", airframe.battery_capacity_mah, integer),
        ]

    def _param_value(self, index: int) -> mavlink.MAVLink_message:
        params = self.parameters()
        name, value, kind = params[index]
        return mavlink.MAVLink_param_value_message(
            name.encode(), float(value), kind, len(params), index
        )

    def _on_param_request_list(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        for index in range(len(self.parameters())):
            self.send(self._param_value(index))

    def _param_index(self, name: str, index: int) -> int | None:
        params = self.parameters()
        if name:
            for i, (param, _, _) in enumerate(params):
                if param == name:
                    return i
            return None
        return index if 0 <= index < len(params) else None

    def _on_param_request_read(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        index = self._param_index(_text(msg.param_id), int(msg.param_index))
        if index is not None:
            self.send(self._param_value(index))

    def _on_param_set(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        index = self._param_index(_text(msg.param_id), -1)
        if index is not None:  # read-only: echo the value in force
            self.send(self._param_value(index))
            self._refuse("param", f"Param {_text(msg.param_id)} is read-only", stamp)

    def _on_mission_request_list(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        self.send(
            mavlink.MAVLink_mission_count_message(
                msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type
            )
        )

    def _on_mission_count(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        self.send(
            mavlink.MAVLink_mission_ack_message(
                msg.get_srcSystem(),
                msg.get_srcComponent(),
                mavlink.MAV_MISSION_UNSUPPORTED,
                msg.mission_type,
            )
        )

    def _on_mission_clear_all(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        self.send(
            mavlink.MAVLink_mission_ack_message(
                msg.get_srcSystem(),
                msg.get_srcComponent(),
                mavlink.MAV_MISSION_ACCEPTED,
                msg.mission_type,
            )
        )

    def _on_mission_item(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        """A guided-mode waypoint (``current`` = 2, as MAVProxy's ``guided`` and QGC send)."""
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        if msg.current != 2:
            self.send(
                mavlink.MAVLink_mission_ack_message(
                    *source, mavlink.MAV_MISSION_UNSUPPORTED, msg.mission_type
                )
            )
            return
        scale = 1e-7 if msg.get_type() == "MISSION_ITEM_INT" else 1.0
        point = self._global_point(msg.frame, msg.x * scale, msg.y * scale, float(msg.z))
        if isinstance(point, str) or not self._goto(point, None, stamp):
            reason = point if isinstance(point, str) else "Guided: not flying in GUIDED"
            self._refuse("goto", reason, stamp)
            self.send(
                mavlink.MAVLink_mission_ack_message(
                    *source, mavlink.MAV_MISSION_ERROR, msg.mission_type
                )
            )
            return
        self.send(
            mavlink.MAVLink_mission_ack_message(
                *source, mavlink.MAV_MISSION_ACCEPTED, msg.mission_type
            )
        )

    # -- commands ----------------------------------------------------------------------
    def _on_command_long(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        params = (
            msg.param1,
            msg.param2,
            msg.param3,
            msg.param4,
            msg.param5,
            msg.param6,
            msg.param7,
        )
        cmd = _Command(
            msg.command, params, None, None, None, msg.get_srcSystem(), msg.get_srcComponent(), msg
        )
        self._dispatch(cmd, stamp)

    def _on_command_int(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        cmd = _Command(
            msg.command,
            params,
            msg.frame,
            msg.x,
            msg.y,
            msg.get_srcSystem(),
            msg.get_srcComponent(),
            msg,
        )
        self._dispatch(cmd, stamp)

    def _dispatch(self, cmd: _Command, stamp: Stamp) -> None:
        handler = self._commands.get(cmd.command)
        if handler is None:
            self._ack(cmd, mavlink.MAV_RESULT_UNSUPPORTED)
            return
        result = handler(cmd, stamp)
        if result >= 0:
            speed = decode_speed_change(cmd.message) if cmd.message is not None else None
            self._ack(cmd, result, speed.sequence if speed is not None else 0)
        # a negative result means the handler already acknowledged

    def _cmd_set_mode(self, cmd: _Command, stamp: Stamp) -> int:
        base, custom = cmd.params[0], cmd.params[1]
        if not _finite(base, custom) or not int(base) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            self.status_text(
                mavlink.MAV_SEVERITY_WARNING, "Mode change failed: custom mode flag not set"
            )
            return mavlink.MAV_RESULT_FAILED
        accepted, reason = self.set_mode(int(custom), stamp)
        if not accepted:
            self.status_text(mavlink.MAV_SEVERITY_WARNING, reason or "Mode change failed")
            return mavlink.MAV_RESULT_FAILED
        return mavlink.MAV_RESULT_ACCEPTED

    def _cmd_arm_disarm(self, cmd: _Command, stamp: Stamp) -> int:
        action, magic = cmd.params[0], cmd.params[1]
        if action == 1.0:
            result, reason = self._arm(stamp, force=magic == FORCE_ARM_MAGIC)
            if reason:
                self.status_text(mavlink.MAV_SEVERITY_CRITICAL, reason)
            return result
        if action == 0.0:
            if not self.armed:
                return mavlink.MAV_RESULT_ACCEPTED
            if self.airborne() and magic != FORCE_DISARM_MAGIC:
                self.status_text(mavlink.MAV_SEVERITY_CRITICAL, "Disarm: vehicle is flying")
                return mavlink.MAV_RESULT_FAILED
            self.disarm(stamp)
            return mavlink.MAV_RESULT_ACCEPTED
        self.status_text(mavlink.MAV_SEVERITY_WARNING, "Arm: param1 must be 0 or 1")
        return mavlink.MAV_RESULT_DENIED

    def _cmd_takeoff(self, cmd: _Command, stamp: Stamp) -> int:
        altitude = cmd.params[6]
        if not _finite(altitude) or not 0.0 < altitude <= self.config.max_altitude_m:
            self.status_text(
                mavlink.MAV_SEVERITY_WARNING,
                f"Takeoff: altitude must be in (0, {self.config.max_altitude_m:g}] m",
            )
            return mavlink.MAV_RESULT_DENIED
        if self.mode != Mode.GUIDED:
            self.status_text(mavlink.MAV_SEVERITY_WARNING, "Takeoff: not in GUIDED mode")
            return mavlink.MAV_RESULT_FAILED
        if not self.armed:
            self.status_text(mavlink.MAV_SEVERITY_WARNING, "Takeoff: not armed")
            return mavlink.MAV_RESULT_FAILED
        if not self.landed:
            self.status_text(mavlink.MAV_SEVERITY_WARNING, "Takeoff: already flying")
            return mavlink.MAV_RESULT_FAILED
        i = self.index
        point = self.dynamics.estimated(i)
        point[2] = self.home_enu[2] + altitude
        self._takeoff_target_z = point[2]
        self._takeoff_started = stamp.sim_s
        self.guided = Guided.TAKEOFF
        self.landed = False
        self._landed_since = None
        self._last_setpoint = None
        self._set_limits(climb=self.config.takeoff_speed_mps)
        self.dynamics.hold(i, point)
        self.dynamics.yaw_target[i] = self.dynamics.yaw[i]
        return mavlink.MAV_RESULT_ACCEPTED

    def _cmd_land(self, cmd: _Command, stamp: Stamp) -> int:
        self.set_mode(Mode.LAND, stamp)
        return mavlink.MAV_RESULT_ACCEPTED

    def _cmd_rtl(self, cmd: _Command, stamp: Stamp) -> int:
        self.set_mode(Mode.RTL, stamp)
        return mavlink.MAV_RESULT_ACCEPTED

    def _cmd_change_speed(self, cmd: _Command, stamp: Stamp) -> int:
        command = decode_speed_change(cmd.message)
        speed = command.speed
        if (
            not _finite(speed)
            or not (speed >= 0.0 or speed in (-1.0, -2.0))
            or speed > self.config.max_setpoint_speed_mps
        ):
            self.status_text(mavlink.MAV_SEVERITY_WARNING, "Speed: param2 must be a speed in m/s")
            return mavlink.MAV_RESULT_DENIED
        if speed < 0:
            return mavlink.MAV_RESULT_ACCEPTED  # -1 / -2: no change / default
        sequence = command.sequence
        effective = command.effective_s
        change = SpeedChange(cmd.source_system, sequence, effective, float(speed), stamp.sim_s)
        if self.speeds.record(change):
            log.info(
                "sysid %d: speed change seq %d: %.2f m/s at %s",
                self.sysid,
                sequence,
                speed,
                effective,
            )
        return mavlink.MAV_RESULT_ACCEPTED

    def _cmd_set_message_interval(self, cmd: _Command, stamp: Stamp) -> int:
        msg_id, interval_us = cmd.params[0], cmd.params[1]
        if not _finite(msg_id, interval_us):
            return mavlink.MAV_RESULT_DENIED
        msg_id = int(msg_id)
        if not self.telemetry.knows(msg_id):
            return mavlink.MAV_RESULT_FAILED
        if interval_us == -1:
            self.telemetry.set_interval(msg_id, 0.0, stamp.sim_s)
        elif interval_us == 0:
            self.telemetry.set_interval(msg_id, None, stamp.sim_s)
        elif interval_us > 0:
            self.telemetry.set_interval(msg_id, interval_us / 1e6, stamp.sim_s)
        else:
            return mavlink.MAV_RESULT_DENIED
        return mavlink.MAV_RESULT_ACCEPTED

    def _cmd_get_message_interval(self, cmd: _Command, stamp: Stamp) -> int:
        msg_id = cmd.params[0]
        if not _finite(msg_id) or not self.telemetry.knows(int(msg_id)):
            return mavlink.MAV_RESULT_FAILED
        self._ack(cmd, mavlink.MAV_RESULT_ACCEPTED)
        interval = self.telemetry.interval(int(msg_id))
        self.send(
            mavlink.MAVLink_message_interval_message(
                int(msg_id), int(interval * 1e6) if interval > 0 else -1
            )
        )
        return -1

    def _cmd_request_message(self, cmd: _Command, stamp: Stamp) -> int:
        msg_id = cmd.params[0]
        if not _finite(msg_id) or int(msg_id) not in telemetry.BUILDERS:
            return mavlink.MAV_RESULT_FAILED
        self._ack(cmd, mavlink.MAV_RESULT_ACCEPTED)
        self.emit(int(msg_id), FleetSnapshot(self.dynamics, self.origin), stamp)
        return -1

    def _cmd_request_autopilot_capabilities(self, cmd: _Command, stamp: Stamp) -> int:
        self._ack(cmd, mavlink.MAV_RESULT_ACCEPTED)
        self.emit(
            mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
            FleetSnapshot(self.dynamics, self.origin),
            stamp,
        )
        return -1

    def _cmd_reposition(self, cmd: _Command, stamp: Stamp) -> int:
        """MAV_CMD_DO_REPOSITION: fly to a point in GUIDED (switching to GUIDED if flying)."""
        speed = cmd.params[0]
        if cmd.frame is None:  # COMMAND_LONG: degrees, relative altitude
            point = self._global_point(
                mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, cmd.params[4], cmd.params[5], cmd.params[6]
            )
        else:
            point = self._global_point(
                cmd.frame, cmd.params[4] * 1e-7, cmd.params[5] * 1e-7, cmd.params[6]
            )
        if isinstance(point, str):
            self.status_text(mavlink.MAV_SEVERITY_WARNING, point)
            return mavlink.MAV_RESULT_DENIED
        if not self.airborne():
            self.status_text(mavlink.MAV_SEVERITY_WARNING, "Reposition: not flying")
            return mavlink.MAV_RESULT_FAILED
        if self.mode != Mode.GUIDED:
            self.set_mode(Mode.GUIDED, stamp)
        self._goto(point, speed if _finite(speed) and speed > 0 else None, stamp)
        return mavlink.MAV_RESULT_ACCEPTED

    def _goto(self, point: np.ndarray, speed: float | None, stamp: Stamp) -> bool:
        if self.mode != Mode.GUIDED or not self.airborne():
            return False
        self.guided = Guided.GOTO
        self._set_limits(speed=speed or self.config.waypoint_speed_mps)
        self.dynamics.hold(self.index, point)
        self.dynamics.yaw_target[self.index] = np.nan
        return True

    # -- setpoints ---------------------------------------------------------------------
    def _global_point(self, frame: int, lat: float, lon: float, alt: float) -> np.ndarray | str:
        """A global position in ``frame`` -> local ENU, or the reason it is refused."""
        if frame in (
            mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT,
            mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
        ):
            return f"Guided: terrain frame {frame} not supported"
        if frame not in (
            mavlink.MAV_FRAME_GLOBAL,
            mavlink.MAV_FRAME_GLOBAL_INT,
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        ):
            return f"Guided: frame {frame} not supported"
        if not _finite(lat, lon, alt) or abs(lat) > 90.0 or abs(lon) > 180.0:
            return "Guided: setpoint latitude/longitude/altitude invalid"
        relative = frame in (
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        )
        amsl = alt + (self.origin.altitude_m + self.home_enu[2] if relative else 0.0)
        if abs(amsl - self.origin.altitude_m) > 100_000.0:
            return "Guided: setpoint altitude out of range"
        point = self.origin.to_local(lat, lon, amsl)
        return self._check_point(point)

    def _check_point(self, point: np.ndarray) -> np.ndarray | str:
        if not np.all(np.isfinite(point)):
            return "Guided: setpoint position is not finite"
        if float(np.hypot(point[0], point[1])) > self.config.max_range_m:
            return "Guided: setpoint too far from home"
        height = point[2] - self.home_enu[2]
        if height > self.config.max_altitude_m or height < -self.config.max_altitude_m:
            return "Guided: setpoint altitude out of range"
        return point

    def _on_position_target_local(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        frame = msg.coordinate_frame
        if frame not in (
            mavlink.MAV_FRAME_LOCAL_NED,
            mavlink.MAV_FRAME_LOCAL_OFFSET_NED,
            mavlink.MAV_FRAME_BODY_NED,
            mavlink.MAV_FRAME_BODY_OFFSET_NED,
        ):
            self._setpoint_refused(f"Guided: frame {frame} not supported", stamp)
            return
        mask = int(msg.type_mask)
        checked = self._check_mask(mask)
        if isinstance(checked, str):
            self._setpoint_refused(checked, stamp)
            return
        use_pos, use_vel, use_acc = checked
        i = self.index
        yaw = float(self.dynamics.yaw[i])
        body = frame in (mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED)

        def to_enu(values: tuple[float, float, float]) -> np.ndarray:
            ned = np.array(values, dtype=float)
            return ned_to_enu(rotate_body_to_ned(ned, yaw) if body else ned)

        position = None
        if use_pos:
            if not _finite(msg.x, msg.y, msg.z):
                self._setpoint_refused("Guided: setpoint position is not finite", stamp)
                return
            offset = to_enu((msg.x, msg.y, msg.z))
            base = (
                self.ekf_origin_enu
                if frame == mavlink.MAV_FRAME_LOCAL_NED
                else self.dynamics.estimated(i)
            )
            position = self._check_point(base + offset)
            if isinstance(position, str):
                self._setpoint_refused(position, stamp)
                return
        self._apply_setpoint(
            position,
            to_enu((msg.vx, msg.vy, msg.vz)) if use_vel else None,
            to_enu((msg.afx, msg.afy, msg.afz)) if use_acc else None,
            mask,
            msg.yaw,
            stamp,
        )

    def _on_position_target_global(self, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
        mask = int(msg.type_mask)
        checked = self._check_mask(mask)
        if isinstance(checked, str):
            self._setpoint_refused(checked, stamp)
            return
        use_pos, use_vel, use_acc = checked
        position = None
        if use_pos:
            position = self._global_point(
                msg.coordinate_frame, msg.lat_int * 1e-7, msg.lon_int * 1e-7, msg.alt
            )
            if isinstance(position, str):
                self._setpoint_refused(position, stamp)
                return
        elif msg.coordinate_frame in (
            mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT,
            mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
        ):
            self._setpoint_refused(
                f"Guided: terrain frame {msg.coordinate_frame} not supported", stamp
            )
            return
        self._apply_setpoint(
            position,
            ned_to_enu((msg.vx, msg.vy, msg.vz)) if use_vel else None,
            ned_to_enu((msg.afx, msg.afy, msg.afz)) if use_acc else None,
            mask,
            msg.yaw,
            stamp,
        )

    @staticmethod
    def _check_mask(mask: int) -> tuple[bool, bool, bool] | str:
        if mask & mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET:
            return "Guided: force setpoints not supported"
        groups = [(mask >> shift) & 0b111 for shift in (0, 3, 6)]
        if any(group not in (0, 0b111) for group in groups):
            return f"Guided: type_mask {mask} ignores only some axes"
        use = tuple(group == 0 for group in groups)
        if not any(use):
            return "Guided: setpoint has no position, velocity or acceleration"
        return use[0], use[1], use[2]

    def _setpoint_refused(self, reason: str, stamp: Stamp) -> None:
        if self.mode == Mode.GUIDED:  # outside GUIDED setpoints are ignored silently
            self._refuse(re.sub(r"\d+", "#", reason), reason, stamp)  # one limiter per kind

    def _apply_setpoint(
        self,
        position: np.ndarray | None,
        velocity: np.ndarray | None,
        acceleration: np.ndarray | None,
        mask: int,
        yaw: float,
        stamp: Stamp,
    ) -> None:
        if self.mode != Mode.GUIDED or not self.armed:
            return  # ignored silently, like ArduCopter
        limit_v = self.config.max_setpoint_speed_mps
        limit_a = self.config.max_setpoint_acceleration_mps2
        if velocity is not None and (
            not np.all(np.isfinite(velocity)) or np.abs(velocity).max() > limit_v
        ):
            self._setpoint_refused("Guided: setpoint velocity invalid", stamp)
            return
        if acceleration is not None and (
            not np.all(np.isfinite(acceleration)) or np.abs(acceleration).max() > limit_a
        ):
            self._setpoint_refused("Guided: setpoint acceleration invalid", stamp)
            return
        if self.landed and self.guided != Guided.TAKEOFF:
            return  # like ArduCopter: a landed vehicle needs MAV_CMD_NAV_TAKEOFF first
        i = self.index
        horizon = min(self.config.failsafe.setpoint_timeout_s, MAX_EXTRAPOLATION_S)
        self._set_limits()
        self.dynamics.set_reference(
            i, position, velocity, acceleration, horizon_s=horizon, time_s=stamp.sim_s
        )
        if not mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE and _finite(yaw):
            self.dynamics.yaw_target[i] = yaw
        else:
            self.dynamics.yaw_target[i] = np.nan
        if self._setpoint_timed_out:
            self._setpoint_timed_out = False
            self.status_text(mavlink.MAV_SEVERITY_INFO, "Guided: setpoints resumed")
        self.guided = Guided.SETPOINTS
        self._last_setpoint = stamp
