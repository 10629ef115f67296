"""COMMAND_LONG and COMMAND_INT: normalised to one :class:`Command`, dispatched to the handler of
its MAV_CMD and acknowledged (COMMAND_ACK UNSUPPORTED for a command without one, as ArduCopter
answers a command it does not know; e.g. MAV_CMD_DO_CHANGE_ALTITUDE, which ArduCopter 4.7
implements only in Plane).

``MAV_CMD_DO_SET_MODE`` is acknowledged (``SET_MODE`` is not); arming is refused outside
STABILIZE, GUIDED and LOITER with ``Arm: Mode not armable`` and ACK FAILED;
``MAV_CMD_NAV_TAKEOFF`` needs GUIDED, armed and landed (COMMAND_INT: frame
GLOBAL_RELATIVE_ALT); ``MAV_CMD_MISSION_START`` is :mod:`vehicles.autopilot.auto`'s;
``MAV_CMD_CONDITION_YAW`` turns the vehicle in GUIDED, AUTO and RTL
(``GCS_MAVLINK_Copter::handle_MAV_CMD_CONDITION_YAW``); ``MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN``
param1 1 (or 3) reboots a disarmed vehicle after its ACK (``GCS_MAVLINK::handle_preflight_reboot``:
FAILED while armed, UNSUPPORTED for other param1). Every refusal carries a STATUSTEXT reason. A
handler returns the MAV_RESULT to acknowledge, or -1 when it acknowledged itself (before the
message it answers with, or before rebooting).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.messages import decode_speed_change
from vehicles import telemetry
from vehicles.autopilot import auto, modes, setpoints, speed
from vehicles.autopilot.setpoints import finite
from vehicles.autopilot.types import Guided, Mode, Stamp
from vehicles.telemetry import FleetSnapshot

if TYPE_CHECKING:
    from vehicles.autopilot.core import Autopilot

FORCE_ARM_MAGIC = 2989
FORCE_DISARM_MAGIC = 21196


@dataclass(frozen=True)
class Command:
    """COMMAND_LONG or COMMAND_INT, normalised (params 5-7: x, y, z for COMMAND_INT)."""

    command: int
    params: tuple[float, ...]  # param1..param7
    frame: int | None  # COMMAND_INT only
    x: int | None
    y: int | None
    source_system: int
    source_component: int
    message: mavlink.MAVLink_message | None = None  # as received


# ---------------------------------------------------------------------- messages ------------
def on_command_long(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    params = (
        msg.param1,
        msg.param2,
        msg.param3,
        msg.param4,
        msg.param5,
        msg.param6,
        msg.param7,
    )
    cmd = Command(
        msg.command, params, None, None, None, msg.get_srcSystem(), msg.get_srcComponent(), msg
    )
    dispatch(ap, cmd, stamp)


def on_command_int(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
    cmd = Command(
        msg.command,
        params,
        msg.frame,
        msg.x,
        msg.y,
        msg.get_srcSystem(),
        msg.get_srcComponent(),
        msg,
    )
    dispatch(ap, cmd, stamp)


def dispatch(ap: Autopilot, cmd: Command, stamp: Stamp) -> None:
    """Run the command's handler and acknowledge its result (a speed change's ACK echoes its
    sequence number in ``result_param2``)."""
    handler = COMMANDS.get(cmd.command)
    if handler is None:
        ack(ap, cmd, mavlink.MAV_RESULT_UNSUPPORTED)
        return
    result = handler(ap, cmd, stamp)
    if result >= 0:
        change = decode_speed_change(cmd.message) if cmd.message is not None else None
        ack(ap, cmd, result, change.sequence if change is not None else 0)
    # a negative result means the handler already acknowledged


def ack(ap: Autopilot, cmd: Command, result: int, result_param2: int = 0) -> None:
    ap.send(
        mavlink.MAVLink_command_ack_message(
            cmd.command, result, 0, result_param2, cmd.source_system, cmd.source_component
        )
    )


# ---------------------------------------------------------------------- handlers ------------
def set_mode_command(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_DO_SET_MODE: param1 base mode (custom mode flag set), param2 custom mode."""
    base, custom = cmd.params[0], cmd.params[1]
    if not finite(base, custom) or not int(base) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Mode change failed: custom mode flag not set")
        return mavlink.MAV_RESULT_FAILED
    accepted, reason = modes.set_mode(ap, int(custom), stamp)
    if not accepted:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, reason or "Mode change failed")
        return mavlink.MAV_RESULT_FAILED
    return mavlink.MAV_RESULT_ACCEPTED


