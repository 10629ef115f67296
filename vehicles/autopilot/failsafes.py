"""The autopilot's failsafes: the setpoint timeout in GUIDED (brake at WPNAV_ACCEL and hold;
follow again when setpoints resume, PX4's offboard-loss behaviour) and the GCS failsafe (hold
in BRAKE, then LAND; armed by the GCS's first HEARTBEAT, cleared by any message from the GCS).

Every timeout counts simulated time and never fires before a wall-clock floor
(``FailsafeConfig.wall_floor_s``), so a busy machine at a high speedup does not trip them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.autopilot import modes
from vehicles.autopilot.types import Guided, Mode, Stamp

if TYPE_CHECKING:
    from vehicles.autopilot.core import Autopilot


def expired(ap: Autopilot, since: Stamp, timeout_s: float, now: Stamp) -> bool:
    """``timeout_s`` of simulated time since ``since``, and at least the wall-clock floor."""
    floor = min(ap.config.failsafe.wall_floor_s, timeout_s)
    return now.sim_s - since.sim_s >= timeout_s and now.wall_s - since.wall_s >= floor


def update_setpoint_timeout(ap: Autopilot, stamp: Stamp) -> None:
    """In GUIDED, setpoints that stop for ``setpoint_timeout_s``: brake and hold."""
    if ap.mode != Mode.GUIDED or ap.guided != Guided.SETPOINTS or ap.last_setpoint is None:
        return
    timeout = ap.config.failsafe.setpoint_timeout_s
    if expired(ap, ap.last_setpoint, timeout, stamp):
        ap.guided = Guided.HOLD
        ap.setpoint_timed_out = True
        modes.guided_brake(ap)
        ap.status_text(
            mavlink.MAV_SEVERITY_WARNING, f"Guided: no setpoint for {timeout:g} s, holding"
        )


def update_gcs_failsafe(ap: Autopilot, stamp: Stamp) -> None:
    """The GCS lost for ``gcs_timeout_s``: disarm on the ground, carry on down in LAND or RTL,
    otherwise hold (BRAKE) for ``gcs_hold_s``, then LAND."""
    fs = ap.config.failsafe
    if ap.gcs_last is None or not ap.armed:
        ap.gcs_failsafe = None if not ap.armed else ap.gcs_failsafe
        return
    if not expired(ap, ap.gcs_last, fs.gcs_timeout_s, stamp):
        return
    if ap.gcs_failsafe is None:
        ap.gcs_failsafe_since = stamp
        if ap.landed:
            ap.gcs_failsafe = "land"
            modes.disarm(ap, stamp, "GCS Failsafe: disarming")
            return
        if ap.mode in (Mode.LAND, Mode.RTL):  # already on its way down: carry on
            ap.gcs_failsafe = "land"
            ap.status_text(mavlink.MAV_SEVERITY_CRITICAL, "GCS Failsafe: no heartbeat, landing")
            return
        ap.gcs_failsafe = "hold"
        modes.set_mode(ap, Mode.BRAKE, stamp)
        ap.status_text(
            mavlink.MAV_SEVERITY_CRITICAL,
            f"GCS Failsafe: no heartbeat for {fs.gcs_timeout_s:g} s, holding",
        )
    elif ap.gcs_failsafe == "hold" and ap.gcs_failsafe_since is not None:
        if expired(ap, ap.gcs_failsafe_since, fs.gcs_hold_s, stamp):
            ap.gcs_failsafe = "land"
            modes.set_mode(ap, Mode.LAND, stamp)
            ap.status_text(mavlink.MAV_SEVERITY_CRITICAL, "GCS Failsafe: landing")


def gcs_alive(ap: Autopilot, stamp: Stamp) -> None:
    """The GCS failsafe is armed by the GCS's first HEARTBEAT; from then on any valid
    message from its system id proves it alive (docs/outputs.md, MAVLink), so that on a lossy
    link its 10 Hz setpoints keep the failsafe off when five 1 Hz heartbeats are lost."""
    ap.gcs_last = stamp
    if ap.gcs_failsafe is not None:
        ap.gcs_failsafe = None
        ap.gcs_failsafe_since = None
        if ap.armed:
            ap.status_text(mavlink.MAV_SEVERITY_INFO, "GCS Failsafe Cleared")
