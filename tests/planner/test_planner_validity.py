"""Definition 4 (conditions 1-5), eqs. 14-15 and the pre-search refusals, on hand-made maps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.formation import parking_rows
from planner.obstacles import Obstacles
from planner.types import PathProblem
from planner.validity import check_path, check_rows, precheck
from tests.planner_maps import RHO, problem, square


def rows_for(pb: PathProblem, fleet_size: int = 1):
    return parking_rows(
        pb.start,
        pb.goal,
        pb.start_angle_deg,
        pb.goal_angle_deg,
        fleet_size,
        pb.safety_margin,
        pb.parking,
    )


# A wall from (0,0) to (0,100); A and B on its margin lines at exactly rho_c; the only route
# goes round the top end with two bends of exactly 90 degrees, segments exactly 2 rho_c apart.
WALL = Obstacles(walls=np.array([[[0.0, 0.0], [0.0, 100.0]]]))
HUG = problem((-5.0, 50.0), (5.0, 50.0), WALL, theta_a=90.0, theta_b=-90.0)
HUG_PATH = np.array([[-5.0, 50.0], [-5.0, 105.0], [5.0, 105.0], [5.0, 50.0]])


def test_boundary_cases_are_valid_hugging_exactly_rho_and_bending_exactly_90_degrees():
    violations = check_path(HUG_PATH, HUG, rows_for(HUG))
    assert violations.ok, violations.describe()
    assert violations.describe() is None


def test_condition_1_obstacle_margin_is_detected_just_inside_the_tolerance():
    inside = HUG_PATH.copy()
    inside[:2, 0] = -5.0 + 1e-4  # 1e-4 m too close, far beyond the 1e-6 m tolerance
    violations = check_path(
        inside, problem(inside[0], inside[-1], WALL, 90.0, -90.0), rows_for(HUG)
    )
    assert len(violations.obstacle) >= 1
    assert violations.obstacle[0, 2] == pytest.approx(5.0 - 1e-4)
    assert "condition 1" in violations.describe()
    within_tolerance = HUG_PATH.copy()
    within_tolerance[:2, 0] = -5.0 + 5e-7
    pb = problem(within_tolerance[0], within_tolerance[-1], WALL, 90.0, -90.0)
    assert not len(check_path(within_tolerance, pb, rows_for(pb)).obstacle)


def test_solid_polygons_are_solid_but_a_ring_of_walls_is_not():
    box = square(0.0, 0.0, 100.0)
    inside_path = np.array([[40.0, 50.0], [60.0, 50.0]])  # far from every edge
    solid = problem(inside_path[0], inside_path[1], Obstacles(polygons=(box,)))
    hit = check_path(inside_path, solid, rows_for(solid))
    assert len(hit.obstacle) == 1 and hit.obstacle[0, 2] == 0.0
    ring = np.stack([box, np.roll(box, -1, axis=0)], axis=1)
    walled = problem(inside_path[0], inside_path[1], Obstacles(walls=ring))
    assert check_path(inside_path, walled, rows_for(walled)).ok


def test_condition_2_rows_exempt_the_first_and_last_segments_only():
    pb = problem((0.0, 0.0), (100.0, 0.0))
    rows = rows_for(pb, fleet_size=3)  # rows 2*dS_c + rho = 33.3 m long
    # first segment starts on Delta_A: exempt; the last ends on Delta_B: exempt.
    assert check_path(np.array([[0.0, 0.0], [50.0, 40.0], [100.0, 0.0]]), pb, rows).ok
    # a second segment that comes back within 2 rho_c of the row behind A breaks (2).
    back = np.array([[0.0, 0.0], [30.0, 30.0], [-20.0, 8.0], [100.0, 40.0], [100.0, 0.0]])
    violations = check_path(back, pb, rows)
    assert len(violations.start_row) and violations.start_row[0, 0] >= 1
    assert violations.start_row[:, 1].min() < 2 * RHO


def test_condition_3_departure_and_arrival_angles_allow_exactly_90_degrees():
    pb = problem((0.0, 0.0), (100.0, 0.0))
    rows = rows_for(pb)
    square_turn = np.array([[0.0, 0.0], [0.0, 50.0], [100.0, 50.0], [100.0, 0.0]])
    violations = check_path(square_turn, pb, rows)
    assert violations.departure_angle_deg is None
    # the arrival is heading -y, exactly 90 degrees from e_K = +x: allowed.
    assert violations.arrival_angle_deg is None
    backwards = np.array([[0.0, 0.0], [-0.01, 50.0], [100.0, 50.0], [100.0, 0.0]])
    violations = check_path(backwards, pb, rows)
    assert violations.departure_angle_deg == pytest.approx(90.0 + math.degrees(0.01 / 50), abs=1e-6)
    assert "condition 3" in violations.describe()


def test_condition_4_bends_over_90_degrees_are_reported_with_their_vertex():
    pb = problem((0.0, 0.0), (100.0, 0.0))
    sharp = np.array([[0.0, 0.0], [60.0, 0.0], [40.0, 30.0], [100.0, 30.0], [100.0, 0.0]])
    violations = check_path(sharp, pb, rows_for(pb))
    assert violations.bends[:, 0].tolist() == [1.0, 2.0]
    assert violations.bends[:, 1] == pytest.approx([180.0 - math.degrees(math.atan2(30, 20))] * 2)
    assert "condition 4" in violations.describe()


def test_condition_5_non_adjacent_segments_need_2_rho_and_adjacent_ones_never_count():
    # A square-cornered hook: segment 2 runs back 9 m (< 2 rho_c) from segment 0, and
    # segment 3 starts 9 m from it; adjacent segments (sharing a point) never count.
    hook = np.array([[0.0, 0.0], [60.0, 0.0], [60.0, 9.0], [30.0, 9.0], [30.0, 60.0]])
    theta = -math.degrees(math.atan2(60.0, 30.0))  # e_0 = +x, so the departure is straight
    pb = problem(hook[0], hook[-1], theta_a=theta)
    violations = check_path(hook, pb, rows_for(pb))
    assert violations.proximity[:, :2].tolist() == [[0.0, 2.0], [0.0, 3.0]]
    assert violations.proximity[:, 2] == pytest.approx([9.0, 9.0])
    assert violations.describe() == "segments 0 and 2 come 9 m apart (condition 5)"
    wide = hook.copy()
    wide[2:4, 1] = 10.0  # exactly 2 rho_c: allowed
    pb = problem(wide[0], wide[-1], theta_a=theta)
    assert check_path(wide, pb, rows_for(pb)).ok


def test_definition_1_repeated_points_and_wrong_ends_are_structural_breaches():
    pb = problem((0.0, 0.0), (100.0, 0.0))
    loop = np.array([[0.0, 0.0], [50.0, 50.0], [50.0, -50.0], [50.0, 50.0], [100.0, 0.0]])
    violations = check_path(loop, pb, rows_for(pb))
    assert any("repeats" in s for s in violations.structure)
    assert not check_path(np.array([[1.0, 0.0], [100.0, 0.0]]), pb, rows_for(pb)).ok


def test_check_rows_names_eq_14_and_eq_15():
    near = Obstacles(polygons=(square(-30.0, 4.0, 10.0),))  # 4 m beside the row behind A
    pb = problem((0.0, 0.0), (100.0, 0.0), near)
    assert "eq. 14" in check_rows(pb, rows_for(pb, 3))
    assert check_rows(pb, rows_for(pb, 1)) is None  # a 5 m row stays clear of it
    facing = problem((0.0, 0.0), (100.0, 0.0), theta_a=180.0, theta_b=180.0)
    assert "eq. 15" in check_rows(facing, rows_for(facing, 10))


@pytest.mark.parametrize(
    ("start", "obstacles", "fragment"),
    [
        ((50.0, 50.0), Obstacles(polygons=(square(0.0, 0.0, 100.0),)), "A (50, 50) lies inside"),
        ((-3.0, 50.0), Obstacles(polygons=(square(0.0, 0.0, 100.0),)), "inside its safety margin"),
        ((-3.0, 50.0), WALL, "3 m from obstacle 0"),
    ],
)
def test_precheck_refuses_a_start_inside_an_obstacle_or_its_margin(start, obstacles, fragment):
    assert fragment in precheck(problem(start, (300.0, 50.0), obstacles))


def test_precheck_other_refusals_and_acceptance():
    assert "coincide" in precheck(problem((1.0, 1.0), (1.0, 1.0)))
    assert "eq. 9" in precheck(problem((0.0, 0.0), (100.0, 0.0), radio_range=20.0))
    assert "B (" in precheck(
        problem((-50.0, 0.0), (50.0, 50.0), Obstacles(polygons=(square(0.0, 0.0, 100.0),)))
    )
    behind = Obstacles(polygons=(square(-300.0, -5.0, 10.0),))  # 290 m behind A on the row line
    assert precheck(problem((0.0, 0.0), (100.0, 0.0), behind)) is None
    assert "eq. 14" in precheck(problem((0.0, 0.0), (100.0, 0.0), behind, parking="ray"))
    # a ring of walls is not solid: a start inside it is accepted by the precheck
    box = square(-100.0, -100.0, 200.0)
    ring = Obstacles(walls=np.stack([box, np.roll(box, -1, axis=0)], axis=1))
    assert precheck(problem((0.0, 0.0), (50.0, 0.0), ring)) is None


def test_precheck_issue_names_the_input_and_the_obstacle_for_the_mission_loader():
    from planner.validity import precheck_issue

    boxes = Obstacles(polygons=(square(200.0, 200.0, 10.0), square(-30.0, 3.0, 10.0)))
    issue = precheck_issue(problem((0.0, 0.0), (100.0, 0.0), boxes, fleet_size=3))
    assert (issue.subject, issue.obstacle) == ("start_row", 1)
    assert issue.distance == pytest.approx(3.0)
    assert issue.message == precheck(problem((0.0, 0.0), (100.0, 0.0), boxes, fleet_size=3))
    inside = precheck_issue(problem((205.0, 205.0), (100.0, 0.0), boxes))
    assert (inside.subject, inside.obstacle, inside.distance) == ("start", 0, 0.0)
    assert precheck_issue(problem((0.0, 0.0), (100.0, 0.0), boxes)) is None  # 1 UAV: 5 m row
