"""The autopilot state machine in-process (real pymavlink frames, decoded as the sim does):
timeouts with their wall-clock floor, setpoint validation under arbitrary input, telemetry
contents, the mission clock, speed changes and leader requests."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from tests.autopilot_bench import GCS, Bench
from vehicles.autopilot import Autopilot, AutopilotConfig, FailsafeConfig, Guided, Mode, Stamp
from vehicles.autopilot.parameters import parameters
from vehicles.dynamics import DynamicsConfig, FleetDynamics
from vehicles.fleet_speed import (
    HeardSpeedChange,
    LeaderRequest,
    LeaderSchedule,
    MissionClock,
    SpeedBook,
)
from vehicles.link import make_codec
from vehicles.sim import DEFAULT_ORIGIN
from vehicles.telemetry import BUILDERS, FleetSnapshot, TelemetryRates, TelemetrySchedule


def test_setpoint_timeout_counts_simulated_time_but_never_less_than_the_wall_floor():
    bench = Bench(
        AutopilotConfig(
            boot_time_s=0.0, failsafe=FailsafeConfig(setpoint_timeout_s=1.0, wall_floor_s=0.25)
        )
    )
    bench.fly()
    bench.local_setpoint(0.0, 0.0, -10.0)
    assert bench.autopilot.guided == Guided.SETPOINTS
    bench.run(1.2, speedup=100.0)  # 1.2 s simulated = 12 ms of wall clock: not yet
    assert bench.autopilot.guided == Guided.SETPOINTS
    bench.run(20.0, speedup=100.0)  # 0.2 s of wall clock in all: still below the floor
    assert bench.autopilot.guided == Guided.SETPOINTS
    bench.run(6.0, speedup=100.0)  # past 0.25 s of wall clock
    assert bench.autopilot.guided == Guided.HOLD
    assert any("no setpoint" in t for t in bench.texts())


def test_at_real_time_the_setpoint_timeout_is_exact():
    bench = Bench()
    bench.fly()
    bench.local_setpoint(5.0, 0.0, -10.0, 1.0, 0.0, 0.0)
    bench.run(0.98)
    assert bench.autopilot.guided == Guided.SETPOINTS
    bench.run(0.04)
    assert bench.autopilot.guided == Guided.HOLD


def test_gcs_failsafe_holds_then_lands_and_clears_on_heartbeat():
    bench = Bench(
        AutopilotConfig(boot_time_s=0.0, failsafe=FailsafeConfig(gcs_timeout_s=2.0, gcs_hold_s=3.0))
    )
    bench.heartbeats = True
    bench.fly(6.0)
    bench.heartbeats = False
    bench.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
    bench.run(1.9)
    assert bench.autopilot.mode == Mode.GUIDED
    bench.run(0.2)
    assert bench.autopilot.mode == Mode.BRAKE and bench.autopilot.gcs_failsafe == "hold"
    bench.run(2.9)
    assert bench.autopilot.mode == Mode.BRAKE
    bench.run(0.2)
    assert bench.autopilot.mode == Mode.LAND
    bench.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
    assert bench.autopilot.gcs_failsafe is None and "GCS Failsafe Cleared" in bench.texts()
    bench.run(30.0)
    assert not bench.autopilot.armed and bench.autopilot.mode == Mode.LAND


def test_heartbeats_from_other_systems_do_not_count_as_the_gcs():
    bench = Bench(AutopilotConfig(boot_time_s=0.0, failsafe=FailsafeConfig(gcs_timeout_s=1.5)))
    bench.heartbeats = True
    bench.fly(5.0)
    bench.heartbeats = False
    other = mavlink.MAVLink(None, srcSystem=42, srcComponent=190)
    for _ in range(20):
        for m in bench.codec.parse_buffer(
            bytearray(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(other))
        ):
            bench.autopilot.handle(m, bench.stamp())
        bench.run(0.1)
    assert bench.autopilot.gcs_failsafe is not None


@pytest.fixture(scope="module")
def flying_bench() -> Bench:
    """One vehicle in flight, reused (and put back at rest) by every hypothesis example."""
    bench = Bench(AutopilotConfig(boot_time_s=0.0, failsafe=FailsafeConfig(gcs_timeout_s=1e6)))
    bench.fly(10.0)
    return bench


FLOATS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=32),
    st.floats(-1e3, 1e3, width=32),
    st.sampled_from([0.0, -0.0, 1e30, -1e30, float("nan"), float("inf")]),
)


@settings(derandomize=True, max_examples=300, deadline=None)
@given(
    frame=st.sampled_from([0, 1, 3, 5, 6, 7, 8, 9, 10, 11, 12, 21, 255]),
    mask=st.one_of(
        st.sampled_from([0, 3520, 3072, 3576, 0b111111000, 0b111000111, 4095, 512 | 3072]),
        st.integers(0, 65535),
    ),
    global_message=st.booleans(),
    values=st.lists(FLOATS, min_size=11, max_size=11),
    lat=st.integers(-(2**31), 2**31 - 1),
    lon=st.integers(-(2**31), 2**31 - 1),
)
def test_any_setpoint_is_followed_or_refused_and_the_state_stays_finite(
    flying_bench, frame, mask, global_message, values, lat, lon
):
    bench = flying_bench
    bench.reset_in_flight()
    if global_message:
        message = mavlink.MAVLink_set_position_target_global_int_message(
            0, 1, 1, frame, mask, lat, lon, *values[:9]
        )
    else:
        message = mavlink.MAVLink_set_position_target_local_ned_message(
            0, 1, 1, frame, mask, *values
        )
    bench.send(message)
    bench.run(0.1)
    dyn = bench.dynamics
    for array in (
        dyn.position,
        dyn.velocity,
        dyn.reference_position,
        dyn.reference_velocity,
        dyn.reference_acceleration,
    ):
        assert np.all(np.isfinite(array))
    assert np.hypot(dyn.velocity[0, 0], dyn.velocity[0, 1]) <= 15.0 * 1.05
    assert bench.autopilot.airborne()


def test_setpoint_refusals_name_the_reason():
    bench = Bench()
    bench.fly()
    bench.local_setpoint(mask=0b110000111000)  # position and acceleration, no velocity
    bench.local_setpoint(mask=0b110000000000 | 512)  # force with acceleration
    bench.local_setpoint(frame=mavlink.MAV_FRAME_BODY_FRD)
    bench.send(
        mavlink.MAVLink_set_position_target_global_int_message(
            0, 1, 1, 11, 3520, 0, 0, 10.0, 0, 0, 0, 0, 0, 0, 0, 0
        )
    )
    bench.local_setpoint(x=float("nan"))
    bench.local_setpoint(x=1e7)
    bench.local_setpoint(mask=3072, afx=1e4)
    texts = " | ".join(bench.texts())
    for reason in (
        "position and acceleration need velocity",
        "force setpoints not supported",
        "frame 12 not supported",
        "terrain frame 11",
        "not finite",
        "too far",
        "acceleration invalid",
    ):
        assert reason in texts
    assert bench.autopilot.guided == Guided.HOLD  # none was followed


def test_local_offset_and_body_frames_move_relative_to_the_vehicle():
    bench = Bench()
    bench.fly()
    start = bench.dynamics.estimated(0)
    bench.local_setpoint(3.0, 4.0, 0.0, frame=mavlink.MAV_FRAME_LOCAL_OFFSET_NED)
    target = bench.dynamics.reference_position[0]
    np.testing.assert_allclose(target - start, [4.0, 3.0, 0.0], atol=1e-9)
    yaw = bench.dynamics.yaw[0]
    bench.local_setpoint(10.0, 0.0, 0.0, frame=mavlink.MAV_FRAME_BODY_OFFSET_NED)
    offset = bench.dynamics.reference_position[0] - bench.dynamics.estimated(0)
    np.testing.assert_allclose(offset[:2], [10 * math.sin(yaw), 10 * math.cos(yaw)], atol=1e-6)


def test_every_telemetry_message_encodes_in_every_state():
    bench = Bench(
        AutopilotConfig(
            boot_time_s=0.0, telemetry=TelemetryRates(position_hz=50, status_hz=50, home_hz=50)
        )
    )
    for msg_id in BUILDERS:
        bench.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 20000)
    bench.run(0.5)
    bench.fly(20.0)
    bench.local_setpoint(
        1e4, -1e4, -900.0, 100.0, -100.0, 50.0, mask=3520
    )  # far, fast: clamped fields
    bench.run(2.0)
    bench.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 21196)
    bench.run(15.0)
    kinds = {m.get_type() for m in bench.sent}
    assert {
        "GLOBAL_POSITION_INT",
        "SIM_STATE",
        "BATTERY_STATUS",
        "GPS_RAW_INT",
        "POSITION_TARGET_LOCAL_NED",
    } <= kinds


def test_battery_drains_while_flying():
    bench = Bench()
    full = bench.autopilot.battery()
    bench.fly(20.0)
    bench.run(60.0)
    used = bench.autopilot.battery()
    assert full.remaining_fraction == 1.0 and 0.9 < used.remaining_fraction < 0.99
    assert used.voltage_v < full.voltage_v and used.current_a > 5.0


def test_battery_capacity_per_vehicle():
    """The same energy drawn from 8000 and 1000 mAh: 8 times the share of the small one, in
    its SYS_STATUS and its BATT_CAPACITY."""
    dynamics = FleetDynamics(DynamicsConfig(), np.zeros((2, 3)), [(0, 1), (0, 2)], (8000, 1000))
    autopilots = [
        Autopilot(
            sysid=k + 1,
            index=k,
            count=2,
            config=AutopilotConfig(),
            dynamics=dynamics,
            origin=DEFAULT_ORIGIN,
        )
        for k in range(2)
    ]
    dynamics.energy_used_j[:] = 20_000.0
    big, small = (ap.battery() for ap in autopilots)
    assert 1 - small.remaining_fraction == pytest.approx(8 * (1 - big.remaining_fraction))
    stamp = Stamp(0.0, 0.0)
    snapshot = FleetSnapshot(dynamics, DEFAULT_ORIGIN)
    build = BUILDERS[mavlink.MAVLINK_MSG_ID_SYS_STATUS]
    reported = [build(ap.status(stamp), snapshot, stamp).battery_remaining for ap in autopilots]
    assert reported == [round(100 * b.remaining_fraction) for b in (big, small)]
    assert reported[1] < reported[0] - 40
    capacities = [dict((n, v) for n, v, _ in parameters(ap))["BATT_CAPACITY"] for ap in autopilots]
    assert capacities == [8000, 1000]
    with pytest.raises(ValueError, match="one battery capacity per vehicle"):
        FleetDynamics(DynamicsConfig(), np.zeros((2, 3)), [(0, 1), (0, 2)], (8000,))


def test_telemetry_schedule_rates_and_overrides():
    schedule = TelemetrySchedule(TelemetryRates().intervals(), phase=0.0)
    counts: dict[int, int] = {}
    for k in range(500):  # 10 s at 50 Hz
        for msg_id in schedule.due(k * 0.02):
            counts[msg_id] = counts.get(msg_id, 0) + 1
    assert counts[mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT] == 100
    assert counts[mavlink.MAVLINK_MSG_ID_HEARTBEAT] == 10
    schedule.set_interval(
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 0.001, now_s=10.0
    )  # capped at 50 Hz
    schedule.set_interval(mavlink.MAVLINK_MSG_ID_ATTITUDE, 0.0, now_s=10.0)
    counts = {}
    for k in range(500, 1000):
        for msg_id in schedule.due(k * 0.02):
            counts[msg_id] = counts.get(msg_id, 0) + 1
    assert counts[mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT] == 500
    assert mavlink.MAVLINK_MSG_ID_ATTITUDE not in counts


def test_speed_book_drops_duplicates_and_applies_timed_changes_at_their_time():
    clock = MissionClock()
    book = SpeedBook()
    assert book.record(HeardSpeedChange(255, 1, None, 10.0, received_sim_s=1.0))
    assert not book.record(HeardSpeedChange(255, 1, None, 3.0, received_sim_s=2.0))
    assert book.record(
        HeardSpeedChange(4, 1, None, 7.0, received_sim_s=2.5)
    )  # another sender's sequence
    assert book.fleet_speed(3.0, clock) == 7.0
    clock.sync(mission_time_s=100.0, sim_time_s=10.0)
    assert book.record(HeardSpeedChange(255, 2, 105.0, 5.0, received_sim_s=11.0))
    assert book.fleet_speed(14.9, clock) == 7.0
    assert book.fleet_speed(15.0, clock) == 5.0
    assert clock.now(20.0) == pytest.approx(110.0)


def test_leader_schedule_sends_when_due_retries_and_settles_on_acks():
    schedule = LeaderSchedule(
        (LeaderRequest(5.0, 4.0), LeaderRequest(2.0, 6.0)), retry_interval_s=1.0, max_tries=3
    )
    assert schedule.due(None) == [] and schedule.due(1.9) == []
    assert schedule.due(2.0) == [(1, 6.0)]
    schedule.sent(1, 6.0, sim_s=2.0, wall_s=0.0)
    again, given_up = schedule.resend_due(sim_s=3.0, wall_s=1.0, wall_floor_s=0.25)
    assert [p.sequence for p in again] == [1] and not given_up
    schedule.sent(1, 6.0, sim_s=3.0, wall_s=1.0)
    schedule.sent(1, 6.0, sim_s=4.0, wall_s=2.0)
    _, given_up = schedule.resend_due(sim_s=5.0, wall_s=3.0, wall_floor_s=0.25)
    assert given_up == [1] and schedule.abandoned == [1]
    assert schedule.due(6.0) == [(2, 4.0)]
    schedule.sent(2, 4.0, sim_s=6.0, wall_s=4.0)
    assert schedule.acknowledge(0) == 2 and not schedule.active()


def test_a_leader_requests_speed_from_the_gcs_at_mission_time():
    bench = Bench(leader=[LeaderRequest(3.0, 5.0)])
    bench.run(1.0)
    assert not [m for m in bench.sent if m.get_type() == "COMMAND_INT"]  # no mission clock yet
    bench.send(mavlink.MAVLink_named_value_int_message(0, b"MSN_TIME", 1000))  # mission time 1 s
    bench.run(1.9)
    assert not [m for m in bench.sent if m.get_type() == "COMMAND_INT"]
    bench.run(0.2)
    requests = [m for m in bench.sent if m.get_type() == "COMMAND_INT"]
    assert len(requests) == 1
    request = requests[0]
    assert (request.target_system, request.command, request.param2, request.x, request.y) == (
        255,
        178,
        5.0,
        0,
        1,
    )
    bench.run(1.1)  # not acknowledged: sent again
    assert len([m for m in bench.sent if m.get_type() == "COMMAND_INT"]) == 2
    bench.send(mavlink.MAVLink_command_ack_message(178, 0, 0, 1, 1, 1))
    bench.run(3.0)
    assert len([m for m in bench.sent if m.get_type() == "COMMAND_INT"]) == 2


# ------------------------------------------------------------------ catching up after a stall
@pytest.mark.slow  # the simulation binds its vehicle's UDP socket (never read here)
def test_a_process_catching_up_hands_each_message_over_when_its_clock_reaches_it():
    """A process stopped for a while reads everything that queued at once, then catches up
    over several wake-ups: a message that arrived at simulated 1.0 s is handled when the
    steps reach 1.0 s, not at the first wake-up (that would fly the setpoints of the end of
    a stall seconds early)."""
    from vehicles.sim import Arrival, SimConfig, Simulation, VehicleSpec

    sim = Simulation(
        SimConfig(
            vehicles=(VehicleSpec(1, 0, (0.0, 0.0, 0.0)),),
            autopilot=AutopilotConfig(boot_time_s=0.0),
        )
    )
    try:
        step_s = sim.config.dynamics.step_s
        codec = make_codec(1)
        packed = mavlink.MAVLink_command_long_message(
            1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, Mode.GUIDED, 0, 0, 0, 0, 0
        ).pack(GCS)
        (message,) = codec.parse_buffer(bytearray(packed))
        queued = [Arrival(Stamp(1.0, 1.0), 0, message)]
        sim.advance(round(0.2 / step_s), queued)  # the first wake-up: up to 0.2 s
        assert sim.autopilots[0].mode == Mode.STABILIZE
        sim.advance(round(0.98 / step_s), [])
        assert sim.autopilots[0].mode == Mode.STABILIZE
        sim.advance(round(1.2 / step_s), [])
        assert sim.autopilots[0].mode == Mode.GUIDED
    finally:
        sim.close()


@pytest.mark.slow  # the simulation binds its vehicle's UDP socket (never read here)
def test_every_clock_slip_is_reported_with_its_total_none_dropped():
    """Slips are said at most every `_SLIP_REPORT_INTERVAL_S` of wall clock, with the total
    since the last report. A slip inside the interval is said once the interval is over
    (the run loop asks at every wake-up), not held back until a later slip (it was, so the
    ground station kept mapping that vehicle's samples a slip too early)."""
    from fleetwire.messages import parse_clock_slipped
    from vehicles.sim import _SLIP_REPORT_INTERVAL_S, SimConfig, Simulation, VehicleSpec

    sim = Simulation(
        SimConfig(
            vehicles=(VehicleSpec(1, 0, (0.0, 0.0, 0.0)),),
            autopilot=AutopilotConfig(boot_time_s=0.0),
        )
    )
    step_s = sim.config.dynamics.step_s
    autopilot = sim.autopilots[0]

    def reported() -> list[float]:
        slips = [
            parse_clock_slipped(m.text) for m in autopilot.outbox if m.get_type() == "STATUSTEXT"
        ]
        autopilot.outbox.clear()
        return [s for s in slips if s is not None]

    try:
        reported()
        sim._slip(round(0.5 / step_s), now=100.0)  # the first slip: said at once
        assert reported() == pytest.approx([0.5])
        sim._slip(round(0.25 / step_s), now=100.2)  # inside the interval: held
        sim._slip(round(0.25 / step_s), now=100.4)
        assert reported() == []
        sim._report_slip(100.0 + _SLIP_REPORT_INTERVAL_S / 2)
        assert reported() == []
        sim._report_slip(100.0 + _SLIP_REPORT_INTERVAL_S)  # the interval is over: the total
        assert reported() == pytest.approx([0.5])
        sim._report_slip(100.0 + 3 * _SLIP_REPORT_INTERVAL_S)  # nothing new: nothing said
        assert reported() == []
        assert sim.stats.slipped_sim_s == pytest.approx(1.0)
    finally:
        sim.close()
