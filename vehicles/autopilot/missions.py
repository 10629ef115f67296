"""The mission protocol, as ArduCopter speaks it (``libraries/GCS_MAVLink/MissionItemProtocol.cpp``,
``MissionItemProtocol_Waypoints.cpp``, ``AP_Mission``): the mission stored, uploaded, downloaded
and cleared. AUTO flies it (:mod:`vehicles.autopilot.auto`).

* **Item 0 is home.** An upload's item 0 is stored but always read back as home (MAV_CMD_NAV_
  WAYPOINT, frame GLOBAL, AMSL); AUTO starts at item 1. An empty mission has 0 items.
* **Upload**: MISSION_COUNT -> MISSION_REQUEST_INT for each item in turn (asked again after
  ``mission_request_retry_s`` without an answer) -> MISSION_ITEM_INT (or MISSION_ITEM, with
  ArduPilot's warning) -> the next request ... -> STATUSTEXT ``Flight plan received`` and
  MISSION_ACK ACCEPTED. An item out of sequence: ACK INVALID_SEQUENCE, the upload goes on; an
  item refused: ACK with the reason, the upload ends; no item for ``mission_upload_timeout_s``:
  ``Mission upload timeout`` and ACK OPERATION_CANCELLED; another sender meanwhile: ACK DENIED.
  More than ``mission_capacity`` items: ACK NO_SPACE ``Only N items are supported``. The new
  mission replaces the old one when the last item arrives.
* **Items flown**: NAV_WAYPOINT, NAV_TAKEOFF, NAV_LAND, NAV_RETURN_TO_LAUNCH (global frames
  0/3/5/6), DO_CHANGE_SPEED. Any other command is refused (ACK UNSUPPORTED, STATUSTEXT
  ``Mission: command N not supported``; ArduCopter knows more), terrain frames too (ACK
  UNSUPPORTED_FRAME).
* **Download**: MISSION_REQUEST_LIST -> MISSION_COUNT; MISSION_REQUEST_INT -> MISSION_ITEM_INT
  (MISSION_REQUEST -> MISSION_ITEM); a sequence beyond the mission: MISSION_COUNT and ACK ERROR.
  Refused while an upload is in progress (ACK DENIED).
* **MISSION_CLEAR_ALL**: ACK ACCEPTED, or ERROR while AUTO flies the mission (AP_Mission::clear).
* Fence and rally items (mission_type 1, 2): the vehicle has none (count 0); uploads are refused
  (ACK UNSUPPORTED).
* Guided-mode waypoints (``current`` = 2, as MAVProxy's ``guided`` and QGC send) are flown to in
  GUIDED; ``current`` = 3 (change altitude) is refused (ACK UNSUPPORTED; ArduCopter 4.7 does not
  implement it either).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.autopilot import failsafes, setpoints
from vehicles.autopilot.types import Mode, Stamp

if TYPE_CHECKING:
    from vehicles.autopilot.core import Autopilot

MISSION = mavlink.MAV_MISSION_TYPE_MISSION
GLOBAL_FRAMES = frozenset(
    {
        mavlink.MAV_FRAME_GLOBAL,
        mavlink.MAV_FRAME_GLOBAL_INT,
        mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
        mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    }
)
RELATIVE_FRAMES = frozenset(
    {mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
)
_TERRAIN_FRAMES = frozenset(
    {mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT}
)
#: Navigation commands flown in AUTO (they need a global frame) and the DO commands run.
NAV_COMMANDS = frozenset(
    {
        mavlink.MAV_CMD_NAV_WAYPOINT,
        mavlink.MAV_CMD_NAV_TAKEOFF,
        mavlink.MAV_CMD_NAV_LAND,
        mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH,
    }
)
DO_COMMANDS = frozenset({mavlink.MAV_CMD_DO_CHANGE_SPEED})
_POSITIONED = frozenset(
    {mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND}
)


@dataclass(frozen=True)
class MissionItem:
    """One stored mission item, as MISSION_ITEM_INT carries it (x, y: degrees * 1e7 in global
    frames)."""

    seq: int
    frame: int
    command: int
    params: tuple[float, float, float, float]
    x: int
    y: int
    z: float

    @property
    def latitude(self) -> float:
        return self.x * 1e-7

    @property
    def longitude(self) -> float:
        return self.y * 1e-7


@dataclass(frozen=True)
class Upload:
    """A mission upload in progress: who sends it, how many items, those received so far and
    when the last item came and the last request went."""

    source: tuple[int, int]
    count: int
    items: tuple[MissionItem, ...]
    received: Stamp
    requested: Stamp

    @property
    def next_seq(self) -> int:
        return len(self.items)


def _source(msg: mavlink.MAVLink_message) -> tuple[int, int]:
    return msg.get_srcSystem(), msg.get_srcComponent()


def ack(ap: Autopilot, to: tuple[int, int], result: int, mission_type: int = MISSION) -> None:
    ap.send(mavlink.MAVLink_mission_ack_message(*to, result, mission_type))


def item_of(msg: mavlink.MAVLink_message) -> MissionItem:
    """The item a MISSION_ITEM_INT or MISSION_ITEM carries (MISSION_ITEM's degrees scaled)."""
    x, y = msg.x, msg.y
    if msg.get_type() == "MISSION_ITEM":
        scale = 1e7 if msg.frame in GLOBAL_FRAMES or msg.frame in _TERRAIN_FRAMES else 1.0
        x = round(x * scale) if math.isfinite(x) else 0
        y = round(y * scale) if math.isfinite(y) else 0
    params = (float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4))
    return MissionItem(int(msg.seq), int(msg.frame), int(msg.command), params, x, y, float(msg.z))