def arm_disarm(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_COMPONENT_ARM_DISARM: param1 1 arm, 0 disarm; param2 the force magic."""
    action, magic = cmd.params[0], cmd.params[1]
    if action == 1.0:
        result, reason = modes.arm(ap, stamp, force=magic == FORCE_ARM_MAGIC)
        if reason:
            ap.status_text(mavlink.MAV_SEVERITY_CRITICAL, reason)
        return result
    if action == 0.0:
        if not ap.armed:
            return mavlink.MAV_RESULT_ACCEPTED
        if ap.airborne() and magic != FORCE_DISARM_MAGIC:
            ap.status_text(mavlink.MAV_SEVERITY_CRITICAL, "Disarm: vehicle is flying")
            return mavlink.MAV_RESULT_FAILED
        modes.disarm(ap, stamp)
        return mavlink.MAV_RESULT_ACCEPTED
    ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Arm: param1 must be 0 or 1")
    return mavlink.MAV_RESULT_DENIED


def takeoff(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_NAV_TAKEOFF: climb to param7 m above home (GUIDED, armed, landed); it also
    auto-arms the vehicle (``Mode::do_user_takeoff``)."""
    if cmd.frame is not None and cmd.frame != mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Takeoff: frame must be GLOBAL_RELATIVE_ALT")
        return mavlink.MAV_RESULT_DENIED
    altitude = cmd.params[6]
    if not finite(altitude) or not 0.0 < altitude <= ap.config.max_altitude_m:
        ap.status_text(
            mavlink.MAV_SEVERITY_WARNING,
            f"Takeoff: altitude must be in (0, {ap.config.max_altitude_m:g}] m",
        )
        return mavlink.MAV_RESULT_DENIED
    if ap.mode != Mode.GUIDED:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Takeoff: not in GUIDED mode")
        return mavlink.MAV_RESULT_FAILED
    if not ap.armed:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Takeoff: not armed")
        return mavlink.MAV_RESULT_FAILED
    if not ap.landed:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Takeoff: already flying")
        return mavlink.MAV_RESULT_FAILED
    i = ap.index
    point = ap.dynamics.estimated(i)
    point[2] = ap.home_enu[2] + altitude
    ap.takeoff_target_z = point[2]
    ap.takeoff_started_s = stamp.sim_s
    ap.guided = Guided.TAKEOFF
    ap.auto_armed = True
    ap.landed = False
    ap.landed_since = None
    ap.last_setpoint = None
    modes.set_limits(ap, climb=ap.config.takeoff_speed_mps)
    ap.dynamics.hold(i, point)
    ap.dynamics.yaw_target[i] = ap.dynamics.yaw[i]
    return mavlink.MAV_RESULT_ACCEPTED


def _mode_command(ap: Autopilot, mode: Mode, stamp: Stamp) -> int:
    """A command that is a mode change (ArduCopter: FAILED if the mode refuses)."""
    accepted, reason = modes.set_mode(ap, mode, stamp)
    if not accepted:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, reason or "Mode change failed")
        return mavlink.MAV_RESULT_FAILED
    return mavlink.MAV_RESULT_ACCEPTED


