"""Flight modes and the ground state of one autopilot: mode changes (SET_MODE, and the mode
logic behind the commands), arming and disarming, take-off progress, RTL and landing, ground
contact and the automatic disarm, and the references each asks of the position controller
(speed limits, hold a point, idle on the ground).

Arming follows ArduCopter (``AP_Arming_Copter``, ``Mode::allows_arming``): in STABILIZE (the
mode it boots in), GUIDED and LOITER; elsewhere ``Arm: Mode not armable``. Armed on the ground,
nothing happens until a take-off (GUIDED ``MAV_CMD_NAV_TAKEOFF``, an AUTO mission started with
``MAV_CMD_MISSION_START``), and after DISARM_DELAY it disarms by itself. AUTO's mission is
:mod:`vehicles.autopilot.auto`'s.

Functions of the :class:`~vehicles.autopilot.Autopilot` whose state they change; the facade
calls :func:`update_ground_state` and :func:`update_mode` at every control tick.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.autopilot import auto
from vehicles.autopilot.types import ARMABLE_MODES, Guided, Mode, Stamp
from vehicles.telemetry import FleetSnapshot

if TYPE_CHECKING:
    from vehicles.autopilot.core import Autopilot

_MODE_NUMBERS = Mode._value2member_map_


# ---------------------------------------------------------------------- references ----------
def set_limits(
    ap: Autopilot,
    speed: float | None = None,
    climb: float | None = None,
    descent: float | None = None,
) -> None:
    """Speed limits of the position controller (None: the airframe's own)."""
    airframe = ap.dynamics.config.airframe
    ap.dynamics.set_limits(
        ap.index,
        airframe.max_speed_mps if speed is None else speed,
        airframe.max_climb_mps if climb is None else climb,
        airframe.max_descent_mps if descent is None else descent,
    )


def idle_on_ground(ap: Autopilot) -> None:
    """On the ground: push down (motors at idle when armed), no yaw target."""
    point = ap.dynamics.position[ap.index].copy()
    point[2] = ap.dynamics.ground_z[ap.index] - 1.0
    set_limits(ap, descent=ap.config.land_speed_mps)
    ap.dynamics.hold(ap.index, point)
    ap.dynamics.yaw_target[ap.index] = np.nan


def hold_here(ap: Autopilot, deceleration: float | None = None) -> None:
    """Brake to the stopping point at ``deceleration`` (m/s^2; None: the controller's shaping
    deceleration) and hold it."""
    set_limits(ap)
    ap.dynamics.hold(ap.index, ap.dynamics.stopping_point(ap.index, deceleration))


def guided_brake(ap: Autopilot) -> None:
    """GUIDED's stop (entering GUIDED in the air, a setpoint timeout): brake at the guided
    acceleration WPNAV_ACCEL (the airframe's horizontal limit here), as ArduCopter's
    ``ModeGuided::pva_control_start`` gives the position controller the waypoint navigator's
    acceleration; stopping at a gentler shaping deceleration overshot a formation that stopped
    at a_max by up to 14 m."""
    hold_here(ap, ap.dynamics.config.airframe.max_acceleration_mps2)
    ap.dynamics.yaw_target[ap.index] = ap.dynamics.yaw[ap.index]


def start_landing(ap: Autopilot) -> None:
    """Descend from the stopping point to the ground."""
    point = ap.dynamics.stopping_point(ap.index)
    point[2] = ap.dynamics.ground_z[ap.index] - 1.0
    set_limits(ap, descent=land_descent_rate(ap))
    ap.dynamics.hold(ap.index, point)


def land_descent_rate(ap: Autopilot) -> float:
    """LAND_SPEED_HIGH above ``land_slow_below_m``, LAND_SPEED below."""
    height = ap.dynamics.estimated(ap.index)[2] - ap.dynamics.ground_z[ap.index]
    if height > ap.config.land_slow_below_m:
        return ap.config.land_speed_high_mps
    return ap.config.land_speed_mps


# ---------------------------------------------------------------------- modes ---------------
def set_mode(ap: Autopilot, mode: int, stamp: Stamp) -> tuple[bool, str | None]:
    """Switch to ``mode``; (accepted, reason when refused)."""
    if mode not in _MODE_NUMBERS:
        return False, f"No such mode {mode}"
    mode = Mode(mode)
    if mode == Mode.STABILIZE and ap.airborne():
        return False, "Mode change failed: STABILIZE needs RC input"
    if mode == ap.mode:
        return True, None
    if mode == Mode.AUTO and not auto.can_enter(ap):
        return False, "Mode change to AUTO failed: init failed"  # Copter::mode_change_failed
    if ap.mode == Mode.AUTO:
        auto.leave(ap)
    ap.mode = mode
    ap.rtl_phase = ""
    if mode == Mode.STABILIZE:
        ap.auto_armed = False  # ArduCopter: manual throttle at zero
    if mode == Mode.AUTO:
        auto.enter(ap)
    if not ap.airborne():
        if mode == Mode.GUIDED:
            ap.guided = Guided.IDLE
        idle_on_ground(ap)
        return True, None
    if mode == Mode.GUIDED:
        ap.guided = Guided.HOLD
        ap.last_setpoint = None
        guided_brake(ap)
    elif mode in (Mode.LOITER, Mode.BRAKE, Mode.AUTO):  # AUTO holds until its mission starts
        hold_here(ap)
    elif mode == Mode.LAND:
        start_landing(ap)
    elif mode == Mode.RTL:
        start_return(ap)
    return True, None


def start_return(ap: Autopilot) -> None:
    """RTL's first leg: climb (or stay) to RTL_ALT above home at the stopping point."""
    ap.rtl_phase = "climb"
    point = ap.dynamics.stopping_point(ap.index)
    point[2] = max(point[2], ap.home_enu[2] + ap.config.rtl_altitude_m)
    set_limits(ap)
    ap.dynamics.hold(ap.index, point)


def on_set_mode(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    """SET_MODE (never acknowledged, like ArduCopter; a refusal still says why)."""
    if not msg.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return
    accepted, reason = set_mode(ap, int(msg.custom_mode), stamp)
    if not accepted and reason:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, reason)


# ---------------------------------------------------------------------- arming --------------
def arm(ap: Autopilot, stamp: Stamp, force: bool) -> tuple[int, str | None]:
    """Arm (on the ground, home here); (MAV_RESULT, reason when refused)."""
    if ap.armed:
        return mavlink.MAV_RESULT_ACCEPTED, None
    if ap.booting(stamp):
        return mavlink.MAV_RESULT_FAILED, "Arm: System not initialised"
    if not force:
        if ap.mode not in ARMABLE_MODES:
            return mavlink.MAV_RESULT_FAILED, "Arm: Mode not armable"
        if ap.battery().remaining_fraction <= 0.1:
            return mavlink.MAV_RESULT_FAILED, "Arm: Battery below minimum"
    ap.armed = True
    ap.landed = True
    ap.landed_since = stamp.sim_s
    ap.dynamics.motors_on[ap.index] = True
    ap.home_enu = ap.dynamics.estimated(ap.index)
    ap.guided = Guided.IDLE
    idle_on_ground(ap)
    ap.status_text(mavlink.MAV_SEVERITY_INFO, "Arming motors")
    ap.emit(mavlink.MAVLINK_MSG_ID_HOME_POSITION, FleetSnapshot(ap.dynamics, ap.origin), stamp)
    return mavlink.MAV_RESULT_ACCEPTED, None


def disarm(ap: Autopilot, stamp: Stamp, reason: str = "Disarming motors") -> None:
    if not ap.armed:
        return
    ap.armed = False
    ap.auto_armed = False
    ap.dynamics.motors_on[ap.index] = False
    ap.guided = Guided.IDLE
    ap.last_setpoint = None
    ap.status_text(mavlink.MAV_SEVERITY_INFO, reason)


# ---------------------------------------------------------------------- control tick --------
def update_ground_state(ap: Autopilot, stamp: Stamp) -> None:
    """Ground contact: take-off detected, landing detected (then disarm in LAND and RTL), the
    automatic disarm after ``disarm_delay_s`` on the ground."""
    i = ap.index
    grounded = bool(ap.dynamics.grounded[i])
    if grounded:
        if ap.grounded_since is None:
            ap.grounded_since = stamp.sim_s
    else:
        ap.grounded_since = None
    if not ap.armed:
        ap.landed = True
        return
    if ap.landed:
        if not grounded and ap.dynamics.position[i, 2] > ap.dynamics.ground_z[i] + 0.2:
            ap.landed = False
            ap.landed_since = None
        elif ap.landed_since is not None:
            waited = stamp.sim_s - ap.landed_since
            delay = ap.config.disarm_delay_s
            if landing_disarms(ap) or (delay > 0 and waited >= delay):
                disarm(ap, stamp)
        return
    if ap.grounded_since is None:
        return  # flying: the common case
    taking_off = (ap.mode == Mode.GUIDED and ap.guided == Guided.TAKEOFF) or (
        ap.mode == Mode.AUTO and ap.auto_phase == "takeoff"
    )
    if stamp.sim_s - ap.grounded_since >= ap.config.land_detect_s and not (
        taking_off and stamp.sim_s - ap.takeoff_started_s < 3.0
    ):
        ap.landed = True
        ap.landed_since = stamp.sim_s
        if ap.mode == Mode.GUIDED:
            ap.guided = Guided.IDLE
        idle_on_ground(ap)
        if landing_disarms(ap):
            disarm(ap, stamp, "Disarming motors")


def landing_disarms(ap: Autopilot) -> bool:
    """Touching down disarms: LAND, RTL, and AUTO's LAND and RTL items (``land_run``)."""
    mode = ap.mode
    return mode in (Mode.LAND, Mode.RTL) or (mode == Mode.AUTO and ap.auto_phase in ("land", "rtl"))


def update_mode(ap: Autopilot, stamp: Stamp) -> None:
    """A flying vehicle's mode in progress: landing speed, take-off reached, RTL's legs."""
    if not ap.airborne():
        return
    mode = ap.mode
    if mode == Mode.GUIDED:
        if ap.guided == Guided.TAKEOFF:
            i = ap.index
            if ap.dynamics.estimated(i)[2] >= ap.takeoff_target_z - 0.5:
                ap.guided = Guided.HOLD
                set_limits(ap)
    elif mode == Mode.LAND or (mode == Mode.RTL and ap.rtl_phase == "land"):
        set_limits(ap, descent=land_descent_rate(ap))
    elif mode == Mode.RTL:
        update_return(ap)


def update_return(ap: Autopilot) -> None:
    """RTL: climb, then fly home at the waypoint speed, then land."""
    i = ap.index
    est = ap.dynamics.estimated(i)
    target = ap.dynamics.reference_position[i]
    if ap.rtl_phase == "climb" and abs(est[2] - target[2]) < 0.5:
        ap.rtl_phase = "return"
        point = ap.home_enu.copy()
        point[2] = target[2]
        set_limits(ap, speed=ap.config.waypoint_speed_mps)
        ap.dynamics.hold(i, point)
    elif ap.rtl_phase == "return":
        distance = float(np.hypot(*(est[:2] - ap.home_enu[:2])))
        speed = float(np.hypot(*ap.dynamics.velocity[i, :2]))
        if distance < 1.0 and speed < 0.5:
            ap.rtl_phase = "land"
            start_landing(ap)
