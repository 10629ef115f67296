"""What third-party tools (MAVProxy, MAVSDK, QGroundControl) rely on, in process on simulated
time (no sockets): the simulated autopilot behaves as ArduCopter 4.7 there. Arming in
STABILIZE, guided targets (position targets never time out, velocity targets do, ArduCopter's
type-mask reading), the mission protocol and AUTO, MAVFTP refused at once, the parameter list,
SYS_STATUS's geofence bits, reboot, CONDITION_YAW, and the honest refusals. The ArduCopter facts
are cited where each is tested (tests/sitl transcripts or the ArduPilot source file)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from tests.autopilot_bench import Bench
from tests.fakes.replay import load
from vehicles import telemetry
from vehicles.autopilot import AutopilotConfig, FailsafeConfig, Guided, Mode
from vehicles.autopilot import ftp as mavftp
from vehicles.autopilot.parameters import parameters
from vehicles.sim import DEFAULT_ORIGIN

LAT, LON, ALT = DEFAULT_ORIGIN.lat, DEFAULT_ORIGIN.lon, DEFAULT_ORIGIN.alt
ACCEPTED, FAILED, DENIED = (
    mavlink.MAV_RESULT_ACCEPTED,
    mavlink.MAV_RESULT_FAILED,
    mavlink.MAV_RESULT_DENIED,
)
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
RELATIVE = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT


def of_type(bench: Bench, kind: str, start: int = 0) -> list:
    return [m for m in bench.sent[start:] if m.get_type() == kind]


def command_int(bench: Bench, command: int, frame: int, *params: float, x=0, y=0, z=0.0) -> int:
    values = list(params) + [0.0] * (4 - len(params))
    bench.send(mavlink.MAVLink_command_int_message(1, 1, frame, command, 0, 0, *values, x, y, z))
    return bench.acks(command)[-1]


def set_mode(bench: Bench, mode: int) -> int:
    return bench.command(mavlink.MAV_CMD_DO_SET_MODE, 1, mode)


def position(bench: Bench) -> np.ndarray:
    return bench.dynamics.estimated(0)


# ---------------------------------------------------------------------- 1. arming ----------
def test_it_arms_in_stabilize_where_it_boots_then_takes_off_in_guided():
    """ArduCopter arms in STABILIZE (Mode::allows_arming; MAVSDK's arm() then takeoff()), then
    GUIDED + MAV_CMD_NAV_TAKEOFF as MAVSDK's takeoff_async_apm sends it."""
    bench = Bench()
    assert bench.autopilot.mode == Mode.STABILIZE
    assert bench.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
    assert bench.autopilot.armed and "Arming motors" in bench.texts()
    bench.run(3.0)
    assert bench.autopilot.landed and position(bench)[2] < 0.1  # armed, idling on the ground
    assert set_mode(bench, Mode.GUIDED) == ACCEPTED
    assert bench.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0) == ACCEPTED
    bench.run(6.0)
    assert bench.autopilot.airborne() and position(bench)[2] > 9.0


def test_armed_and_idle_on_the_ground_it_disarms_after_disarm_delay():
    """Copter::auto_disarm_check: landed with the throttle at zero for DISARM_DELAY (10 s)."""
    bench = Bench()
    assert bench.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
    bench.run(9.8)
    assert bench.autopilot.armed
    bench.run(0.4)
    assert not bench.autopilot.armed and bench.texts()[-1] == "Disarming motors"


@pytest.mark.parametrize("mode", [Mode.AUTO, Mode.LAND, Mode.RTL, Mode.BRAKE])
def test_arming_is_refused_where_arducopter_refuses_it(mode):
    bench = Bench()
    assert set_mode(bench, mode) == ACCEPTED  # disarmed: any mode (Copter::set_mode)
    assert bench.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == FAILED
    assert bench.texts()[-1] == "Arm: Mode not armable" and not bench.autopilot.armed


