"""Connectivity by line of sight (docs/line-of-sight.md): every plan
says how it stands under both rules (plan JSON `connectivity`, one warning line for a disk plan
whose links pass through buildings); `connectivity.rule: line_of_sight` plans the rigid
formation whose spacing is the path's chord reach or the elastic one that closes up at the
corners, whichever needs fewer UAVs, and every sampled instant of it is
connected by line of sight, checked by brute force (shapely and networkx, none of the code
under test) on the examples, random buildings and a city grid; it is flown so in the fast
mode; a fleet too small for it, or a stations mission, is refused with one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from gcs.mission import load_mission
from gcs.planning import plan_json, plan_mission
from gcs.sim.fastsim import FastOptions, fly_fast
from planner.scenarios import city_grid, random_buildings
from tests.sight_checks import brute_connected

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def with_rule(folder: Path, source: Path, rule: str = "line_of_sight", **changes) -> Path:
    data = yaml.safe_load(source.read_text())
    data["connectivity"] = {"rule": rule}
    data.update(changes)
    path = folder / source.name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    for footprints in source.parent.glob("*.geojson"):  # relative to the mission file
        (folder / footprints.name).write_bytes(footprints.read_bytes())
    return path


def scenario_mission(folder: Path, scenario) -> Path:
    """A mission file of a planner scenario (rectangles), line of sight, speed capped."""
    data = {
        "version": 1,
        "name": scenario.name,
        "start": {"x": float(scenario.start[0]), "y": float(scenario.start[1]), "theta_deg": 0},
        "goal": {"x": float(scenario.goal[0]), "y": float(scenario.goal[1]), "theta_deg": 0},
        "safety_margin": scenario.safety_margin,
        "radio_range": 120.0,
        "altitude": 20,
        "speed": {"max": 8, "cap_to_safe": True},
        "connectivity": {"rule": "line_of_sight"},
        "obstacles": [
            {"rectangle": {"center": [float(r[0]), float(r[1])], "size": [float(r[2]), float(r[3])],
                           "angle_deg": float(r[4])}}
            for r in scenario.rectangles
        ],
    }  # fmt: skip
    path = folder / f"{scenario.name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def assert_connected_by_sight(plan, samples: int = 150) -> None:
    mission, formation = plan.mission, plan.formation
    polygons = list(mission.obstacles.polygons)
    walls = mission.obstacles.walls
    stations = mission.base_station_points
    for distance in np.linspace(0.0, formation.total_distance, samples):
        xy = formation.positions(np.array([distance]))[0]
        assert brute_connected(xy, stations, polygons, walls, mission.radio_range), distance


def test_a_disk_plan_says_how_often_its_links_pass_through_buildings(gcs_main, caplog, tmp_path):
    path = with_rule(tmp_path, EXAMPLES / "city-blocks.yaml", "disk")
    result = gcs_main("mission", "plan", path, "--json")
    assert result.returncode == 0
    connectivity = json.loads(result.stdout)["connectivity"]
    assert connectivity["rule"] == "disk" and connectivity["fleet_size"] == 8
    assert connectivity["eq28_fleet_size"] == 8
    assert 0.1 < connectivity["los_connected_fraction"] < 0.2  # 14.5 % measured by hand
    assert connectivity["rigid_los_fleet_size"] > 40  # the rigid baseline: 55 by hand
    # closing up at the corners needs far fewer on the same path (17)
    assert 8 < connectivity["elastic_los_fleet_size"] < connectivity["rigid_los_fleet_size"] / 2
    assert connectivity["spacing"] == "rigid" and connectivity["warp_m"] is None
    warnings = [r.getMessage() for r in caplog.records if r.name == "gcs.connectivity"]
    assert len(warnings) == 1
    assert "connected by line of sight 14." in warnings[0]
    assert f"needs {connectivity['elastic_los_fleet_size']} UAVs" in warnings[0]
    assert "connectivity.rule: line_of_sight" in warnings[0]


def test_the_line_of_sight_plan_of_the_small_mission_is_connected_at_every_instant(tmp_path):
    """On the shortest path the rigid formation needs 10 UAVs (chords clear 35 m apart round
    its corners); closing up at the corners, the 4 UAVs of eq. 28 keep line of sight on the
    same path."""
    plan = plan_mission(load_mission(with_rule(tmp_path, EXAMPLES / "small.yaml")))
    disk = plan_mission(load_mission(EXAMPLES / "small.yaml"))
    assert plan.valid and plan.fleet_size == disk.fleet_size == 4
    assert plan_json(disk)["connectivity"]["rigid_los_fleet_size"] == 10
    data = plan_json(plan)["connectivity"]
    assert data["rule"] == "line_of_sight" and data["los_connected_fraction"] == 1.0
    assert data["fleet_size"] == data["elastic_los_fleet_size"] == plan.fleet_size
    assert data["spacing"] == "elastic" and len(data["warp_m"]) > 2
    assert data["corner_margin_m"] == plan.mission.safety_margin  # the shortest path
    assert plan.path_plan.length_m == disk.path_plan.length_m and plan.path_plan.certified
    assert plan.duration_s > disk.duration_s  # the UAVs wait at the corners
    assert_connected_by_sight(plan, samples=600)
    # the disk plan is not: the brute force finds an instant cut off by a building
    with pytest.raises(AssertionError):
        assert_connected_by_sight(disk)


@pytest.mark.parametrize(
    "scenario",
    [random_buildings(12, seed=3, size=500.0), random_buildings(25, seed=8, size=700.0),
     city_grid(4, 3)],
    ids=lambda s: s.name,
)  # fmt: skip
def test_line_of_sight_plans_of_random_and_grid_maps_are_connected_by_sight(tmp_path, scenario):
    plan = plan_mission(load_mission(scenario_mission(tmp_path, scenario)))
    assert plan.valid, plan.reason
    assert_connected_by_sight(plan)


def test_flown_in_the_fast_mode_the_line_of_sight_plan_stays_connected_by_sight(tmp_path):
    disk = fly_fast(plan_mission(load_mission(EXAMPLES / "small.yaml")), FastOptions())
    sight = fly_fast(
        plan_mission(load_mission(with_rule(tmp_path, EXAMPLES / "small.yaml"))), FastOptions()
    )
    assert disk.run_json["connected_fraction"] == sight.run_json["connected_fraction"] == 1.0
    assert disk.run_json["los_connected_fraction"] < 0.95
    assert sight.run_json["los_connected_fraction"] == 1.0
    assert sight.run_json["completed"] and sight.run_json["max_tracking_error_m"] < 5.0


def test_a_fixed_fleet_too_small_for_line_of_sight_is_refused_with_the_number(tmp_path, gcs_main):
    """city-blocks: eq. 28 needs 8 UAVs, line of sight 9 (elastic, corners taken wider; the
    rigid formation 64 on the shortest path)."""
    path = with_rule(tmp_path, EXAMPLES / "city-blocks.yaml", fleet={"size": 8})
    result = gcs_main("mission", "check", path)
    assert result.returncode == 2 and result.stderr.count("\n") == 1
    assert "fleet.size" in result.stderr and "for line of sight" in result.stderr
    assert "at least 9 UAVs" in result.stderr and "elastic" in result.stderr


def test_a_stations_mission_with_line_of_sight_is_refused(tmp_path, gcs_main):
    result = gcs_main("mission", "check", with_rule(tmp_path, EXAMPLES / "stations.yaml"))
    assert result.returncode == 2 and "connectivity.rule" in result.stderr
    assert "A -> B missions" in result.stderr


def test_an_unknown_rule_is_refused(tmp_path, gcs_main):
    result = gcs_main("mission", "check", with_rule(tmp_path, EXAMPLES / "small.yaml", "sight"))
    assert result.returncode == 2 and result.stderr.count("\n") == 1
    assert "connectivity.rule" in result.stderr and "line_of_sight" in result.stderr


def test_through_a_medium_that_knows_buildings_the_disk_plan_breaks_and_the_sight_plan_holds(
    tmp_path,
):
    """`radio.buildings: true`: the fast mode's medium cuts links through obstacles. The small
    mission's disk plan loses UAV 1 behind the block (the formation holds, then everyone
    lands: the link stayed lost); its line-of-sight plan flies through, every sample of the
    medium connected."""
    source = EXAMPLES / "small.yaml"
    disk = fly_fast(
        plan_mission(load_mission(with_rule(tmp_path, source, "disk", radio={"buildings": True}))),
        FastOptions(),
    )
    sight = fly_fast(
        plan_mission(load_mission(with_rule(tmp_path, source, radio={"buildings": True}))),
        FastOptions(),
    )
    assert disk.run_json["completed"] is False and "link lost" in disk.run_json["reason"]
    assert disk.run_json["radio"]["connected_fraction"] < 0.9
    assert sight.run_json["completed"] is True
    assert sight.run_json["radio"]["connected_fraction"] == 1.0


SLALOM = """\
version: 1
name: slalom
start: {x: 0, y: 0, theta_deg: 0}
goal: {x: 300, y: 0, theta_deg: 0}
safety_margin: 5
radio_range: 120
altitude: 20
speed: {max: 5, cap_to_safe: true}
connectivity: {rule: line_of_sight}
obstacles:
  - segment: [[100, -200], [100, 12]]
  - segment: [[112, -12], [112, 200]]
  - segment: [[124, -200], [124, 12]]
  - segment: [[136, -12], [136, 200]]
"""


def test_a_mission_without_any_line_of_sight_formation_is_refused_saying_why(tmp_path, gcs_main):
    """A slalom through four walls: eq. 28 needs 4 UAVs, line of sight 8 (they close up at
    every gate). With a building 77 m behind A the parking row of 8 UAVs (104 m) does not
    fit, and the refusal says so instead of blaming the chords."""
    fits = tmp_path / "slalom.yaml"
    fits.write_text(SLALOM)
    result = gcs_main("mission", "plan", fits, "--json")
    assert result.returncode == 0, result.stderr
    plan = json.loads(result.stdout)
    assert plan["fleet_size"] == 8 and plan["min_fleet_size"] == 4
    assert plan["connectivity"]["spacing"] == "elastic"
    blocked = tmp_path / "slalom-blocked.yaml"
    blocked.write_text(SLALOM + "  - rectangle: {center: [-80, 0], size: [6, 60], angle_deg: 0}\n")
    result = gcs_main("mission", "check", blocked)
    assert result.returncode == 2 and result.stderr.count("\n") == 1
    assert "connectivity.rule" in result.stderr and "no line-of-sight formation" in result.stderr
    assert "needs 8 UAVs" in result.stderr and "parking row behind A (104 m)" in result.stderr
