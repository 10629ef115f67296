"""A real `vehicles sim` process over UDP, driven with pymavlink as a GCS would: identity,
modes, arming and take-off refusals, unknown commands, speed changes, message intervals and
requests, parameters, missions, time sync and a leader's speed requests."""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.modes import COPTER_MODE
from vehicles.testing import GroundStation, VehicleProcess, local_of

SPEEDUP = 5.0
GUIDED, LOITER, LAND, STABILIZE, RTL = (
    COPTER_MODE[m] for m in ("GUIDED", "LOITER", "LAND", "STABILIZE", "RTL")
)
UNKNOWN_COMMAND = 12345


@pytest.fixture(scope="module")
def vehicle():
    args = ["--seed", "1", "--positions", "12,-7"]
    with VehicleProcess(count=1, speedup=SPEEDUP, args=args) as process:
        gcs = GroundStation(process.port(), speedup=SPEEDUP)
        gcs.connect()
        gcs.wait_armable()
        yield gcs
        gcs.close()
        code, stderr = process.stop()
        assert code == 0, stderr


@pytest.fixture
def gcs(vehicle: GroundStation) -> GroundStation:
    """The module's vehicle, disarmed and in STABILIZE at the start of each test."""
    vehicle.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0)
    vehicle.set_mode(STABILIZE)
    vehicle.wait_for(
        lambda: vehicle.heartbeat_is(custom_mode=STABILIZE, armed=False), 5.0, "STABILIZE, disarmed"
    )
    return vehicle


def barrier(gcs: GroundStation) -> int:
    """An unknown command whose UNSUPPORTED ack proves everything sent before was handled."""
    start = len(gcs.acks)
    assert gcs.command(UNKNOWN_COMMAND).result == mavlink.MAV_RESULT_UNSUPPORTED
    return start


def test_heartbeat_identifies_an_arducopter_at_one_hertz(gcs: GroundStation):
    beat = gcs.latest["HEARTBEAT"]
    assert beat.type == mavlink.MAV_TYPE_QUADROTOR
    assert beat.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert beat.mavlink_version == 3 and beat.get_header().srcComponent == 1
    assert beat.base_mode == 81 and beat.system_status == mavlink.MAV_STATE_STANDBY  # as ArduCopter
    assert gcs.conn.WIRE_PROTOCOL_VERSION == "2.0"
    beats: list[float] = []

    def listener(message) -> None:
        if message.get_type() == "HEARTBEAT":
            beats.append(gcs.tick_time_s)

    gcs.listeners.append(listener)
    gcs.run_for(5.0)
    gcs.listeners.remove(listener)
    assert 4 <= len(beats) <= 6
    assert np.allclose(np.diff(beats), 1.0, atol=0.03)


def test_do_set_mode_is_acknowledged_and_set_mode_is_not(gcs: GroundStation):
    start = len(gcs.acks)
    gcs.mav.set_mode_send(1, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED)
    barrier(gcs)
    assert [a.command for a in gcs.acks[start:]] == [UNKNOWN_COMMAND]
    gcs.wait_for(lambda: gcs.heartbeat_is(custom_mode=GUIDED), 5.0, "GUIDED")
    assert gcs.latest["HEARTBEAT"].base_mode == 89
    assert gcs.set_mode(LOITER) == mavlink.MAV_RESULT_ACCEPTED
    gcs.wait_for(lambda: gcs.heartbeat_is(custom_mode=LOITER), 5.0, "LOITER")
    texts = len(gcs.texts)
    assert gcs.set_mode(99) == mavlink.MAV_RESULT_FAILED
    assert gcs.text_matching("No such mode 99", texts)
    texts, start = len(gcs.texts), len(gcs.acks)
    gcs.mav.set_mode_send(1, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 99)
    barrier(gcs)
    assert gcs.text_matching("No such mode 99", texts)
    assert [a.command for a in gcs.acks[start:]] == [UNKNOWN_COMMAND]
    assert gcs.heartbeat_is(custom_mode=LOITER)


def test_arming_is_refused_outside_stabilize_guided_and_loiter_with_a_reason(gcs: GroundStation):
    for mode in (LAND, RTL):
        assert gcs.set_mode(mode) == mavlink.MAV_RESULT_ACCEPTED
        texts = len(gcs.texts)
        assert gcs.arm() == mavlink.MAV_RESULT_FAILED
        refusal = gcs.text_matching("Arm: Mode not armable", texts)
        assert refusal and refusal.severity == mavlink.MAV_SEVERITY_CRITICAL
    barrier(gcs)
    assert gcs.heartbeat_is(armed=False)
    assert gcs.set_mode(STABILIZE) == mavlink.MAV_RESULT_ACCEPTED  # ArduCopter arms in it
    assert gcs.arm() == mavlink.MAV_RESULT_ACCEPTED
    gcs.wait_for(lambda: gcs.heartbeat_is(custom_mode=STABILIZE, armed=True), 5.0, "armed")