# ---------------------------------------------------------------------- 2-3. guided targets --
def test_a_position_only_target_is_flown_to_and_never_times_out():
    """MAVProxy `position 10 0 -10` (BODY_NED, type_mask 3576): ArduCopter's set_destination
    has no GUID_TIMEOUT, so it flies all the way and holds there."""
    bench = Bench()
    bench.fly(10.0)
    start = position(bench)
    yaw = float(bench.dynamics.yaw[0])
    bench.local_setpoint(10.0, 0.0, -10.0, mask=3576, frame=mavlink.MAV_FRAME_BODY_NED)
    bench.run(30.0)
    assert bench.autopilot.guided == Guided.GOTO
    expected = start + np.array([10 * math.sin(yaw), 10 * math.cos(yaw), 10.0])
    assert np.linalg.norm(position(bench) - expected) < 0.5
    assert not any("no setpoint" in text for text in bench.texts())


def test_velocity_targets_stop_after_guid_timeout():
    """MAVProxy `velocity 1 0 0` (BODY_NED, type_mask 4039 with the force bit): followed, and
    stopped after GUID_TIMEOUT (here ArduCopter's 3 s) without a new one."""
    bench = Bench(AutopilotConfig(boot_time_s=0.0, failsafe=FailsafeConfig(setpoint_timeout_s=3.0)))
    bench.fly(10.0)
    bench.local_setpoint(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, mask=4039, frame=mavlink.MAV_FRAME_BODY_NED)
    bench.run(2.9)
    assert bench.autopilot.guided == Guided.SETPOINTS
    assert abs(float(np.hypot(*bench.dynamics.velocity[0, :2])) - 1.0) < 0.1
    bench.run(0.2)
    assert bench.autopilot.guided == Guided.HOLD
    assert "Guided: no setpoint for 3 s, holding" in bench.texts()


def test_a_setpoint_timeout_brakes_at_wpnav_accel():
    """After GUID_TIMEOUT the copter stops at the guided acceleration (WPNAV_ACCEL), as
    ArduCopter's ModeGuided::pva_control_start gives the position controller the waypoint
    navigator's acceleration: from 10 m/s at 6 m/s^2, about 8.3 m (a gentler shaping
    deceleration of 3 m/s^2 ran 16.7 m, past a formation that stopped at a_max)."""
    bench = Bench(AutopilotConfig(boot_time_s=0.0, failsafe=FailsafeConfig(setpoint_timeout_s=1.0)))
    accel = bench.dynamics.config.airframe.max_acceleration_mps2
    assert dict((name, value) for name, value, _ in parameters(bench.autopilot))[
        "WPNAV_ACCEL"
    ] == pytest.approx(accel * 100)
    bench.fly(10.0)
    for _ in range(60):  # 6 s of 10 m/s east, velocity targets at 10 Hz
        bench.local_setpoint(0.0, 0.0, 0.0, 0.0, 10.0, 0.0, mask=0b110111000111)
        bench.run(0.1)
    while bench.autopilot.guided == Guided.SETPOINTS:
        bench.run(0.02)
    speed = float(np.hypot(*bench.dynamics.velocity[0, :2]))
    start = position(bench)
    bench.run(8.0)
    assert speed == pytest.approx(10.0, abs=0.3)
    run = float(np.hypot(*(position(bench) - start)[:2]))
    assert speed**2 / (2 * accel) - 0.5 <= run <= speed**2 / (2 * accel) + 1.5


