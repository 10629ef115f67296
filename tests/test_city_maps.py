"""Real city maps (issue 13): the Helsinki example (OpenStreetMap footprints) planned and
certified, the time limit with an injected clock, and the plan JSON's certification keys."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from gcs.mission import load_mission
from gcs.planning import plan_json, plan_mission
from planner.types import PathProblem
from planner.validity import check_path
from tests.conftest import EXAMPLES

HELSINKI = EXAMPLES / "helsinki-centre.yaml"


@pytest.fixture(scope="module")
def helsinki():
    return load_mission(HELSINKI)


def _problem(mission) -> PathProblem:
    return PathProblem(
        start=mission.start.xy,
        goal=mission.goal.xy,
        start_angle_deg=mission.start.theta_deg,
        goal_angle_deg=mission.goal.theta_deg,
        safety_margin=mission.safety_margin,
        radio_range=mission.radio_range,
        obstacles=mission.obstacles,
    )


def test_helsinki_example_is_planned_certified_and_valid(helsinki, gcs_main):
    result = gcs_main("mission", "check", HELSINKI, "--json")
    assert result.returncode == 0, result.stderr
    plan = json.loads(result.stdout)
    assert plan["valid"] and plan["certified"] and not plan["stopped"]
    assert plan["lower_bound_m"] == plan["length_m"] and plan["gap_m"] == 0.0
    assert plan["graph"] in ("taut", "full")
    assert plan["map"]["used"] + plan["map"]["below_altitude"] == 446
    # checked again, independently of the search, against every footprint kept
    path = np.array(plan["path"])
    problem = _problem(helsinki)
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