def check_item(item: MissionItem) -> tuple[int, str | None]:
    """(MAV_MISSION_RESULT, reason) of storing ``item`` (item 0, home, is never checked)."""
    if item.seq == 0:
        return mavlink.MAV_MISSION_ACCEPTED, None
    command = item.command
    if command not in NAV_COMMANDS and command not in DO_COMMANDS:
        return mavlink.MAV_MISSION_UNSUPPORTED, f"Mission: command {command} not supported"
    if command in _POSITIONED:
        if item.frame in _TERRAIN_FRAMES:
            reason = f"Mission: terrain frame {item.frame} not supported"
            return mavlink.MAV_MISSION_UNSUPPORTED_FRAME, reason
        if item.frame not in GLOBAL_FRAMES:
            return (
                mavlink.MAV_MISSION_UNSUPPORTED_FRAME,
                f"Mission: frame {item.frame} not supported",
            )
        if abs(item.x) > 900_000_000:
            return mavlink.MAV_MISSION_INVALID_PARAM5_X, "Mission: latitude out of range"
        if abs(item.y) > 1_800_000_000:
            return mavlink.MAV_MISSION_INVALID_PARAM6_Y, "Mission: longitude out of range"
        if not math.isfinite(item.z) or abs(item.z) > 100_000.0:
            return mavlink.MAV_MISSION_INVALID_PARAM7, "Mission: altitude invalid"
    if command == mavlink.MAV_CMD_NAV_WAYPOINT and not (0.0 <= item.params[0] <= 3600.0):
        return mavlink.MAV_MISSION_INVALID_PARAM1, "Mission: hold time invalid"
    return mavlink.MAV_MISSION_ACCEPTED, None


# ---------------------------------------------------------------------- the stored mission --
def set_mission(ap: Autopilot, items: tuple[MissionItem, ...]) -> None:
    """Replace the mission; AUTO carries on with the new one (AP_Mission's change detector:
    the current item again, or the start if it is gone)."""
    ap.mission = items
    ap.mission_complete = False
    if ap.mission_nav >= len(items):
        ap.mission_nav = 0
    if ap.mode == Mode.AUTO and ap.mission_running:
        ap.mission_running = False
        ap.auto_waiting = True
    elif ap.mode != Mode.AUTO:
        ap.mission_running = False