@pytest.mark.parametrize(
    "mask",
    [
        4039,  # MAVProxy `velocity`: position and acceleration ignored, force, yaw, yaw rate
        3527,  # velocity, yaw ignored
        2503,  # MAVSDK set_velocity_ned: velocity and yaw
        455,  # velocity, yaw and yaw rate used
        0b110111000001,  # only x ignored: ArduCopter ignores the whole position group
        0b110000000111,  # velocity and acceleration
    ],
)
def test_velocity_masks_arducopter_accepts_are_followed(mask):
    """handle_message_set_position_target_local_ned: a group with any ignore bit is ignored, the
    force bit only matters with acceleration."""
    bench = Bench()
    bench.fly(10.0)
    bench.local_setpoint(0.0, 0.0, 0.0, 0.0, 2.0, 0.0, mask=mask, frame=mavlink.MAV_FRAME_LOCAL_NED)
    bench.run(0.9)  # within the 1 s setpoint timeout
    assert bench.autopilot.guided == Guided.SETPOINTS
    assert not bench.dynamics.use_position[0]
    assert abs(float(bench.dynamics.velocity[0, 0]) - 2.0) < 0.2  # east at 2 m/s


@pytest.mark.parametrize("mask", [3520, 3072])
def test_the_ground_stations_position_velocity_streams_still_time_out(mask):
    """The fleetline GCS's masks (fleetwire.messages) keep the 1 s setpoint timeout its failsafe
    and stall handling rely on."""
    bench = Bench()
    bench.fly(10.0)
    bench.local_setpoint(5.0, 0.0, -10.0, 1.0, 0.0, 0.0, mask=mask)
    bench.run(0.98)
    assert bench.autopilot.guided == Guided.SETPOINTS
    bench.run(0.04)
    assert bench.autopilot.guided == Guided.HOLD


# ---------------------------------------------------------------------- 4. missions ---------
def item(seq, command, lat=0.0, lon=0.0, alt=0.0, frame=RELATIVE, p1=0.0, p2=0.0, current=0):
    return mavlink.MAVLink_mission_item_int_message(
        1, 1, seq, frame, command, current, 1, p1, p2, 0.0, 0.0,
        round(lat * 1e7), round(lon * 1e7), alt,
    )  # fmt: skip


def home_item():
    return item(0, mavlink.MAV_CMD_NAV_WAYPOINT, LAT, LON, ALT, frame=mavlink.MAV_FRAME_GLOBAL)


DLAT = 30.0 / 111_200.0  # about 30 m north
DLON = 30.0 / (111_200.0 * math.cos(math.radians(LAT)))  # about 30 m east


def survey() -> list:
    """Home, take-off to 10 m, 30 m north, speed 4 m/s, 30 m east (2 s), land."""
    return [
        home_item(),
        item(1, mavlink.MAV_CMD_NAV_TAKEOFF, alt=10.0),
        item(2, mavlink.MAV_CMD_NAV_WAYPOINT, LAT + DLAT, LON, 12.0),
        item(3, mavlink.MAV_CMD_DO_CHANGE_SPEED, p1=1.0, p2=4.0, frame=mavlink.MAV_FRAME_MISSION),
        item(4, mavlink.MAV_CMD_NAV_WAYPOINT, LAT + DLAT, LON + DLON, 12.0, p1=2.0),
        item(5, mavlink.MAV_CMD_NAV_LAND),
    ]


SURVEY = survey()


def renumbered(items: list) -> list:
    for seq, message in enumerate(items):
        message.seq = seq
    return items


def upload(bench: Bench, items) -> int:
    """MISSION_COUNT, then each item as the vehicle asks for it; the MISSION_ACK type."""
    start = len(bench.sent)
    bench.send(mavlink.MAVLink_mission_count_message(1, 1, len(items)))
    for _ in items:
        asked = of_type(bench, "MISSION_REQUEST_INT", start)
        if not asked or of_type(bench, "MISSION_ACK", start):
            break
        bench.send(items[asked[-1].seq])
        start = len(bench.sent) - 1
    return of_type(bench, "MISSION_ACK")[-1].type


