"""AUTO: the stored mission (:mod:`vehicles.autopilot.missions`) flown as ArduCopter flies it
(``ArduCopter/mode_auto.cpp``, ``libraries/AP_Mission/AP_Mission.cpp``,
``GCS_MAVLINK_Copter::handle_MAV_CMD_MISSION_START``).

* **Entering AUTO** (``ModeAuto::init``): always allowed while disarmed; armed, it needs a
  mission (more than item 0, home) and, on the ground, one whose first navigation item is a
  take-off (else ``Auto: Missing Takeoff Cmd``), else ``Mode change to AUTO failed: init
  failed``. Arming in AUTO is refused (AUTO_OPTIONS 0).
* **Starting**: the mission starts, or resumes at the item it was interrupted at (MIS_RESTART 0;
  a completed mission starts again), at the first control tick in AUTO. On the ground, the
  take-off waits for the vehicle to be *auto-armed*: ``MAV_CMD_MISSION_START`` (which also
  switches to AUTO; param1/param2 other than 0 are DENIED) or a GUIDED take-off sets it, a
  disarm or STABILIZE clears it (``Copter::update_auto_armed``, throttle stick at zero).
* **Items** (``Mission: N <type>`` STATUSTEXT when each starts; MISSION_CURRENT at once):
  NAV_TAKEOFF climbs straight up to its altitude; NAV_WAYPOINT flies to its point at the
  mission speed and is reached within WPNAV_RADIUS, then holds param1 seconds (``Reached
  command #N``); NAV_LAND flies to its point at the current altitude if it has one, then lands
  and disarms; NAV_RETURN_TO_LAUNCH flies RTL (climb to RTL_ALT, home, land, disarm); the
  DO_CHANGE_SPEED items after a navigation item run when it starts (speed type 0/1: the
  horizontal mission speed). A latitude/longitude of 0 means "where the last item went", an
  altitude of 0 "its altitude". Each navigation item done sends MISSION_ITEM_REACHED.
* **The end** (``ModeAuto::exit_mission``): in the air it holds where it is (still AUTO); on the
  ground it disarms.
* **Leaving AUTO** stops the mission where it is (MISSION_CURRENT PAUSED) until AUTO again.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.autopilot import missions, modes, setpoints
from vehicles.autopilot.setpoints import finite
from vehicles.autopilot.types import Mode, Stamp
from vehicles.telemetry import FleetSnapshot

if TYPE_CHECKING:
    from vehicles.autopilot.commands import Command
    from vehicles.autopilot.core import Autopilot
    from vehicles.autopilot.missions import MissionItem

_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
_WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
_LAND = mavlink.MAV_CMD_NAV_LAND
_RTL = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
_CHANGE_SPEED = mavlink.MAV_CMD_DO_CHANGE_SPEED
#: AP_Mission::Mission_Command::type() of the items flown.
_TYPE_NAMES = {
    _WAYPOINT: "WP",
    _TAKEOFF: "Takeoff",
    _LAND: "Land",
    _RTL: "RTL",
    _CHANGE_SPEED: "ChangeSpeed",
}
_TAKEOFF_REACHED_M = 0.5  # as GUIDED's take-off: within this of the altitude


# ---------------------------------------------------------------------- mode changes --------
def can_enter(ap: Autopilot) -> bool:
    """``ModeAuto::init``: any time disarmed; armed, with a mission that, on the ground, starts
    with a take-off."""
    if not ap.armed:
        return True
    if len(ap.mission) <= 1:
        return False
    if ap.landed and _first_nav_command(ap) != _TAKEOFF:
        ap.status_text(mavlink.MAV_SEVERITY_CRITICAL, "Auto: Missing Takeoff Cmd")
        return False
    return True


def _first_nav_command(ap: Autopilot) -> int | None:
    for item in ap.mission[1:]:
        if item.command in missions.NAV_COMMANDS:
            return item.command
    return None


def enter(ap: Autopilot) -> None:
    """AUTO selected: the mission starts (or resumes) at the next tick at WPNAV_SPEED."""
    ap.auto_waiting = True
    ap.auto_phase = ""
    ap.nav_speed_mps = ap.config.waypoint_speed_mps


def leave(ap: Autopilot) -> None:
    """Another mode: the mission stops at the item in progress."""
    ap.mission_running = False
    ap.auto_waiting = False
    ap.auto_phase = ""


def mission_start(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_MISSION_START: AUTO, auto-armed, the mission started (or resumed)."""
    if cmd.params[0] != 0.0 or cmd.params[1] != 0.0:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Mission start: first/last item not supported")
        return mavlink.MAV_RESULT_DENIED
    accepted, reason = modes.set_mode(ap, Mode.AUTO, stamp)
    if not accepted:
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, reason or "Mode change to AUTO failed")
        return mavlink.MAV_RESULT_FAILED
    ap.auto_armed = ap.armed
    if not ap.mission_running:
        ap.auto_waiting = True
    return mavlink.MAV_RESULT_ACCEPTED


