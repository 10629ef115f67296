"""Telemetry of one simulated vehicle: what it streams, how often, and the message contents.

Each message builder is a function of the autopilot's frozen
:class:`~vehicles.autopilot.AutopilotStatus` (mode, arming, battery, home...), the per-tick
:class:`FleetSnapshot` (the vehicles' physical state) and the :class:`~vehicles.autopilot.Stamp`,
and returns a pymavlink message (ArduCopter field conventions: NED velocities in cm/s,
altitudes in mm, angles in centidegrees); it cannot change the autopilot. Rates are in
simulated time and can be changed with ``MAV_CMD_SET_MESSAGE_INTERVAL`` (no I/O here: the sim
sends).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.geodesy import Origin
from fleetwire.messages import MISSION_TIME_NAME, encode_mission_time
from fleetwire.modes import COPTER_MODE
from vehicles.dynamics import GRAVITY_MPS2, FleetDynamics

if TYPE_CHECKING:
    from vehicles.autopilot.status import AutopilotStatus
    from vehicles.autopilot.types import Stamp

_AUTO = COPTER_MODE["AUTO"]
MAX_MESSAGE_RATE_HZ = 50.0
UINT16_MAX = 65535
INT16_MAX = 32767
FLIGHT_SW_VERSION = 0x040500FF  # reported as ArduCopter 4.5.0 (official) for GCS compatibility
CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
)
#: SYS_STATUS words of ArduCopter 4.7 SITL ready to fly (tests/sitl ardupilot-session.jsonl:
#: present 0x5371fc2f, enabled 0x5361fc2f, health 0x4771fc2f, plus PREARM_CHECK when armable).
ARDUCOPTER_SENSORS_PRESENT = 0x5371FC2F
ARDUCOPTER_SENSORS_ENABLED = 0x5361FC2F
ARDUCOPTER_SENSORS_HEALTH = 0x4771FC2F
#: What the simulation has not (an RC receiver, a terrain database, on-board logging): not
#: present nor enabled, and never unhealthy (health bits set, as ArduCopter sets PROXIMITY's).
NOT_SIMULATED = (
    mavlink.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
    | mavlink.MAV_SYS_STATUS_TERRAIN
    | mavlink.MAV_SYS_STATUS_LOGGING
)
#: The geofence is present but not enabled (FENCE_ENABLE 0) and healthy: nothing is breached.
SENSORS_PRESENT = ARDUCOPTER_SENSORS_PRESENT & ~NOT_SIMULATED
SENSORS_ENABLED = ARDUCOPTER_SENSORS_ENABLED & ~NOT_SIMULATED
SENSORS_HEALTH = ARDUCOPTER_SENSORS_HEALTH & ~mavlink.MAV_SYS_STATUS_PREARM_CHECK


@dataclass(frozen=True)
class TelemetryRates:
    """Default stream rates in Hz of simulated time (0: only on request)."""

    position_hz: float = 10.0  # GLOBAL_POSITION_INT, LOCAL_POSITION_NED
    attitude_hz: float = 10.0  # ATTITUDE
    truth_hz: float = 10.0  # SIM_STATE: the true (noise-free) state, for the GCS's metrics
    status_hz: float = 1.0  # SYS_STATUS, BATTERY_STATUS, EXTENDED_SYS_STATE, VFR_HUD,
    #                         MISSION_CURRENT
    home_hz: float = 0.2  # HOME_POSITION (also sent on arming and on request)

    def intervals(self) -> dict[int, float]:
        """Default interval in simulated seconds per message id (0: off)."""

        def every(hz: float) -> float:
            return 1.0 / min(hz, MAX_MESSAGE_RATE_HZ) if hz > 0 else 0.0

        return {
            mavlink.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
            mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: every(self.position_hz),
            mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: every(self.position_hz),
            mavlink.MAVLINK_MSG_ID_ATTITUDE: every(self.attitude_hz),
            mavlink.MAVLINK_MSG_ID_SIM_STATE: every(self.truth_hz),
            mavlink.MAVLINK_MSG_ID_SYS_STATUS: every(self.status_hz),
            mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: every(self.status_hz),
            mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: every(self.status_hz),
            mavlink.MAVLINK_MSG_ID_VFR_HUD: every(self.status_hz),
            mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: every(self.status_hz),
            mavlink.MAVLINK_MSG_ID_HOME_POSITION: every(self.home_hz),
            mavlink.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT: 1.0,  # FLEET_SPD, once known
            mavlink.MAVLINK_MSG_ID_NAMED_VALUE_INT: 1.0,  # MSN_TIME, once synchronised
            mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: 0.0,
            mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 0.0,
            mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: 0.0,
        }


def phase_of(index: int, count: int) -> float:
    """Fraction of an interval by which vehicle ``index`` is offset: large fleets send in
    up to 5 staggered groups (smaller bursts), small ones together (fewer conversions)."""
    groups = min(5, max(1, count // 20))
    return (index % groups) / groups


class TelemetrySchedule:
    """Per-message intervals and next due times of one vehicle, in simulated seconds."""

    def __init__(self, defaults: dict[int, float], phase: float) -> None:
        self._defaults = dict(defaults)
        self._intervals = dict(defaults)
        self._phase = phase % 1.0
        self._due = {msg_id: self._phase * every for msg_id, every in defaults.items() if every > 0}
        self._next = min(self._due.values(), default=float("inf"))

    def knows(self, msg_id: int) -> bool:
        return msg_id in self._defaults

    def interval(self, msg_id: int) -> float:
        return self._intervals.get(msg_id, 0.0)

    def set_interval(self, msg_id: int, interval_s: float | None, now_s: float) -> None:
        """None: back to the default; 0: off; otherwise every ``interval_s`` (rate-capped)."""
        every = self._defaults[msg_id] if interval_s is None else interval_s
        if every > 0:
            every = max(every, 1.0 / MAX_MESSAGE_RATE_HZ)
            self._due[msg_id] = now_s + self._phase * every
        else:
            self._due.pop(msg_id, None)
        self._intervals[msg_id] = every
        self._next = min(self._due.values(), default=float("inf"))

    def due(self, now_s: float) -> list[int]:
        """Message ids due at ``now_s``; their next due time moves on by one interval."""
        if now_s + 1e-9 < self._next:
            return []
        out = []
        for msg_id, when in self._due.items():
            if now_s + 1e-9 >= when:
                out.append(msg_id)
                every = self._intervals[msg_id]
                nxt = when + every
                self._due[msg_id] = nxt if nxt > now_s else now_s + every
        self._next = min(self._due.values())
        return out


class FleetSnapshot:
    """The fleet at one control tick as the telemetry reads it: geodetic and estimated positions
    and attitudes, each computed at most once per vehicle and on demand (plain floats).

    The sim calls :meth:`prefetch` with the vehicles whose due messages need them, so the
    geodetic conversion runs vectorised once per tick; anything else is converted one by one.
    """

    def __init__(self, dynamics: FleetDynamics, origin: Origin) -> None:
        self.dynamics = dynamics
        self.origin = origin
        self._estimated: dict[int, tuple[float, float, float]] = {}
        self._true: dict[int, tuple[float, float, float]] = {}
        self._estimated_enu: dict[int, tuple[float, float, float]] = {}
        self._attitude: dict[int, tuple[float, float, float]] = {}

    @classmethod
    def for_due(
        cls, dynamics: FleetDynamics, origin: Origin, due_lists: list[list[int]]
    ) -> FleetSnapshot:
        """The snapshot of a tick whose due messages are `due_lists` (per vehicle), with the
        geodetic positions they need already converted in one call."""
        estimated: list[int] = []
        true: list[int] = []
        for k, due in enumerate(due_lists):
            if due:  # most ticks send nothing: the per-tick hot path of the simulator
                if not NEEDS_ESTIMATED_GEODETIC.isdisjoint(due):
                    estimated.append(k)
                if not NEEDS_TRUE_GEODETIC.isdisjoint(due):
                    true.append(k)
        snapshot = cls(dynamics, origin)
        snapshot.prefetch(estimated, true)
        return snapshot

    def prefetch(self, estimated: list[int], true: list[int]) -> None:
        """Convert the listed vehicles' estimated and true positions in one vectorised call."""
        if not estimated and not true:
            return
        dyn = self.dynamics
        enu = np.concatenate(
            [dyn.position[estimated] + dyn.navigation_error[estimated], dyn.position[true]]
        )
        lat, lon, alt = self.origin.to_geodetic(enu)
        points = list(zip(lat.tolist(), lon.tolist(), alt.tolist(), strict=True))
        self._estimated.update(zip(estimated, points[: len(estimated)], strict=True))
        self._true.update(zip(true, points[len(estimated) :], strict=True))
        local = map(tuple, enu[: len(estimated)].tolist())
        self._estimated_enu.update(zip(estimated, local, strict=True))

    def estimated_enu(self, index: int) -> tuple[float, float, float]:
        """Vehicle ``index``'s estimated position, local ENU metres."""
        point = self._estimated_enu.get(index)
        if point is None:
            point = self._estimated_enu[index] = tuple(self.dynamics.estimated(index).tolist())
        return point

    def estimated_geodetic(self, index: int) -> tuple[float, float, float]:
        if index not in self._estimated:
            self.prefetch([index], [])
        return self._estimated[index]

    def true_geodetic(self, index: int) -> tuple[float, float, float]:
        if index not in self._true:
            self.prefetch([], [index])
        return self._true[index]

    def attitude(self, index: int) -> tuple[float, float, float]:
        """Vehicle ``index``'s roll, pitch and yaw (rad, see :func:`attitude_of`)."""
        attitude = self._attitude.get(index)
        if attitude is None:
            attitude = self._attitude[index] = attitude_of(self.dynamics, index)
        return attitude


