"""Mission model: parsing, defaults, obstacles, GeoJSON footprints, geodesy."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.errors import InputError
from gcs.geodesy import Origin, enu_to_geodetic, geodetic_to_enu, local_to_lonlat, lonlat_to_local
from gcs.mission import DEFAULT_ORIGIN, DEFAULT_TRACKING_FRACTION, load_mission
from tests.conftest import EXAMPLES
from tests.mission_texts import LYON, MINIMAL


def write(tmp_path: Path, text: str, name: str = "mission.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def refusal(path: Path) -> InputError:
    with pytest.raises(InputError) as caught:
        load_mission(path)
    return caught.value


# --- the model --------------------------------------------------------------------------------


def test_minimal_mission_gets_the_documented_defaults(tmp_path):
    mission = load_mission(write(tmp_path, MINIMAL, "my mission.yaml"))
    assert mission.name == "my-mission"  # the file name, made safe for log names
    assert mission.origin == DEFAULT_ORIGIN
    assert (mission.start.theta_deg, mission.goal.theta_deg) == (0.0, 0.0)
    assert mission.parking == "segment"
    assert mission.speed.initial == mission.speed.max == 8.0
    assert mission.speed.changes == () and mission.speed.cap_to_safe is False
    assert mission.fleet.size is None and mission.fleet.backend == "sim"
    assert mission.fleet.connections == ()
    v = mission.vehicle
    assert (v.max_speed, v.max_acceleration, v.radius) == (15.0, 6.0, 0.5)
    assert v.tracking_allowance == pytest.approx(DEFAULT_TRACKING_FRACTION * 5)
    assert mission.error_budget == pytest.approx(5 * (1 - DEFAULT_TRACKING_FRACTION))
    assert mission.sim.setpoint_rate_hz == 10.0 and mission.sim.seed == 1
    assert mission.sim.battery_mah is None and mission.sim.battery_capacities(4) is None
    assert mission.radio.enabled and mission.radio.loss == 0.0
    assert mission.signing.key_file is None
    assert len(mission.obstacles) == 0 and mission.base_stations == ()
    assert mission.text == MINIMAL


def test_contract_example_keys_are_all_accepted(tmp_path):
    """The mission file of docs/mission-file.md, key for key (noise spelt as documented)."""
    (tmp_path / "buildings.geojson").write_text(
        json.dumps(feature_collection([square_lonlat(LYON, 800, 800, 30)]))
    )
    text = """\
version: 1
name: table-ii
origin: {lat: 45.7640, lon: 4.8357, alt: 170.0}
start: {x: 200, y: 200, theta_deg: 0}
goal:  {x: 700, y: 700, theta_deg: 0}
safety_margin: 5
radio_range: 220
altitude: 30
parking: segment
speed:
  max: 10
  initial: 10
  changes:
    - {at: 120, speed: 5}
    - {at: 300, speed: 10, leader: 4}
fleet:
  size: auto
  backend: sim
  connections: []
vehicle:
  max_speed: 15
  max_acceleration: 6
  radius: 0.5
base_stations:
  - {x: 1000, y: 900}
obstacles:
  - rectangle: {center: [300, 250], size: [80, 40], angle_deg: 0}
  - polygon: [[400, 400], [460, 400], [430, 470]]
  - segment: [[100, 500], [180, 560]]
  - geojson: buildings.geojson
ground_users:
  - {x: 450, y: 300, rate_bps: 800}
sim:
  setpoint_rate_hz: 10
  seed: 1
  noise: {wind_mean_mps: 2, wind_direction_deg: 90, wind_gust_mps: 1, wind_time_s: 4,
          position_m: 0.2}
radio:
  enabled: true
  hop_latency_ms: 2
  jitter_ms: 1
  loss: 0.0
signing:
  key_file: fleet.key
