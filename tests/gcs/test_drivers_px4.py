"""Conformance: the PX4 driver against the fake PX4 over real UDP on loopback.

The fake reproduces PX4 SITL (SIH) as recorded (`tests/fakes/px4.py`): it pushes its telemetry
to the ground station's port (PX4's offboard link towards 14540+i), answers DO_SET_MODE twice,
needs a setpoint stream for OFFBOARD and falls back to POSCTL after COM_OF_LOSS_T (1 s, wall
clock) without one. Its boot and flight are compressed by the speedup the driver is told.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from gcs.drivers.base import FlightMode, Phase
from gcs.geodesy import Origin
from tests.fakes.flight import Flight, SinkDriver, home_of, hover, leg
from tests.fakes.px4 import (
    ARM_DENIED_TEXT,
    OFFBOARD,
    OFFBOARD_NOT_AVAILABLE_TEXT,
    POSCTL,
    Px4Model,
)
from tests.fakes.replay import drive, load, reencode

# Every test here starts a process or flies over UDP.
pytestmark = pytest.mark.slow

SPEEDUP = 20.0
ORIGIN = Origin(47.3975, 8.5450, 488.0)
SLOT = (-30.0, 45.0)
HOME_UP = -2.0  # the vehicle's home is 2 m below the mission origin
ALTITUDE = 20.0  # above the origin: 22 m above this home
RELATIVE = ALTITUDE - HOME_UP


def start(model: Px4Model) -> Flight:
    return Flight.start(
        "px4", model, origin=ORIGIN, slot=SLOT, altitude=ALTITUDE, speedup=model.speedup
    )


def px4(speedup: float = SPEEDUP, **kwargs) -> Px4Model:
    kwargs.setdefault("home", home_of(ORIGIN, SLOT, HOME_UP))
    return Px4Model(speedup=speedup, seed=3, **kwargs)


def received(flight: Flight, command: int) -> list:
    return [e for e in flight.fake.received("COMMAND_LONG") if e.message.command == command]


def acks(flight: Flight, command: int) -> list:
    with flight.fake.lock:
        return [
            e for e in flight.fake.exchanges
            if e.direction == "tx" and e.message.get_type() == "COMMAND_ACK"
            and e.message.command == command
        ]  # fmt: skip


def take_off(flight: Flight, timeout: float = 10.0) -> None:
    flight.follow(hover((*SLOT, ALTITUDE)))
    flight.driver.takeoff(ALTITUDE, time.monotonic())  # before it is ready: it waits
    assert flight.run_until(lambda: flight.driver.phase == Phase.FOLLOWING, timeout), (
        flight.driver.phase,
        flight.driver.failure_reason,
    )


def test_happy_path_stream_then_offboard_arm_climb_follow_land_disarm():
    model = px4()
    with start(model) as flight:
        driver = flight.driver
        take_off(flight)

        # OFFBOARD was selected only once the stream flowed, and answered twice.
        (offboard,) = received(flight, 176)
        assert (offboard.message.param2, offboard.message.param3) == (6, 0)
        setpoints = flight.fake.received("SET_POSITION_TARGET_GLOBAL_INT")
        before = [s for s in setpoints if s.t < offboard.t]
        assert len(before) >= 3
        assert [a.message.result for a in acks(flight, 176)] == [0, 0]
        # One ARM, accepted: never refused because of a missing stream.
        assert [a.message.result for a in acks(flight, 400)] == [0]
        # Take-off by the stream in frame 6, altitude relative to this vehicle's (noisy) home.
        assert all(
            s.message.coordinate_frame == 6 and s.message.type_mask == 3520 for s in setpoints
        )
        assert setpoints[-1].message.alt == pytest.approx(
            ALTITUDE + ORIGIN.alt - model.home.alt, abs=0.01
        )
        home = driver.telemetry.home_enu
        assert 0.0 < np.hypot(*(home[:2] - SLOT)) < driver.home_tolerance_m  # noise accepted

        flight.follow(leg((*SLOT, ALTITUDE), (5.0, 0.0, 0.0), 2.0))  # 10 m east

        def at_end() -> bool:
            p = driver.telemetry.position_enu
            return p is not None and np.hypot(p[0] - (SLOT[0] + 10.0), p[1] - SLOT[1]) < 0.5

        assert flight.run_until(at_end, 6.0)
        # The stream never fell below 2 Hz while the vehicle was in OFFBOARD.
        times = [s.t for s in flight.fake.received("SET_POSITION_TARGET_GLOBAL_INT")]
        assert max(np.diff(times)) < 0.5
        assert model.mode == OFFBOARD and not model.failsafe

        driver.land(time.monotonic())
        assert flight.run_until(lambda: not model.armed, 10.0)
        (land,) = received(flight, 21)
        assert all(math.isnan(p) for p in (land.message.param4, land.message.param7))
        disarm = [c for c in received(flight, 400) if c.message.param1 == 0]
        assert len(disarm) == 1  # PX4 stays armed after `Landing detected`: the driver disarms
        assert driver.phase == Phase.LANDED
        # PX4's EVENTs (UNKNOWN_410 to pymavlink) were set aside by the link, harmlessly.
        assert driver.link.counters.bad > 0


def test_offboard_without_stream_refuses_arming_and_the_driver_retries_with_it():
    # PX4 left in OFFBOARD by a previous flight (P1 ends so): the mode is already "guided",
    # but arming needs the stream (P1 7.76).
    model = px4(initial_mode=OFFBOARD)
    with start(model) as flight:
        flight.stream_paused = True
        flight.follow(hover((*SLOT, ALTITUDE)))
        flight.driver.takeoff(ALTITUDE, time.monotonic())
        refusal = f"arming refused: {ARM_DENIED_TEXT.strip()}"
        assert flight.run_until(lambda: refusal in flight.texts("command"), 5.0)
        assert not model.armed
        flight.stream_paused = False
        assert flight.run_until(lambda: flight.driver.phase == Phase.FOLLOWING, 8.0)
        results = [a.message.result for a in acks(flight, 400)]
        assert results[0] == 1 and results[-1] == 0  # TEMPORARILY_REJECTED, then ACCEPTED


def test_refused_arming_is_retried_with_a_growing_back_off():
    # OFFBOARD without a stream (P1 7.76): every ARM is TEMPORARILY_REJECTED.
    model = px4(speedup=8.0, initial_mode=OFFBOARD)
    with start(model) as flight:
        driver = flight.driver
        flight.stream_paused = True
        flight.follow(hover((*SLOT, ALTITUDE)))
        driver.takeoff(ALTITUDE, time.monotonic())
        assert flight.run_until(lambda: len(received(flight, 400)) >= 4, 6.0), driver.phase
        assert [a.message.result for a in acks(flight, 400)][:3] == [1, 1, 1]
        refusals = [t for t in flight.texts("command") if t.startswith("arming refused")]
        assert refusals[:3] == [f"arming refused: {ARM_DENIED_TEXT.strip()}"] * 3
        gaps = np.diff([a.t for a in received(flight, 400)])
        wall, backoff = driver.timing.wall, driver.retry_policy.refusal
        expected = np.array([wall(backoff.delay(n)) for n in (1, 2, 3)])  # 0.25, 0.25, 0.5 s
        assert np.all(gaps >= 0.9 * expected), (gaps, expected)
        # it grows: the third gap is 1.5 x the first delay at least (not the first gap, which
        # scheduling may stretch: 0.335 s for 0.25 s once, and 0.501 < 1.5 x 0.335)
        assert gaps[2] >= 1.5 * expected[0]
        assert not model.armed


def test_mode_change_the_heartbeat_never_shows_is_asked_again_slowly():
    # PX4 acknowledges OFFBOARD twice ACCEPTED and stays in Hold (as P2 4.58 for an unknown
    # mode): the driver waits for the heartbeat, then asks again after a growing back-off,
    # never at its tick rate (the heartbeat comes at 1 Hz of vehicle time).
    model = px4(speedup=4.0, ignored_modes=frozenset({OFFBOARD}))
    with start(model) as flight:
        driver = flight.driver
        flight.follow(hover((*SLOT, ALTITUDE)))
        driver.takeoff(ALTITUDE, time.monotonic())
        assert flight.run_until(lambda: len(received(flight, 176)) >= 3, 6.0), driver.phase
        modes = received(flight, 176)
        assert all((m.message.param2, m.message.param3) == (6, 0) for m in modes)
        assert [a.message.result for a in acks(flight, 176)][:4] == [0, 0, 0, 0]
        elapsed = modes[-1].t - modes[0].t
        assert len(modes) <= 1 + 3 * elapsed  # at most 3 per second
        wall, policy = driver.timing.wall, driver.retry_policy
        expected = np.array(
            [wall(policy.confirm_s) + wall(policy.refusal.delay(n)) for n in (1, 2)]
        )  # 0.625 + 0.25, 0.625 + 0.5 s
        gaps = np.diff([m.t for m in modes])
        assert np.all(gaps >= 0.9 * expected), (gaps, expected)
        unconfirmed = "mode guided: accepted, but the heartbeat did not show it"
        assert unconfirmed in flight.texts("command")
        assert driver.phase == Phase.ARMING and driver.current_mode() == FlightMode.HOLD
        assert not received(flight, 400)  # no ARM outside OFFBOARD


def test_offboard_loss_failsafe_is_an_event_and_offboard_comes_back_with_the_stream():
    model = px4()
    with start(model) as flight:
        driver = flight.driver
        take_off(flight)
        flight.stream_paused = True  # the GCS stalls: PX4 must notice after COM_OF_LOSS_T
        stalled = time.monotonic()
        assert flight.run_until(lambda: driver.phase == Phase.HOLDING, 4.0)
        assert time.monotonic() - stalled >= model.params.com_of_loss_t
        assert model.mode == POSCTL and model.failsafe
        assert flight.texts("failsafe") == [
            "the vehicle left guided flight by itself: mode POSCTL (offboard-loss failsafe)"
        ]
        # PX4 says so 9 ms after switching (P1 44.32-44.33): maybe after the heartbeat showed it.
        assert flight.run_until(lambda: "Failsafe activated" in flight.texts("statustext"), 1.0)

        # Resuming: PX4 refuses OFFBOARD until the stream flows again, then takes it back.
        driver.resume(time.monotonic())
        flight.stream_paused = False
        assert flight.run_until(lambda: model.mode == OFFBOARD, 5.0)
        refusal = f"mode guided refused: {OFFBOARD_NOT_AVAILABLE_TEXT.strip()}"
        assert refusal in flight.texts("command")
        assert flight.run_until(lambda: driver.current_mode() is not None, 3.0)
        assert driver.phase == Phase.FOLLOWING and model.armed


def test_home_away_from_its_parking_slot_is_refused_before_arming():
    model = px4(home=home_of(ORIGIN, (SLOT[0], SLOT[1] - 25.0), HOME_UP))
    with start(model) as flight:
        flight.follow(hover((*SLOT, ALTITUDE)))
        flight.driver.takeoff(ALTITUDE, time.monotonic())
        assert flight.run_until(lambda: flight.driver.phase == Phase.FAILED, 5.0)
        reason = flight.driver.failure_reason
        assert reason.startswith("home is 2") and reason.endswith(
            "from its parking slot (-30.0, 45.0)"
        )
        assert not received(flight, 400) and not model.armed


def test_landing_from_a_vehicle_failsafe_mode_is_followed():
    model = px4()
    with start(model) as flight:
        take_off(flight)
        with flight.fake.lock:  # e.g. a low-battery failsafe: PX4 lands by itself
            model.land_by_itself(flight.fake.now())
        assert flight.run_until(lambda: flight.driver.phase == Phase.LANDING, 3.0)
        assert flight.run_until(lambda: flight.driver.phase == Phase.LANDED, 10.0)
        assert flight.run_until(lambda: not model.armed, 3.0)


def test_recorded_px4_session_drives_the_state_machine():
    """P1 as recorded (PX4 SITL's own messages, re-encoded; EVENTs dropped as the link drops
    them) into the driver: ready at the pre-arm bit, no ARM while OFFBOARD lacks the stream (the
    recorder's stream starts at 9.29, the bit at 9.42), the climb, and the offboard-loss
    failsafe at 45.31 reported as an event."""
    records = load("px4-session.jsonl.gz")
    origin = Origin(47.3977456, 8.545593, 487.643)  # the recorded home, before arming
    with SinkDriver.start("px4", 1, origin, (0.0, 0.0), 20.0) as bench:
        driver = bench.driver
        drive(driver, records, 60.0, step=0.004, actions={1.0: lambda t: driver.takeoff(20, t)})
        events = driver.drain_events()
        phases = [(e.time, e.text.split(" -> ")[1].split()[0]) for e in events if e.kind == "phase"]
        assert [p for _, p in phases] == [
            "initialising", "ready", "arming", "taking_off", "following", "holding"
        ]  # fmt: skip
        at = {p: t for t, p in phases}
        assert 4.5 <= at["ready"] < 4.8  # pre-arm bit at 4.73
        assert 12.67 <= at["taking_off"] < 12.7  # HEARTBEAT armed at 12.67
        assert 20.0 <= at["following"] < 26.0  # 19 m (relative to home) reached
        assert 45.30 <= at["holding"] < 45.4  # HEARTBEAT POSCTL / CRITICAL at 45.308
        failsafes = [e.text for e in events if e.kind == "failsafe"]
        assert failsafes == [
            "the vehicle left guided flight by itself: mode POSCTL (offboard-loss failsafe)"
        ]
        texts = [e.text for e in events if e.kind == "statustext"]
        assert "Arming denied: Resolve system health failures first" in texts  # chunks joined
        assert "Failsafe activated" in texts
        arms = bench.commands(400)
        assert arms and arms[0][0] >= 9.42  # not while OFFBOARD had no stream (bit at 9.42)
        assert not bench.commands(176)  # OFFBOARD already selected (by the recorder)


def test_recorded_px4_battery_is_the_telemetry_s_remaining_charge():
    """SYS_STATUS battery_remaining of P1 (99 % at boot, down to SIH's floor of 51 % in
    flight, 99 % again once landed at 75.8) is the driver's `battery_remaining_pct`."""
    statuses = [r for r in load("px4-session.jsonl.gz") if r.type == "SYS_STATUS"]
    origin = Origin(47.3977456, 8.545593, 487.643)
    with SinkDriver.start("px4", 1, origin, (0.0, 0.0), 20.0) as bench:
        telemetry = bench.driver.telemetry
        seen = []
        for record in statuses:
            bench.driver.on_message(reencode(record), record.t)
            seen.append(telemetry.battery_remaining_pct)
        assert seen == [float(r.fields["battery_remaining"]) for r in statuses]
        assert (seen[0], min(seen), seen[-1]) == (99.0, 51.0, 99.0)