def land(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    return _mode_command(ap, Mode.LAND, stamp)


def return_to_launch(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    return _mode_command(ap, Mode.RTL, stamp)


def loiter_unlimited(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_NAV_LOITER_UNLIM: LOITER."""
    return _mode_command(ap, Mode.LOITER, stamp)


#: Modes whose yaw CONDITION_YAW sets (ArduCopter's ``auto_yaw`` users among ours).
_AUTO_YAW_MODES = (Mode.GUIDED, Mode.AUTO, Mode.RTL)


def condition_yaw(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_CONDITION_YAW: param1 heading (deg, 0-360), param3 direction of a relative turn
    (-1 counter-clockwise), param4 1 relative / 0 absolute. The turn rate is the airframe's
    (param2 is not honoured). Accepted on the ground too, where it does nothing, as in
    ArduCopter."""
    angle, _, direction, relative = cmd.params[:4]
    if not (finite(angle) and 0.0 <= angle <= 360.0 and relative in (0.0, 1.0)):
        ap.status_text(
            mavlink.MAV_SEVERITY_WARNING, "Yaw: param1 must be in [0, 360] deg, param4 0 or 1"
        )
        return mavlink.MAV_RESULT_FAILED
    if ap.airborne() and ap.mode in _AUTO_YAW_MODES:
        i = ap.index
        heading = math.radians(angle)
        if relative == 1.0:
            heading = float(ap.dynamics.yaw[i]) + (-heading if direction < 0 else heading)
        ap.dynamics.yaw_target[i] = heading % (2.0 * math.pi)
    return mavlink.MAV_RESULT_ACCEPTED


def reboot(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: param1 1 (or 3, reboot to the bootloader, which in
    simulation is a reboot) reboots a disarmed autopilot after the ACK."""
    if ap.armed:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Reboot: disarm first")
        return mavlink.MAV_RESULT_FAILED
    if cmd.params[0] not in (1.0, 3.0):
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Reboot: only param1 1 (reboot) is supported")
        return mavlink.MAV_RESULT_UNSUPPORTED
    ack(ap, cmd, mavlink.MAV_RESULT_ACCEPTED)
    ap.reboot(stamp)
    return -1


def set_message_interval(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_SET_MESSAGE_INTERVAL: param2 us, -1 off, 0 back to the default."""
    msg_id, interval_us = cmd.params[0], cmd.params[1]
    if not finite(msg_id, interval_us):
        return mavlink.MAV_RESULT_DENIED
    msg_id = int(msg_id)
    if not ap.telemetry.knows(msg_id):
        return mavlink.MAV_RESULT_FAILED
    if interval_us == -1:
        ap.telemetry.set_interval(msg_id, 0.0, stamp.sim_s)
    elif interval_us == 0:
        ap.telemetry.set_interval(msg_id, None, stamp.sim_s)
    elif interval_us > 0:
        ap.telemetry.set_interval(msg_id, interval_us / 1e6, stamp.sim_s)
    else:
        return mavlink.MAV_RESULT_DENIED
    return mavlink.MAV_RESULT_ACCEPTED


def get_message_interval(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_GET_MESSAGE_INTERVAL: ACK, then MESSAGE_INTERVAL (-1 when off)."""
    msg_id = cmd.params[0]
    if not finite(msg_id) or not ap.telemetry.knows(int(msg_id)):
        return mavlink.MAV_RESULT_FAILED
    ack(ap, cmd, mavlink.MAV_RESULT_ACCEPTED)
    interval = ap.telemetry.interval(int(msg_id))
    ap.send(
        mavlink.MAVLink_message_interval_message(
            int(msg_id), int(interval * 1e6) if interval > 0 else -1
        )
    )
    return -1


def request_message(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_REQUEST_MESSAGE: ACK, then the message (any the telemetry can build)."""
    msg_id = cmd.params[0]
    if not finite(msg_id) or int(msg_id) not in telemetry.BUILDERS:
        return mavlink.MAV_RESULT_FAILED
    ack(ap, cmd, mavlink.MAV_RESULT_ACCEPTED)
    ap.emit(int(msg_id), FleetSnapshot(ap.dynamics, ap.origin), stamp)
    return -1


def request_autopilot_capabilities(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: ACK, then AUTOPILOT_VERSION."""
    ack(ap, cmd, mavlink.MAV_RESULT_ACCEPTED)
    ap.emit(
        mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
        FleetSnapshot(ap.dynamics, ap.origin),
        stamp,
    )
    return -1


def reposition(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_DO_REPOSITION: fly to a point in GUIDED (switching to GUIDED if flying)."""
    speed_mps = cmd.params[0]
    if cmd.frame is None:  # COMMAND_LONG: degrees, relative altitude
        point = setpoints.global_point(
            ap, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, cmd.params[4], cmd.params[5], cmd.params[6]
        )
    else:
        point = setpoints.global_point(
            ap, cmd.frame, cmd.params[4] * 1e-7, cmd.params[5] * 1e-7, cmd.params[6]
        )
    if isinstance(point, str):
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, point)
        return mavlink.MAV_RESULT_DENIED
    if not ap.airborne():
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Reposition: not flying")
        return mavlink.MAV_RESULT_FAILED
    if ap.mode != Mode.GUIDED:
        modes.set_mode(ap, Mode.GUIDED, stamp)
    setpoints.goto(ap, point, speed_mps if finite(speed_mps) and speed_mps > 0 else None, stamp)
    return mavlink.MAV_RESULT_ACCEPTED


#: The commands the autopilot implements, by MAV_CMD.
COMMANDS: dict[int, Callable[[Autopilot, Command, Stamp], int]] = {
    mavlink.MAV_CMD_DO_SET_MODE: set_mode_command,
    mavlink.MAV_CMD_COMPONENT_ARM_DISARM: arm_disarm,
    mavlink.MAV_CMD_NAV_TAKEOFF: takeoff,
    mavlink.MAV_CMD_NAV_LAND: land,
    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: return_to_launch,
    mavlink.MAV_CMD_DO_CHANGE_SPEED: speed.change_speed,
    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: set_message_interval,
    mavlink.MAV_CMD_GET_MESSAGE_INTERVAL: get_message_interval,
    mavlink.MAV_CMD_REQUEST_MESSAGE: request_message,
    mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: request_autopilot_capabilities,
    mavlink.MAV_CMD_DO_REPOSITION: reposition,
    mavlink.MAV_CMD_MISSION_START: auto.mission_start,
    mavlink.MAV_CMD_NAV_LOITER_UNLIM: loiter_unlimited,
    mavlink.MAV_CMD_CONDITION_YAW: condition_yaw,
    mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: reboot,
}
