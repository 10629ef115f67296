"""Monitoring-station missions end to end: `gcs mission run` with real vehicle processes over
loopback UDP, and one against fake ArduCopter autopilots.

The mission is tests/missions/stations.yaml (4 UAVs, two points). With its dwells the fleet
comes home by itself; without them it holds its stations until a real `gcs return` process
asks over the operator socket (a `gcs speed` meanwhile is refused: the formation stands
still on station). Against fake ArduCopters (tests/fakes, the ArduPilot driver) a one-point
mission flies out, holds and comes home with nothing new in the drivers.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

from gcs.geodesy import geodetic_to_enu
from gcs.mission import load_mission
from gcs.recording.logreader import read_recording
from gcs.sim.sitl import plan_for_launch
from tests.conftest import MISSIONS
from tests.fakes.common import enu_to_global
from tests.flying import Flight, environment, flight_speedup, gcs_command, read_log
from tests.sitl_fleet import SPEEDUP as SITL_SPEEDUP
from tests.sitl_fleet import fake_fleet

MISSION = MISSIONS / "stations.yaml"
SPEEDUP = str(flight_speedup(5))  # lower on a busy machine (tests/flying.py)
pytestmark = [pytest.mark.slow, pytest.mark.timeout(150)]


def _home_on_start_slots(run: dict, log: Path) -> None:
    """Every UAV landed on its start slot (true positions from the recording)."""
    topics = read_log(log)
    plan = topics["/plan"][0][1]
    slots = np.array(plan["parking_slots"]["A"])
    for uav in range(1, run["fleet_size"] + 1):
        last = topics[f"/uav{uav}/state"][-1][1]
        assert last["phase"] == "landed"
        x, y, z = last["true_position"]
        assert np.hypot(x - slots[uav - 1][0], y - slots[uav - 1][1]) < 1.5
        assert z < 0.5


def _within_guarantees(run: dict, rho: float) -> None:
    tracking = run["max_tracking_error_m"]
    assert tracking < rho
    assert run["min_uav_uav_m"] >= 2 * rho - 2 * tracking
    assert run["min_uav_obstacle_m"] >= rho - tracking
    assert run["connected_fraction"] == 1.0


def test_a_stations_mission_flies_out_holds_and_comes_home(tmp_path: Path):
    log = tmp_path / "stations.mcap"
    done = subprocess.run(
        gcs_command("mission", "run", str(MISSION), "--speedup", SPEEDUP, "--json", "--log",
                    str(log)),
        capture_output=True, text=True, cwd=tmp_path, env=environment(), timeout=140,
    )  # fmt: skip
    assert done.stdout.count("\n") == 1, done.stderr[-3000:]
    run = json.loads(done.stdout)
    assert done.returncode == 0, (run.get("reason"), done.stderr[-3000:])
    assert run["completed"] is True
    _within_guarantees(run, load_mission(MISSION).safety_margin)
    _home_on_start_slots(run, log)
    stations = run["stations"]
    assert [(p["name"], p["uav"]) for p in stations["points"]] == [("north", 3), ("east", 1)]
    assert all(p["on_station_s"] >= d for p, d in zip(stations["points"], (5, 8), strict=True))
    assert stations["held_connected_fraction"] == 1.0
    (record,) = [m for _, m in read_log(log)["/return"]]
    assert record["source"] == "dwell" and record["effective_s"] == stations["return_s"]
    assert [c["source"] for c in run["speed_changes"]] == ["hold", "return", "return"]
    for change in run["speed_changes"]:  # every UAV acknowledged each
        assert sorted(change["acks"]) == [str(u) for u in range(1, run["fleet_size"] + 1)]


def _holding_flight(source: Path, tmp_path: Path):
    """`gcs mission run` of `source` without its dwells (no dwell, no return.at: the fleet
    holds until asked): (the mission data, its log, the running flight, `ask(*args)` running
    another `gcs` command against it)."""
    data = yaml.safe_load(source.read_text())
    for point in data["stations"]["points"]:
        del point["dwell_s"]
    mission = tmp_path / "hold.yaml"
    mission.write_text(yaml.safe_dump(data, sort_keys=False))
    log = tmp_path / "hold.mcap"
    flight = Flight(
        ["-v", "mission", "run", str(mission), "--speedup", SPEEDUP, "--json", "--log", str(log)],
        tmp_path,
    )

    def ask(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            gcs_command(*args, "--log", str(log)),
            capture_output=True, text=True, cwd=tmp_path, env=environment(), timeout=30,
        )  # fmt: skip

    return data, log, flight, ask


def test_the_operator_brings_the_fleet_home_with_gcs_return(tmp_path: Path):
    data, log, flight, ask = _holding_flight(MISSION, tmp_path)
    try:
        flight.wait_for("holding until the operator asks", timeout=100)
        speed = ask("speed", "3")
        assert speed.returncode == 1 and "holds its station" in speed.stderr, speed.stderr
        back = ask("return", "--json")
        assert back.returncode == 0, back.stderr
        answer = json.loads(back.stdout)
        assert answer["ok"] is True and "return home at mission time" in back.stderr
        again = ask("return")
        assert again.returncode == 1 and "already returning" in again.stderr
        code, out, err = flight.finish(timeout=100)
    finally:
        flight.kill()
    assert code == 0, err[-3000:]
    run = json.loads(out)
    assert run["completed"] is True
    _within_guarantees(run, data["safety_margin"])
    _home_on_start_slots(run, log)
    stations = run["stations"]
    assert stations["return_s"] == answer["effective_s"]
    assert stations["held_connected_fraction"] == 1.0
    (record,) = [m for _, m in read_log(log)["/return"]]
    assert record["source"] == "operator"
    assert record["effective_s"] == answer["effective_s"]
    assert record["distance"] == pytest.approx(answer["distance"])
    assert [c["source"] for c in run["speed_changes"]] == ["hold", "return", "return"]


SITL_MISSION = {
    "version": 1,
    "name": "sitl-stations",
    "origin": {"lat": 47.3975, "lon": 8.545, "alt": 488.0},
    "start": {"x": 0, "y": 0, "theta_deg": 0},
    "safety_margin": 5,
    "radio_range": 100,
    "altitude": 15,
    "speed": {"max": 5, "initial": 5},
    "fleet": {"size": "auto", "backend": "ardupilot"},
    "vehicle": {"max_speed": 12, "max_acceleration": 6, "radius": 0.5, "apply_limits": True},
    "stations": {"points": [{"name": "mast", "x": 150, "y": 0, "dwell_s": 3}]},
}


def test_fake_arducopters_fly_a_stations_mission_with_the_drivers_as_they_are(
    gcs_main, tmp_path: Path
):
    path = tmp_path / "mission.yaml"
    path.write_text(yaml.safe_dump(SITL_MISSION))
    mission = load_mission(path)
    speedup = SITL_SPEEDUP["ardupilot"]
    fakes, urls = fake_fleet(mission, "ardupilot", speedup)
    for fake in fakes:
        fake.start()
    try:
        result = gcs_main(
            "mission", "run", path, "--speedup", f"{speedup:g}", "--json", "--no-live",
            "--log", tmp_path / "run.mcap", "--connect", *urls,
        )  # fmt: skip
    finally:
        for fake in fakes:
            fake.stop()
    assert result.returncode == 0, result.stderr[-3000:]
    run = json.loads(result.stdout)
    assert run["completed"] is True and run["fleet_size"] == len(fakes) == 2
    assert run["max_tracking_error_m"] < mission.safety_margin
    (point,) = run["stations"]["points"]
    assert (point["name"], point["uav"]) == ("mast", 1) and point["on_station_s"] >= 3.0
    recording = read_recording(tmp_path / "run.mcap")
    assert [m["source"] for _, m in recording.messages("/return")] == ["dwell"]
    # every fake is down and disarmed on its start slot, where it really is
    slots = plan_for_launch(mission).formation.start_slots
    for fake, slot in zip(fakes, slots, strict=True):
        model = fake.model
        assert not model.armed
        lat, lon, _ = enu_to_global(model.boot_home, model.body.position)
        landed = geodetic_to_enu(lat, lon, mission.origin.alt, mission.origin)
        assert np.hypot(*(landed[:2] - slot)) < 1.5


@pytest.mark.timeout(300)
def test_the_operator_relieves_one_uav_with_gcs_relieve(tmp_path: Path):
    """tests/missions/stations-relief.yaml (5 UAVs where 3 would do) without dwells: once the
    fleet holds, a real `gcs relieve 3` sends UAV 3 (holder of `north`) home alone: UAV 4 takes
    `north`, UAV 3 lands on the last slot; a second relief and the return are refused until it
    has landed; then `gcs return` brings the four others home onto the first four slots."""
    data, log, flight, ask = _holding_flight(MISSIONS / "stations-relief.yaml", tmp_path)
    try:
        flight.wait_for("holding until the operator asks", timeout=100)
        relief = ask("relieve", "3", "--json")
        assert relief.returncode == 0, relief.stderr
        answer = json.loads(relief.stdout)
        assert answer["ok"] is True and answer["uav"] == 3
        assert "UAV 3 relieved at mission time" in relief.stderr
        second = ask("relieve", "4")
        assert second.returncode == 1 and "one relief at a time" in second.stderr
        early = ask("return")
        assert early.returncode == 1 and "is being relieved" in early.stderr
        flight.wait_for("UAV 3: landing -> landed", timeout=120)
        back = ask("return")
        assert back.returncode == 0, back.stderr
        code, out, err = flight.finish(timeout=120)
    finally:
        flight.kill()
    assert code == 0, err[-3000:]
    run = json.loads(out)
    assert run["completed"] is True
    _within_guarantees(run, data["safety_margin"])
    stations = run["stations"]
    assert [p["uav"] for p in stations["points"]] == [4, 1]
    (relieved,) = stations["relieved"]
    assert relieved["uav"] == 3 and relieved["source"] == "operator"
    topics = read_log(log)
    slots = np.array(topics["/plan"][0][1]["parking_slots"]["A"])
    ends = {}
    for uav in range(1, 6):
        last = topics[f"/uav{uav}/state"][-1][1]
        assert last["phase"] == "landed"
        ends[uav] = np.array(last["true_position"][:2])
    assert np.hypot(*(ends[3] - slots[4])) < 1.5
    for rank, uav in enumerate((1, 2, 4, 5)):
        assert np.hypot(*(ends[uav] - slots[rank])) < 1.5
    (record,) = [m for _, m in topics["/relief"]]
    assert record["members"] == [1, 2, 4, 5]
