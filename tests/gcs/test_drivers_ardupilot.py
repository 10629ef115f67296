"""Conformance: the ArduPilot driver against the fake ArduCopter over real UDP on loopback.

The fake reproduces ArduCopter 4.7 SITL as recorded (`tests/fakes/ardupilot.py`); its slow
boot (position estimate ~40 s) is compressed by the same speedup the driver is told.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from gcs.drivers.base import Phase
from gcs.geodesy import Origin
from gcs.transport.link import mavutil
from tests.fakes.ardupilot import GUIDED, LAND, ArduCopterModel, ArduCopterParams
from tests.fakes.flight import Flight, SinkDriver, home_of, hover, leg
from tests.fakes.replay import drive, load, reencode
from tests.flying import flight_speedup

# Every test here starts a process or flies over UDP.
pytestmark = pytest.mark.slow

mavlink = mavutil.mavlink
SPEEDUP = flight_speedup(40.0)  # the boot's ~42 s take ~1 s (lower on a busy machine)
ORIGIN = Origin(-35.3632, 149.1652, 584.0)
SLOT = (25.0, -40.0)
HOME_UP = 6.0  # the vehicle's home is 6 m above the mission origin
ALTITUDE = 20.0  # above the origin: 14 m above this home
RELATIVE = ALTITUDE - HOME_UP


def start(model: ArduCopterModel, slot=SLOT) -> Flight:
    return Flight.start(
        "ardupilot", model, origin=ORIGIN, slot=slot, altitude=ALTITUDE, speedup=model.speedup
    )


def copter(speedup: float = SPEEDUP, **kwargs) -> ArduCopterModel:
    kwargs.setdefault("home", home_of(ORIGIN, SLOT, HOME_UP))
    return ArduCopterModel(speedup=speedup, **kwargs)


def commands(flight: Flight, command: int) -> list:
    return [
        e for e in flight.fake.received("COMMAND_LONG") + flight.fake.received("COMMAND_INT")
        if e.message.command == command
    ]  # fmt: skip


def take_off(flight: Flight, timeout: float = 15.0) -> None:
    flight.follow(hover((*SLOT, ALTITUDE)))
    flight.driver.takeoff(ALTITUDE, time.monotonic())  # before it is ready: it waits
    assert flight.run_until(lambda: flight.driver.phase == Phase.FOLLOWING, timeout), (
        flight.driver.phase,
        flight.driver.failure_reason,
    )


def test_happy_path_waits_for_the_ekf_then_guided_arm_takeoff_follow_land():
    model = copter()
    with start(model) as flight:
        driver = flight.driver
        take_off(flight)

        # Streams were asked for: ArduPilot sends nothing else by default.
        assert {1, 24, 33, 193, 242, 245} <= set(model.intervals)
        # GUIDED by MAV_CMD_DO_SET_MODE (acknowledged), never by SET_MODE.
        modes = commands(flight, 176)
        assert [(m.message.param1, m.message.param2) for m in modes] == [(1, GUIDED)]
        assert not flight.fake.received("SET_MODE")
        # No ARM before the EKF used GPS (A1: `Arm: Need Position Estimate` otherwise).
        arms = commands(flight, 400)
        estimate_at = model.timeline.position_estimate / model.speedup
        assert len(arms) == 1 and arms[0].t >= estimate_at
        # Take-off to the cruise altitude relative to this vehicle's home.
        (takeoff,) = commands(flight, 22)
        assert takeoff.message.param7 == pytest.approx(RELATIVE, abs=0.01)
        assert driver.telemetry.relative_altitude == pytest.approx(RELATIVE, abs=1.0)

        # Follow a 10 m leg north at 5 m/s: frame 6, mask 3520, altitude relative to home.
        flight.follow(leg((*SLOT, ALTITUDE), (0.0, 5.0, 0.0), 2.0))
        end = np.array([SLOT[0], SLOT[1] + 10.0])

        def arrived() -> bool:  # at the end of the leg and stopped there
            p, v = driver.telemetry.position_enu, driver.telemetry.velocity_enu
            return (
                p is not None
                and v is not None
                and np.hypot(*(p[:2] - end)) < 0.5
                and np.hypot(*v[:2]) < 0.2
            )

        assert flight.run_until(arrived, 10.0)
        targets = flight.fake.received("SET_POSITION_TARGET_GLOBAL_INT")
        assert targets and all(
            e.message.coordinate_frame == 6 and e.message.type_mask == 3520 for e in targets
        )
        assert all(e.message.alt == pytest.approx(RELATIVE, abs=0.01) for e in targets)
        # Velocity feed-forward in NED: 5 m/s north.
        assert max(e.message.vx for e in targets) == pytest.approx(5.0)
        assert all(e.message.vy == 0.0 and e.message.vz == 0.0 for e in targets)

        driver.land(time.monotonic())
        assert flight.run_until(lambda: driver.phase == Phase.LANDED, 10.0)
        assert commands(flight, 176)[-1].message.param2 == LAND
        assert flight.run_until(lambda: not model.armed, 5.0)  # ArduPilot disarms by itself
        assert np.hypot(*(driver.telemetry.position_enu[:2] - end)) < 0.5
        assert driver.link.counters.bad == 0


def test_arming_refused_is_reported_and_retried_after_a_back_off():
    model = copter(extra_arm_refusals=2, speedup=20.0)  # two back-offs within the arming time
    with start(model) as flight:
        take_off(flight)
        refusals = [t for t in flight.texts("command") if t.startswith("arming refused")]
        assert refusals == ["arming refused: Arm: Need Position Estimate"] * 2
        arms = commands(flight, 400)
        assert len(arms) == 3 and model.armed
        gaps = np.diff([a.t for a in arms])
        driver = flight.driver
        backoff = [driver.timing.wall(driver.retry_policy.refusal.delay(n)) for n in (1, 2)]
        assert np.all(gaps >= np.array(backoff) * 0.9), gaps  # never at the tick rate


def test_a_vehicle_that_disarms_before_the_take_off_took_is_armed_again():
    # Every try of the first take-off is lost (a lossy link): ArduCopter disarms after its
    # DISARM_DELAY on the ground; the driver arms it again and takes off, never failing.
    model = copter(lost_takeoffs=5, speedup=20.0)
    with start(model) as flight:
        take_off(flight, timeout=30.0)
        assert "disarmed on the ground before the take-off took (the autopilot's disarm " \
            "delay): arming again" in flight.texts("command")  # fmt: skip
        assert len(commands(flight, 400)) == 2  # armed twice
        assert model.flying() and flight.driver.failure_reason is None


def sent(flight: Flight, type_name: str, what=lambda m: True) -> list:
    """What the fake sent of one message type (and `what` selects), in order."""
    with flight.fake.lock:
        return [
            e for e in flight.fake.exchanges
            if e.direction == "tx" and e.message.get_type() == type_name and what(e.message)
        ]  # fmt: skip


def test_refusal_reason_is_the_warning_just_after_the_ack_never_an_info_text():
    # The reason comes 5 ms after the refusing ACK; an INFO text comes with the ACK.
    model = copter(
        extra_arm_refusals=1,
        refusal_text_delay_s=0.005,
        info_text_with_refusals="EKF3 IMU0 is using GPS",
    )
    with start(model) as flight:
        take_off(flight)
        (refused,) = sent(flight, "COMMAND_ACK", lambda m: m.command == 400 and m.result == 4)
        (reason,) = sent(flight, "STATUSTEXT", lambda m: m.text.startswith("Arm:"))
        assert reason.t > refused.t  # on the wire: the text after the ACK
        refusals = [t for t in flight.texts("command") if t.startswith("arming refused")]
        assert refusals == ["arming refused: Arm: Need Position Estimate"]
        assert len(commands(flight, 400)) == 2 and model.armed


def test_arming_timeout_names_the_refusal_not_the_last_info_text():
    # Every ARM is refused; each refusal comes with an INFO text sent after its reason.
    model = copter(extra_arm_refusals=10**6, info_text_with_refusals="EKF3 IMU0 is using GPS")
    with start(model) as flight:
        flight.driver.takeoff(ALTITUDE, time.monotonic())
        assert flight.run_until(lambda: flight.driver.phase == Phase.FAILED, 10.0)
        assert flight.driver.last_statustext() == "EKF3 IMU0 is using GPS"  # the trap
        assert flight.driver.failure_reason == "could not arm: Arm: Need Position Estimate"
        assert not model.armed


def test_home_position_requests_are_paced_until_the_ekf_origin():
    # Before its EKF origin (+19 s) ArduPilot acknowledges REQUEST_MESSAGE(HOME_POSITION) and
    # sends nothing: the driver waits, then asks again later and later, never at its tick rate.
    model = copter(speedup=10.0)  # origin at 1.9 s wall
    with start(model) as flight:
        driver = flight.driver
        assert flight.run_until(lambda: driver.telemetry.home_enu is not None, 5.0)
        requests = [
            e for e in commands(flight, 512) if e.message.param1 == 242
        ]  # fmt: skip
        acked = sent(flight, "COMMAND_ACK", lambda m: m.command == 512 and m.result == 0)
        assert len(acked) >= len(requests) >= 3  # each answered, none brought a home
        pacing = driver.retry_policy.home_request
        wall = driver.timing.wall
        expected = [wall(pacing.first_s) + wall(pacing.delay(n)) for n in range(1, len(requests))]
        gaps = np.diff([e.t for e in requests])
        assert np.all(gaps >= 0.9 * np.array(expected)), (gaps, expected)
        assert gaps[-1] > gaps[0]  # the back-off grows


def test_mode_refused_is_reported_with_the_vehicles_reason():
    model = copter(known_modes=frozenset({0, 4, 5, 9}))  # built without BRAKE
    with start(model) as flight:
        take_off(flight)
        flight.driver.hold(time.monotonic())
        refusal = "mode hold refused: No such mode 17"
        assert flight.run_until(lambda: refusal in flight.texts("command"), 3.0)
        assert model.mode == GUIDED  # still hovering at its last target


def test_home_away_from_its_parking_slot_is_refused_before_arming():
    model = copter(home=home_of(ORIGIN, (SLOT[0] + 40.0, SLOT[1]), HOME_UP))
    with start(model) as flight:
        flight.driver.takeoff(ALTITUDE, time.monotonic())
        assert flight.run_until(lambda: flight.driver.phase == Phase.FAILED, 10.0)
        assert flight.driver.failure_reason == "home is 40.0 m from its parking slot (25.0, -40.0)"
        assert not commands(flight, 400) and not model.armed


def test_vehicle_leaving_guided_by_itself_is_a_failsafe_event():
    model = copter()
    with start(model) as flight:
        take_off(flight)
        with flight.fake.lock:
            model.change_mode_by_itself(LAND, flight.fake.now())  # e.g. a GCS failsafe
        assert flight.run_until(lambda: flight.driver.phase == Phase.LANDING, 3.0)
        assert flight.texts("failsafe") == ["the vehicle left guided flight by itself: mode LAND"]


def test_recorded_ardupilot_session_drives_the_state_machine():
    """A1 as recorded (ArduCopter SITL's own messages, re-encoded) into the driver: it is ready
    only once the EKF uses GPS and the pre-arm bit agrees (42.59), follows the recorded arming
    and climb, and takes the LAND the recorder commanded at 77.08 for a mode change of the
    vehicle's own (a failsafe, from the driver's point of view)."""
    records = load("ardupilot-session.jsonl")
    origin = Origin(-35.363261, 149.1652299, 584.09)  # the recorded home
    with SinkDriver.start("ardupilot", 1, origin, (0.0, 0.0), 20.0) as bench:
        driver = bench.driver
        drive(driver, records, 110.0, step=0.004, actions={1.0: lambda t: driver.takeoff(20, t)})
        events = driver.drain_events()
        phases = [(e.time, e.text.split(" -> ")[1].split()[0]) for e in events if e.kind == "phase"]
        assert [p for _, p in phases] == [
            "initialising", "ready", "arming", "taking_off", "following", "landing", "landed"
        ]  # fmt: skip
        at = {p: t for t, p in phases}
        # EKF_STATUS_REPORT uses GPS at 41.59; in GUIDED the pre-arm bit follows at 42.59.
        assert 42.59 <= at["ready"] < 42.7
        assert 42.94 <= at["taking_off"] < 43.0  # HEARTBEAT armed at 42.94
        assert 55.0 <= at["following"] < 57.5  # 19 m reached
        assert 77.08 <= at["landing"] < 77.2  # HEARTBEAT LAND at 77.08
        assert 107.0 <= at["landed"] < 108.0  # landed_state 1 at 107.10
        texts = [e.text for e in events if e.kind in ("failsafe", "statustext")]
        assert "the vehicle left guided flight by itself: mode LAND" in texts
        assert "Arm: Need Position Estimate" in texts
        arms = bench.commands(400)
        assert arms and arms[0][0] >= 42.59  # never before the pre-arm bit in GUIDED


def test_recorded_ardupilot_battery_is_the_telemetry_s_remaining_charge():
    """SYS_STATUS battery_remaining of A1 (100 % at boot, 85 % after 110 s of it) is the
    driver's `battery_remaining_pct`; -1 (unknown) makes it None again."""
    statuses = [r for r in load("ardupilot-session.jsonl") if r.type == "SYS_STATUS"]
    with SinkDriver.start("ardupilot", 1, ORIGIN, (0.0, 0.0), 20.0) as bench:
        telemetry = bench.driver.telemetry
        assert telemetry.battery_remaining_pct is None  # nothing heard yet
        seen = []
        for record in statuses:
            bench.driver.on_message(reencode(record), record.t)
            seen.append(telemetry.battery_remaining_pct)
        assert seen == [float(r.fields["battery_remaining"]) for r in statuses]
        assert (seen[0], seen[-1]) == (100.0, 85.0)
        unknown = replace(statuses[-1], fields={**statuses[-1].fields, "battery_remaining": -1})
        bench.driver.on_message(reencode(unknown), unknown.t)
        assert telemetry.battery_remaining_pct is None