def test_a_mission_uploads_item_by_item_and_downloads_with_home_as_item_0():
    """MissionItemProtocol: MISSION_COUNT -> MISSION_REQUEST_INT 0..n-1 -> `Flight plan
    received` + MISSION_ACK ACCEPTED; item 0 reads back as home (AP_Mission)."""
    bench = Bench()
    start = len(bench.sent)
    assert upload(bench, SURVEY) == mavlink.MAV_MISSION_ACCEPTED
    assert [m.seq for m in of_type(bench, "MISSION_REQUEST_INT", start)] == list(range(6))
    assert "Flight plan received" in bench.texts()
    bench.send(mavlink.MAVLink_mission_request_list_message(1, 1))
    assert of_type(bench, "MISSION_COUNT")[-1].count == 6
    bench.send(mavlink.MAVLink_mission_request_int_message(1, 1, 0))
    home = of_type(bench, "MISSION_ITEM_INT")[-1]
    assert (home.seq, home.command, home.frame) == (0, 16, mavlink.MAV_FRAME_GLOBAL)
    assert (home.x, home.y, round(home.z, 3)) == (round(LAT * 1e7), round(LON * 1e7), ALT)
    bench.send(mavlink.MAVLink_mission_request_int_message(1, 1, 4))
    got = of_type(bench, "MISSION_ITEM_INT")[-1]
    assert (got.seq, got.command, got.x, got.y, got.param1) == (
        4,
        16,
        SURVEY[4].x,
        SURVEY[4].y,
        2.0,
    )
    bench.send(mavlink.MAVLink_mission_request_int_message(1, 1, 9))  # beyond the mission
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_ERROR
    bench.send(mavlink.MAVLink_mission_clear_all_message(1, 1))
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_ACCEPTED
    bench.send(mavlink.MAVLink_mission_request_list_message(1, 1))
    assert of_type(bench, "MISSION_COUNT")[-1].count == 0


def test_mission_uploads_refuse_what_is_not_flown_with_arducopters_results():
    bench = Bench()
    loiter = item(2, mavlink.MAV_CMD_NAV_LOITER_TIME, LAT, LON, 10.0)
    assert upload(bench, [home_item(), SURVEY[1], loiter]) == mavlink.MAV_MISSION_UNSUPPORTED
    assert "Mission: command 19 not supported" in bench.texts()
    terrain = item(1, 16, LAT, LON, 10.0, frame=mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)
    assert upload(bench, [home_item(), terrain]) == mavlink.MAV_MISSION_UNSUPPORTED_FRAME
    bench.send(mavlink.MAVLink_mission_request_list_message(1, 1))
    assert of_type(bench, "MISSION_COUNT")[-1].count == 0  # nothing was replaced
    bench.send(mavlink.MAVLink_mission_count_message(1, 1, 10_000))
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_NO_SPACE
    bench.send(mavlink.MAVLink_mission_count_message(1, 1, 3, mavlink.MAV_MISSION_TYPE_FENCE))
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_UNSUPPORTED
    # out of sequence: INVALID_SEQUENCE, the upload goes on; another sender: DENIED
    bench.send(mavlink.MAVLink_mission_count_message(1, 1, 2))
    bench.send(SURVEY[1])
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_INVALID_SEQUENCE
    other = mavlink.MAVLink(None, srcSystem=42, srcComponent=190)
    for m in bench.codec.parse_buffer(
        bytearray(mavlink.MAVLink_mission_count_message(1, 1, 2).pack(other))
    ):
        bench.autopilot.handle(m, bench.stamp())
    bench.collect()
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_DENIED
    # a MISSION_ITEM (float) is taken, with ArduPilot's warning
    float_item = mavlink.MAVLink_mission_item_message(
        1, 1, 0, 0, 16, 0, 1, 0, 0, 0, 0, LAT, LON, ALT
    )
    bench.send(float_item)
    assert "got MISSION_ITEM; GCS should send MISSION_ITEM_INT" in bench.texts()
    assert of_type(bench, "MISSION_REQUEST_INT")[-1].seq == 1