# ---------------------------------------------------------------------- control tick --------
def update(ap: Autopilot, stamp: Stamp) -> None:
    """In AUTO, at every control tick: start the mission when due, run the current item."""
    if ap.auto_waiting:
        ap.auto_waiting = False
        _start_or_resume(ap, stamp)
    if not ap.mission_running:
        return
    item = ap.mission[ap.mission_nav]
    if _verify(ap, item, stamp):
        ap.send(mavlink.MAVLink_mission_item_reached_message(item.seq))
        _start_next(ap, ap.mission_nav + 1, stamp, leading_do=False)


def _start_or_resume(ap: Autopilot, stamp: Stamp) -> None:
    """``AP_Mission::start_or_resume`` with MIS_RESTART 0."""
    if len(ap.mission) <= 1:
        ap.mission_running = False
        return
    if ap.mission_complete or ap.mission_nav == 0:
        ap.mission_complete = False
        _start_next(ap, 1, stamp, leading_do=True)
    else:
        _start_item(ap, ap.mission_nav, stamp)


def _start_next(ap: Autopilot, index: int, stamp: Stamp, leading_do: bool) -> None:
    """Start the first navigation item from ``index`` (with ``leading_do``, the DO items before
    it run first), or complete the mission."""
    items = ap.mission
    k = index
    while k < len(items) and items[k].command not in missions.NAV_COMMANDS:
        if leading_do:
            _run_do(ap, items[k])
        k += 1
    if k >= len(items):
        _complete(ap, stamp)
        return
    _start_item(ap, k, stamp)


def _start_item(ap: Autopilot, index: int, stamp: Stamp) -> None:
    """Start navigation item ``index``, then run the DO items that follow it."""
    items = ap.mission
    item = items[index]
    ap.mission_running = True
    ap.mission_nav = index
    ap.wp_arrived_s = None
    ap.status_text(mavlink.MAV_SEVERITY_INFO, f"Mission: {index} {_TYPE_NAMES[item.command]}")
    ap.emit(mavlink.MAVLINK_MSG_ID_MISSION_CURRENT, FleetSnapshot(ap.dynamics, ap.origin), stamp)
    k = index + 1
    while k < len(items) and items[k].command not in missions.NAV_COMMANDS:
        _run_do(ap, items[k])
        k += 1
    command = item.command
    if command == _TAKEOFF:
        ap.auto_phase = "takeoff_wait"
        ap.auto_target = _takeoff_point(ap, item)
        _try_takeoff(ap, stamp)
    elif command == _RTL:
        ap.auto_phase = "rtl"
        if ap.airborne():
            modes.start_return(ap)
    else:
        target = _location(ap, item)
        if isinstance(target, str):
            ap.status_text(mavlink.MAV_SEVERITY_WARNING, f"Mission: item {index}: {target[8:]}")
            _start_next(ap, index + 1, stamp, leading_do=False)  # a command that cannot start
            return
        if command == _LAND and item.x == 0 and item.y == 0:
            ap.auto_phase = "land"
            ap.auto_target = None
            if ap.airborne():
                modes.start_landing(ap)
            return
        if command == _LAND:  # fly there at the current altitude first
            target[2] = ap.dynamics.estimated(ap.index)[2]
        ap.auto_phase = "wp" if command == _WAYPOINT else "land_approach"
        ap.auto_target = target
        _fly_to(ap, target)


def _run_do(ap: Autopilot, item: MissionItem) -> None:
    ap.status_text(mavlink.MAV_SEVERITY_INFO, f"Mission: {item.seq} {_TYPE_NAMES[item.command]}")
    if item.command == _CHANGE_SPEED:
        speed_type, speed = item.params[0], item.params[1]
        if speed_type in (0.0, 1.0) and finite(speed) and speed > 0.0:
            ap.nav_speed_mps = float(speed)
            if ap.auto_phase in ("wp", "land_approach") and ap.airborne():
                modes.set_limits(ap, speed=ap.nav_speed_mps)


