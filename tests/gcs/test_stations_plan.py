"""Planning a stations mission through the ground station (docs/design.md 7): the plan JSON's
`stations` block, the summary, the plot and the Foxglove scene, and the refusals that need the
route (an unreachable point, a fixed fleet too small for the stations), each one line with
exit 2 naming its key."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.recording.scene import SceneGeometry, plan_geojson
from planner.formation import collision_spacing, radio_spacing
from tests.conftest import EXAMPLES

OPEN = """\
version: 1
origin: {lat: 45.7640, lon: 4.8357, alt: 170.0}
start: {x: 0, y: 0}
safety_margin: 5
radio_range: 100
altitude: 30
speed: {max: 5}
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "mission.yaml"
    path.write_text(text)
    return path


def test_plan_json_lists_points_holders_and_stations(gcs_main, tmp_path):
    out = tmp_path / "plan.json"
    code, _, err = gcs_main("mission", "plan", EXAMPLES / "stations.yaml", "--out", out)
    assert code == 0, err
    plan = json.loads(out.read_text())
    block = plan["stations"]
    names = [p["name"] for p in block["points"]]
    assert sorted(names) == ["bridge", "clinic", "school", "shelter"]
    stations = np.array(block["uav_stations_m"])
    assert len(stations) == plan["fleet_size"] and np.all(np.diff(stations) < 0)
    rho, radio = plan["safety_margin_m"], plan["radio_range_m"]
    gaps = -np.diff(np.concatenate([stations, [0.0]]))
    assert np.all(gaps >= collision_spacing(rho) - 1e-6)
    assert np.all(gaps <= radio_spacing(rho, radio) + 1e-6)
    for point in block["points"]:  # each point held by its UAV, at its distance
        assert stations[point["uav"] - 1] == pytest.approx(point["distance_m"])
        held = block["uav_station_xy"][point["uav"] - 1]
        assert held == pytest.approx(point["xy"], abs=1e-6)
    holders = {p["uav"] for p in block["points"]}
    assert set(block["relays"]) == set(range(1, plan["fleet_size"] + 1)) - holders
    assert plan["parking_rows"]["B"] == [] and plan["graph"] == "route"
    assert block["on_station_s"] > 0 and block["return_at_s"] is None


def test_summary_names_the_points_in_visiting_order(gcs_main):
    code, out, _ = gcs_main("mission", "check", EXAMPLES / "stations.yaml")
    assert code == 0
    text = " ".join(re.sub("[│┃]", " ", out).split())  # the table's cells, unwrapped
    assert "clinic (UAV 7" in text and "shelter (UAV 1" in text
    assert "returns 60 s later (dwell_s)" in text


def test_scene_and_map_show_points_and_uav_stations():
    plan = plan_mission(load_mission(EXAMPLES / "stations.yaml"))
    geometry = SceneGeometry.from_plan(plan)
    assert len(geometry.points) == 4 and geometry.point_names[0].startswith("clinic (UAV ")
    np.testing.assert_allclose(geometry.uav_stations, plan.formation.station_slots)
    assert len(geometry.rows) == 1  # Delta_A only: no row at the route's end
    assert len(geometry.slots) == plan.fleet_size
    features = json.loads(plan_geojson(geometry))["features"]
    named = [f["properties"]["name"] for f in features]
    assert sum(name.startswith("monitoring point ") for name in named) == 4


def test_plot_is_written(gcs_main, tmp_path):
    figure = tmp_path / "stations.png"
    code, _, err = gcs_main("mission", "plan", EXAMPLES / "stations.yaml", "--plot", figure)
    assert code == 0, err
    assert figure.stat().st_size > 10_000


def test_an_unreachable_point_is_refused_naming_it(gcs_main, tmp_path):
    # the yard is walled in on every side
    walls = "\n".join(
        f"  - segment: [[{a[0]}, {a[1]}], [{b[0]}, {b[1]}]]"
        for a, b in [((90, -60), (210, -60)), ((210, -60), (210, 60)),
                     ((210, 60), (90, 60)), ((90, 60), (90, -60))]
    )  # fmt: skip
    text = OPEN + (
        "stations:\n  order: given\n  points:\n"
        "    - {name: out, x: 300, y: 0}\n    - {name: yard, x: 150, y: 0}\n"
        f"obstacles:\n{walls}\n"
    )
    code, out, err = gcs_main("mission", "check", write(tmp_path, text))
    assert code == 2 and out == ""
    line = err.strip()
    assert "\n" not in line and "stations.points[1]" in line and "'yard'" in line


def test_a_fixed_fleet_too_small_for_the_stations_is_refused(gcs_main, tmp_path):
    text = OPEN + "fleet: {size: 2}\nstations:\n  points:\n    - {name: far, x: 400, y: 0}\n"
    code, _, err = gcs_main("mission", "check", write(tmp_path, text))
    assert code == 2
    assert "fleet.size" in err and "at least 5 UAVs" in err  # ceil(400 / 90)


def test_more_uavs_than_needed_become_relays(tmp_path):
    text = OPEN + "fleet: {size: 7}\nstations:\n  points:\n    - {name: far, x: 400, y: 0}\n"
    plan = plan_mission(load_mission(write(tmp_path, text)))
    layout = plan.route.layout
    assert plan.fleet_size == 7 and layout.minimum == 5 and layout.relays.sum() == 6
    gaps = -np.diff(np.concatenate([layout.stations, [0.0]]))
    assert np.all(gaps <= radio_spacing(5, 100) + 1e-6)
    assert np.all(gaps >= collision_spacing(5) - 1e-6)


def test_gap_ends_the_certification_of_every_leg_of_a_stations_route(gcs_main, tmp_path):
    """`--gap` applies to stations routes as to A -> B paths: each leg carries it."""
    out = tmp_path / "plan.json"
    code, _, err = gcs_main(
        "mission", "plan", EXAMPLES / "stations.yaml", "--gap", "5", "--out", out
    )
    assert code == 0, err
    assert json.loads(out.read_text())["gap_tolerance"] == pytest.approx(0.05)
    plan = plan_mission(load_mission(EXAMPLES / "stations.yaml"), gap_tolerance=0.05)
    assert plan.route is not None and len(plan.route.legs) == 4
    assert all(leg.gap_tolerance == pytest.approx(0.05) for leg in plan.route.legs)


def test_a_route_whose_legs_are_within_the_gap_says_so():
    from dataclasses import replace

    from gcs.cli.cmd_mission import certification_text

    plan = plan_mission(load_mission(EXAMPLES / "stations.yaml"), gap_tolerance=0.05)
    route = plan.route
    assert route.certified and not route.within_gap
    assert certification_text(plan.path_plan, route).startswith("every leg certified shortest")
    first = route.legs[0]  # proven within 1 % of the shortest, not certified
    near = replace(first, certified=False, lower_bound_m=0.99 * first.length_m)
    within = replace(route, legs=(near, *route.legs[1:]))
    assert within.within_gap and not within.certified
    text = certification_text(within.path_plan(), within)
    assert text.startswith("every leg within the --gap of 5 % or certified shortest")
    far = replace(near, lower_bound_m=0.9 * first.length_m)  # 10 %: beyond the gap
    outside = replace(route, legs=(far, *route.legs[1:]))
    assert not outside.within_gap
    assert certification_text(outside.path_plan(), outside).startswith("not every leg")
