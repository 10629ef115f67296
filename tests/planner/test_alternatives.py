"""planner.alternatives and `gcs mission check`'s "accepted instead": the nearest accepted
parking angles and start points for refused rows (eqs. 14-15), checked by brute force."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from planner.alternatives import AngleSuggestion, suggest
from planner.obstacles import Obstacles
from planner.types import PathProblem
from planner.validity import precheck_issue

RHO = 1.0
# A -> B along +x, 100 m; rho_R 20 m: dS_r = 18 m, so N = 6 and the rows are 15.1 m long.
A, B = (0.0, 0.0), (100.0, 0.0)
N = 6


def walls(*segments) -> Obstacles:
    return Obstacles(walls=np.array(segments, float).reshape(-1, 2, 2))


def make(obstacles: Obstacles, theta_a: float = 0.0, theta_b: float = 0.0, **kw) -> PathProblem:
    values = dict(
        start=A,
        goal=B,
        start_angle_deg=theta_a,
        goal_angle_deg=theta_b,
        safety_margin=RHO,
        radio_range=20.0,
        obstacles=obstacles,
    )
    return PathProblem(**(values | kw))


# A wall across the row behind A (which runs from A towards -x): it reaches 4.5 m below the
# row and 6 m above it, so turning theta_A counter-clockwise (the row swings down) clears it
# first, near +30 degrees. MIRRORED is the same wall flipped: the nearest turn is clockwise.
WALL_A = ((-10.0, -4.5), (-10.0, 6.0))
MIRRORED_A = ((-10.0, 4.5), (-10.0, -6.0))
# The same behind B's row (from B towards +x).
WALL_B = ((110.0, -6.0), (110.0, 4.5))


def accepted(pb: PathProblem, fleet_size: int = N, **changes) -> bool:
    return precheck_issue(replace(pb, **changes), fleet_size) is None


def brute_nearest(pb: PathProblem, which: str, fleet_size: int = N) -> float | None:
    """The accepted offset of least |delta| (ties counter-clockwise) every 0.1 degree."""
    key = "start_angle_deg" if which == "theta_A" else "goal_angle_deg"
    base = getattr(pb, key)
    hits = [k / 10 for k in range(-1799, 1801) if accepted(pb, fleet_size, **{key: base + k / 10})]
    return min(hits, key=lambda d: (abs(d), d < 0)) if hits else None


# --- angles ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("wall", "sign"), [(WALL_A, 1), (MIRRORED_A, -1)], ids=["counter-clockwise", "clockwise"]
)
def test_the_nearest_theta_a_is_the_smallest_accepted_turn(wall, sign):
    pb = make(walls(wall))
    assert precheck_issue(pb, N).subject == "start_row"
    found = suggest(pb, N)
    assert found.refusal.subject == "start_row" and found.fleet_size == N
    expected = brute_nearest(pb, "theta_A")
    assert expected is not None and 25 < sign * expected < 35
    assert found.angles == (AngleSuggestion("theta_A", expected, expected),)
    assert found.pair is None and found.points == ()
    assert accepted(pb, start_angle_deg=expected)
    text = found.describe()
    assert text == f"accepted instead: theta_A = {expected:g} deg ({expected:+g})"


def test_the_nearest_theta_b_is_found_the_same_way_and_angles_wrap():
    # The requested theta_B is 170 degrees: the answer turns past 180 and is given in
    # (-180, 180], its delta from the requested angle.
    base = 170.0
    wall = np.array(WALL_B)
    turn = np.radians(base)  # WALL_B turned about B with the row
    rot = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
    wall = (wall - B) @ rot.T + B
    pb = make(walls(wall), theta_b=base)
    assert precheck_issue(pb, N).subject == "goal_row"
    expected = brute_nearest(pb, "theta_B")
    assert expected is not None and base + expected > 180
    found = suggest(pb, N)
    (only,) = found.angles
    assert only.which == "theta_B" and only.delta_deg == expected
    assert only.angle_deg == pytest.approx(base + expected - 360, abs=1e-9)
    assert -180 < only.angle_deg <= 180
    assert accepted(pb, goal_angle_deg=only.angle_deg)


def test_the_row_length_follows_the_fleet_size_of_the_refusal():
    # A second wall 28 m behind A: the 15.1 m rows of 6 UAVs never reach it, the 32.1 m
    # rows of 12 UAVs do unless turned past about 33 degrees.
    pb = make(walls(WALL_A, ((-28.0, -30.0), (-28.0, 30.0))))
    assert suggest(pb, 2).refusal is None  # rows of 3.8 m reach no wall
    (six,) = suggest(pb, N).angles
    (twelve,) = suggest(pb, 12).angles
    assert six.delta_deg == brute_nearest(pb, "theta_A", N)
    assert twelve.delta_deg == brute_nearest(pb, "theta_A", 12)
    assert abs(twelve.delta_deg) > 32 > abs(six.delta_deg)
    assert not accepted(pb, 12, start_angle_deg=six.angle_deg)


def test_rows_too_close_name_both_angles_when_either_alone_works():
    # B 12 m ahead with its 15.1 m row pointing back over A (eq. 15).
    pb = make(Obstacles(), theta_b=180.0, goal=(12.0, 0.0))
    assert precheck_issue(pb, N).subject == "rows"
    found = suggest(pb, N)
    assert [a.which for a in found.angles] == ["theta_B"]  # B's row runs through A itself
    assert found.angles[0].delta_deg == brute_nearest(pb, "theta_B")
    # Rows of 6.7 m (3 UAVs) that overlap between A and B: turning either clears them.
    pb = make(Obstacles(), theta_a=180.0, theta_b=180.0, goal=(12.0, 0.0))
    found = suggest(pb, 3)
    assert [a.which for a in found.angles] == ["theta_A", "theta_B"]
    for a in found.angles:
        assert a.delta_deg == brute_nearest(pb, a.which, 3)


def test_only_a_pair_works_when_both_rows_are_blocked():
    pb = make(walls(WALL_A, WALL_B))
    found = suggest(pb, N)
    assert found.angles == () and found.pair is not None
    turn_a, turn_b = found.pair
    assert (turn_a.which, turn_b.which) == ("theta_A", "theta_B")
    assert accepted(pb, start_angle_deg=turn_a.angle_deg, goal_angle_deg=turn_b.angle_deg)
    # The rows are far apart, so the nearest pair is each row's own nearest turn.
    assert turn_a.delta_deg == brute_nearest(make(walls(WALL_A)), "theta_A")
    assert turn_b.delta_deg == brute_nearest(make(walls(WALL_B)), "theta_B")
    text = found.describe()
    assert text.startswith("accepted instead: theta_A = ") and " with theta_B = " in text
    entries = found.as_json()
    assert [e["which"] for e in entries] == ["theta_A", "theta_B"]
    assert all(e["pair"] is True for e in entries)


def ring(center, radius: float, sides: int = 16):
    angles = np.linspace(0, 2 * math.pi, sides, endpoint=False)
    pts = np.column_stack([np.cos(angles), np.sin(angles)]) * radius + center
    return [(pts[i], pts[(i + 1) % sides]) for i in range(sides)]


def test_nothing_within_180_degrees_says_so():
    pb = make(walls(*ring(A, 3.0)))  # A walled in 3 m away, rows 15 m long
    assert precheck_issue(pb, N).subject == "start_row"
    found = suggest(pb, N)
    assert not found.found and found.angles == () and found.pair is None
    assert brute_nearest(pb, "theta_A") is None
    assert found.describe() == (
        "no theta_A, theta_B or pair of them within 180 degrees of the requested ones "
        f"gives accepted rows for {N} UAVs"
    )
    found = suggest(pb, N, near_m=1.5)
    assert found.describe().endswith("; no start point within 1.5 m does with the requested angles")


def test_no_refusal_and_other_refusals_suggest_nothing():
    assert suggest(make(Obstacles()), N) == suggest(make(Obstacles()), N)
    assert suggest(make(Obstacles()), N).describe() is None
    same = make(Obstacles(), goal=A)  # A equal to B: no point or angle answers it
    found = suggest(same, N, near_m=5)
    assert found.refusal.subject == "goal" and not found.found


# --- points -----------------------------------------------------------------------------------


def ring_points(center, radius: float) -> list[tuple[float, float]]:
    """The candidate points of the module's documented rings (1 m, 10 degrees, 0.1 m grid)."""
    out = []
    for r in np.arange(1.0, radius + 1e-9, 1.0):
        for t in np.radians(np.arange(0.0, 360.0, 10.0)):
            p = np.round((np.asarray(center) + r * np.array([math.cos(t), math.sin(t)])) / 0.1)
            out.append(tuple(p * 0.1))
    return sorted(out, key=lambda p: math.dist(p, center))


