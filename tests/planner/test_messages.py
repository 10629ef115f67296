"""Refusals never contradict themselves through rounding, and counts agree with their noun
(issue 13: "at least safety_margin = 5 m ... is 5 m from it" for 4.999 m, "1 UAVs")."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from gcs.errors import InputError
from gcs.mission import load_mission
from planner.formation import ParkingRows
from planner.numbers import digits_against, fmt_against, plural
from planner.obstacles import Obstacles
from planner.validity import check_path, precheck, row_refusal
from tests.planner_maps import problem

# --- the helper ------------------------------------------------------------------------------


def test_a_value_just_below_its_limit_is_printed_with_the_digits_that_show_it():
    assert fmt_against(4.999, 5) == "4.999"
    assert fmt_against(5, 4.999) == "5"
    shown = fmt_against(9.9999999, 10)
    assert shown == "9.9999999" and shown != fmt_against(10, 9.9999999) == "10"


@pytest.mark.parametrize(
    ("value", "limit"),
    [
        (4.999, 5.0),
        (9.9999999, 10.0),
        (10.000001, 10.0),
        (24.14213, 2 * (1 + math.sqrt(2)) * 10),
        (0.30000000000000004, 0.3),
        (1e-12, 0.0),
        (-1e-9, 0.0),
        (123456.7, 123456.8),
        (1.0 + 2**-52, 1.0),
    ],
)
def test_different_numbers_never_read_the_same_and_keep_their_order(value, limit):
    for digits in (3, 4, 6):
        a, b = fmt_against(value, limit, digits), fmt_against(limit, value, digits)
        assert a != b
        assert (float(a) < float(b)) == (value < limit)  # rounding never swaps them
        assert digits_against(value, limit, digits) >= digits


def test_few_digits_when_few_are_enough_and_equal_numbers_stay_short():
    assert fmt_against(3.14159, 5) == "3.14"
    assert fmt_against(3.14159, 5, 6) == "3.14159"
    assert fmt_against(5.0, 5.0) == "5"
    assert fmt_against(math.nan, 5.0) == "nan"


def test_counts_agree_with_their_noun():
    assert plural(1, "UAV") == "1 UAV"
    assert plural(2, "UAV") == "2 UAVs"
    assert plural(0, "UAV") == "0 UAVs"
    assert plural(1, "vertex", "vertices") == "1 vertex"
    assert plural(3, "vertex", "vertices") == "3 vertices"


# --- the planner's refusals -----------------------------------------------------------------

WALL = Obstacles(walls=np.array([[[0.0, 0.0], [0.0, 100.0]]]))


def test_precheck_a_start_4_999_m_from_an_obstacle_does_not_read_5_m():
    message = precheck(problem((-4.999, 50.0), (300.0, 50.0), WALL))
    assert "is 4.999 m from obstacle 0" in message
    assert "rho_c = 5 m" in message


def test_a_parking_row_just_inside_the_margin_reads_below_it():
    near = Obstacles(walls=np.array([[[-3.0, 4.999], [-1.0, 4.999]]]))  # 4.999 m beside Delta_A
    pb = problem((0.0, 0.0), (100.0, 0.0), near)
    rows = ParkingRows(
        start_row=np.array([[0.0, 0.0], [-20.0, 0.0]]),
        goal_row=np.array([[100.0, 0.0], [120.0, 0.0]]),
        start_direction=np.array([1.0, 0.0]),
        goal_direction=np.array([1.0, 0.0]),
    )
    refusal = row_refusal(pb, rows)
    assert refusal.subject == "start_row"
    assert "comes 4.999 m from obstacle 0" in refusal.message
    assert "at least rho_c = 5 m" in refusal.message


def test_rows_9_9999985_m_apart_do_not_read_10_m_apart():
    pb = problem((0.0, 0.0), (9.9999985, 0.0))
    rows = ParkingRows(
        start_row=np.array([[0.0, 0.0], [0.0, -20.0]]),
        goal_row=np.array([[9.9999985, 0.0], [9.9999985, -20.0]]),
        start_direction=np.array([0.0, 1.0]),
        goal_direction=np.array([0.0, -1.0]),
    )
    refusal = row_refusal(pb, rows)
    assert refusal.subject == "rows"
    gap, limit = re.search(r"are (\S+) m apart; .* = (\S+) m apart", refusal.message).groups()
    assert limit == "10" and gap != "10" and float(gap) < 10.0


def test_path_breaches_just_inside_a_limit_read_inside_it():
    # segments 0 and 2 of a hook 9.9999985 m apart (2 rho_c = 10 m)
    hook = np.array([[0.0, 0.0], [60.0, 0.0], [60.0, 9.9999985], [30.0, 9.9999985], [30.0, 60]])
    theta = -math.degrees(math.atan2(60.0, 30.0))
    pb = problem(hook[0], hook[-1], theta_a=theta)
    rows = ParkingRows(
        start_row=np.array([hook[0], hook[0] - [5.0, 0.0]]),
        goal_row=np.array([hook[-1], hook[-1] + [0.0, 5.0]]),
        start_direction=np.array([1.0, 0.0]),
        goal_direction=np.array([0.0, 1.0]),
    )
    text = check_path(hook, pb, rows).describe()
    apart = re.search(r"come (\S+) m apart \(condition 5\)", text).group(1)
    assert apart != "10" and float(apart) < 10.0
    # a bend a hair over 90 degrees (condition 4) does not read "90 degrees"
    eps = 1e-7
    bent = np.array([[0.0, 0.0], [50.0, 0.0], [50.0 - eps * 50.0, 50.0], [40.0, 120.0]])
    pb = problem(bent[0], bent[-1], theta_a=0.0, theta_b=math.degrees(math.atan2(70.0, -10.0)))
    rows = ParkingRows(
        start_row=np.array([bent[0], bent[0] - [5.0, 0.0]]),
        goal_row=np.array([bent[-1], bent[-1] + [-1.0, 7.0]]),
        start_direction=np.array([1.0, 0.0]),
        goal_direction=np.array([-1.0, 7.0]) / math.hypot(1.0, 7.0),
    )
    violations = check_path(bent, pb, rows)
    angle = re.search(r"bends (\S+) degrees at point 1", violations.describe()).group(1)
    assert angle != "90" and float(angle) > 90.0


# --- the mission file's refusals ------------------------------------------------------------

MISSION = """\
version: 1
name: near
start: {{x: 0, y: 0, theta_deg: 0}}
goal: {{x: 300, y: 100, theta_deg: 0}}
safety_margin: 5
radio_range: {radio}
altitude: 20
speed: {{max: 8}}
vehicle: {{radius: {radius}}}
obstacles:
  - segment: [[{x}, -10], [{x}, 10]]
"""


def refusal(tmp_path: Path, radio=120, radius=0.5, x=50) -> str:
    path = tmp_path / "near.yaml"
    path.write_text(MISSION.format(radio=radio, radius=radius, x=x))
    with pytest.raises(InputError) as refused:
        load_mission(path)
    return str(refused.value)


def test_mission_a_start_just_inside_the_margin_reads_inside_it(tmp_path):
    message = refusal(tmp_path, x=4.9999985)
    assert "at least safety_margin (5 m)" in message
    got = re.search(r"it is (\S+) m from it", message).group(1)
    assert got != "5" and float(got) < 5.0


def test_mission_radio_range_a_hair_below_eq_9_reads_below_it(tmp_path):
    message = refusal(tmp_path, radio=24.14213)  # eq. 9 needs 24.1421356... m
    needed, got = re.search(r"= (\S+) m \(eq\. 9\), got (\S+)", message).groups()
    assert needed != got and float(got) < float(needed)


def test_mission_a_radius_a_hair_above_the_margin_reads_above_it(tmp_path):
    message = refusal(tmp_path, radius=5.0000001)
    assert message.endswith("less than safety_margin (5 m), got 5.0000001")
