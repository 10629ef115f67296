"""The fleet-speed protocol on one vehicle: speed changes heard (``MAV_CMD_DO_CHANGE_SPEED``,
recorded once per sender and sequence), the GCS's mission clock (``NAMED_VALUE_INT MSN_TIME``),
and a leader's speed requests to the GCS, sent when due, retried until acknowledged
(``COMMAND_ACK``) or given up. The bookkeeping is :mod:`vehicles.fleet_speed`'s; the encoding
:mod:`fleetwire.messages`'.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.messages import (
    SPEED_CHANGE_COMMAND,
    SPEED_CHANGE_FRAME,
    decode_mission_time,
    decode_speed_change,
    encode_speed_change,
)
from vehicles.autopilot.setpoints import finite
from vehicles.autopilot.types import Stamp
from vehicles.fleet_speed import HeardSpeedChange

if TYPE_CHECKING:
    from vehicles.autopilot.commands import Command
    from vehicles.autopilot.core import Autopilot

log = logging.getLogger(__name__)


def change_speed(ap: Autopilot, cmd: Command, stamp: Stamp) -> int:
    """MAV_CMD_DO_CHANGE_SPEED: param2 m/s (-1 no change, -2 default), from mission time x."""
    command = decode_speed_change(cmd.message)
    speed = command.speed
    if (
        not finite(speed)
        or not (speed >= 0.0 or speed in (-1.0, -2.0))
        or speed > ap.config.max_setpoint_speed_mps
    ):
        ap.status_text(mavlink.MAV_SEVERITY_WARNING, "Speed: param2 must be a speed in m/s")
        return mavlink.MAV_RESULT_DENIED
    if speed < 0:
        return mavlink.MAV_RESULT_ACCEPTED  # -1 / -2: no change / default
    sequence = command.sequence
    effective = command.effective_s
    change = HeardSpeedChange(cmd.source_system, sequence, effective, float(speed), stamp.sim_s)
    if ap.speeds.record(change):
        log.info(
            "sysid %d: speed change seq %d: %.2f m/s at %s",
            ap.sysid,
            sequence,
            speed,
            effective,
        )
    return mavlink.MAV_RESULT_ACCEPTED


def on_named_value_int(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    """MSN_TIME from the GCS: anchor the mission clock."""
    if msg.get_srcSystem() != ap.config.failsafe.gcs_system:
        return
    mission_time = decode_mission_time(msg)
    if mission_time is not None:
        ap.mission_clock.sync(mission_time, stamp.sim_s)


def on_command_ack(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    """The GCS's COMMAND_ACK of a leader's request settles it."""
    if msg.get_srcSystem() != ap.config.failsafe.gcs_system:
        return
    if msg.command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
        ap.leader.acknowledge(int(msg.result_param2))


def update_leader(ap: Autopilot, stamp: Stamp) -> None:
    """Send the leader's requests now due, resend the unacknowledged, report the given up."""
    now = ap.mission_clock.now(stamp.sim_s)
    for sequence, speed in ap.leader.due(now):
        ap.status_text(
            mavlink.MAV_SEVERITY_INFO, f"Leader: requesting {speed:g} m/s (seq {sequence})"
        )
        send_leader_request(ap, sequence, speed, stamp)
    again, given_up = ap.leader.resend_due(
        stamp.sim_s, stamp.wall_s, ap.config.failsafe.wall_floor_s
    )
    for entry in again:
        send_leader_request(ap, entry.sequence, entry.speed_mps, stamp)
    for sequence in given_up:
        ap.status_text(
            mavlink.MAV_SEVERITY_WARNING, f"Leader: speed request {sequence} not acknowledged"
        )


def send_leader_request(ap: Autopilot, sequence: int, speed: float, stamp: Stamp) -> None:
    ap.send(
        mavlink.MAVLink_command_int_message(
            ap.config.failsafe.gcs_system,
            0,
            SPEED_CHANGE_FRAME,
            SPEED_CHANGE_COMMAND,
            0,
            0,
            *encode_speed_change(speed, 0, sequence),
        )
    )
    ap.leader.sent(sequence, speed, stamp.sim_s, stamp.wall_s)
