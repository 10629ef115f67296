"""Real city maps (issue 13): the Helsinki example (OpenStreetMap footprints) planned and
certified, the time limit with an injected clock, and the plan JSON's certification keys."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from gcs.mission import load_mission
from gcs.planning import mission_problem, plan_json, plan_mission
from planner.validity import check_path
from tests.conftest import EXAMPLES
from tests.footprint_files import MESSY

HELSINKI = EXAMPLES / "helsinki-centre.yaml"


@pytest.fixture(scope="module")
def helsinki():
    return load_mission(HELSINKI)


@pytest.fixture(scope="module")
def helsinki_disk(tmp_path_factory) -> Path:
    """The example under the paper's disk rule (its own is line of sight, whose corners are
    taken wider: no shortest path to certify)."""
    folder = tmp_path_factory.mktemp("helsinki")
    text = HELSINKI.read_text().replace("rule: line_of_sight", "rule: disk")
    (folder / HELSINKI.name).write_text(text)
    for footprints in EXAMPLES.glob("helsinki-centre.geojson"):
        (folder / footprints.name).write_bytes(footprints.read_bytes())
    return folder / HELSINKI.name


def test_helsinki_example_is_planned_certified_and_valid(helsinki_disk, gcs_main):
    helsinki = load_mission(helsinki_disk)
    result = gcs_main("mission", "check", helsinki_disk, "--json")
    assert result.returncode == 0, result.stderr
    plan = json.loads(result.stdout)
    assert plan["valid"] and plan["certified"] and not plan["stopped"]
    assert plan["lower_bound_m"] == plan["length_m"] and plan["gap_m"] == 0.0
    assert plan["graph"] in ("taut", "full")
    assert plan["map"]["used"] + plan["map"]["below_altitude"] == 446
    # checked again, independently of the search, against every footprint kept
    path = np.array(plan["path"])
    problem = mission_problem(helsinki)
    mission_plan = plan_mission(helsinki)
    assert check_path(path, problem, mission_plan.path_plan.rows).ok
    assert "certified shortest" in result.stderr or "certified shortest" in result.stdout


def test_time_limit_stops_the_search_and_says_so(helsinki):
    ticks = itertools.count()
    clock = lambda: float(next(ticks))  # noqa: E731 - one second per reading
    seen = []
    plan = plan_mission(
        helsinki, time_limit_s=2.5, clock=clock, on_progress=lambda s, t: seen.append(t)
    )
    assert plan.path_plan.stopped and not plan.path_plan.certified
    assert seen and max(seen) >= 2.5
    data = plan_json(plan)
    assert data["stopped"] is True and data["certified"] is False
    if not plan.valid:
        assert "stopped (time limit)" in plan.reason


@pytest.mark.parametrize("value", ["0", "-3", "soon", "nan"])
def test_time_limit_must_be_a_positive_number(value, gcs_main):
    result = gcs_main("mission", "check", HELSINKI, "--time-limit", value)
    assert result.returncode == 2
    assert "--time-limit" in result.stderr and "positive number of seconds" in result.stderr


@pytest.mark.parametrize("value", ["-0.5", "100", "tight", "nan"])
def test_gap_must_be_a_percentage(value, gcs_main):
    result = gcs_main("mission", "check", HELSINKI, "--gap", value)
    assert result.returncode == 2
    assert "--gap" in result.stderr and "percentage from 0 to below 100" in result.stderr
    assert "Traceback" not in result.stderr


def test_the_plan_says_which_gap_tolerance_it_was_given(helsinki, gcs_main):
    assert plan_json(plan_mission(helsinki))["gap_tolerance"] == 0.0
    result = gcs_main("mission", "check", HELSINKI, "--json", "--gap", "0.5")
    assert result.returncode == 0
    assert json.loads(result.stdout)["gap_tolerance"] == 0.005


def _messy_mission(tmp_path, goal_x: float) -> str:
    (tmp_path / "messy.geojson").write_text(json.dumps(MESSY))
    path = tmp_path / "m.yaml"
    path.write_text(
        "version: 1\nname: messy\norigin: {lat: 0.0, lon: 0.0, alt: 0.0}\n"
        f"start: {{x: 0, y: 0, theta_deg: 0}}\ngoal: {{x: {goal_x}, y: 0, theta_deg: 0}}\n"
        "safety_margin: 5\nradio_range: 40\naltitude: 20\nspeed: {max: 3}\n"
        "fleet: {size: auto, backend: sim}\n"
        "vehicle: {max_speed: 12, max_acceleration: 8, radius: 0.5}\n"
        "obstacles:\n  - geojson: messy.geojson\n"
    )
    return str(path)


def _footprint_warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "gcs.mission.footprints"]


def test_footprint_warnings_wait_for_the_input_to_be_accepted(tmp_path, gcs_main, caplog):
    # the row behind A (many UAVs for a long path) reaches the footprint: refused, exit 2,
    # and the footprint file's warning is not printed beside the one-line refusal
    caplog.set_level("WARNING")
    refused = gcs_main("mission", "check", _messy_mission(tmp_path, 300))
    assert refused.returncode == 2 and "theta_deg" in refused.stderr
    assert _footprint_warnings(caplog) == []
    caplog.clear()
    # a short mission whose rows clear it: accepted, and the warning is printed
    accepted = gcs_main("mission", "check", _messy_mission(tmp_path, 30))
    assert accepted.returncode == 0, accepted.stderr
    warnings = _footprint_warnings(caplog)
    assert len(warnings) == 1 and "skipped 1 (features[0] Point)" in warnings[0]