def test_the_nearest_start_point_keeps_the_requested_angles():
    pb = make(walls(WALL_A))
    found = suggest(pb, N, near_m=10)
    (point,) = found.points
    assert point.which == "start" and point.distance_m <= 10
    assert math.dist((point.x, point.y), A) == pytest.approx(point.distance_m)
    assert accepted(pb, start=(point.x, point.y))
    # No candidate nearer is accepted (brute force with the planner's own check).
    nearer = [p for p in ring_points(A, 10) if math.dist(p, A) < point.distance_m - 1e-9]
    assert nearer and not any(accepted(pb, start=p) for p in nearer)
    assert found.describe().endswith(
        f", or start at ({point.x:.1f}, {point.y:.1f}), {point.distance_m:.1f} m from A"
    )
    assert found.as_json()[-1] == {
        "which": "start",
        "x": point.x,
        "y": point.y,
        "distance_m": point.distance_m,
    }


def test_a_start_inside_a_margin_gets_a_point_and_no_angle():
    pb = make(Obstacles(polygons=(np.array([[-3, -3], [2, -3], [2, 3], [-3, 3]], float),)))
    assert precheck_issue(pb, N).subject == "start"
    found = suggest(pb, N, near_m=8)
    assert found.angles == () and found.pair is None
    (point,) = found.points
    assert accepted(pb, start=(point.x, point.y))
    nearer = [p for p in ring_points(A, 8) if math.dist(p, A) < point.distance_m - 1e-9]
    assert not any(accepted(pb, start=p) for p in nearer)
    assert suggest(pb, N).describe() is None  # without a radius: nothing to say


