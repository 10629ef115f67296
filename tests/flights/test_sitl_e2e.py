"""`gcs mission run` flies a fleet of fake ArduPilot / PX4 SITL instances end to end.

The fakes boot where `gcs sitl launch-plan` puts each SITL instance (home on its parking slot),
listen or push on their own UDP ports, and run at the same speedup as the mission; the real
runtime picks the driver from `fleet.backend`, takes off, flies the formation and lands.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from gcs.geodesy import geodetic_to_enu
from gcs.mission import load_mission
from gcs.recording.logreader import read_recording
from gcs.sim.sitl import plan_for_launch
from gcs.transport.link import mavutil
from tests.fakes.common import enu_to_global
from tests.sitl_fleet import SPEEDUP, fake_fleet

pytestmark = pytest.mark.slow
mavlink = mavutil.mavlink

MISSION = {
    "version": 1,
    "name": "sitl-e2e",
    "origin": {"lat": 47.3975, "lon": 8.545, "alt": 488.0},
    "start": {"x": 0, "y": 0, "theta_deg": 0},
    "goal": {"x": 120, "y": 0, "theta_deg": 0},
    "safety_margin": 5,
    "radio_range": 100,
    "altitude": 15,
    "speed": {"max": 5, "initial": 5},
    "fleet": {"size": "auto"},
    "vehicle": {"max_speed": 12, "max_acceleration": 6, "radius": 0.5},
}


@pytest.fixture
def run_command(gcs_main):
    """`gcs ...` in this process (conftest's `gcs_main`)."""
    return gcs_main


def _fly(run_command, tmp_path, backend: str, *flags: str, **changes):
    """Fly MISSION (with `changes`, a dict merged one level) on fake SITL: (result, mission,
    fakes)."""
    data = {**MISSION, "fleet": {"size": "auto", "backend": backend}}
    for key, value in changes.items():
        data[key] = {**data[key], **value} if isinstance(value, dict) else value
    path = tmp_path / "mission.yaml"
    path.write_text(yaml.safe_dump(data))
    mission = load_mission(path)
    speedup = SPEEDUP[backend]
    fakes, urls = fake_fleet(mission, backend, speedup)
    for fake in fakes:
        fake.start()
    try:
        result = run_command(
            "mission", "run", path, "--speedup", f"{speedup:g}", "--json", "--no-live",
            "--log", tmp_path / "run.mcap", *flags, "--connect", *urls,
        )  # fmt: skip
    finally:
        for fake in fakes:
            fake.stop()
    return result, mission, fakes


def _landed_on_slots(mission, fakes, backend: str) -> None:
    goal_slots = plan_for_launch(mission).formation.goal_slots
    for fake, slot in zip(fakes, goal_slots, strict=True):
        model = fake.model
        assert not model.armed  # ArduPilot disarmed itself, PX4 was disarmed by the driver
        boot = model.boot_home if backend == "ardupilot" else model.boot_spot
        lat, lon, _ = enu_to_global(boot, model.body.position)  # where it really is
        landed = geodetic_to_enu(lat, lon, mission.origin.alt, mission.origin)
        assert np.hypot(*(landed[:2] - slot)) < 1.5
        if backend == "px4":
            assert not model.failsafe


def test_a_mission_assuming_more_than_the_autopilots_allow_is_refused_before_take_off(
    run_command, tmp_path
):
    """max_acceleration 6 m/s^2 against ArduCopter's WPNAV_ACCEL 250 cm/s^2: one line, exit
    2, nobody armed; the log says why."""
    result, mission, fakes = _fly(run_command, tmp_path, "ardupilot")
    assert result.returncode == 2, result.stderr[-2000:]
    assert result.stdout == ""
    line = result.stderr.strip().splitlines()[-1]
    assert line.startswith(f"{mission.source}: vehicle.max_speed: expected at most 10 m/s")
    assert "UAV 1's autopilot" in line and "WPNAV_SPEED = 1000 cm/s" in line
    assert "--cap-speed" in line and "vehicle.apply_limits" in line
    assert all(not fake.model.armed and not fake.model.flying() for fake in fakes)
    assert all(
        cmd != mavlink.MAV_CMD_COMPONENT_ARM_DISARM
        for fake in fakes
        for _, cmd, _ in fake.model.commands
    )
    outcome = read_recording(tmp_path / "run.mcap").metadata["outcome"]
    assert outcome["completed"] == "false" and "WPNAV_SPEED" in outcome["reason"]


def test_ardupilot_limits_are_set_for_the_flight_and_put_back_after_landing(run_command, tmp_path):
    """vehicle.apply_limits: WPNAV_SPEED and WPNAV_ACCEL raised to the mission's values by
    PARAM_SET before take-off, flown, and set back to the firmware's values once landed."""
    result, mission, fakes = _fly(
        run_command, tmp_path, "ardupilot", vehicle={"apply_limits": True}
    )
    assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads(result.stdout)
    assert summary["completed"] and summary["fleet_size"] == len(fakes) == 2
    assert summary["max_tracking_error_m"] < mission.safety_margin
    for fake in fakes:
        sets = [(name, value) for _, name, value in fake.model.param_sets]
        assert sets == [
            ("WPNAV_SPEED", 1200.0),
            ("WPNAV_ACCEL", 600.0),
            ("WPNAV_SPEED", 1000.0),
            ("WPNAV_ACCEL", 250.0),
        ]
        assert fake.model.parameters["WPNAV_ACCEL"][0] == 250.0
    _landed_on_slots(mission, fakes, "ardupilot")


def test_px4_with_cap_speed_flies_a_plan_within_its_own_limits(run_command, tmp_path):
    """--cap-speed: MPC_ACC_HOR_MAX 5 m/s^2 < the mission's 6: re-planned with 5, flown."""
    result, mission, fakes = _fly(run_command, tmp_path, "px4", "--cap-speed")
    assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads(result.stdout)
    assert summary["completed"] and summary["fleet_size"] == len(fakes) == 2
    assert summary["max_tracking_error_m"] < mission.safety_margin
    capped = [e for e in summary["events"] if e["kind"] == "limits_capped"]
    assert len(capped) == 1 and "MPC_ACC_HOR_MAX = 5 m/s^2" in capped[0]["text"]
    assert all(not fake.model.param_sets for fake in fakes)  # nothing was changed on them
    _landed_on_slots(mission, fakes, "px4")