def test_an_unanswered_item_is_asked_again_then_the_upload_times_out():
    bench = Bench()
    start = len(bench.sent)
    bench.send(mavlink.MAVLink_mission_count_message(1, 1, 3))
    bench.run(1.1)
    assert [m.seq for m in of_type(bench, "MISSION_REQUEST_INT", start)] == [0, 0]
    bench.run(7.0)
    assert "Mission upload timeout" in bench.texts()
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_OPERATION_CANCELLED


def fly_survey(bench: Bench) -> None:
    assert upload(bench, SURVEY) == mavlink.MAV_MISSION_ACCEPTED
    assert set_mode(bench, Mode.GUIDED) == ACCEPTED
    assert bench.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED


def test_auto_flies_takeoff_waypoints_speed_change_and_land_then_disarms():
    """mode_auto.cpp / AP_Mission: MISSION_START switches to AUTO and auto-arms; each item starts
    with `Mission: N <type>` and MISSION_CURRENT, ends with MISSION_ITEM_REACHED; the
    DO_CHANGE_SPEED after item 2 sets the speed while it flies; LAND disarms on touch-down."""
    bench = Bench()
    fly_survey(bench)
    start = len(bench.sent)
    assert bench.command(mavlink.MAV_CMD_MISSION_START) == ACCEPTED
    speeds = []
    for _ in range(120):
        bench.run(1.0)
        speeds.append(float(np.hypot(*bench.dynamics.velocity[0, :2])))
        if not bench.autopilot.armed:
            break
    assert not bench.autopilot.armed and bench.autopilot.mode == Mode.AUTO
    assert [m.seq for m in of_type(bench, "MISSION_ITEM_REACHED", start)] == [1, 2, 4, 5]
    currents = [m.seq for m in of_type(bench, "MISSION_CURRENT", start)]
    assert {1, 2, 4, 5} <= set(currents) and currents == sorted(currents)
    texts = bench.texts()
    for text in ("Mission: 1 Takeoff", "Mission: 2 WP", "Mission: 3 ChangeSpeed", "Reached command #2",
                 "Mission: 4 WP", "Reached command #4", "Mission: 5 Land", "Disarming motors"):  # fmt: skip
        assert text in texts
    assert max(speeds) <= 4.2  # DO_CHANGE_SPEED 4 m/s from item 2 on
    north, east = 30.0, 30.0
    assert np.hypot(position(bench)[0] - east, position(bench)[1] - north) < 2.5
    assert bench.autopilot.mission_complete


def test_an_rtl_item_returns_home_lands_and_disarms():
    bench = Bench()
    mission = [*SURVEY[:3], item(3, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)]
    assert upload(bench, mission) == mavlink.MAV_MISSION_ACCEPTED
    assert set_mode(bench, Mode.GUIDED) == ACCEPTED
    assert bench.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
    assert bench.command(mavlink.MAV_CMD_MISSION_START) == ACCEPTED
    bench.run(12.0)
    assert (bench.autopilot.auto_phase, bench.autopilot.rtl_phase) == ("rtl", "return")
    assert position(bench)[2] >= 14.0  # climbed to RTL_ALT (15 m) first
    for _ in range(90):
        bench.run(1.0)
        if not bench.autopilot.armed:
            break
    assert not bench.autopilot.armed
    assert of_type(bench, "MISSION_ITEM_REACHED")[-1].seq == 3
    assert np.hypot(*position(bench)[:2]) < 1.5


def test_auto_needs_a_mission_and_on_the_ground_a_takeoff_first():
    """ModeAuto::init and Copter::mode_change_failed."""
    bench = Bench()
    assert set_mode(bench, Mode.GUIDED) == ACCEPTED
    assert bench.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
    assert set_mode(bench, Mode.AUTO) == FAILED
    assert bench.texts()[-1] == "Mode change to AUTO failed: init failed"
    fresh = survey()
    no_takeoff = renumbered([fresh[0], fresh[2], fresh[5]])
    assert upload(bench, no_takeoff) == mavlink.MAV_MISSION_ACCEPTED
    assert set_mode(bench, Mode.AUTO) == FAILED
    assert bench.texts()[-2:] == [
        "Auto: Missing Takeoff Cmd",
        "Mode change to AUTO failed: init failed",
    ]
    assert bench.command(mavlink.MAV_CMD_MISSION_START, 1, 3) == DENIED  # first/last item


