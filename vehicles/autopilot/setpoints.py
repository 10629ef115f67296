"""Guided targets: SET_POSITION_TARGET_LOCAL_NED and SET_POSITION_TARGET_GLOBAL_INT decoded
(frames, type masks), checked and applied to the position controller, and the go-to points of
DO_REPOSITION and guided mission items.

Type masks are read as ArduCopter reads them (``GCS_MAVLINK_Copter::handle_message_set_position
_target_local_ned``): a group (position, velocity, acceleration) with any of its three bits set is
ignored as a whole; the force bit is refused only when acceleration is used; the combinations
followed are position (+ velocity (+ acceleration)), velocity (+ acceleration), acceleration and
position only; position with acceleration but no velocity, and a target with nothing, are refused.
A position-only target is flown to and held like a DO_REPOSITION point (it never times out, as
ArduCopter's position targets); a target with velocity or acceleration is extrapolated and
trips the setpoint timeout (GUID_TIMEOUT, :mod:`vehicles.autopilot.failsafes`) if the stream stops.

Position targets outside GUIDED are ignored silently (like ArduCopter); in GUIDED a refused one
says why in a rate-limited STATUSTEXT (one limiter per kind of reason).
"""

from __future__ import annotations

import math
import re
from typing import TYPE_CHECKING

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.messages import SETPOINT_EXTRAPOLATION_S
from vehicles.autopilot import modes
from vehicles.autopilot.types import Guided, Mode, Stamp
from vehicles.frames import ned_to_enu, rotate_body_to_ned

if TYPE_CHECKING:
    from vehicles.autopilot.core import Autopilot


_LOCAL_FRAMES = (
    mavlink.MAV_FRAME_LOCAL_NED,
    mavlink.MAV_FRAME_LOCAL_OFFSET_NED,
    mavlink.MAV_FRAME_BODY_NED,
    mavlink.MAV_FRAME_BODY_OFFSET_NED,
)
_BODY_FRAMES = (mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED)
_TERRAIN_FRAMES = (mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)
_GLOBAL_FRAMES = (
    mavlink.MAV_FRAME_GLOBAL,
    mavlink.MAV_FRAME_GLOBAL_INT,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
)
_RELATIVE_FRAMES = (
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
)


def finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def _within(vector: np.ndarray, limit: float) -> bool:
    """Every component finite and at most ``limit`` in magnitude."""
    values = vector.tolist()
    return all(map(math.isfinite, values)) and max(map(abs, values)) <= limit


# ---------------------------------------------------------------------- points --------------
def global_point(ap: Autopilot, frame: int, lat: float, lon: float, alt: float) -> np.ndarray | str:
    """A global position in ``frame`` -> local ENU, or the reason it is refused."""
    if frame in _TERRAIN_FRAMES:
        return f"Guided: terrain frame {frame} not supported"
    if frame not in _GLOBAL_FRAMES:
        return f"Guided: frame {frame} not supported"
    if not finite(lat, lon, alt) or abs(lat) > 90.0 or abs(lon) > 180.0:
        return "Guided: setpoint latitude/longitude/altitude invalid"
    relative = frame in _RELATIVE_FRAMES
    amsl = alt + (ap.origin.alt + ap.home_enu[2] if relative else 0.0)
    if abs(amsl - ap.origin.alt) > 100_000.0:
        return "Guided: setpoint altitude out of range"
    point = ap.origin.to_local(lat, lon, amsl)
    return check_point(ap, point)


def check_point(ap: Autopilot, point: np.ndarray) -> np.ndarray | str:
    """``point`` (local ENU) if it is finite, within range and altitude, else the reason."""
    if not np.all(np.isfinite(point)):
        return "Guided: setpoint position is not finite"
    if float(np.hypot(point[0], point[1])) > ap.config.max_range_m:
        return "Guided: setpoint too far from home"
    height = point[2] - ap.home_enu[2]
    if height > ap.config.max_altitude_m or height < -ap.config.max_altitude_m:
        return "Guided: setpoint altitude out of range"
    return point


#: The groups of a type_mask: position, velocity, acceleration (any bit set ignores the group).
_POSITION_BITS = 0b000000111
_VELOCITY_BITS = 0b000111000
_ACCELERATION_BITS = 0b111000000


def check_mask(mask: int) -> tuple[bool, bool, bool] | str:
    """(use position, use velocity, use acceleration) of a type_mask, read as ArduCopter reads
    it, or the reason it is refused (force with acceleration, position and acceleration without
    velocity, nothing used)."""
    use_pos = not mask & _POSITION_BITS
    use_vel = not mask & _VELOCITY_BITS
    use_acc = not mask & _ACCELERATION_BITS
    if mask & mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET and use_acc:
        return "Guided: force setpoints not supported"
    if not (use_pos or use_vel or use_acc):
        return "Guided: setpoint has no position, velocity or acceleration"
    if use_pos and use_acc and not use_vel:
        return "Guided: position and acceleration need velocity"
    return use_pos, use_vel, use_acc


