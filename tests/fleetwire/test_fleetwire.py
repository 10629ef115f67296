"""What both ends of the wire agree on (`fleetwire`), pinned to the numbers docs/outputs.md and the
autopilots' documentation give: the one place these numbers are typed by hand."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire import messages, modes


def test_identity_masks_and_names_are_the_contracts():
    assert (messages.GCS_SYSTEM_ID, messages.GCS_COMPONENT_ID) == (255, 190)
    assert messages.MASK_POSITION_VELOCITY == 3520
    assert messages.MASK_POSITION_VELOCITY_ACCELERATION == 3072
    assert messages.MISSION_TIME_NAME == b"MSN_TIME"


def test_mode_numbers_come_from_pymavlink_as_the_autopilots_number_them():
    copter = {"STABILIZE": 0, "GUIDED": 4, "LOITER": 5, "RTL": 6, "LAND": 9, "BRAKE": 17}
    assert {name: modes.COPTER_MODE[name] for name in copter} == copter
    assert modes.COPTER_MODE_NAME[21] == "SMART_RTL"
    assert modes.PX4_MODE["OFFBOARD"] == 0x00060000
    assert modes.PX4_MODE["LOITER"] == 0x03040000  # AUTO.LOITER
    assert modes.PX4_MODE_PARTS["LAND"] == (4, 6)  # AUTO.LAND
    assert modes.px4_mode_name(modes.PX4_MODE["TAKEOFF"]) == "TAKEOFF"
    with pytest.raises(TypeError):
        modes.COPTER_MODE["GUIDED"] = 5  # shared: read-only


def test_mission_time_round_trips_in_ms_within_int32():
    assert messages.encode_mission_time(12.3456) == 12346
    assert messages.encode_mission_time(-1.5) == -1500
    assert messages.encode_mission_time(1e12) == 2**31 - 1
    assert messages.encode_mission_time(math.nan) == 0
    msg = mavlink.MAVLink_named_value_int_message(0, messages.MISSION_TIME_NAME, 12346)
    assert messages.decode_mission_time(msg) == 12.346
    other = mavlink.MAVLink_named_value_int_message(0, b"X", 12346)
    assert messages.decode_mission_time(other) is None


def wire(msg):
    """`msg` sent by the GCS and decoded as the other end sees it."""
    sender = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    receiver = mavlink.MAVLink(None)
    return receiver.decode(bytearray(msg.pack(sender)))


def test_a_speed_change_decodes_to_what_was_encoded():
    params = messages.encode_speed_change(7.5, 123_400, 3)
    assert params == (1.0, 7.5, -1.0, 0.0, 123_400, 3, 0.0)  # docs/outputs.md: param1 1, x, y
    msg = mavlink.MAVLink_command_int_message(
        1, 1, messages.SPEED_CHANGE_FRAME, messages.SPEED_CHANGE_COMMAND, 0, 0, *params
    )
    change = messages.decode_speed_change(wire(msg))
    assert change == messages.SpeedChangeCommand(7.5, 123_400, 3)
    assert (change.effective_s, change.sequence) == (123.4, 3)
    leader = messages.decode_speed_change(
        wire(mavlink.MAVLink_command_long_message(255, 0, 178, 0, 1, 4.0, -1, 0, 0, 0, 0))
    )
    assert leader == messages.SpeedChangeCommand(4.0, None, None)
    assert (leader.effective_s, leader.sequence) == (None, 0)  # at once, unsequenced
    takeoff = mavlink.MAVLink_command_long_message(1, 1, 22, 0, 0, 0, 0, 0, 0, 0, 10)
    assert messages.decode_speed_change(wire(takeoff)) is None


def test_a_backlog_keeps_the_newest_telemetry_of_each_system_and_every_other_frame():
    """Of a backlog, each system's streamed telemetry is shed but for the newest two of each
    message; an acknowledgement and a text in the middle, and a frame of another system,
    stay, in their order."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from fleetwire.frames import frames, newest_telemetry

    def frame(sysid, build):
        codec = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=1)
        return build(codec).pack(codec)

    def beat(sysid, status):
        return frame(sysid, lambda c: c.heartbeat_encode(2, 3, 0, 4, status))

    backlog = [beat(1, k % 8) for k in range(100)]
    ack = frame(1, lambda c: c.command_ack_encode(176, 0, 0, 0, 255, 190))
    text = frame(1, lambda c: c.statustext_encode(4, b"Guided: no setpoint"))
    stranger = beat(7, 5)
    backlog[50:50] = [ack, text, stranger]
    kept = newest_telemetry(backlog, keep=2)
    assert kept == [ack, text, stranger, backlog[-2], backlog[-1]]
    assert [frames(d)[0][:2] for d in kept] == [(77, 1), (253, 1), (0, 7), (0, 1), (0, 1)]