def _complete(ap: Autopilot, stamp: Stamp) -> None:
    """``ModeAuto::exit_mission``: hold in the air, disarm on the ground."""
    ap.mission_running = False
    ap.mission_complete = True
    ap.auto_phase = ""
    if ap.airborne():
        modes.hold_here(ap)
    elif ap.armed:
        modes.disarm(ap, stamp)


# ---------------------------------------------------------------------- items ---------------
def _takeoff_point(ap: Autopilot, item: MissionItem) -> np.ndarray:
    """Straight up from where it is to the item's altitude (relative to home, or AMSL)."""
    point = ap.dynamics.estimated(ap.index)
    if item.frame in missions.RELATIVE_FRAMES:
        point[2] = ap.home_enu[2] + item.z
    else:
        point[2] = item.z - ap.origin.alt
    return point


def _location(ap: Autopilot, item: MissionItem) -> np.ndarray | str:
    """The item's point in local ENU (``ModeAuto::loc_from_cmd``: latitude and longitude 0 are
    the last target's, altitude 0 its altitude), or the reason it cannot be flown to."""
    previous = ap.auto_target if ap.auto_target is not None else ap.dynamics.estimated(ap.index)
    if item.x == 0 and item.y == 0:
        lat, lon, _ = (float(v[0]) for v in ap.origin.to_geodetic(previous))
    else:
        lat, lon = item.latitude, item.longitude
    point = setpoints.global_point(ap, item.frame, lat, lon, item.z)
    if isinstance(point, str):
        return point
    if item.z == 0.0:
        point[2] = previous[2]
    return point


def _fly_to(ap: Autopilot, point: np.ndarray) -> None:
    if ap.airborne():
        modes.set_limits(ap, speed=ap.nav_speed_mps)
        ap.dynamics.hold(ap.index, point)
        ap.dynamics.yaw_target[ap.index] = np.nan


def _try_takeoff(ap: Autopilot, stamp: Stamp) -> None:
    """Climb once armed and auto-armed (on the ground it waits, like ``ModeAuto::takeoff_run``)."""
    if not (ap.armed and ap.auto_armed):
        return
    ap.auto_phase = "takeoff"
    i = ap.index
    if ap.landed:
        ap.landed = False
        ap.landed_since = None
        ap.takeoff_started_s = stamp.sim_s
    target = ap.auto_target
    if ap.dynamics.estimated(i)[2] >= target[2]:
        target = ap.dynamics.estimated(i)  # already above: no descent
        ap.auto_target = target
    modes.set_limits(ap, climb=ap.config.takeoff_speed_mps)
    ap.dynamics.hold(i, target)
    ap.dynamics.yaw_target[i] = ap.dynamics.yaw[i]


def _verify(ap: Autopilot, item: MissionItem, stamp: Stamp) -> bool:  # noqa: C901 (over 15 branches: to split)
    """Whether the current navigation item is done (``ModeAuto::verify_command``)."""
    phase = ap.auto_phase
    i = ap.index
    if phase == "takeoff_wait":
        _try_takeoff(ap, stamp)
        return False
    if phase == "takeoff":
        if not ap.airborne():
            return False
        return bool(ap.dynamics.estimated(i)[2] >= ap.auto_target[2] - _TAKEOFF_REACHED_M)
    if phase == "wp":
        if not ap.airborne():
            return False
        distance = float(np.linalg.norm(ap.dynamics.estimated(i) - ap.auto_target))
        if distance > ap.config.waypoint_radius_m and ap.wp_arrived_s is None:
            return False
        if ap.wp_arrived_s is None:
            ap.wp_arrived_s = stamp.sim_s
        if stamp.sim_s - ap.wp_arrived_s < item.params[0]:
            return False
        ap.status_text(mavlink.MAV_SEVERITY_INFO, f"Reached command #{item.seq}")
        return True
    if phase == "land_approach":
        if not ap.airborne():
            return not ap.armed
        offset = ap.dynamics.estimated(i)[:2] - ap.auto_target[:2]
        if float(np.hypot(*offset)) <= ap.config.waypoint_radius_m:
            ap.auto_phase = "land"
            modes.start_landing(ap)
        return False
    if phase == "land":
        if ap.airborne():
            modes.set_limits(ap, descent=modes.land_descent_rate(ap))
            return False
        return True
    if phase == "rtl":
        if ap.airborne():
            if ap.rtl_phase == "land":
                modes.set_limits(ap, descent=modes.land_descent_rate(ap))
            else:
                modes.update_return(ap)
            return False
        return True
    return False