def test_a_landing_reported_once_is_commanded_until_the_heartbeats_show_it():
    """The vehicle reports LAND by itself (a failsafe, or a report that was not true), then
    GUIDED again: the driver asks for LAND again at once, until the heartbeats show it (a
    forged LAND report no longer leaves a UAV hovering in GUIDED without setpoints)."""
    # ArduCopter's slowest landing (LAND_SPEED 30 cm/s): the UAV is still up when it switches
    model = copter(params=ArduCopterParams(land_speed=0.3, land_speed_high=0.5))
    with start(model) as flight:
        take_off(flight)
        with flight.fake.lock:
            model.change_mode_by_itself(LAND, flight.fake.now())
        assert flight.run_until(lambda: flight.driver.phase == Phase.LANDING, 3.0)
        asked = len(commands(flight, mavlink.MAV_CMD_DO_SET_MODE))
        with flight.fake.lock:
            model.change_mode_by_itself(GUIDED, flight.fake.now())  # it was not landing
        assert flight.run_until(lambda: model.mode == LAND, 5.0), model.mode
        modes = [e.message.param2 for e in commands(flight, mavlink.MAV_CMD_DO_SET_MODE)]
        assert LAND in modes[asked:]
        left = "the vehicle left LAND: mode GUIDED; asking for LAND again"
        assert left in flight.texts("failsafe")
