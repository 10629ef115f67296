"""The sim driver's state machine against real `vehicles sim` processes over loopback UDP,
and what `gcs mission run` puts on those processes' command lines."""

from __future__ import annotations

import selectors
import time
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from gcs.cli.cmd_run import sim_setup
from gcs.drivers import BackendUnavailable, driver_class
from gcs.drivers.base import DriverTiming, Phase, UavSpec
from gcs.drivers.sim import SimDriver, SimFleet, SimVehicleSetup
from gcs.geodesy import Origin
from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.speed import SpeedChange
from gcs.transport.link import Link, mavutil
from tests.conftest import MISSIONS
from tests.flying import flight_speedup
from vehicles.cli import build_parser, config_from_args

mavlink = mavutil.mavlink
ORIGIN = Origin(45.7640, 4.8357, 170.0)
SPEEDUP = flight_speedup(10.0)  # lower on a busy machine (tests/flying.py)


def pump(drivers: list[SimDriver], until: Callable[[], bool], seconds: float) -> None:
    """Run the drivers' loop (receive, step) until `until()` or fail at the deadline."""
    selector = selectors.SelectSelector()
    for index, driver in enumerate(drivers):
        selector.register(driver.link.fileno(), selectors.EVENT_READ, index)
    deadline = time.monotonic() + seconds
    try:
        while not until():
            if time.monotonic() > deadline:
                phases = [(d.uav_id, d.phase.value, d.failure_reason) for d in drivers]
                raise AssertionError(f"condition not reached in {seconds} s: {phases}")
            for key, _ in selector.select(0.01):
                driver = drivers[key.data]
                now = time.monotonic()
                for message in driver.link.receive(now):
                    driver.on_message(message, now)
            now = time.monotonic()
            for driver in drivers:
                driver.step(now)
    finally:
        selector.close()


def start(homes, slots=None, sysids=None, leaders=None):
    """Start vehicles on `homes`; drivers expecting `slots` and `sysids`."""
    homes = np.asarray(homes, float)
    fleet = SimFleet(
        SimVehicleSetup(homes=homes, origin=ORIGIN, speedup=SPEEDUP, leaders=leaders or {})
    )
    urls = fleet.start()
    slots = homes if slots is None else np.asarray(slots, float)
    drivers = []
    for k, url in enumerate(urls):
        sysid = (sysids or {}).get(k + 1, k + 1)
        spec = UavSpec(k + 1, sysid, url, ORIGIN, slots[k], slots[k], 20.0)
        drivers.append(SimDriver(spec, Link(url, sysid), DriverTiming(SPEEDUP)))
    return fleet, drivers


def close(fleet, drivers):
    for driver in drivers:
        driver.link.close()
    fleet.close()
    for process in fleet.processes:
        assert process.poll() is not None, "a vehicle process was left running"


def test_the_vehicle_processes_get_each_uavs_battery_capacity(tmp_path):
    """`sim.battery_mah` of the mission -> `gcs mission run`'s `SimVehicleSetup` -> each
    process's `vehicles sim --battery-mah`, as that process reads it."""
    text = (MISSIONS / "core.yaml").read_text()
    path = tmp_path / "core.yaml"
    path.write_text(text.replace("seed: 3}", "seed: 3, battery_mah: [8000, 500, 1000, 250]}"))
    args = SimpleNamespace(speedup=1.0, vehicles_per_process=3)

    def fleet(mission_path: Path) -> SimFleet:
        mission = load_mission(mission_path)
        formation = plan_mission(mission).formation
        return SimFleet(sim_setup(mission, formation, args, {}, path.with_suffix(".mcap")))

    small = fleet(path)
    assert small.setup.groups() == [[0, 1, 2], [3]]
    got = []
    for group in small.setup.groups():
        command = small.vehicle_command(group, 14560)
        got += [
            v.battery_mah for v in config_from_args(build_parser().parse_args(command[3:])).vehicles
        ]
    assert got == [8000.0, 500.0, 1000.0, 250.0]
    assert "--battery-mah" not in fleet(MISSIONS / "core.yaml").vehicle_command([0, 1, 2], 14560)


