"""The parameter protocol, the little a GCS needs to connect: PARAM_REQUEST_LIST answered with
every parameter in index order (each PARAM_VALUE with the total ``param_count`` and its
``param_index``), PARAM_REQUEST_READ by name or index; every parameter is read-only (PARAM_SET
echoes the value in force and says so). Values mirror the autopilot's configuration under
ArduCopter's names and units. Parameter files over MAVFTP (``@PARAM/param.pck``) are refused at
once (:mod:`vehicles.autopilot.ftp`), so tools fall back to PARAM_REQUEST_LIST."""

from __future__ import annotations

from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.autopilot.types import Stamp

if TYPE_CHECKING:
    from vehicles.autopilot.core import Autopilot


def parameters(ap: Autopilot) -> list[tuple[str, float, int]]:
    """(name, value, MAV_PARAM_TYPE) of every parameter, in index order."""
    fs = ap.config.failsafe
    cfg = ap.config
    airframe = ap.dynamics.config.airframe
    real, integer = mavlink.MAV_PARAM_TYPE_REAL32, mavlink.MAV_PARAM_TYPE_INT32
    return [
        ("SYSID_THISMAV", ap.sysid, integer),
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
        ("BATT_CAPACITY", ap.dynamics.battery_capacity_mah[ap.index], integer),
        ("WPNAV_RADIUS", cfg.waypoint_radius_m * 100, real),
        ("FENCE_ENABLE", 0, integer),  # SYS_STATUS: geofence present, not enabled
        ("AUTO_OPTIONS", 0, integer),  # AUTO neither arms nor takes off without MISSION_START
        ("MIS_RESTART", 0, integer),  # AUTO resumes a mission where it stopped
    ]


def _text(value: object) -> str:
    if isinstance(value, bytes | bytearray):
        return value.split(b"\x00", 1)[0].decode("ascii", "replace")
    return str(value).split("\x00", 1)[0]


def _param_value(
    params: list[tuple[str, float, int]], index: int
) -> mavlink.MAVLink_param_value_message:
    name, value, kind = params[index]
    return mavlink.MAVLink_param_value_message(
        name.encode(), float(value), kind, len(params), index
    )


def _param_index(ap: Autopilot, name: str, index: int) -> int | None:
    params = parameters(ap)
    if name:
        for i, (param, _, _) in enumerate(params):
            if param == name:
                return i
        return None
    return index if 0 <= index < len(params) else None


def on_param_request_list(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    params = parameters(ap)
    for index in range(len(params)):
        ap.send(_param_value(params, index))


def on_param_request_read(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    index = _param_index(ap, _text(msg.param_id), int(msg.param_index))
    if index is not None:
        ap.send(_param_value(parameters(ap), index))


def on_param_set(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    index = _param_index(ap, _text(msg.param_id), -1)
    if index is not None:  # read-only: echo the value in force
        ap.send(_param_value(parameters(ap), index))
        ap.refuse("param", f"Param {_text(msg.param_id)} is read-only", stamp)