def home_item(ap: Autopilot) -> MissionItem:
    """Item 0: home, always read back from the vehicle's home (AMSL, frame GLOBAL)."""
    lat, lon, alt = (float(v[0]) for v in ap.origin.to_geodetic(ap.home_enu))
    frame, command = mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_CMD_NAV_WAYPOINT
    return MissionItem(
        0, frame, command, (0.0, 0.0, 0.0, 0.0), round(lat * 1e7), round(lon * 1e7), alt
    )


def stored_item(ap: Autopilot, seq: int) -> MissionItem:
    return home_item(ap) if seq == 0 else ap.mission[seq]


# ---------------------------------------------------------------------- upload --------------
def on_mission_count(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    source = _source(msg)
    if msg.mission_type != MISSION:
        ap.refuse("fence", "Mission: fence and rally items not supported", stamp)
        ack(ap, source, mavlink.MAV_MISSION_UNSUPPORTED, msg.mission_type)
        return
    upload = ap.mission_upload
    if upload is not None and upload.source != source:
        ack(ap, source, mavlink.MAV_MISSION_DENIED)
        return
    ap.mission_upload = None
    count = int(msg.count)
    if count > ap.config.mission_capacity:
        ack(ap, source, mavlink.MAV_MISSION_NO_SPACE)
        ap.status_text(
            mavlink.MAV_SEVERITY_WARNING, f"Only {ap.config.mission_capacity} items are supported"
        )
        return
    if count == 0:
        set_mission(ap, ())
        ap.status_text(mavlink.MAV_SEVERITY_INFO, "Flight plan received")
        ack(ap, source, mavlink.MAV_MISSION_ACCEPTED)
        return
    ap.mission_upload = Upload(source, count, (), stamp, stamp)
    _request(ap, ap.mission_upload)


def _request(ap: Autopilot, upload: Upload) -> None:
    ap.send(mavlink.MAVLink_mission_request_int_message(*upload.source, upload.next_seq, MISSION))


def _on_uploaded_item(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    source = _source(msg)
    upload = ap.mission_upload
    if msg.mission_type != MISSION:
        ack(ap, source, mavlink.MAV_MISSION_UNSUPPORTED, msg.mission_type)
        return
    if upload is None:
        ack(ap, source, mavlink.MAV_MISSION_ERROR)
        return
    if source != upload.source:
        ack(ap, source, mavlink.MAV_MISSION_DENIED)
        return
    if msg.seq != upload.next_seq:
        ack(ap, source, mavlink.MAV_MISSION_INVALID_SEQUENCE)
        return
    if msg.get_type() == "MISSION_ITEM" and not ap.mission_item_warned:
        ap.mission_item_warned = True
        ap.status_text(
            mavlink.MAV_SEVERITY_WARNING, "got MISSION_ITEM; GCS should send MISSION_ITEM_INT"
        )
    item = item_of(msg)
    result, reason = check_item(item)
    if result != mavlink.MAV_MISSION_ACCEPTED:
        ap.mission_upload = None
        if reason:
            ap.status_text(mavlink.MAV_SEVERITY_WARNING, reason)
        ack(ap, source, result)
        return
    upload = replace(upload, items=(*upload.items, item), received=stamp, requested=stamp)
    if upload.next_seq < upload.count:
        ap.mission_upload = upload
        _request(ap, upload)
        return
    ap.mission_upload = None
    set_mission(ap, upload.items)
    ap.status_text(mavlink.MAV_SEVERITY_INFO, "Flight plan received")
    ack(ap, source, mavlink.MAV_MISSION_ACCEPTED)


def update(ap: Autopilot, stamp: Stamp) -> None:
    """An upload in progress: ask again for an unanswered item, give up after the timeout."""
    upload = ap.mission_upload
    if upload is None:
        return
    if failsafes.expired(ap, upload.received, ap.config.mission_upload_timeout_s, stamp):
        ap.mission_upload = None
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Mission upload timeout")
        ack(ap, upload.source, mavlink.MAV_MISSION_OPERATION_CANCELLED)
    elif failsafes.expired(ap, upload.requested, ap.config.mission_request_retry_s, stamp):
        ap.mission_upload = replace(upload, requested=stamp)
        _request(ap, upload)


# ---------------------------------------------------------------------- download ------------
def on_mission_request_list(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    source = _source(msg)
    if ap.mission_upload is not None:
        ack(ap, source, mavlink.MAV_MISSION_DENIED, msg.mission_type)
        return
    count = len(ap.mission) if msg.mission_type == MISSION else 0
    ap.send(mavlink.MAVLink_mission_count_message(*source, count, msg.mission_type))


def _on_request(ap: Autopilot, msg: mavlink.MAVLink_message, as_int: bool) -> None:
    source = _source(msg)
    if ap.mission_upload is not None:
        ack(ap, source, mavlink.MAV_MISSION_DENIED, msg.mission_type)
        return
    seq = int(msg.seq)
    count = len(ap.mission) if msg.mission_type == MISSION else 0
    if msg.mission_type != MISSION or (seq != 0 and seq >= count):
        ap.send(mavlink.MAVLink_mission_count_message(*source, count, msg.mission_type))
        ack(ap, source, mavlink.MAV_MISSION_ERROR, msg.mission_type)
        return
    item = stored_item(ap, seq)
    current = int(seq == ap.mission_nav and seq > 0)
    if as_int:
        x, y = item.x, item.y
        message_class = mavlink.MAVLink_mission_item_int_message
    else:
        scale = 1e-7 if item.frame in GLOBAL_FRAMES else 1.0
        x, y = item.x * scale, item.y * scale
        message_class = mavlink.MAVLink_mission_item_message
    ap.send(
        message_class(
            *source, seq, item.frame, item.command, current, 1, *item.params, x, y, item.z, MISSION
        )
    )


def on_mission_request_int(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    _on_request(ap, msg, as_int=True)


def on_mission_request(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    if not ap.mission_request_warned:
        ap.mission_request_warned = True
        ap.status_text(
            mavlink.MAV_SEVERITY_WARNING, "got MISSION_REQUEST; use MISSION_REQUEST_INT!"
        )
    _on_request(ap, msg, as_int=False)


# ---------------------------------------------------------------------- clear, items --------
def on_mission_clear_all(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    source = _source(msg)
    if msg.mission_type != MISSION:
        ack(ap, source, mavlink.MAV_MISSION_ACCEPTED, msg.mission_type)  # it holds none
        return
    upload = ap.mission_upload
    if upload is not None and upload.source != source:
        ack(ap, source, mavlink.MAV_MISSION_DENIED)
        return
    if ap.mode == Mode.AUTO and ap.mission_running:
        ack(ap, source, mavlink.MAV_MISSION_ERROR)  # AP_Mission::clear: not while running
        return
    ap.mission_upload = None
    set_mission(ap, ())
    ap.mission_nav = 0
    ack(ap, source, mavlink.MAV_MISSION_ACCEPTED)


def on_mission_item(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    """MISSION_ITEM(_INT): a guided-mode waypoint (``current`` = 2), else an uploaded item."""
    if msg.current == 2:
        _guided_waypoint(ap, msg, stamp)
    elif msg.current == 3:
        ap.refuse("alt", "Mission: change-altitude items not supported", stamp)
        ack(ap, _source(msg), mavlink.MAV_MISSION_UNSUPPORTED, msg.mission_type)
    else:
        _on_uploaded_item(ap, msg, stamp)


def _guided_waypoint(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    source = _source(msg)
    scale = 1e-7 if msg.get_type() == "MISSION_ITEM_INT" else 1.0
    point = setpoints.global_point(ap, msg.frame, msg.x * scale, msg.y * scale, float(msg.z))
    if isinstance(point, str) or not setpoints.goto(ap, point, None, stamp):
        reason = point if isinstance(point, str) else "Guided: not flying in GUIDED"
        ap.refuse("goto", reason, stamp)
        ack(ap, source, mavlink.MAV_MISSION_ERROR, msg.mission_type)
        return
    ack(ap, source, mavlink.MAV_MISSION_ACCEPTED, msg.mission_type)