def test_arm_and_disarm_on_the_ground(gcs: GroundStation):
    assert gcs.set_mode(GUIDED) == mavlink.MAV_RESULT_ACCEPTED
    texts = len(gcs.texts)
    assert gcs.arm() == mavlink.MAV_RESULT_ACCEPTED
    assert gcs.text_matching("Arming motors", texts)
    gcs.wait_for(
        lambda: gcs.heartbeat_is(custom_mode=GUIDED, armed=True), 5.0, "armed in the heartbeat"
    )
    assert gcs.latest["HEARTBEAT"].base_mode == 217
    assert (
        gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0).result == mavlink.MAV_RESULT_ACCEPTED
    )
    gcs.wait_for(lambda: gcs.heartbeat_is(armed=False), 5.0, "disarmed in the heartbeat")
    assert (
        gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0).result == mavlink.MAV_RESULT_ACCEPTED
    )


def test_takeoff_is_refused_unless_armed_in_guided(gcs: GroundStation):
    takeoff = (mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 20.0)
    assert gcs.command(*takeoff).result == mavlink.MAV_RESULT_FAILED  # STABILIZE
    assert gcs.set_mode(GUIDED) == mavlink.MAV_RESULT_ACCEPTED
    texts = len(gcs.texts)
    assert gcs.command(*takeoff).result == mavlink.MAV_RESULT_FAILED  # disarmed
    assert gcs.text_matching("Takeoff: not armed", texts)
    assert gcs.arm() == mavlink.MAV_RESULT_ACCEPTED
    nan_altitude = (mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, float("nan"))
    assert gcs.command(*nan_altitude).result == mavlink.MAV_RESULT_DENIED


def test_unknown_commands_are_unsupported_and_other_systems_ignored(gcs: GroundStation):
    assert gcs.command(UNKNOWN_COMMAND, 1).result == mavlink.MAV_RESULT_UNSUPPORTED
    assert gcs.command_int(UNKNOWN_COMMAND, 1).result == mavlink.MAV_RESULT_UNSUPPORTED
    start = len(gcs.acks)
    gcs.mav.command_long_send(
        7, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, GUIDED, 0, 0, 0, 0, 0
    )  # system 7
    gcs.mav.command_long_send(
        1, 100, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, GUIDED, 0, 0, 0, 0, 0
    )  # a camera
    barrier(gcs)
    assert [a.command for a in gcs.acks[start:]] == [UNKNOWN_COMMAND]
    assert gcs.heartbeat_is(custom_mode=STABILIZE)


def test_speed_changes_are_acknowledged_recorded_once_and_timed(gcs: GroundStation):
    def change(speed: float, sequence: int, effective_ms: int = 0):
        return gcs.command_int(
            mavlink.MAV_CMD_DO_CHANGE_SPEED,
            1,
            speed,
            -1,
            frame=mavlink.MAV_FRAME_MISSION,
            x=effective_ms,
            y=sequence,
        )

    def fleet_speed() -> float:
        gcs.latest.pop("NAMED_VALUE_FLOAT", None)
        return gcs.wait_for(lambda: gcs.latest.get("NAMED_VALUE_FLOAT"), 5.0, "FLEET_SPD").value

    ack = change(4.0, 7)
    assert (ack.result, ack.result_param2) == (mavlink.MAV_RESULT_ACCEPTED, 7)
    assert fleet_speed() == 4.0
    ack = change(6.0, 7)  # a retransmission with the same sequence number: acknowledged, dropped
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED and fleet_speed() == 4.0
    assert change(6.0, 8).result == mavlink.MAV_RESULT_ACCEPTED and fleet_speed() == 6.0
    assert (
        gcs.command(mavlink.MAV_CMD_DO_CHANGE_SPEED, 1, 3.0, -1).result
        == mavlink.MAV_RESULT_ACCEPTED
    )
    assert fleet_speed() == 3.0
    assert change(float("nan"), 9).result == mavlink.MAV_RESULT_DENIED
    # mission clock: MSN_TIME from the GCS; a change effective 3 s of mission time later
    gcs.mav.named_value_int_send(0, b"MSN_TIME", 100_000)
    synced = gcs.wait_for(lambda: gcs.latest.get("NAMED_VALUE_INT"), 5.0, "the vehicle's MSN_TIME")
    assert abs(synced.value - 100_000) < 1500
    effective_at = gcs.vehicle_time() + 3.0
    assert change(2.0, 10, effective_ms=gcs.latest["NAMED_VALUE_INT"].value + 3000).result == 0
    assert fleet_speed() == 3.0
    gcs.wait_for(lambda: gcs.vehicle_time() > effective_at + 1.5, 10.0, "the effective time")
    assert fleet_speed() == 2.0