# ---------------------------------------------------------------------- messages ------------
def on_position_target_local(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    """SET_POSITION_TARGET_LOCAL_NED in LOCAL_NED (from the EKF origin), LOCAL_OFFSET_NED (from
    the vehicle), BODY_NED or BODY_OFFSET_NED (offsets and vectors turned by the heading)."""
    frame = msg.coordinate_frame
    if frame not in _LOCAL_FRAMES:
        setpoint_refused(ap, f"Guided: frame {frame} not supported", stamp)
        return
    mask = int(msg.type_mask)
    checked = check_mask(mask)
    if isinstance(checked, str):
        setpoint_refused(ap, checked, stamp)
        return
    use_pos, use_vel, use_acc = checked
    i = ap.index
    yaw = float(ap.dynamics.yaw[i])
    body = frame in _BODY_FRAMES

    def to_enu(values: tuple[float, float, float]) -> np.ndarray:
        ned = np.array(values, dtype=float)
        if body and finite(*values):  # (not finite: refused below, unrotated)
            ned = rotate_body_to_ned(ned, yaw)
        return ned_to_enu(ned)

    position = None
    if use_pos:
        if not finite(msg.x, msg.y, msg.z):
            setpoint_refused(ap, "Guided: setpoint position is not finite", stamp)
            return
        offset = to_enu((msg.x, msg.y, msg.z))
        base = (
            ap.ekf_origin_enu if frame == mavlink.MAV_FRAME_LOCAL_NED else ap.dynamics.estimated(i)
        )
        position = check_point(ap, base + offset)
        if isinstance(position, str):
            setpoint_refused(ap, position, stamp)
            return
    apply_setpoint(
        ap,
        position,
        to_enu((msg.vx, msg.vy, msg.vz)) if use_vel else None,
        to_enu((msg.afx, msg.afy, msg.afz)) if use_acc else None,
        mask,
        msg.yaw,
        stamp,
    )


def on_position_target_global(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    """SET_POSITION_TARGET_GLOBAL_INT in a global frame (AMSL or relative to home; no terrain)."""
    mask = int(msg.type_mask)
    checked = check_mask(mask)
    if isinstance(checked, str):
        setpoint_refused(ap, checked, stamp)
        return
    use_pos, use_vel, use_acc = checked
    position = None
    if use_pos:
        position = global_point(
            ap, msg.coordinate_frame, msg.lat_int * 1e-7, msg.lon_int * 1e-7, msg.alt
        )
        if isinstance(position, str):
            setpoint_refused(ap, position, stamp)
            return
    elif msg.coordinate_frame in _TERRAIN_FRAMES:
        setpoint_refused(ap, f"Guided: terrain frame {msg.coordinate_frame} not supported", stamp)
        return
    apply_setpoint(
        ap,
        position,
        ned_to_enu((msg.vx, msg.vy, msg.vz)) if use_vel else None,
        ned_to_enu((msg.afx, msg.afy, msg.afz)) if use_acc else None,
        mask,
        msg.yaw,
        stamp,
    )


def setpoint_refused(ap: Autopilot, reason: str, stamp: Stamp) -> None:
    if ap.mode == Mode.GUIDED:  # outside GUIDED setpoints are ignored silently
        ap.refuse(re.sub(r"\d+", "#", reason), reason, stamp)  # one limiter per kind


def apply_setpoint(
    ap: Autopilot,
    position: np.ndarray | None,
    velocity: np.ndarray | None,
    acceleration: np.ndarray | None,
    mask: int,
    yaw: float,
    stamp: Stamp,
) -> None:
    """Follow a checked setpoint (GUIDED, armed, flying or taking off): a position alone is
    flown to and held (no timeout); velocity and acceleration feed-forwards are extrapolated for
    at most the setpoint timeout, which then applies."""
    if ap.mode != Mode.GUIDED or not ap.armed:
        return  # ignored silently, like ArduCopter
    if velocity is not None and not _within(velocity, ap.config.max_setpoint_speed_mps):
        setpoint_refused(ap, "Guided: setpoint velocity invalid", stamp)
        return
    if acceleration is not None and not _within(
        acceleration, ap.config.max_setpoint_acceleration_mps2
    ):
        setpoint_refused(ap, "Guided: setpoint acceleration invalid", stamp)
        return
    if ap.landed and ap.guided != Guided.TAKEOFF:
        return  # like ArduCopter: a landed vehicle needs MAV_CMD_NAV_TAKEOFF first
    i = ap.index
    if velocity is None and acceleration is None:
        ap.guided = Guided.GOTO  # ArduCopter's set_destination: no GUID_TIMEOUT
        ap.last_setpoint = None
        modes.set_limits(ap, speed=ap.config.waypoint_speed_mps)
        ap.dynamics.hold(i, position)
    else:
        horizon = min(ap.config.failsafe.setpoint_timeout_s, SETPOINT_EXTRAPOLATION_S)
        modes.set_limits(ap)
        ap.dynamics.set_reference(
            i, position, velocity, acceleration, horizon_s=horizon, time_s=stamp.sim_s
        )
        ap.guided = Guided.SETPOINTS
        ap.last_setpoint = stamp
    if not mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE and finite(yaw):
        ap.dynamics.yaw_target[i] = yaw
    else:
        ap.dynamics.yaw_target[i] = np.nan
    if ap.setpoint_timed_out:
        ap.setpoint_timed_out = False
        ap.status_text(mavlink.MAV_SEVERITY_INFO, "Guided: setpoints resumed")


def goto(ap: Autopilot, point: np.ndarray, speed: float | None, stamp: Stamp) -> bool:
    """Fly to ``point`` in GUIDED (no setpoint timeout); False unless flying in GUIDED."""
    if ap.mode != Mode.GUIDED or not ap.airborne():
        return False
    ap.guided = Guided.GOTO
    modes.set_limits(ap, speed=speed or ap.config.waypoint_speed_mps)
    ap.dynamics.hold(ap.index, point)
    ap.dynamics.yaw_target[ap.index] = np.nan
    return True
