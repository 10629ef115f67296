"""Line-formation kinematics (paper sec. IV-A) and the smoothed reference (docs/design.md 3.5)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from planner.formation import collision_spacing, parking_rows, radio_spacing
from planner.kinematics import (
    LineFormation,
    SpeedProfile,
    recommended_window,
    safe_speed,
    smoothed_reference,
    smoothing_error_bound,
)

PROPERTY = settings(max_examples=40, deadline=None, derandomize=True)
SQRT2 = math.sqrt(2.0)


def formation_on(path, fleet_size=3, rho_c=5.0, rho_r=60.0, theta_a=0.0, theta_b=0.0):
    path = np.asarray(path, float)
    rows = parking_rows(path[0], path[-1], theta_a, theta_b, fleet_size, rho_c)
    return LineFormation(path, fleet_size, rho_c, rho_r, rows)


def aligned_formation(path, fleet_size=3, rho_c=5.0, rho_r=60.0):
    """Rows continue the first and last path segments: no row<->path bends."""
    path = np.asarray(path, float)
    ab = math.atan2(*(path[-1] - path[0])[::-1])
    first = math.atan2(*(path[1] - path[0])[::-1])
    last = math.atan2(*(path[-1] - path[-2])[::-1])
    return formation_on(
        path, fleet_size, rho_c, rho_r, math.degrees(first - ab), math.degrees(last - ab)
    )


ELL = [[0, 0], [100, 0], [100, 100], [200, 100]]  # two 90-degree bends, length 300


def norms(vectors):
    return np.hypot(vectors[..., 0], vectors[..., 1])


# ----- speed profile: S(t) and Phi(s), eqs. 19-22 -------------------------------------------


@st.composite
def profiles(draw):
    initial = draw(st.one_of(st.just(0.0), st.floats(0.5, 20.0)))
    count = draw(st.integers(0, 5))
    gaps = draw(st.lists(st.floats(0.1, 30.0), min_size=count, max_size=count))
    speeds = draw(
        st.lists(st.one_of(st.just(0.0), st.floats(0.5, 20.0)), min_size=count, max_size=count)
    )
    changes = list(zip(np.cumsum(gaps).tolist(), speeds, strict=True))
    return SpeedProfile.from_changes(initial, changes)


def plateau_end(profile: SpeedProfile, t: float) -> float:
    """End of the zero-speed run holding t, by brute force (inf if it never ends)."""
    index = int(np.searchsorted(profile.times, t, side="right")) - 1
    later = [j for j in range(index + 1, len(profile.times)) if profile.speeds[j] > 0]
    return float(profile.times[later[0]]) if later else math.inf


def test_constant_profile_is_linear_eq22():
    profile = SpeedProfile.constant(4.0)
    t = np.array([-1.0, 0.0, 2.5, 10.0])
    assert np.allclose(profile.distance(t), [0.0, 0.0, 10.0, 40.0])
    assert np.allclose(profile.time_at_distance([0.0, 10.0, 40.0]), [0.0, 2.5, 10.0])


def test_distance_and_inverse_with_a_stop_eq20():
    # 10 m/s for 5 s, stopped 5 s, then 2 m/s.
    profile = SpeedProfile.from_changes(10.0, [(5.0, 0.0), (10.0, 2.0)])
    assert np.allclose(profile.distance([5.0, 7.0, 10.0, 12.0]), [50.0, 50.0, 50.0, 54.0])
    # Phi at the plateau's distance is the END of the zero-speed stretch (eq. 20) ...
    assert profile.time_at_distance(50.0) == pytest.approx(10.0)
    # ... and jumps there: its left limit is the start of the stretch.
    assert profile.time_at_distance(50.0 - 1e-9) == pytest.approx(5.0, abs=1e-6)
    assert profile.time_at_distance(54.0) == pytest.approx(12.0)


def test_never_reached_distance_is_infinite():
    profile = SpeedProfile.from_changes(10.0, [(5.0, 0.0)])
    assert profile.time_at_distance(49.0) == pytest.approx(4.9)
    assert math.isinf(profile.time_at_distance(50.0))
    assert math.isinf(profile.time_at_distance(60.0))
    assert profile.distance(math.inf) == pytest.approx(50.0)


def test_initial_stop_moves_phi_of_zero():
    profile = SpeedProfile.from_changes(0.0, [(3.0, 5.0)])
    assert profile.time_at_distance(0.0) == pytest.approx(3.0)
    assert profile.time_at_distance(5.0) == pytest.approx(4.0)


@PROPERTY
@given(profiles(), st.lists(st.floats(0.0, 150.0), min_size=1, max_size=20))
def test_phi_inverts_s(profile, times):
    t = np.array(times)
    s = profile.distance(t)
    back = profile.time_at_distance(s)
    expected = np.array(
        [ti if profile.speed_at(ti) > 0 else plateau_end(profile, ti) for ti in times]
    )
    finite = np.isfinite(expected)
    assert np.array_equal(np.isfinite(back), finite)
    assert np.allclose(back[finite], expected[finite], rtol=1e-9, atol=1e-9)
    assert np.all(back[finite] >= t[finite] - 1e-9)
    # S(Phi(s)) == s wherever Phi(s) is finite.
    assert np.allclose(profile.distance(back[finite]), s[finite], rtol=1e-9, atol=1e-9)


@PROPERTY
@given(profiles(), st.lists(st.floats(0.0, 500.0), min_size=2, max_size=20))
def test_phi_is_monotone_with_derivative_one_over_v(profile, distances):
    s = np.sort(np.array(distances))
    phi = profile.time_at_distance(s)
    assert np.all(phi[1:] >= phi[:-1])
    h = 1e-6
    ahead = profile.time_at_distance(s + h)
    moving = np.isfinite(ahead) & (profile.speed_at(phi) > 0) & (profile.speed_at(ahead) > 0)
    moving &= profile.speed_before(ahead) > 0
    slope = (ahead[moving] - phi[moving]) / h
    assert np.allclose(slope, 1.0 / profile.speed_at(phi[moving]), rtol=1e-4)


@PROPERTY
@given(profiles())
def test_distance_integral_matches_quadrature(profile):
    t = np.linspace(-1.0, 160.0, 200_001)
    quadrature = np.concatenate(
        [[0.0], np.cumsum(np.diff(t) * 0.5 * (profile.distance(t)[1:] + profile.distance(t)[:-1]))]
    )
    assert np.allclose(profile.distance_integral(t), quadrature, atol=1e-3)


def test_with_change_keeps_the_past_and_drops_the_future():
    profile = SpeedProfile.from_changes(10.0, [(5.0, 2.0), (20.0, 8.0)])
    changed = profile.with_change(10.0, 0.0)
    assert changed.times.tolist() == [0.0, 5.0, 10.0]
    assert changed.speeds.tolist() == [10.0, 2.0, 0.0]
    assert SpeedProfile.from_changes(3.0, [(0.0, 7.0)]).speeds.tolist() == [7.0]


@pytest.mark.parametrize(
    ("times", "speeds"),
    [([1.0], [1.0]), ([0.0, 0.0], [1.0, 2.0]), ([0.0], [-1.0]), ([0.0], [math.nan]), ([], [])],
)
def test_bad_profiles_are_refused(times, speeds):
    with pytest.raises(ValueError):
        SpeedProfile(np.array(times), np.array(speeds))
    with pytest.raises(ValueError):
        SpeedProfile.from_changes(1.0, [(5.0, 1.0), (5.0, 2.0)])


# ----- formation: thresholds, slots, V_n(S) (eqs. 16-28) ------------------------------------


def test_thresholds_match_the_papers_formulas_by_hand():
    formation = formation_on(ELL)  # N = 3, rho_c = 5, rho_R = 60: dS_c = 14.142, dS_r = 50
    c = 10 * SQRT2
    expected = [
        [0.0, 0.0, 100.0, 200.0, 300.0, 300.0 + 2 * c],  # n = 1 skips phases 1-2
        [50.0 - c, 50.0, 150.0, 250.0, 350.0, 350.0 + c],
        [100.0 - 2 * c, 100.0, 200.0, 300.0, 400.0, 400.0],  # n = N skips phases 4-5
    ]
    assert np.allclose(formation.thresholds, expected)
    assert formation.total_distance == pytest.approx(400.0)  # len(P) + (N-1) dS_r
    assert np.allclose(formation.departure_distance, [0.0, 50.0 - c, 100.0 - 2 * c])
    assert np.allclose(formation.arrival_distance, [300.0 + 2 * c, 350.0 + c, 400.0])


def test_directions_and_slots_by_hand():
    # A=(0,0), B=(200,100); theta_A = theta_B = 0 so e_0 = e_K = AB / |AB|.
    formation = formation_on(ELL)
    ab = np.array([200.0, 100.0]) / math.hypot(200.0, 100.0)
    assert np.allclose(formation.segment_directions, [ab, [1, 0], [0, 1], [1, 0], ab])
    c = 10 * SQRT2
    assert np.allclose(formation.start_slots, [[0, 0], -c * ab, -2 * c * ab])
    assert np.allclose(
        formation.goal_slots, [[200, 100] + 2 * c * ab, [200, 100] + c * ab, [200, 100]]
    )


def literal_eq27(formation, s):
    """Eq. 27 as printed: P_0,n + sum_k ramp(S; L_k,n, L_k+1,n) e_k, k = 0..K."""
    thresholds = formation.thresholds
    ramps = np.clip(
        s[:, None, None] - thresholds[None, :, :-1], 0.0, np.diff(thresholds, axis=1)[None]
    )
    return formation.start_slots[None] + np.einsum(
        "tnk,kd->tnd", ramps, formation.segment_directions
    )


@st.composite
def formations(draw):
    """Paths with bends up to 90 degrees, random rows and fleet sizes."""
    count = draw(st.integers(2, 6))
    point, heading, points = np.zeros(2), draw(st.floats(-math.pi, math.pi)), [np.zeros(2)]
    for _ in range(count - 1):
        heading += draw(st.floats(-math.pi / 2, math.pi / 2))
        point = point + draw(st.floats(5.0, 120.0)) * np.array(
            [math.cos(heading), math.sin(heading)]
        )
        points.append(point)
    rho_c = draw(st.floats(1.0, 10.0))
    rho_r = draw(st.floats(2 * (1 + SQRT2) * rho_c, 30 * rho_c))
    return formation_on(
        np.array(points),
        draw(st.integers(1, 7)),
        rho_c,
        rho_r,
        draw(st.floats(-90, 90)),
        draw(st.floats(-90, 90)),
    )


@PROPERTY
@given(formations())
def test_positions_equal_the_literal_eq27(formation):
    s = np.linspace(-5.0, formation.total_distance + 5.0, 2001)
    assert np.allclose(formation.positions(s), literal_eq27(formation, s), atol=1e-9)


@PROPERTY
@given(formations())
def test_virtual_uavs_are_continuous_with_unit_speed_while_moving(formation):
    s = np.linspace(0.0, formation.total_distance, 4001)
    positions = formation.positions(s)
    step = norms(np.diff(positions, axis=0))  # (T-1, N)
    ds = np.diff(s)[:, None]
    assert np.all(step <= ds + 1e-9)  # 1-Lipschitz: continuous, never faster than v
    thresholds = formation.thresholds
    inside = (s[:-1, None] >= thresholds[:, 0]) & (s[1:, None] <= thresholds[:, -1])
    crosses = (
        (s[:-1, None, None] < thresholds[None, :, 1:-1])
        & (s[1:, None, None] > thresholds[None, :, 1:-1])
    ).any(axis=2)
    straight = inside & ~crosses
    assert np.allclose(step[straight], np.broadcast_to(ds, step.shape)[straight], atol=1e-9)
    # dV/dS is a unit vector while moving, zero while parked (eq. 30).
    direction = norms(formation.directions(s))
    moving = (s[:, None] >= thresholds[:, 0]) & (s[:, None] < thresholds[:, -1])
    assert np.allclose(direction[moving], 1.0)
    assert np.allclose(direction[~moving], 0.0)


@PROPERTY
@given(formations())
def test_uavs_start_and_end_on_their_slots(formation):
    assert np.allclose(formation.positions(0.0), formation.start_slots)
    assert np.allclose(formation.positions(formation.total_distance), formation.goal_slots)
    assert np.allclose(formation.positions(formation.total_distance + 50.0), formation.goal_slots)
    assert np.allclose(
        formation.positions(formation.departure_distance).diagonal(axis1=0, axis2=1).T,
        formation.start_slots,
    )
    at_arrival = formation.positions(formation.arrival_distance).diagonal(axis1=0, axis2=1).T
    assert np.allclose(at_arrival, formation.goal_slots)


@PROPERTY
@given(formations())
def test_theorem2_rows_then_path_then_rows(formation):
    s = np.linspace(0.0, formation.total_distance, 1501)
    positions = formation.positions(s)
    thresholds = formation.thresholds
    a, b = formation.path[0], formation.path[-1]
    e0, ek = formation.segment_directions[0], formation.segment_directions[-1]
    on_start = s[:, None] <= thresholds[:, 1]
    rel = positions - a
    assert np.allclose((rel[..., 0] * e0[1] - rel[..., 1] * e0[0])[on_start], 0.0, atol=1e-9)
    assert np.all((rel[..., 0] * e0[0] + rel[..., 1] * e0[1])[on_start] <= 1e-9)
    on_goal = s[:, None] >= thresholds[:, -2]
    rel = positions - b
    assert np.allclose((rel[..., 0] * ek[1] - rel[..., 1] * ek[0])[on_goal], 0.0, atol=1e-9)
    assert np.all((rel[..., 0] * ek[0] + rel[..., 1] * ek[1])[on_goal] >= -1e-9)
    phases = formation.phases(s)
    assert np.all(phases[on_start & (s[:, None] > thresholds[:, 0])] == 1)
    assert np.all(phases[s[:, None] <= thresholds[:, 0]] == 0)
    assert np.all(phases[s[:, None] > thresholds[:, -1]] == 4)


@PROPERTY
@given(formations())
def test_spacing_on_the_path_is_the_radio_spacing(formation):
    first_on, last_off = formation.thresholds[-1, 1], formation.thresholds[0, -2]
    assume(first_on <= last_off)  # true whenever N meets eq. 28
    s = np.linspace(first_on, last_off, 101)
    beyond = formation.distance_beyond_start(s)
    spacing = radio_spacing(formation.safety_margin, formation.radio_range)
    assert np.allclose(-np.diff(beyond, axis=1), spacing)
    euclid = norms(np.diff(formation.positions(s), axis=1))
    assert np.all(euclid <= spacing + 1e-9)  # the triangle inequality of fig. 4


def test_parked_uavs_are_collision_spacing_apart():
    formation = formation_on(ELL, fleet_size=5, rho_r=120.0)
    gaps = norms(np.diff(formation.positions(0.0), axis=0))
    assert np.allclose(gaps, collision_spacing(5.0))


def test_duration_eq25():
    formation = formation_on(ELL)
    assert formation.duration(SpeedProfile.constant(8.0)) == pytest.approx(400.0 / 8.0)
    stop = SpeedProfile.from_changes(10.0, [(10.0, 0.0), (25.0, 5.0)])
    # 100 m by t=10, stopped until 25, then 300 m at 5 m/s: 25 + 60.
    assert formation.duration(stop) == pytest.approx(85.0)
    assert np.allclose(formation.threshold_times(stop)[0, :3], [0.0, 0.0, 25.0])
    assert math.isinf(formation.duration(SpeedProfile.from_changes(10.0, [(10.0, 0.0)])))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"path": [[0, 0], [0, 0], [5, 5]]},
        {"path": [[0, 0]]},
        {"rho_r": 20.0},  # below 2(1+sqrt 2) rho_c = 24.1 (eq. 9)
        {"fleet_size": 0},
    ],
)
def test_bad_formations_are_refused(kwargs):
    args = {"path": ELL, "fleet_size": 3, "rho_c": 5.0, "rho_r": 60.0} | kwargs
    with pytest.raises(ValueError):
        formation_on(**args)


# ----- smoothed reference --------------------------------------------------------------------

STOP_AND_GO = SpeedProfile.from_changes(10.0, [(12.0, 0.0), (20.0, 4.0), (33.0, 10.0)])


def quadrature_average(formation, profile, times, window):
    u = np.linspace(-window / 2, window / 2, 8001)
    samples = formation.positions(profile.distance(times[:, None] + u[None, :]))
    return np.trapezoid(samples, u, axis=1) / window


@pytest.mark.parametrize("window", [0.5, 2.0, 7.0])
def test_smoothed_reference_is_the_moving_average(window):
    formation = formation_on(ELL, theta_a=30.0, theta_b=-45.0)
    times = np.random.default_rng(1).uniform(-5.0, formation.duration(STOP_AND_GO) + 5.0, 60)
    reference = smoothed_reference(formation, STOP_AND_GO, times, window)
    expected = quadrature_average(formation, STOP_AND_GO, times, window)
    assert np.allclose(reference.positions, expected, atol=1e-5)


def test_smoothed_derivatives_match_finite_differences():
    formation = formation_on(ELL, theta_a=30.0, theta_b=-45.0)
    times = np.random.default_rng(2).uniform(-3.0, formation.duration(STOP_AND_GO) + 3.0, 300)
    window, h = 3.0, 1e-6
    at = smoothed_reference(formation, STOP_AND_GO, times, window)
    ahead = smoothed_reference(formation, STOP_AND_GO, times + h, window)
    behind = smoothed_reference(formation, STOP_AND_GO, times - h, window)
    assert np.allclose((ahead.positions - behind.positions) / (2 * h), at.velocities, atol=1e-3)
    assert np.allclose(
        (ahead.velocities - behind.velocities) / (2 * h), at.accelerations, atol=1e-3
    )
    # Integrated over a long stretch: the velocity/acceleration are the derivatives everywhere.
    grid = np.linspace(0.0, 60.0, 600_001)
    dense = smoothed_reference(formation, STOP_AND_GO, grid, window)
    travelled = np.trapezoid(dense.velocities, grid, axis=0)
    assert np.allclose(travelled, dense.positions[-1] - dense.positions[0], atol=1e-4)
    gained = np.sum(dense.accelerations[:-1] * np.diff(grid)[:, None, None], axis=0)
    assert np.allclose(gained, dense.velocities[-1] - dense.velocities[0], atol=1e-2)


def test_smoothed_reference_is_parked_far_from_the_mission():
    formation = formation_on(ELL)
    profile = SpeedProfile.constant(10.0)
    end = formation.duration(profile)
    reference = smoothed_reference(formation, profile, np.array([-2.5, end + 2.5]), 4.0)
    assert np.allclose(reference.positions[0], formation.start_slots)
    assert np.allclose(reference.positions[1], formation.goal_slots)
    assert np.allclose(reference.velocities, 0.0)
    assert np.allclose(reference.accelerations, 0.0)


def test_zero_window_is_the_virtual_target():
    formation = formation_on(ELL)
    times = np.linspace(0, 50, 101)
    reference = smoothed_reference(formation, STOP_AND_GO, times, 0.0)
    assert np.allclose(reference.positions, formation.positions(STOP_AND_GO.distance(times)))
    speeds = norms(reference.velocities)
    assert np.all(speeds <= STOP_AND_GO.speed_at(times)[:, None] + 1e-12)


def test_single_bend_error_is_dv_window_over_8():
    # Rows aligned with the path, one 90-degree bend: the only kinks are start/stop and the bend.
    formation = aligned_formation([[0, 0], [500, 0], [500, 500]], fleet_size=2, rho_r=100.0)
    profile, window = SpeedProfile.constant(10.0), 2.0
    bend_times = formation.threshold_times(profile)[:, 2]
    reference = smoothed_reference(formation, profile, bend_times, window)
    virtual = formation.positions(profile.distance(bend_times))
    error = norms(reference.positions - virtual).diagonal()
    assert np.allclose(error, SQRT2 * 10.0 * window / 8)  # |dv| = 2 v sin(45 deg)
    # It points to the inside of the bend.
    inside = (reference.positions - virtual).diagonal(axis1=0, axis2=1).T
    assert np.all(inside[:, 0] < 0) and np.all(inside[:, 1] > 0)
    assert smoothing_error_bound(formation, profile, window) == pytest.approx(
        SQRT2 * 10.0 * window / 8
    )


def test_starts_and_speed_steps_are_kinks_too():
    # One UAV on a straight path, rows continuing it: the only kinks are the start (0 -> 10 m/s
    # at t = 1, the end of an initial stop), a step 10 -> 2 at t = 5 and the stop at 2 m/s.
    formation = aligned_formation([[0, 0], [300, 0]], fleet_size=1)
    profile = SpeedProfile.from_changes(0.0, [(1.0, 10.0), (5.0, 2.0)])
    window = 1.0
    kinks = np.array([1.0, 5.0])
    reference = smoothed_reference(formation, profile, kinks, window)
    error = norms(reference.positions - formation.positions(profile.distance(kinks)))[:, 0]
    assert np.allclose(error, [10.0 * window / 8, 8.0 * window / 8])
    assert smoothing_error_bound(formation, profile, window) == pytest.approx(10.0 * window / 8)
    # A speed step larger than the start dominates.
    profile = SpeedProfile.from_changes(2.0, [(5.0, 14.0), (10.0, 2.0)])
    assert smoothing_error_bound(formation, profile, window) == pytest.approx(12.0 * window / 8)


def test_uav_one_starts_on_the_path_not_on_its_row():
    # UAV 1 is parked at A: its start and the row->path bend are one kink of |e_1| = 1, however
    # the row is turned; a lone UAV on a straight path is limited by that start alone.
    formation = formation_on([[0, 0], [1000, 0]], fleet_size=1, theta_a=90.0)
    assert safe_speed(formation, 5.0, 5.0) == pytest.approx(math.sqrt(8 * 5.0 * 5.0), rel=1e-6)
    profile = SpeedProfile.constant(10.0)
    assert smoothing_error_bound(formation, profile, 2.0) == pytest.approx(10.0 * 2.0 / 8)


@pytest.mark.parametrize(
    ("path", "profile"),
    [
        (ELL, STOP_AND_GO),
        ([[0, 0], [30, 0], [30, 8], [60, 8], [60, 60]], SpeedProfile.constant(12.0)),
        (
            [[0, 0], [30, 0], [30, 8], [60, 8], [60, 60]],
            SpeedProfile.from_changes(2.0, [(3.0, 0.0), (4.0, 12.0), (9.0, 3.0)]),
        ),
        (
            [[0, 0], [40, 0], [47, 7], [47, 60]],
            SpeedProfile.from_changes(0.0, [(1.0, 9.0), (7.5, 0.0), (8.0, 9.0)]),
        ),
    ],
)
@pytest.mark.parametrize("window", [0.7, 2.5, 6.0])
def test_smoothing_error_stays_within_the_bound(path, profile, window):
    formation = formation_on(path, fleet_size=4, rho_c=3.0, rho_r=40.0, theta_a=60.0, theta_b=-20.0)
    end = formation.duration(profile)
    times = np.linspace(-window, end + window, 20_001)
    reference = smoothed_reference(formation, profile, times, window)
    error = norms(reference.positions - formation.positions(profile.distance(times)))
    bound = smoothing_error_bound(formation, profile, window)
    assert error.max() <= bound + 1e-9
    assert error.max() >= 0.45 * bound  # the bound is not vacuous


# ----- safe speed and window ---------------------------------------------------------------


def test_safe_speed_for_a_90_degree_bend_is_the_design_example():
    # docs/design.md 3.5: a 90-degree bend at 10 m/s with a_max = 5 costs 5 m.
    bend = [[0, 0], [1000, 0], [1000, 1000]]
    assert safe_speed(np.array(bend, float), 5.0, 5.0) == pytest.approx(10.0, rel=1e-6)
    formation = aligned_formation(bend, fleet_size=3, rho_r=220.0)
    assert safe_speed(formation, 5.0, 5.0) == pytest.approx(10.0, rel=1e-6)
    assert recommended_window(10.0, 5.0) == pytest.approx(SQRT2 * 10.0 / 5.0)
    assert recommended_window(10.0, 5.0, formation) == pytest.approx(SQRT2 * 10.0 / 5.0)


@pytest.mark.parametrize("angle_deg", [20.0, 45.0, 70.0, 90.0])
def test_safe_speed_of_an_isolated_bend(angle_deg):
    angle = math.radians(angle_deg)
    path = np.array([[0, 0], [2000, 0], [2000 + 2000 * math.cos(angle), 2000 * math.sin(angle)]])
    dv_per_speed = 2 * math.sin(angle / 2)
    assert safe_speed(path, 3.0, 2.0) == pytest.approx(
        math.sqrt(8 * 3.0 * 2.0) / dv_per_speed, rel=1e-6
    )


def test_close_kinks_add_up_rectangle_corner():
    rho_c = 5.0
    corner = np.array(
        [
            [0, 0],
            [500, 0],
            [500 + 2 * rho_c / SQRT2, 2 * rho_c / SQRT2],
            [500 + 2 * rho_c / SQRT2, 500],
        ]
    )
    one_45 = np.array([[0, 0], [500, 0], [1000, 500]])
    one_90 = np.array([[0, 0], [500, 0], [500, 500]])
    v_corner = safe_speed(corner, 5.0, 5.0)
    assert safe_speed(one_90, 5.0, 5.0) < v_corner < safe_speed(one_45, 5.0, 5.0)


def test_a_shorter_window_can_allow_more_speed():
    # A U-turn: two 90-degree bends 25 m apart whose jumps add up to 2 (vs sqrt 2 each). The
    # budget alone allows a 28.3 m window, which would hold both bends (v^2 = a 28.3 / 2); a
    # window just under 25 m holds one (v^2 = a 25 / sqrt 2) and is faster.
    u_turn = np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 25.0], [0.0, 25.0]])
    expected = math.sqrt(5.0 * 25.0 / SQRT2)
    assert safe_speed(u_turn, 5.0, 5.0) == pytest.approx(expected, rel=1e-5)
    formation = aligned_formation(u_turn, fleet_size=1)
    assert safe_speed(formation, 5.0, 5.0) == pytest.approx(expected, rel=1e-5)
    window = recommended_window(expected, 5.0, formation)
    assert window * expected < 25.0
    profile = SpeedProfile.constant(expected)
    assert smoothing_error_bound(formation, profile, window) <= 5.0


@pytest.mark.parametrize(
    ("path", "theta_a", "theta_b", "a_max", "budget"),
    [
        (ELL, 30.0, -45.0, 5.0, 5.0),
        (ELL, 0.0, 0.0, 2.0, 1.0),
        ([[0, 0], [30, 0], [30, 8], [60, 8], [60, 60]], 60.0, -20.0, 6.0, 2.5),
        ([[0, 0], [40, 0], [47, 7], [47, 60]], 0.0, 90.0, 10.0, 3.0),
    ],
)
def test_safe_speed_and_window_keep_the_budget_and_the_acceleration(
    path, theta_a, theta_b, a_max, budget
):
    formation = formation_on(
        path, fleet_size=4, rho_c=3.0, rho_r=40.0, theta_a=theta_a, theta_b=theta_b
    )
    speed = safe_speed(formation, a_max, budget)
    window = recommended_window(speed, a_max, formation)
    profile = SpeedProfile.constant(speed)
    assert smoothing_error_bound(formation, profile, window) <= budget * (1 + 1e-6)
    times = np.linspace(-window, formation.duration(profile) + window, 40_001)
    reference = smoothed_reference(formation, profile, times, window)
    assert norms(reference.accelerations).max() <= a_max * (1 + 1e-6)
    error = norms(reference.positions - formation.positions(profile.distance(times)))
    assert error.max() <= budget * (1 + 1e-6)
    # And the speed is the highest such: 2 % faster, the best window breaks the budget.
    faster = speed * 1.02
    faster_window = recommended_window(faster, a_max, formation)
    assert smoothing_error_bound(formation, SpeedProfile.constant(faster), faster_window) > budget


def test_straight_path_has_no_speed_limit():
    assert math.isinf(safe_speed(np.array([[0.0, 0.0], [100.0, 0.0]]), 5.0, 1.0))
    assert recommended_window(0.0, 5.0) == 0.0
    with pytest.raises(ValueError):
        safe_speed(np.array(ELL, float), 0.0, 1.0)


def test_a_pause_one_window_long_gives_a_standing_start():
    """`with_pause(p, w)`: the formation stands still for w from p, then goes on at the speed
    it had, every later change w later; the smoothed reference stands at V(p) with zero
    velocity at p + w/2, then accelerates at speed / w (the restart after a ground-station
    stall)."""
    formation = aligned_formation([[0.0, 0.0], [400.0, 0.0]])
    profile = SpeedProfile.from_changes(8.0, [(20.0, 5.0)])
    window = 1.2
    paused = profile.with_pause(10.0, window)
    assert paused.times.tolist() == [0.0, 10.0, 10.0 + window, 20.0 + window]
    assert paused.speeds.tolist() == [8.0, 0.0, 8.0, 5.0]
    assert paused.distance(25.0 + window) == pytest.approx(profile.distance(25.0))
    middle = 10.0 + window / 2
    reference = smoothed_reference(formation, paused, [middle, middle + 0.3], window)
    virtual = formation.positions(profile.distance(10.0))
    np.testing.assert_allclose(reference.positions[0], virtual, atol=1e-9)
    np.testing.assert_allclose(reference.velocities[0], 0.0, atol=1e-9)
    moving = np.hypot(*reference.accelerations[1].T) > 0  # the UAVs already under way
    np.testing.assert_allclose(np.hypot(*reference.accelerations[1][moving].T), 8.0 / window)
    with pytest.raises(ValueError):
        profile.with_pause(-1.0, window)