def test_in_auto_on_the_ground_the_takeoff_waits_for_mission_start():
    """Copter::update_auto_armed: AUTO selected on the ground (MAVProxy `mode auto`, MAVSDK
    Mission.start_mission) does not take off with the throttle at zero; MISSION_START does."""
    bench = Bench()
    fly_survey(bench)
    assert set_mode(bench, Mode.AUTO) == ACCEPTED
    bench.run(3.0)
    assert bench.autopilot.landed and bench.autopilot.mission_nav == 1
    assert of_type(bench, "MISSION_CURRENT")[-1].mission_state == mavlink.MISSION_STATE_ACTIVE
    assert bench.command(mavlink.MAV_CMD_MISSION_START) == ACCEPTED
    bench.run(3.0)
    assert bench.autopilot.airborne() and bench.autopilot.auto_phase == "takeoff"


def test_leaving_auto_pauses_the_mission_and_auto_resumes_it_at_the_same_item():
    """AP_Mission::resume (MIS_RESTART 0); MISSION_CLEAR_ALL refused while AUTO runs it."""
    bench = Bench()
    fly_survey(bench)
    bench.command(mavlink.MAV_CMD_MISSION_START)
    bench.run(8.0)
    assert bench.autopilot.mission_nav == 2
    assert set_mode(bench, Mode.LOITER) == ACCEPTED
    bench.run(1.0)
    assert of_type(bench, "MISSION_CURRENT")[-1].mission_state == mavlink.MISSION_STATE_PAUSED
    texts = len(bench.texts())
    assert set_mode(bench, Mode.AUTO) == ACCEPTED
    bench.run(0.1)
    assert bench.texts()[texts:][:2] == ["Mission: 2 WP", "Mission: 3 ChangeSpeed"]
    bench.send(mavlink.MAVLink_mission_clear_all_message(1, 1))
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_ERROR
    assert set_mode(bench, Mode.LOITER) == ACCEPTED
    bench.send(mavlink.MAVLink_mission_clear_all_message(1, 1))
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_ACCEPTED


# ---------------------------------------------------------------------- 5. FTP, parameters --
def ftp_request(bench: Bench, opcode: int, seq: int = 7, session: int = 3, path: bytes = b""):
    payload = mavftp.pack(mavftp.FtpOp(seq, session, opcode, len(path)), path)
    bench.send(mavlink.MAVLink_file_transfer_protocol_message(0, 1, 1, payload))
    reply = of_type(bench, "FILE_TRANSFER_PROTOCOL")[-1]
    return reply, mavftp.FtpOp.unpack(reply.payload), reply.payload[12]


@pytest.mark.parametrize(
    ("opcode", "answer", "error"),
    [
        (mavftp.OPEN_FILE_RO, mavftp.NAK, mavftp.ERR_FILE_NOT_FOUND),  # @PARAM/param.pck
        (mavftp.LIST_DIRECTORY, mavftp.NAK, mavftp.ERR_FILE_NOT_FOUND),
        (mavftp.TERMINATE_SESSION, mavftp.NAK, mavftp.ERR_INVALID_SESSION),
        (mavftp.BURST_READ_FILE, mavftp.NAK, mavftp.ERR_INVALID_SESSION),
        (mavftp.CREATE_FILE, mavftp.NAK, mavftp.ERR_FAIL),
        (99, mavftp.NAK, mavftp.ERR_UNKNOWN_COMMAND),
        (mavftp.RESET_SESSIONS, mavftp.ACK, 0),
    ],
)
def test_mavftp_requests_are_answered_at_once_so_tools_fall_back(opcode, answer, error):
    """MAVProxy's param module asks for @PARAM/param.pck over FTP first and falls back to
    PARAM_REQUEST_LIST when the open fails; a NAK now saves it its FTP timeouts."""
    bench = Bench()
    reply, op, data = ftp_request(bench, opcode, path=b"@PARAM/param.pck?withdefaults=1")
    assert (reply.target_system, reply.target_component) == (255, 190)  # the sender
    assert (op.seq, op.session, op.opcode, op.req_opcode) == (8, 3, answer, opcode)
    assert len(reply.payload) == 251
    if answer == mavftp.NAK:
        assert op.size == 1 and data == error