def _boot_ms(stamp: Stamp) -> int:
    return int(stamp.sim_s * 1000.0) & 0xFFFFFFFF


def _deg_e7(value: float) -> int:
    return int(round(value * 1e7))


def _clamp_int(value: float, low: int, high: int) -> int:
    """``value`` rounded and clamped to [low, high]; 0 if it is not finite."""
    if not math.isfinite(value):
        return 0
    rounded = round(value)
    return low if rounded < low else high if rounded > high else int(rounded)


def attitude_of(dynamics: FleetDynamics, index: int) -> tuple[float, float, float]:
    """Roll, pitch (rad) that produce the vehicle's thrust acceleration, and its yaw (NED)."""
    east, north, up = dynamics.thrust_acceleration[index].tolist()
    yaw = float(dynamics.yaw[index])
    up = up + GRAVITY_MPS2
    forward = east * math.sin(yaw) + north * math.cos(yaw)
    right = east * math.cos(yaw) - north * math.sin(yaw)
    pitch = -math.atan2(forward, up)
    roll = math.atan2(right, math.hypot(forward, up))
    return roll, pitch, yaw


def _quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def heartbeat(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_QUADROTOR,
        mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
        status.base_mode,
        status.mode,
        status.system_status,
        3,
    )


def sys_status(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    battery = status.battery
    health = SENSORS_HEALTH
    if status.prearm_ok:
        health |= mavlink.MAV_SYS_STATUS_PREARM_CHECK
    return mavlink.MAVLink_sys_status_message(
        SENSORS_PRESENT,
        SENSORS_ENABLED,
        health,
        0,
        _clamp_int(battery.voltage_v * 1000, 0, UINT16_MAX - 1),
        _clamp_int(battery.current_a * 100, 0, INT16_MAX),
        _clamp_int(battery.remaining_fraction * 100, 0, 100),
        0,
        min(status.comm_errors, UINT16_MAX),
        0,
        0,
        0,
        0,
    )


def battery_status(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    battery = status.battery
    voltages = [_clamp_int(battery.voltage_v * 1000, 0, UINT16_MAX - 1)] + [UINT16_MAX] * 9
    remaining = battery.remaining_fraction
    charge_state = (
        mavlink.MAV_BATTERY_CHARGE_STATE_OK
        if remaining > 0.3
        else mavlink.MAV_BATTERY_CHARGE_STATE_LOW
        if remaining > 0.15
        else mavlink.MAV_BATTERY_CHARGE_STATE_CRITICAL
    )
    return mavlink.MAVLink_battery_status_message(
        0,
        mavlink.MAV_BATTERY_FUNCTION_ALL,
        mavlink.MAV_BATTERY_TYPE_LIPO,
        INT16_MAX,
        voltages,
        _clamp_int(battery.current_a * 100, 0, INT16_MAX),
        _clamp_int(battery.consumed_mah, 0, 2**31 - 1),
        _clamp_int(battery.consumed_j / 100.0, 0, 2**31 - 1),
        _clamp_int(remaining * 100, 0, 100),
        _clamp_int(battery.time_remaining_s, 0, 2**31 - 1),
        charge_state,
    )


def global_position_int(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    i = status.index
    dyn = snap.dynamics
    lat, lon, alt = snap.estimated_geodetic(i)
    up = snap.estimated_enu(i)[2]
    v_east, v_north, v_up = dyn.velocity[i].tolist()
    heading = math.degrees(float(dyn.yaw[i])) % 360.0
    return mavlink.MAVLink_global_position_int_message(
        _boot_ms(stamp),
        _deg_e7(lat),
        _deg_e7(lon),
        _clamp_int(alt * 1000, -(2**31), 2**31 - 1),
        _clamp_int((up - status.home_enu[2]) * 1000, -(2**31), 2**31 - 1),
        _clamp_int(v_north * 100, -32768, 32767),
        _clamp_int(v_east * 100, -32768, 32767),
        _clamp_int(-v_up * 100, -32768, 32767),
        _clamp_int(heading * 100, 0, 35999),
    )


def local_position_ned(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    i = status.index
    east, north, up = snap.estimated_enu(i)
    origin_east, origin_north, origin_up = status.ekf_origin_enu
    v_east, v_north, v_up = snap.dynamics.velocity[i].tolist()
    return mavlink.MAVLink_local_position_ned_message(
        _boot_ms(stamp),
        north - origin_north,
        east - origin_east,
        -(up - origin_up),
        v_north,
        v_east,
        -v_up,
    )


def attitude(status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp) -> mavlink.MAVLink_message:
    """ATTITUDE; its rates are the differences from the last ATTITUDE reported (the autopilot
    notes each one it sends)."""
    roll, pitch, yaw = snap.attitude(status.index)
    previous = status.reported_attitude
    if previous is None or stamp.sim_s <= previous[0]:
        rates = (0.0, 0.0, 0.0)
    else:
        dt = stamp.sim_s - previous[0]
        dyaw = math.remainder(yaw - previous[3], 2 * math.pi)
        rates = ((roll - previous[1]) / dt, (pitch - previous[2]) / dt, dyaw / dt)
    return mavlink.MAVLink_attitude_message(_boot_ms(stamp), roll, pitch, yaw, *rates)


def sim_state(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    i = status.index
    dyn = snap.dynamics
    lat, lon, alt = snap.true_geodetic(i)
    roll, pitch, yaw = snap.attitude(i)
    a_east, a_north, a_up = dyn.thrust_acceleration[i].tolist()
    v_east, v_north, v_up = dyn.velocity[i].tolist()
    dist = dyn.config.disturbances
    return mavlink.MAVLink_sim_state_message(
        *_quaternion(roll, pitch, yaw),
        roll,
        pitch,
        yaw,
        a_north,
        a_east,
        -a_up - GRAVITY_MPS2,
        0.0,
        0.0,
        0.0,
        lat,
        lon,
        alt,
        dist.navigation_sigma_m,
        dist.navigation_sigma_vertical_m,
        v_north,
        v_east,
        -v_up,
        _deg_e7(lat),
        _deg_e7(lon),
    )


def extended_sys_state(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_extended_sys_state_message(
        mavlink.MAV_VTOL_STATE_MC, status.landed_state
    )


def vfr_hud(status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp) -> mavlink.MAVLink_message:
    i = status.index
    dyn = snap.dynamics
    vel = dyn.velocity[i]
    air = vel - dyn.wind[i]
    _, _, alt = snap.estimated_geodetic(i)
    throttle = 0.0
    if dyn.motors_on[i]:
        throttle = 50.0 * (float(dyn.thrust_acceleration[i][2]) + GRAVITY_MPS2) / GRAVITY_MPS2
    return mavlink.MAVLink_vfr_hud_message(
        float(np.hypot(air[0], air[1])),
        float(np.hypot(vel[0], vel[1])),
        _clamp_int(math.degrees(float(dyn.yaw[i])) % 360.0, 0, 359),
        _clamp_int(throttle, 0, 100),
        alt,
        float(vel[2]),
    )


def home_position(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    lat, lon, alt = snap.origin.to_geodetic(status.home_enu)
    east, north, up = status.home_enu
    origin_east, origin_north, origin_up = status.ekf_origin_enu
    return mavlink.MAVLink_home_position_message(
        _deg_e7(float(lat[0])),
        _deg_e7(float(lon[0])),
        _clamp_int(float(alt[0]) * 1000, -(2**31), 2**31 - 1),
        north - origin_north,
        east - origin_east,
        -(up - origin_up),
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        0.0,
        0.0,
        int(stamp.sim_s * 1e6),
    )


def gps_global_origin(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    lat, lon, alt = snap.origin.to_geodetic(status.ekf_origin_enu)
    return mavlink.MAVLink_gps_global_origin_message(
        _deg_e7(float(lat[0])),
        _deg_e7(float(lon[0])),
        _clamp_int(float(alt[0]) * 1000, -(2**31), 2**31 - 1),
        int(stamp.sim_s * 1e6),
    )


def gps_raw_int(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    i = status.index
    lat, lon, alt = snap.estimated_geodetic(i)
    vel = snap.dynamics.velocity[i]
    dist = snap.dynamics.config.disturbances
    course = math.degrees(math.atan2(float(vel[0]), float(vel[1]))) % 360.0
    return mavlink.MAVLink_gps_raw_int_message(
        int(stamp.sim_s * 1e6),
        mavlink.GPS_FIX_TYPE_3D_FIX,
        _deg_e7(lat),
        _deg_e7(lon),
        _clamp_int(alt * 1000, -(2**31), 2**31 - 1),
        80,
        120,
        _clamp_int(float(np.hypot(vel[0], vel[1])) * 100, 0, UINT16_MAX - 1),
        _clamp_int(course * 100, 0, 35999),
        12,
        _clamp_int(alt * 1000, -(2**31), 2**31 - 1),
        _clamp_int(dist.navigation_sigma_m * 1000, 0, 2**31 - 1),
        _clamp_int(dist.navigation_sigma_vertical_m * 1000, 0, 2**31 - 1),
        100,
        0,
        0,
    )


def position_target_local_ned(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    i = status.index
    dyn = snap.dynamics
    pos, vel, acc = dyn.reference_now(i)
    rel = pos - np.array(status.ekf_origin_enu)
    mask = 0b110000000000  # yaw and yaw rate not reported
    if not dyn.use_position[i]:
        mask |= 0b111
    if not dyn.use_velocity[i]:
        mask |= 0b111000
    if not dyn.use_acceleration[i]:
        mask |= 0b111000000
    return mavlink.MAVLink_position_target_local_ned_message(
        _boot_ms(stamp),
        mavlink.MAV_FRAME_LOCAL_NED,
        mask,
        float(rel[1]),
        float(rel[0]),
        -float(rel[2]),
        float(vel[1]),
        float(vel[0]),
        -float(vel[2]),
        float(acc[1]),
        float(acc[0]),
        -float(acc[2]),
        0.0,
        0.0,
    )


def fleet_speed(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message | None:
    speed = status.fleet_speed_mps
    if speed is None:
        return None
    return mavlink.MAVLink_named_value_float_message(_boot_ms(stamp), b"FLEET_SPD", speed)


def mission_time(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message | None:
    now = status.mission_time_s
    if now is None:
        return None
    return mavlink.MAVLink_named_value_int_message(
        _boot_ms(stamp), MISSION_TIME_NAME, encode_mission_time(now)
    )


def mission_current(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    """MISSION_CURRENT (``GCS_MAVLINK::send_mission_current``): the navigation item AUTO is at,
    the number of items without home, the mission's state and whether AUTO flies it."""
    mode = (1 if status.mode == _AUTO else 2) if status.mission_count > 1 else 0
    return mavlink.MAVLink_mission_current_message(
        status.mission_nav, max(status.mission_count - 1, 0), status.mission_state, mode
    )


def autopilot_version(
    status: AutopilotStatus, snap: FleetSnapshot, stamp: Stamp
) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_autopilot_version_message(
        CAPABILITIES,
        FLIGHT_SW_VERSION,
        0,
        0,
        0,
        list(b"fleetln\x00"),
        [0] * 8,
        [0] * 8,
        0,
        0,
        status.sysid,
        [0] * 18,
    )


#: A message builder: a function of the status, the snapshot and the moment (None: nothing to
#: send yet, e.g. FLEET_SPD before any speed change).
Builder = Callable[["AutopilotStatus", FleetSnapshot, "Stamp"], "mavlink.MAVLink_message | None"]

NEEDS_ESTIMATED_GEODETIC = frozenset(
    {
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
        mavlink.MAVLINK_MSG_ID_VFR_HUD,
        mavlink.MAVLINK_MSG_ID_GPS_RAW_INT,
    }
)
NEEDS_TRUE_GEODETIC = frozenset({mavlink.MAVLINK_MSG_ID_SIM_STATE})

BUILDERS: dict[int, Builder] = {
    mavlink.MAVLINK_MSG_ID_HEARTBEAT: heartbeat,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: sys_status,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: battery_status,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: global_position_int,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: local_position_ned,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: attitude,
    mavlink.MAVLINK_MSG_ID_SIM_STATE: sim_state,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: extended_sys_state,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: vfr_hud,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: home_position,
    mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: gps_global_origin,
    mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: gps_raw_int,
    mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: position_target_local_ned,
    mavlink.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT: fleet_speed,
    mavlink.MAVLINK_MSG_ID_NAMED_VALUE_INT: mission_time,
    mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION: autopilot_version,
    mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: mission_current,
}
