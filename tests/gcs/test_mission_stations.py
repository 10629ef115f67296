"""Monitoring stations in the mission file (use case 1): `stations` (with
`relieve_below_pct`), `return`, an optional `goal`, their refusals (one line naming the key, exit 2 from the CLI) and
`Mission.base_station_points`."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gcs.errors import InputError
from gcs.geodesy import geodetic_to_enu
from gcs.mission import Mission, Station, load_mission
from tests.conftest import EXAMPLES
from tests.mission_texts import LYON

HEAD = """\
version: 1
origin: {lat: 45.7640, lon: 4.8357, alt: 170.0}
start: {x: 0, y: 0}
safety_margin: 5
radio_range: 120
altitude: 30
speed: {max: 8}
obstacles:
  - rectangle: {center: [200, 200], size: [20, 20]}
"""

STATIONS = (
    HEAD
    + """\
stations:
  points:
    - {name: north-shelter, x: 120, y: 340, dwell_s: 600}
    - {name: school, lat: 45.7652, lon: 4.8391}
    - {x: 50, y: -40}
"""
)


def write(tmp_path: Path, text: str, name: str = "mission.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def refusal(path: Path, **kwargs) -> InputError:
    with pytest.raises(InputError) as caught:
        load_mission(path, **kwargs)
    return caught.value


def assert_one_line(error: InputError, path: Path, key: str, *mentions: str) -> None:
    text = str(error)
    assert error.key_path == key, text
    assert text.startswith(f"{path}: {key}: expected "), text
    assert "\n" not in text
    for words in mentions:
        assert words in text, text


# --- accepted ----------------------------------------------------------------------------------


def test_stations_mission_loads_with_its_defaults(tmp_path):
    mission = load_mission(write(tmp_path, STATIONS))
    assert mission.goal is None
    assert mission.station_order == "tsp"
    assert mission.return_at is None
    assert mission.relieve_below_pct is None  # no UAV relieved for its battery
    assert [s.name for s in mission.stations] == ["north-shelter", "school", "P3"]
    shelter, school, p3 = mission.stations
    assert shelter == Station("north-shelter", 120.0, 340.0, 600.0)
    assert p3 == Station("P3", 50.0, -40.0)  # the default name by position, dwell 0
    assert p3.dwell_s == 0.0
    assert p3.xy.tolist() == [50.0, -40.0]
    # lat/lon through the origin, at the origin's altitude
    east, north, _ = geodetic_to_enu(45.7652, 4.8391, LYON.alt, LYON)
    assert (school.x, school.y) == pytest.approx((east, north))
    assert 250 < school.x < 280 and 120 < school.y < 145  # about 265 m east, 133 m north
    assert all(isinstance(v, float) for s in mission.stations for v in (s.x, s.y, s.dwell_s))


def test_order_given_and_return_at(tmp_path):
    text = STATIONS.replace("  points:", "  order: given\n  points:") + "return: {at: 900}\n"
    mission = load_mission(write(tmp_path, text))
    assert mission.station_order == "given"
    assert mission.return_at == 900.0
    assert [s.name for s in mission.stations] == ["north-shelter", "school", "P3"]


def relieve_below(value: str) -> str:
    """STATIONS with `stations.relieve_below_pct: value`."""
    return STATIONS.replace("  points:", f"  relieve_below_pct: {value}\n  points:")


def test_relieve_below_pct(tmp_path):
    assert load_mission(write(tmp_path, relieve_below("25"))).relieve_below_pct == 25.0
    mission = load_mission(write(tmp_path, relieve_below("99.5")))
    assert mission.relieve_below_pct == 99.5 and isinstance(mission.relieve_below_pct, float)
    assert len(mission.stations) == 3


def test_goal_is_kept_with_stations(tmp_path):
    text = STATIONS + "goal: {x: 300, y: 0, theta_deg: 10}\nbase_stations:\n  - {x: -50, y: 60}\n"
    mission = load_mission(write(tmp_path, text))
    assert mission.goal is not None and mission.goal.xy.tolist() == [300.0, 0.0]
    assert mission.goal.theta_deg == 10.0
    assert len(mission.stations) == 3


def test_stations_exactly_at_each_limit_are_accepted(tmp_path):
    rho = 5.0
    from_a = 2 * math.sqrt(2) * rho
    text = (
        HEAD
        + f"""\
stations:
  points:
    - {{x: {from_a!r}, y: 0}}
    - {{x: {from_a!r}, y: {2 * rho!r}}}
    - {{x: 200, y: {210 + rho!r}}}