def test_registry_picks_the_family_from_the_backend():
    assert driver_class("sim") is SimDriver
    with pytest.raises(BackendUnavailable, match="unknown backend"):
        driver_class("betaflight")


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_connect_takeoff_speed_change_leader_and_land():
    fleet, drivers = start([[0.0, 0.0], [-14.0, 0.0]], leaders={2: [(1.0, 3.0)]})
    try:
        pump(drivers, lambda: all(d.phase == Phase.READY for d in drivers), 30)
        assert all(d.telemetry.home_enu is not None for d in drivers)
        now = time.monotonic()
        for driver in drivers:
            driver.set_mission_clock(lambda wall, t0=now: (wall - t0) * SPEEDUP)
            driver.takeoff(20.0, now)
        assert all(d.phase == Phase.ARMING for d in drivers)
        pump(drivers, lambda: all(d.phase == Phase.FOLLOWING for d in drivers), 20)
        for driver in drivers:
            assert driver.telemetry.armed
            # 20 m above the mission origin, within the driver's 1 m take-off tolerance; the
            # vehicle reports its altitude above its home, which sits a few decimetres off the
            # origin (navigation noise), hence the home's height (and 1 mm of rounding) added
            above_origin = driver.telemetry.relative_altitude + driver.telemetry.home_enu[2]
            assert above_origin == pytest.approx(20.0, abs=1.0 + 1e-3)

        # the leader (UAV 2) asks at mission time 1 s; the driver acknowledges it
        requests = []
        pump(drivers, lambda: requests.extend(drivers[1].drain_leader_requests()) or requests, 10)
        assert requests[0].uav_id == 2 and requests[0].speed == 3.0 and requests[0].seq == 1

        change = SpeedChange(seq=7, effective_s=30.0, speed=4.0, source="test", requested_s=1.0)
        sent = time.monotonic()
        for driver in drivers:
            driver.send_speed_change(change, sent)
        pump(drivers, lambda: all(7 in d.speed_acks for d in drivers), 10)
        assert all(d.speed_results[7] == mavlink.MAV_RESULT_ACCEPTED for d in drivers)
        assert all(d.speed_acks[7] >= sent for d in drivers)

        # a setpoint stream keeps them in GUIDED, following
        def stream():
            now = time.monotonic()
            for driver in drivers:
                xy = driver.spec.start_slot
                driver.send_setpoint([xy[0] + 5, xy[1], 20.0], [0, 0, 0], [0, 0, 0], 0.0, now)
            return all(
                d.telemetry.true_position_enu is not None
                and abs(d.telemetry.true_position_enu[0] - d.spec.start_slot[0] - 5) < 1.0
                for d in drivers
            )

        pump(drivers, stream, 20)
        now = time.monotonic()
        for driver in drivers:
            driver.land(now)
        assert all(d.phase == Phase.LANDING for d in drivers)
        # until a heartbeat shows LAND, a vehicle that missed the request still flies guided:
        # the stream goes on (the one it carries on may be braking); it stops once LAND shows
        assert all(d.wants_setpoints for d in drivers)
        pump(drivers, lambda: all(d.mode_goal is None for d in drivers), 10)
        assert not any(d.wants_setpoints for d in drivers)
        pump(drivers, lambda: all(d.phase == Phase.LANDED for d in drivers), 30)
        assert not any(d.telemetry.armed for d in drivers)
        texts = [text for d in drivers for _, _, text in d.statustexts]
        assert "Arming motors" in texts
    finally:
        close(fleet, drivers)


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_wrong_system_id_and_misplaced_home_are_refused():
    # UAV 1 answers as system 1 but the driver expects 3; UAV 2 starts 10 m off its slot
    fleet, drivers = start(
        [[0.0, 0.0], [-24.0, 0.0]], slots=[[0.0, 0.0], [-14.0, 0.0]], sysids={1: 3}
    )
    try:
        pump(drivers, lambda: all(d.phase == Phase.FAILED for d in drivers), 30)
        assert "heard system id 1, expected 3" in drivers[0].failure_reason
        assert "home is 10.0 m from its parking slot" in drivers[1].failure_reason
        events = [e.text for e in drivers[1].drain_events()]
        assert any("failed" in text for text in events)
    finally:
        close(fleet, drivers)


@pytest.mark.slow
def test_land_before_takeoff_needs_no_flight(tmp_path):
    link = Link("udpout:127.0.0.1:9", 1)
    try:
        spec = UavSpec(1, 1, link.url, ORIGIN, np.zeros(2), np.zeros(2), 20.0)
        driver = SimDriver(spec, link, DriverTiming())
        driver.land(time.monotonic())
        assert driver.phase == Phase.LANDED
    finally:
        link.close()
