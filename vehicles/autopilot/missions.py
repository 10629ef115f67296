"""The mission protocol, the little a GCS needs to connect: an empty mission on request, uploads
refused (MISSION_ACK UNSUPPORTED), clearing accepted, and guided-mode waypoints (a MISSION_ITEM
or MISSION_ITEM_INT with ``current`` = 2, as MAVProxy's ``guided`` and QGC send) flown to."""

from __future__ import annotations

from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.autopilot import setpoints
from vehicles.autopilot.types import Stamp

if TYPE_CHECKING:
    from vehicles.autopilot.core import Autopilot


def on_mission_request_list(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    ap.send(
        mavlink.MAVLink_mission_count_message(
            msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type
        )
    )


def on_mission_count(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    ap.send(
        mavlink.MAVLink_mission_ack_message(
            msg.get_srcSystem(),
            msg.get_srcComponent(),
            mavlink.MAV_MISSION_UNSUPPORTED,
            msg.mission_type,
        )
    )


def on_mission_clear_all(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    ap.send(
        mavlink.MAVLink_mission_ack_message(
            msg.get_srcSystem(),
            msg.get_srcComponent(),
            mavlink.MAV_MISSION_ACCEPTED,
            msg.mission_type,
        )
    )


def on_mission_item(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    """A guided-mode waypoint (``current`` = 2, as MAVProxy's ``guided`` and QGC send)."""
    source = (msg.get_srcSystem(), msg.get_srcComponent())
    if msg.current != 2:
        ap.send(
            mavlink.MAVLink_mission_ack_message(
                *source, mavlink.MAV_MISSION_UNSUPPORTED, msg.mission_type
            )
        )
        return
    scale = 1e-7 if msg.get_type() == "MISSION_ITEM_INT" else 1.0
    point = setpoints.global_point(ap, msg.frame, msg.x * scale, msg.y * scale, float(msg.z))
    if isinstance(point, str) or not setpoints.goto(ap, point, None, stamp):
        reason = point if isinstance(point, str) else "Guided: not flying in GUIDED"
        ap.refuse("goto", reason, stamp)
        ap.send(
            mavlink.MAVLink_mission_ack_message(
                *source, mavlink.MAV_MISSION_ERROR, msg.mission_type
            )
        )
        return
    ap.send(
        mavlink.MAVLink_mission_ack_message(*source, mavlink.MAV_MISSION_ACCEPTED, msg.mission_type)
    )
