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
from gcs.sim.sitl import launch_plan, plan_for_launch
from tests.fakes.ardupilot import ArduCopterModel
from tests.fakes.common import FakeEndpoint, Home, enu_to_global
from tests.fakes.px4 import Px4Model
from tests.flying import flight_speedup
from vehicles.ports import free_udp_ports

pytestmark = pytest.mark.slow

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
#: The fakes run in threads of this process, beside the GCS: at 10x, 0.1 s of CPU starvation
#: would be 1 s of mission time. (PX4's offboard-loss timeout stays 1 s wall.)
SPEEDUP = {"ardupilot": flight_speedup(5.0), "px4": flight_speedup(5.0)}


@pytest.fixture
def run_command(gcs_main):
    """`gcs ...` in this process (conftest's `gcs_main`)."""
    return gcs_main


@pytest.mark.parametrize("backend", ["ardupilot", "px4"])
def test_mission_run_flies_a_sitl_fleet(run_command, tmp_path, backend):
    path = tmp_path / "mission.yaml"
    path.write_text(yaml.safe_dump({**MISSION, "fleet": {"size": "auto", "backend": backend}}))
    mission = load_mission(path)
    speedup = SPEEDUP[backend]
    fakes, urls = [], []
    for v in launch_plan(mission, backend).vehicles:
        home = Home(v.latitude, v.longitude, v.altitude)
        if backend == "px4":
            port = free_udp_ports()
            model = Px4Model(home, system_id=v.system_id, speedup=speedup, seed=v.uav_id)
            fakes.append(FakeEndpoint(model, f"udpout:127.0.0.1:{port}"))
            urls.append(f"udpin:127.0.0.1:{port}")
        else:
            model = ArduCopterModel(home, system_id=v.system_id, speedup=speedup)
            fakes.append(FakeEndpoint(model, "udpin:127.0.0.1:0"))
            urls.append(f"udpout:127.0.0.1:{fakes[-1].port}")
    for fake in fakes:
        fake.start()
    try:
        result = run_command(
            "mission", "run", path, "--speedup", f"{speedup:g}", "--json", "--no-live",
            "--log", tmp_path / "run.mcap", "--connect", *urls,
        )  # fmt: skip
    finally:
        for fake in fakes:
            fake.stop()
    assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads(result.stdout)
    assert summary["completed"] and summary["fleet_size"] == len(fakes) == 2
    assert summary["max_tracking_error_m"] < mission.safety_margin
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