"""
    )  # 2 sqrt 2 rho from A, 2 rho from each other, rho from the rectangle (y 190..210)
    assert len(load_mission(write(tmp_path, text)).stations) == 3


def test_a_b_mission_is_unchanged(tmp_path):
    mission = load_mission(EXAMPLES / "small.yaml")
    assert mission.stations == () and mission.station_order == "tsp"
    assert mission.return_at is None and mission.goal is not None


# --- base_station_points -----------------------------------------------------------------------


def test_base_station_points_without_goal(tmp_path):
    text = STATIONS + "base_stations:\n  - {x: -50, y: 60}\n  - {x: -80, y: 10}\n"
    points = load_mission(write(tmp_path, text)).base_station_points
    assert points.dtype == np.float64 and points.shape == (3, 2)
    assert points.tolist() == [[0.0, 0.0], [-50.0, 60.0], [-80.0, 10.0]]  # A, then the extras
    assert load_mission(write(tmp_path, STATIONS)).base_station_points.shape == (1, 2)


def test_base_station_points_with_goal(tmp_path):
    text = STATIONS + "goal: {x: 300, y: 0}\nbase_stations:\n  - {x: -50, y: 60}\n"
    points = load_mission(write(tmp_path, text)).base_station_points
    assert points.tolist() == [[0.0, 0.0], [300.0, 0.0], [-50.0, 60.0]]  # A, B, extras


@pytest.mark.parametrize("name", ["small.yaml", "table-ii.yaml", "city-blocks.yaml"])
def test_base_station_points_is_the_old_expression(name):
    mission: Mission = load_mission(EXAMPLES / name)
    old = np.array(
        [mission.start.xy, mission.goal.xy] + [b.xy for b in mission.base_stations], dtype=float
    )
    new = mission.base_station_points
    assert new.dtype == old.dtype and new.shape == old.shape
    assert np.array_equal(new, old)
    new[0] = 1e9  # a fresh array each time: the mission is not changed through it
    assert np.array_equal(mission.base_station_points, old)


# --- refused -----------------------------------------------------------------------------------


def point(text: str) -> str:
    """STATIONS with its third point replaced by `text`."""
    return STATIONS.replace("{x: 50, y: -40}", text)


REFUSED = [
    # (mission text, key, words the message must contain)
    (point("{x: 200, y: 205}"), "stations.points[2]", ["inside it", "obstacles[0].rectangle"]),
    (point("{x: 213, y: 200}"), "stations.points[2]", ["safety_margin (5 m)", "3 m from it"]),
    (
        point("{name: kiosk, x: 124, y: 341}"),
        "stations.points[2]",
        ["2 x safety_margin = 10 m", "kiosk", "north-shelter (stations.points[0])"],
    ),
    (point("{x: 10, y: 0}"), "stations.points[2]", ["2 sqrt 2 x safety_margin", "start", "P3"]),
    (STATIONS.replace("  points:", "  order: nearest\n  points:"), "stations.order", ["tsp"]),
    (STATIONS + "return: {at: 0}\n", "return.at", ["> 0"]),
    (STATIONS + "return: {at: -5}\n", "return.at", ["> 0"]),
    (STATIONS + "return: {at: '900'}\n", "return.at", ["a string"]),
    (STATIONS + "return: {at: .inf}\n", "return.at", ["finite"]),
    (STATIONS + "return: 900\n", "return", ["a mapping"]),
    (STATIONS + "return: {when: 900}\n", "return.when", ["one of at"]),
    (HEAD + "goal: {x: 300, y: 0}\nreturn: {at: 900}\n", "return", ["only with stations"]),
    (HEAD, "goal", ["this required key"]),  # no stations: goal is required as before
    (STATIONS.replace("dwell_s: 600", "dwell: 600"), "stations.points[0].dwell", ["dwell_s"]),
    (STATIONS.replace("  points:", "  mode: x\n  points:"), "stations.mode", ["order, points"]),
    (HEAD + "stations: [{x: 1, y: 2}]\n", "stations", ["a mapping"]),
    (HEAD + "stations: {order: tsp}\n", "stations.points", ["this required key"]),
    (HEAD + "stations: {points: []}\n", "stations.points", ["non-empty list"]),
    (HEAD + "stations: {points: {x: 1}}\n", "stations.points", ["a list of points"]),
    (point("[50, -40]"), "stations.points[2]", ["a mapping"]),
    (point("{x: 50, y: -40, lat: 45.76}"), "stations.points[2]", ["got both"]),
    (point("{name: q, dwell_s: 5}"), "stations.points[2]", ["got neither"]),
    (point("{x: 50}"), "stations.points[2].y", ["this required key"]),
    (point("{lat: 45.765}"), "stations.points[2].lon", ["this required key"]),
    (point("{x: 50, y: true}"), "stations.points[2].y", ["a boolean"]),
    (point("{lat: 95, lon: 4.8}"), "stations.points[2].lat", ["[-90, 90]"]),
    (point("{lat: 45.7, lon: 181}"), "stations.points[2].lon", ["[-180, 180]"]),
    (point("{lat: -35.36, lon: 149.16}"), "stations.points[2]", ["is origin right?"]),
    (point("{name: school, x: 50, y: -40}"), "stations.points[2].name", ["'school'", "[1]"]),
    (STATIONS.replace("name: school,", "name: P3,"), "stations.points[2].name", ["default"]),
    (STATIONS.replace("name: school", "name: ''"), "stations.points[1].name", ["non-empty"]),
    (STATIONS.replace("name: school", "name: 12"), "stations.points[1].name", ["non-empty"]),
    (STATIONS.replace("dwell_s: 600", "dwell_s: -1"), "stations.points[0].dwell_s", [">= 0"]),
    (relieve_below("0"), "stations.relieve_below_pct", ["a number in (0, 100)", "got 0"]),
    (relieve_below("100"), "stations.relieve_below_pct", ["(0, 100)", "got 100"]),
    (relieve_below("-5"), "stations.relieve_below_pct", ["(0, 100)", "got -5"]),
    (relieve_below("'20'"), "stations.relieve_below_pct", ["(0, 100)", "a string"]),
    (relieve_below("true"), "stations.relieve_below_pct", ["(0, 100)", "a boolean"]),
    (relieve_below(".nan"), "stations.relieve_below_pct", ["(0, 100)"]),
    (relieve_below("[20, 30]"), "stations.relieve_below_pct", ["(0, 100)"]),
    (
        STATIONS.replace("  points:", "  relieve_below: 20\n  points:"),
        "stations.relieve_below",
        ["order, points, relieve_below_pct"],
    ),
]


@pytest.mark.parametrize(("text", "key", "mentions"), REFUSED, ids=[c[1] for c in REFUSED])
def test_refused_on_one_line_naming_the_key(tmp_path, text, key, mentions):
    path = write(tmp_path, text)
    assert_one_line(refusal(path), path, key, *mentions)


def test_unknown_top_level_key_lists_the_new_keys(tmp_path):
    path = write(tmp_path, STATIONS + "station: {}\n")
    assert_one_line(refusal(path), path, "station", "signing, stations, return")


def test_station_checks_run_without_the_endpoint_clearance_test(tmp_path):
    """`check_clearance=False` (the `--near` suggestion) skips only the A/B test."""
    path = write(tmp_path, point("{x: 200, y: 205}"))
    assert refusal(path, check_clearance=False).key_path == "stations.points[2]"


def test_the_first_close_pair_is_named(tmp_path):
    text = point("{x: 300, y: 300}").replace(
        "{name: school, lat: 45.7652, lon: 4.8391}", "{name: school, x: 303, y: 304}"
    )
    path = write(tmp_path, text)
    assert_one_line(
        refusal(path), path, "stations.points[2]", "P3 is 5 m from school (stations.points[1])"
    )


# --- the CLI -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "key"),
    [
        (point("{x: 200, y: 205}"), "stations.points[2]"),
        (point("{x: 10, y: 0}"), "stations.points[2]"),
        (STATIONS + "return: {at: 0}\n", "return.at"),
        (relieve_below("100"), "stations.relieve_below_pct"),
        (HEAD + "goal: {x: 300, y: 0}\nreturn: {at: 900}\n", "return"),
    ],
)
@pytest.mark.parametrize("command", ["check", "plan"])
def test_cli_refuses_with_exit_2_and_one_line(gcs_main, tmp_path, text, key, command):
    path = write(tmp_path, text)
    code, out, err = gcs_main("mission", command, path)
    assert code == 2, err
    assert out == ""
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"{path}: {key}: expected "), err


@pytest.mark.slow
def test_cli_refusal_as_a_real_process(gcs_process, tmp_path):
    path = write(tmp_path, point("{x: 124, y: 341}"))
    result = gcs_process("mission", "check", path, "--json")
    assert result.returncode == 2, result.stderr
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert lines[0].startswith(f"{path}: stations.points[2]: expected ")