def test_param_request_list_streams_every_parameter_with_its_count_and_index():
    bench = Bench()
    start = len(bench.sent)
    bench.send(mavlink.MAVLink_param_request_list_message(1, 1))
    values = of_type(bench, "PARAM_VALUE", start)
    assert [v.param_index for v in values] == list(range(len(values)))
    assert {v.param_count for v in values} == {len(values)}
    names = {v.param_id: v.param_value for v in values}
    assert names["FENCE_ENABLE"] == 0 and names["WPNAV_SPEED"] == 1000.0
    assert names["WPNAV_RADIUS"] == 200.0 and names["GUID_TIMEOUT"] == 1.0


# ---------------------------------------------------------------------- 6. SYS_STATUS -------
def test_sys_status_words_are_arducopters_with_the_fence_present_disabled_and_healthy():
    """ardupilot-session.jsonl, ready to fly: present 0x5371fc2f, enabled 0x5361fc2f (the
    geofence present, not enabled), health 0x4771fc2f + PREARM_CHECK. MAVProxy's fence module
    says `fence breach` when the health bit is clear: it must be set."""
    recorded = [r.fields for r in load("ardupilot-session.jsonl") if r.type == "SYS_STATUS"][-1]
    bench = Bench()
    bench.run(1.1)
    status = of_type(bench, "SYS_STATUS")[-1]
    fence = mavlink.MAV_SYS_STATUS_GEOFENCE
    missing = telemetry.NOT_SIMULATED
    assert (
        status.onboard_control_sensors_present
        == recorded["onboard_control_sensors_present"] & ~missing
    )
    assert (
        status.onboard_control_sensors_enabled
        == recorded["onboard_control_sensors_enabled"] & ~missing
    )
    assert status.onboard_control_sensors_health == recorded["onboard_control_sensors_health"]
    assert status.onboard_control_sensors_present & fence
    assert not status.onboard_control_sensors_enabled & fence
    assert status.onboard_control_sensors_health & fence
    enabled = status.onboard_control_sensors_enabled
    assert status.onboard_control_sensors_health & enabled == enabled  # nothing failing


# ---------------------------------------------------------------------- 7. commands ---------
def test_reboot_acknowledges_then_boots_again_keeping_the_mission():
    """GCS_MAVLINK::handle_preflight_reboot: FAILED armed, UNSUPPORTED unless param1 is 1 or 3,
    else the ACK goes first, then the autopilot boots."""
    bench = Bench(AutopilotConfig(boot_time_s=1.0))
    bench.run(1.5)
    assert upload(bench, SURVEY) == mavlink.MAV_MISSION_ACCEPTED
    assert set_mode(bench, Mode.GUIDED) == ACCEPTED
    assert bench.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED
    assert bench.command(mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1) == FAILED
    assert bench.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0) == ACCEPTED
    assert bench.command(mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 2) == UNSUPPORTED  # shutdown
    assert bench.command(mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 0) == UNSUPPORTED
    start = len(bench.sent)
    assert bench.command(mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1) == ACCEPTED
    bench.run(0.5)
    beat = of_type(bench, "HEARTBEAT", start)[-1]
    assert (beat.custom_mode, beat.system_status) == (Mode.STABILIZE, mavlink.MAV_STATE_BOOT)
    assert bench.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == FAILED
    assert bench.texts()[-1] == "Arm: System not initialised"
    bench.run(1.0)
    assert bench.texts().count("ArduPilot Ready") == 2
    assert bench.autopilot.mode == Mode.STABILIZE and not bench.autopilot.armed
    bench.send(mavlink.MAVLink_mission_request_list_message(1, 1))
    assert of_type(bench, "MISSION_COUNT")[-1].count == len(SURVEY)