def test_rays_are_searched_too():
    pb = make(walls(WALL_A), parking="ray")
    found = suggest(pb)
    (turn,) = found.angles
    assert turn.delta_deg == brute_nearest(pb, "theta_A", found.fleet_size)


# --- gcs mission check --------------------------------------------------------------------------

MISSION = """\
version: 1
start: {{x: 0, y: 0, theta_deg: {theta}}}
goal: {{x: 100, y: 0}}
safety_margin: 1
radio_range: 20
altitude: 30
speed: {{max: 5}}
obstacles:
  - segment: [[-10, -4.5], [-10, 6]]
"""


@pytest.fixture
def refused(tmp_path):
    path = tmp_path / "refused.yaml"
    path.write_text(MISSION.format(theta=0))
    return path


def test_check_names_the_accepted_angle_on_the_refusal_line(gcs_main, refused):
    expected = brute_nearest(make(walls(WALL_A)), "theta_A")
    code, out, err = gcs_main("mission", "check", refused)
    assert code == 2 and out == ""
    (line,) = err.splitlines()
    assert line.startswith(f"{refused}: start.theta_deg: expected a parking row")
    assert line.endswith(f"; accepted instead: theta_A = {expected:g} deg ({expected:+g})")
    # The suggestion is accepted: the mission checks (exit 0) with it.
    refused.write_text(MISSION.format(theta=expected))
    code, out, err = gcs_main("mission", "check", refused)
    assert code == 0, err


def test_check_near_names_a_start_point_and_json_keeps_stdout_empty(gcs_main, refused):
    code, out, err = gcs_main("mission", "check", refused, "--near", "10", "--json")
    assert code == 2 and out == ""  # exit 2: no plan JSON (docs/cli.md)
    (line,) = err.splitlines()
    assert "accepted instead: theta_A = " in line and ", or start at (" in line
    assert line.endswith(" m from A")


def test_check_near_for_a_start_inside_an_obstacle(gcs_main, tmp_path):
    path = tmp_path / "inside.yaml"
    text = MISSION.format(theta=0).replace(
        "  - segment: [[-10, -4.5], [-10, 6]]",
        "  - rectangle: {center: [0, 0], size: [4, 4]}",
    )
    path.write_text(text)
    code, out, err = gcs_main("mission", "check", path)
    assert code == 2 and "accepted instead" not in err  # without --near: as before
    code, out, err = gcs_main("mission", "check", path, "--near", "6")
    (line,) = err.splitlines()
    assert line.startswith(f"{path}: start: expected a point at least safety_margin")
    assert "; accepted instead: start at (" in line and line.endswith(" m from A")


@pytest.mark.parametrize("value", ["0", "-3", "nan", "inf"])
def test_check_near_must_be_a_positive_distance(gcs_main, refused, value):
    code, out, err = gcs_main("mission", "check", refused, f"--near={value}")
    assert code == 2 and out == ""
    assert err.strip().startswith("--near: expected a distance in metres > 0")