def test_message_intervals_and_requests(gcs: GroundStation):
    ack = gcs.command(
        mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 200_000
    )
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    stamps: list[float] = []

    def count(message) -> None:
        if message.get_type() == "GLOBAL_POSITION_INT":
            stamps.append(message.time_boot_ms / 1000.0)

    gcs.listeners.append(count)
    gcs.run_for(4.0)
    gcs.listeners.remove(count)
    assert np.allclose(np.diff(stamps), 0.2, atol=0.021)
    gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 0)
    assert (
        gcs.command(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, 33).result == mavlink.MAV_RESULT_ACCEPTED
    )
    interval = gcs.wait_for(lambda: gcs.latest.get("MESSAGE_INTERVAL"), 5.0, "MESSAGE_INTERVAL")
    assert (interval.message_id, interval.interval_us) == (33, 100_000)
    assert (
        gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 9999, 100_000).result
        == mavlink.MAV_RESULT_FAILED
    )
    assert gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 9999).result == mavlink.MAV_RESULT_FAILED
    assert gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 148).result == mavlink.MAV_RESULT_ACCEPTED
    version = gcs.wait_for(lambda: gcs.latest.get("AUTOPILOT_VERSION"), 5.0, "AUTOPILOT_VERSION")
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 and version.uid == 1
    home = gcs.home()
    origin = (45.7640, 4.8357, 170.0)  # the default --home
    assert np.allclose(local_of(origin, *home), [12.0, -7.0, 0.0], atol=1.0)  # --positions 12,-7


def test_parameters_missions_and_time_sync(gcs: GroundStation):
    values: dict[str, float] = {}

    def listener(message) -> None:
        if message.get_type() == "PARAM_VALUE":
            values[message.param_id] = message.param_value

    def complete() -> bool:
        return "PARAM_VALUE" in gcs.latest and len(values) == gcs.latest["PARAM_VALUE"].param_count

    gcs.listeners.append(listener)
    gcs.mav.param_request_list_send(1, 1)
    gcs.wait_for(complete, 5.0, "every parameter")
    assert (
        values["SYSID_THISMAV"] == 1
        and values["FS_GCS_TIMEOUT"] == 5.0
        and values["GUID_TIMEOUT"] == 1.0
    )
    gcs.listeners.remove(listener)
    gcs.mav.mission_request_list_send(1, 1)
    assert gcs.wait_for(lambda: gcs.latest.get("MISSION_COUNT"), 5.0, "MISSION_COUNT").count == 0
    gcs.mav.timesync_send(0, 123456789)
    reply = gcs.wait_for(lambda: gcs.latest.get("TIMESYNC"), 5.0, "TIMESYNC")
    assert reply.ts1 == 123456789 and reply.tc1 > 0


def test_telemetry_reports_a_parked_vehicle(gcs: GroundStation):
    gcs.run_for(1.1)
    status = gcs.latest["SYS_STATUS"]
    assert status.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
    assert 12000 <= status.voltage_battery <= 12600 and status.battery_remaining > 95
    battery = gcs.latest["BATTERY_STATUS"]
    assert battery.voltages[0] == status.voltage_battery and battery.battery_remaining > 95
    assert gcs.latest["EXTENDED_SYS_STATE"].landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
    assert abs(gcs.latest["GLOBAL_POSITION_INT"].relative_alt) < 1500
    attitude = gcs.latest["ATTITUDE"]
    assert abs(attitude.roll) < 0.01 and abs(attitude.pitch) < 0.01
    assert (
        "SIM_STATE" in gcs.latest and "LOCAL_POSITION_NED" in gcs.latest and "VFR_HUD" in gcs.latest
    )


@pytest.mark.slow
def test_a_leader_sends_its_speed_requests_to_the_gcs_at_mission_time():
    with VehicleProcess(count=1, speedup=SPEEDUP, args=["--leader-requests", "3:4.5"]) as process:
        gcs = GroundStation(process.port(), speedup=SPEEDUP)
        gcs.connect()
        requests: list[tuple[float, object]] = []
        gcs.listeners.append(
            lambda m: (
                requests.append((gcs.vehicle_time(), m)) if m.get_type() == "COMMAND_INT" else None
            )
        )
        gcs.mav.named_value_int_send(0, b"MSN_TIME", 1000)  # mission time is 1 s now
        mission_zero = gcs.vehicle_time() - 1.0
        gcs.wait_for(lambda: len(requests) >= 2, 10.0, "the request and one retransmission")
        first_at, first = requests[0]
        assert abs(first_at - mission_zero - 3.0) < 0.2
        assert (first.target_system, first.command, first.frame) == (
            255,
            178,
            mavlink.MAV_FRAME_MISSION,
        )
        assert (first.param1, first.param2, first.x, first.y) == (1.0, 4.5, 0, 1)
        assert requests[1][1].y == 1 and 0.9 < requests[1][0] - first_at < 1.3
        gcs.mav.command_ack_send(178, mavlink.MAV_RESULT_ACCEPTED, 0, 1, 1, 1)
        gcs.run_for(0.5)
        settled = len(requests)
        gcs.run_for(2.5)
        assert len(requests) == settled
        assert gcs.text_matching("Leader: requesting 4.5 m/s (seq 1)")
        gcs.close()