def test_condition_yaw_turns_the_vehicle_in_guided():
    """GCS_MAVLINK_Copter::handle_MAV_CMD_CONDITION_YAW: FAILED unless 0 <= param1 <= 360 and
    param4 is 0 or 1."""
    bench = Bench()
    bench.fly(10.0)
    assert bench.command(mavlink.MAV_CMD_CONDITION_YAW, 90.0, 0, 1, 0) == ACCEPTED
    bench.run(3.0)
    assert math.degrees(float(bench.dynamics.yaw[0])) == pytest.approx(90.0, abs=1.0)
    assert bench.command(mavlink.MAV_CMD_CONDITION_YAW, 30.0, 0, -1, 1) == ACCEPTED  # relative
    bench.run(3.0)
    assert math.degrees(float(bench.dynamics.yaw[0])) == pytest.approx(60.0, abs=1.0)
    assert bench.command(mavlink.MAV_CMD_CONDITION_YAW, 400.0) == FAILED
    assert bench.command(mavlink.MAV_CMD_CONDITION_YAW, 10.0, 0, 1, 2) == FAILED


def test_what_arducopter_does_not_do_is_refused_as_arducopter_refuses_it():
    """DO_CHANGE_ALTITUDE is Plane's (GCS_MAVLINK_Plane), not Copter's: UNSUPPORTED, as any
    unknown command (ardupilot-refusals.jsonl: command 12345 -> 3); a COMMAND_INT take-off in
    another frame than GLOBAL_RELATIVE_ALT is DENIED (handle_MAV_CMD_NAV_TAKEOFF)."""
    bench = Bench()
    bench.fly(10.0)
    assert bench.command(mavlink.MAV_CMD_DO_CHANGE_ALTITUDE, 20.0, 0) == UNSUPPORTED
    assert bench.command(12345) == UNSUPPORTED
    assert (
        command_int(bench, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_FRAME_GLOBAL, z=20.0) == DENIED
    )
    assert bench.command(mavlink.MAV_CMD_NAV_LOITER_UNLIM) == ACCEPTED
    assert bench.autopilot.mode == Mode.LOITER
    bench.send(item(0, 16, LAT, LON, 20.0, current=3))  # guided change-altitude item
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_UNSUPPORTED


def test_guided_waypoints_rtl_and_read_only_parameters_as_the_tools_use_them():
    """MAVProxy `guided LAT LON ALT` (MISSION_ITEM_INT current 2), `mode rtl`, `param set`."""
    bench = Bench()
    bench.fly(10.0)
    bench.send(item(0, mavlink.MAV_CMD_NAV_WAYPOINT, LAT + DLAT, LON, 10.0, current=2))
    assert of_type(bench, "MISSION_ACK")[-1].type == mavlink.MAV_MISSION_ACCEPTED
    bench.run(12.0)
    assert np.hypot(position(bench)[0], position(bench)[1] - 30.0) < 0.5
    assert set_mode(bench, Mode.RTL) == ACCEPTED
    for _ in range(60):
        bench.run(1.0)
        if not bench.autopilot.armed:
            break
    assert not bench.autopilot.armed and np.hypot(*position(bench)[:2]) < 1.5
    bench.send(mavlink.MAVLink_param_set_message(1, 1, b"WPNAV_SPEED", 500.0, 9))
    echo = of_type(bench, "PARAM_VALUE")[-1]
    assert (echo.param_id, echo.param_value) == ("WPNAV_SPEED", 1000.0)
    assert bench.texts()[-1] == "Param WPNAV_SPEED is read-only"