"""
    mission = load_mission(write(tmp_path, text))
    assert mission.name == "table-ii"
    assert mission.speed.changes[1].leader == 4 and mission.speed.changes[0].leader is None
    assert [c.at for c in mission.speed.changes] == [120.0, 300.0]
    assert mission.base_stations[0].x == 1000.0
    assert mission.ground_users[0].rate_bps == 800.0
    assert mission.sim.noise.wind_direction_deg == 90.0 and mission.sim.noise.position_m == 0.2
    assert mission.signing.key_file == (tmp_path / "fleet.key").resolve()
    # rectangle + polygon + one footprint are solids, the segment is a wall; keys line up.
    assert len(mission.obstacles.polygons) == 3 and len(mission.obstacles.walls) == 1
    assert mission.obstacle_keys == (
        "obstacles[0].rectangle",
        "obstacles[1].polygon",
        "obstacles[3].geojson.features[0]",
        "obstacles[2].segment",
    )
    assert len(mission.obstacle_keys) == len(mission.obstacles.geometries)


def test_examples_load():
    small = load_mission(EXAMPLES / "small.yaml")
    assert small.fleet.size is None and len(small.speed.changes) == 2
    assert any(c.leader for c in small.speed.changes)
    table = load_mission(EXAMPLES / "table-ii.yaml")
    assert table.fleet.size == 9 and len(table.obstacles.polygons) == 10
    assert len(table.ground_users) == 6
    assert table.start.xy.tolist() == [200, 200] and table.goal.xy.tolist() == [700, 700]
    assert (table.safety_margin, table.radio_range, table.speed.max) == (5, 220, 10)
    city = load_mission(EXAMPLES / "city-blocks.yaml")
    assert len(city.obstacles.polygons) == 30


def test_rectangle_corners_follow_center_size_and_angle(tmp_path):
    text = (
        MINIMAL
        + "obstacles:\n  - rectangle: {center: [100, -200], size: [40, 10], angle_deg: 90}\n"
    )
    ring = load_mission(write(tmp_path, text)).obstacles.polygons[0]
    shape = shapely.Polygon(ring)
    assert shape.area == pytest.approx(400)
    # Turned by 90 degrees: 10 m wide in x, 40 m tall in y.
    assert shape.bounds == pytest.approx((95, -220, 105, -180))


def test_polygon_may_be_given_closed(tmp_path):
    text = MINIMAL + "obstacles:\n  - polygon: [[100, 100], [120, 100], [110, 130], [100, 100]]\n"
    ring = load_mission(write(tmp_path, text)).obstacles.polygons[0]
    assert len(ring) == 3


def test_yaml_12_exponent_floats_are_numbers(tmp_path):
    mission = load_mission(
        write(tmp_path, MINIMAL.replace("radio_range: 120", "radio_range: 1.2e2"))
    )
    assert mission.radio_range == 120.0
    mission = load_mission(
        write(tmp_path, MINIMAL.replace("radio_range: 120", "radio_range: 12e1"))
    )
    assert mission.radio_range == 120.0


def test_refusal_is_one_line_with_file_and_key(tmp_path):
    path = write(
        tmp_path, MINIMAL + "obstacles:\n  - rectangle: {center: [0, 500], size: [3, -1]}\n"
    )
    error = refusal(path)
    assert error.key_path == "obstacles[0].rectangle.size[1]"
    assert str(error).startswith(f"{path}: obstacles[0].rectangle.size[1]: expected ")
    assert "\n" not in str(error)


def test_unreadable_file_is_refused(tmp_path):
    error = refusal(tmp_path / "missing.yaml")
    assert str(error).startswith(f"{tmp_path / 'missing.yaml'}: expected a readable file")
    assert "directory" in str(refusal(tmp_path))


@pytest.mark.parametrize(
    ("replace", "key"),
    [
        (("altitude: 30", "altitude: true"), "altitude"),
        (("altitude: 30", "altitude: '30'"), "altitude"),
        (("altitude: 30", "altitude: .nan"), "altitude"),
        (("altitude: 30", "altitude: 0"), "altitude"),
        (("{max: 8}", "{max: -.inf}"), "speed.max"),
        (("goal: {x: 300, y: 100}", "goal: {x: 300, y: 100, theta_deg: off}"), "goal.theta_deg"),
        (("version: 1", "version: 1.0"), "version"),
    ],
)
def test_types_are_not_converted(tmp_path, replace, key):
    assert refusal(write(tmp_path, MINIMAL.replace(*replace))).key_path == key


def test_sim_battery_mah_for_every_uav_or_one_each(tmp_path):
    one = load_mission(write(tmp_path, MINIMAL + "sim: {battery_mah: 500}\n")).sim
    assert one.battery_mah == 500.0 and one.battery_capacities(3) == (500.0, 500.0, 500.0)
    each = load_mission(write(tmp_path, MINIMAL + "sim: {battery_mah: [8000, 250.5]}\n")).sim
    assert each.battery_mah == (8000.0, 250.5) and each.battery_capacities(2) == (8000.0, 250.5)
    with pytest.raises(ValueError, match="2 numbers for 3 UAVs"):
        each.battery_capacities(3)


@pytest.mark.parametrize(
    ("value", "key", "expected"),
    [
        ("0", "sim.battery_mah", "a finite number > 0 (mAh), got 0"),
        ("-5", "sim.battery_mah", "a finite number > 0 (mAh), got -5"),
        ("'500'", "sim.battery_mah", "or a list with one per UAV, got '500' (a string)"),
        ("true", "sim.battery_mah", "or a list with one per UAV, got true (a boolean)"),
        ("{uav2: 500}", "sim.battery_mah", "or a list with one per UAV, got a mapping"),
        ("[]", "sim.battery_mah", "or one per UAV, got an empty list"),
        ("[8000, 0]", "sim.battery_mah[1]", "a finite number > 0 (mAh), got 0"),
        ("[8000, .inf]", "sim.battery_mah[1]", "a finite number > 0 (mAh), got inf"),
    ],
)
def test_sim_battery_mah_refusals_name_the_key(tmp_path, value, key, expected):
    path = write(tmp_path, MINIMAL + f"sim: {{battery_mah: {value}}}\n")
    error = refusal(path)
    assert error.key_path == key
    assert str(error).startswith(f"{path}: {key}: expected ") and str(error).endswith(expected)


def test_sim_battery_mah_list_needs_one_number_per_planned_uav(tmp_path):
    """Its length is checked once the fleet size is known (planning, exit 2)."""
    from gcs.planning import plan_mission

    size = plan_mission(load_mission(write(tmp_path, MINIMAL))).fleet_size
    assert size != 2
    path = write(tmp_path, MINIMAL + "sim: {battery_mah: [8000, 500]}\n")
    with pytest.raises(InputError) as caught:
        plan_mission(load_mission(path))
    assert str(caught.value) == (
        f"{path}: sim.battery_mah: expected a number > 0 (mAh) for every UAV, or a list with "
        f"one per UAV ({size}), got 2 numbers"
    )
    text = MINIMAL + f"sim: {{battery_mah: [{', '.join(['500'] * size)}]}}\n"
    assert plan_mission(load_mission(write(tmp_path, text))).fleet_size == size


def test_eq9_boundary_is_accepted(tmp_path):
    bound = 2 * (1 + math.sqrt(2)) * 5
    text = MINIMAL.replace("radio_range: 120", f"radio_range: {bound!r}")
    assert load_mission(write(tmp_path, text)).radio_range == pytest.approx(bound)
    text = MINIMAL.replace("radio_range: 120", f"radio_range: {bound - 1e-3!r}")
    assert refusal(write(tmp_path, text)).key_path == "radio_range"


def test_start_exactly_at_the_margin_is_accepted(tmp_path):
    wall = "obstacles:\n  - segment: [[-5, -10], [-5, 10]]\n"  # 5 m = rho_c from A
    assert len(load_mission(write(tmp_path, MINIMAL + wall)).obstacles) == 1
    wall = "obstacles:\n  - segment: [[-4.9, -10], [-4.9, 10]]\n"
    assert refusal(write(tmp_path, MINIMAL + wall)).key_path == "start"


# --- GeoJSON footprints ------------------------------------------------------------------------


def square_lonlat(origin: Origin, x: float, y: float, side: float) -> list[list[float]]:
    """A closed lon/lat ring of a square with its south-west corner at local (x, y)."""
    local = np.array([[x, y], [x + side, y], [x + side, y + side], [x, y + side], [x, y]])
    return local_to_lonlat(local, origin).tolist()


def feature_collection(rings: list, kind: str = "Polygon") -> dict:
    return {
        "type": "FeatureCollection",
        "features": [
            {"type": "Feature", "properties": {}, "geometry": {"type": kind, "coordinates": [r]}}
            for r in rings
        ],
    }


def test_city_blocks_geojson_lands_on_the_local_grid():
    city = load_mission(EXAMPLES / "city-blocks.yaml")
    shapes = shapely.polygons([np.vstack([p, p[:1]]) for p in city.obstacles.polygons])
    areas = shapely.area(shapes)
    assert areas == pytest.approx(np.full(30, 90 * 60), rel=1e-4)
    first = shapes[0]  # block 0-0: the grid's south-west corner is the origin
    assert first.bounds == pytest.approx((0, 0, 90, 60), abs=0.02)
    assert city.obstacle_keys[0] == "obstacles[0].geojson.features[0]"


def test_geojson_kinds_multipolygon_lines_holes_and_null_geometry(tmp_path):
    outer = square_lonlat(LYON, 500, 0, 40)
    hole = square_lonlat(LYON, 510, 10, 10)
    doc = {
        "type": "FeatureCollection",
        "features": [
            {"type": "Feature", "geometry": None, "properties": {}},
            {
                "type": "Feature",
                "properties": {},
                "geometry": {
                    "type": "MultiPolygon",
                    "coordinates": [[outer, hole], [square_lonlat(LYON, 600, 0, 20)]],
                },
            },
            {
                "type": "Feature",
                "properties": {},
                "geometry": {
                    "type": "LineString",
                    "coordinates": local_to_lonlat(
                        np.array([[0.0, 300.0], [100.0, 300.0], [100.0, 400.0]]), LYON
                    ).tolist(),
                },
            },
        ],
    }
    (tmp_path / "b.geojson").write_text(json.dumps(doc))
    text = "origin: {lat: 45.7640, lon: 4.8357, alt: 170}\n" + MINIMAL
    text += "obstacles:\n  - geojson: b.geojson\n"
    mission = load_mission(write(tmp_path, text))
    polys = mission.obstacles.polygons
    assert len(polys) == 2 and len(mission.obstacles.walls) == 2
    assert shapely.Polygon(polys[0]).area == pytest.approx(1600, rel=1e-4)  # hole ignored
    assert mission.obstacles.walls[1] == pytest.approx(np.array([[100, 300], [100, 400]]), abs=0.01)
    assert mission.obstacle_keys == (
        "obstacles[0].geojson.features[1]",
        "obstacles[0].geojson.features[1]",
        "obstacles[0].geojson.features[2]",
        "obstacles[0].geojson.features[2]",
    )


def test_geojson_path_is_relative_to_the_mission_file(tmp_path, monkeypatch):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.geojson").write_text(
        json.dumps(feature_collection([square_lonlat(LYON, 500, 500, 20)]))
    )
    text = (
        "origin: {lat: 45.7640, lon: 4.8357}\n" + MINIMAL + "obstacles:\n  - geojson: b.geojson\n"
    )
    path = write(tmp_path / "sub", text)
    monkeypatch.chdir(tmp_path)
    assert len(load_mission(path).obstacles) == 1


def test_geojson_bad_coordinates_are_refused(tmp_path):
    ring = square_lonlat(LYON, 500, 500, 20)
    ring[1] = [ring[1][0], 95.0]  # latitude beyond the pole
    (tmp_path / "b.geojson").write_text(json.dumps(feature_collection([ring])))
    text = (
        "origin: {lat: 45.7640, lon: 4.8357}\n" + MINIMAL + "obstacles:\n  - geojson: b.geojson\n"
    )
    error = refusal(write(tmp_path, text))
    assert error.key_path == "obstacles[0].geojson" and "features[0]" in str(error)


# --- geodesy ------------------------------------------------------------------------------------


@settings(max_examples=60, derandomize=True, deadline=None)
@given(
    lat=st.floats(-80, 80),
    lon=st.floats(-179, 179),
    xy=st.lists(st.floats(-50_000, 50_000), min_size=2, max_size=2),
    up=st.floats(-100, 3000),
)
def test_local_geodetic_round_trip(lat, lon, xy, up):
    origin = Origin(lat=lat, lon=lon, alt=100.0)
    geo = enu_to_geodetic(xy[0], xy[1], up, origin)
    back = geodetic_to_enu(geo[0], geo[1], geo[2], origin)
    assert back == pytest.approx([xy[0], xy[1], up], abs=1e-3)
    flat = lonlat_to_local(local_to_lonlat(np.array(xy), origin), origin)
    assert flat == pytest.approx(xy, abs=1e-3)


def test_geodesy_matches_known_distances():
    # One arc-minute of latitude at 45 degrees is 1852 m within 0.2 %; 1 degree of longitude
    # at 45 degrees is about 78.85 km (WGS84).
    origin = Origin(lat=45.0, lon=5.0, alt=0.0)
    north = geodetic_to_enu(45.0 + 1 / 60, 5.0, 0.0, origin)
    assert north[1] == pytest.approx(1852, rel=2e-3) and abs(north[0]) < 1e-6
    east = lonlat_to_local(np.array([6.0, 45.0]), origin)
    assert east[0] == pytest.approx(78_847, rel=1e-3)
    # Vectorised: (N, 2) in, (N, 2) out.
    pts = lonlat_to_local(np.array([[5.0, 45.0], [5.0, 45.001]]), origin)
    assert pts.shape == (2, 2) and pts[0] == pytest.approx([0, 0], abs=1e-9)
