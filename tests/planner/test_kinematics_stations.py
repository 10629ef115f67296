"""Monitoring-station formations (`LineFormation.stations`, `returns`): the line formation of
eq. 27 with each UAV's distance beyond A capped at its station, and the mirrored flight home."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from planner.formation import collision_spacing, parking_rows, radio_spacing
from planner.guarantees import check_positions
from planner.kinematics import (
    LineFormation,
    SpeedProfile,
    recommended_window,
    safe_speed,
    smoothed_reference,
    smoothing_error_bound,
)
from planner.obstacles import Obstacles

PROPERTY = settings(max_examples=40, deadline=None, derandomize=True)
SQRT2 = math.sqrt(2.0)

STRAIGHT = [[0.0, 0.0], [100.0, 0.0]]  # rho_c 5, rho_R 50: dS_r = 40, dS_c = 10 sqrt 2
HAND_STATIONS = [100.0, 70.0, 35.0]  # caps S_n = s_n + (n-1) 40: 100, 110, 115 = S_out
ELL = [[0, 0], [100, 0], [100, 100], [200, 100]]  # two 90-degree bends, length 300


def station_formation(
    path, stations, returns=False, rho_c=5.0, rho_r=50.0, theta_a=0.0, theta_b=0.0
):
    path = np.asarray(path, float)
    rows = parking_rows(path[0], path[-1], theta_a, theta_b, len(stations), rho_c)
    formation = LineFormation(path, len(stations), rho_c, rho_r, rows, stations)
    return formation.with_return(formation.outbound_distance) if returns else formation


def plain_twin(formation: LineFormation) -> LineFormation:
    """The A -> B formation on the same path, rows and spacings."""
    return LineFormation(
        formation.path,
        formation.fleet_size,
        formation.safety_margin,
        formation.radio_range,
        formation.rows,
    )


def norms(vectors):
    return np.hypot(vectors[..., 0], vectors[..., 1])


def point_along(path, start_direction, beyond):
    """The point at arc length `beyond` from A on the path, behind A along the start row."""
    path = np.asarray(path, float)
    arcs = np.concatenate([[0.0], np.cumsum(norms(np.diff(path, axis=0)))])
    on_path = np.stack(
        [np.interp(beyond, arcs, path[:, 0]), np.interp(beyond, arcs, path[:, 1])], axis=-1
    )
    behind = path[0] + np.minimum(beyond, 0.0)[..., None] * start_direction
    return np.where((beyond < 0)[..., None], behind, on_path)


def literal_positions(formation: LineFormation, s):
    """The rule as stated: eq. 27's V_n where its distance beyond A is below s_n, the station
    point s_n along the path once it would pass it; with `returns` at min(S, 2 S_out - S)."""
    s = np.asarray(s, float)
    if formation.returning:
        s = np.minimum(s, 2 * formation.outbound_distance - s)
    plain = plain_twin(formation)
    beyond = plain.distance_beyond_start(s)
    station = point_along(formation.path, formation.segment_directions[0], formation.stations)
    return np.where(
        (beyond < formation.stations)[..., None], plain.positions(s), station[None]
    ), np.minimum(beyond, formation.stations)


@st.composite
def station_formations(draw, returns=None):
    """Paths with bends up to 90 degrees and stations meeting the mission's spacing rules:
    consecutive ones dS_c .. dS_r apart, s_N <= dS_r, s_1 <= len(P)."""
    count = draw(st.integers(2, 6))
    point, heading, points = np.zeros(2), draw(st.floats(-math.pi, math.pi)), [np.zeros(2)]
    for _ in range(count - 1):
        heading += draw(st.floats(-math.pi / 2, math.pi / 2))
        point = point + draw(st.floats(5.0, 120.0)) * np.array(
            [math.cos(heading), math.sin(heading)]
        )
        points.append(point)
    path = np.array(points)
    length = float(np.sum(norms(np.diff(path, axis=0))))
    rho_c = draw(st.floats(1.0, 6.0))
    rho_r = draw(st.floats(2 * (1 + SQRT2) * rho_c, 20 * rho_c))
    spacing_c, spacing_r = collision_spacing(rho_c), radio_spacing(rho_c, rho_r)
    fleet = draw(st.integers(1, 6))
    last = draw(st.floats(0.05, 1.0)) * min(spacing_r, length)
    gaps = [
        spacing_c + draw(st.floats(0.0, 1.0)) * (spacing_r - spacing_c) for _ in range(fleet - 1)
    ]
    stations = last + np.concatenate([np.cumsum(gaps[::-1])[::-1], [0.0]])
    assume(stations[0] <= length)
    assume(np.all(np.diff(stations) < 0))
    if draw(st.booleans()):  # the leader holds on B
        stations = stations + (length - stations[0])
        assume(stations[-1] <= spacing_r)
    returns = draw(st.booleans()) if returns is None else returns
    return station_formation(
        path,
        stations,
        returns,
        rho_c,
        rho_r,
        draw(st.floats(-90, 90)),
        draw(st.floats(-90, 90)),
    )


# ----- V_n(S): the capped eq. 27 and its mirror ---------------------------------------------


@PROPERTY
@given(station_formations())
def test_positions_follow_the_literal_rule(formation):
    s_out = formation.outbound_distance
    s = np.concatenate(
        [
            np.linspace(-5.0, formation.total_distance + 60.0, 3001),
            formation.thresholds.ravel(),
            [s_out, 2 * s_out],
        ]
    )
    expected, beyond = literal_positions(formation, s)
    assert np.allclose(formation.positions(s), expected, atol=1e-9)
    assert np.allclose(formation.distance_beyond_start(s), beyond, atol=1e-9)
    # Past S_out everyone holds (without the return) or is back home (with it).
    later = s_out + np.array([0.0, 1.0, 500.0]) * (1 + formation.returning)
    final = formation.start_slots if formation.returning else formation.station_slots
    assert np.allclose(formation.positions(later[-1]), final, atol=1e-9)
    if not formation.returning:
        assert np.allclose(formation.positions(later), formation.station_slots, atol=1e-9)
    assert np.allclose(formation.goal_slots, final)
    assert np.allclose(formation.positions(0.0), formation.start_slots)


@PROPERTY
@given(station_formations(returns=True))
def test_the_return_mirrors_the_outbound_flight(formation):
    s_out = formation.outbound_distance
    assert formation.total_distance == pytest.approx(2 * s_out)
    outbound = LineFormation(
        formation.path,
        formation.fleet_size,
        formation.safety_margin,
        formation.radio_range,
        formation.rows,
        formation.stations,
    )
    before = np.linspace(-5.0, s_out, 1001)
    assert np.allclose(formation.positions(before), outbound.positions(before), atol=1e-12)
    s = np.linspace(s_out, 2 * s_out + 20.0, 2001)
    assert np.allclose(formation.positions(s), formation.positions(2 * s_out - s), atol=1e-9)
    assert np.allclose(formation.positions(2 * s_out), formation.start_slots, atol=1e-9)
    assert np.allclose(formation.station_slots, outbound.goal_slots)
    # The UAV nearest A leaves first, at S_out; the others as the gaps open.
    fine = np.linspace(s_out, 2 * s_out, 20_001)
    away = norms(formation.positions(fine) - formation.station_slots[None]) > 1e-9
    leaves = fine[np.argmax(away, axis=0)]
    assert np.all(away.any(axis=0))
    assert leaves[-1] == pytest.approx(s_out, abs=2 * (fine[1] - fine[0]))
    step = fine[1] - fine[0]
    assert np.all(np.diff(leaves) <= 2 * step)  # equal when a gap is exactly dS_r
    caps = formation.stations + formation.thresholds[:, 1]  # S_n = s_n + (n-1) dS_r
    assert np.allclose(leaves, 2 * s_out - caps, atol=2 * step)


@PROPERTY
@given(station_formations())
def test_gaps_stay_between_the_spacings_and_the_fleet_stays_connected(formation):
    spacing_c, spacing_r = formation.collision_spacing, formation.radio_spacing
    s = np.concatenate(
        [np.linspace(0.0, formation.total_distance + 10.0, 4001), formation.thresholds.ravel()]
    )
    _, beyond = literal_positions(formation, s)  # along the route, the start row before A
    gaps = -np.diff(beyond, axis=1)
    assert np.all(gaps >= spacing_c - 1e-9)
    assert np.all(gaps <= spacing_r + 1e-9)
    assert np.all(beyond[:, -1] <= spacing_r + 1e-9)  # UAV N within dS_r of A
    # Along-route distances bound the straight ones: a radio chain to A at every S.
    checks = check_positions(
        formation.positions(s), Obstacles(), formation.path[:1], formation.radio_range
    )
    assert np.all(checks.connected)


def test_straight_route_keeps_theorems_4_and_5():
    formation = station_formation(STRAIGHT, HAND_STATIONS, returns=True)
    s = np.linspace(0.0, formation.total_distance + 10.0, 4001)
    checks = check_positions(formation.positions(s), Obstacles(), np.zeros((1, 2)), 50.0)
    assert np.all(checks.connected)
    assert checks.min_uav_uav_m.min() >= 2 * 5.0 - 1e-9
    assert checks.min_uav_uav_m.min() == pytest.approx(10 * SQRT2)  # parked, dS_c apart
    on_stations = checks.min_uav_uav_m[(s >= 115.0) & (s <= 120.0)]
    assert np.allclose(on_stations, 30.0)  # stations 100 and 70


@PROPERTY
@given(station_formations())
def test_directions_are_the_right_derivative(formation):
    s = np.linspace(-1.0, formation.total_distance + 5.0, 3001)
    thresholds = formation.thresholds.ravel()
    h = 1e-4
    clear = np.abs(s[:, None] - thresholds[None]).min(axis=1) > 10 * h
    slope = (formation.positions(s + h) - formation.positions(s)) / h
    directions = formation.directions(s)
    assert np.allclose(directions[clear], slope[clear], atol=1e-6)
    assert np.allclose(norms(directions)[clear], np.round(norms(directions)[clear]))


# ----- hand-computed example: 100 m straight, rho_c 5, rho_R 50, stations 100, 70, 35 ------


def test_hand_computed_thresholds_distances_and_duration():
    c = 10 * SQRT2  # dS_c
    formation = station_formation(STRAIGHT, HAND_STATIONS)
    assert formation.radio_spacing == pytest.approx(40.0)
    assert formation.outbound_distance == pytest.approx(115.0)
    assert formation.total_distance == pytest.approx(115.0)
    expected = [
        [0.0, 0.0, 100.0, 100.0],  # UAV 1 stops on B, its goal-row threshold collapses
        [40.0 - c, 40.0, 110.0, 110.0],
        [80.0 - 2 * c, 80.0, 115.0, 115.0],
    ]
    assert np.allclose(formation.thresholds, expected)
    assert np.allclose(formation.arrival_distance, [100.0, 110.0, 115.0])
    assert np.allclose(formation.station_slots, [[100, 0], [70, 0], [35, 0]])
    assert np.allclose(formation.goal_slots, formation.station_slots)
    constant = SpeedProfile.constant(5.0)
    assert formation.duration(constant) == pytest.approx(23.0)

    home = station_formation(STRAIGHT, HAND_STATIONS, returns=True)
    assert home.outbound_distance == pytest.approx(115.0)
    assert home.total_distance == pytest.approx(230.0)
    mirrored = 230.0 - np.array(expected)[:, ::-1]
    assert np.allclose(home.thresholds, np.concatenate([expected, mirrored], axis=1))
    assert np.allclose(home.arrival_distance, [230.0, 230.0 - (40.0 - c), 230.0 - (80.0 - 2 * c)])
    assert np.allclose(home.goal_slots, home.start_slots)
    assert np.allclose(home.station_slots, [[100, 0], [70, 0], [35, 0]])
    assert home.duration(constant) == pytest.approx(46.0)
    held = constant.with_pause(23.0, 10.0)  # hold 10 s on the stations
    assert home.duration(held) == pytest.approx(56.0)
    assert np.allclose(home.threshold_times(held)[2, 2:6], [33.0] * 4)  # Phi at the hold: its end
    # A plain formation: S_out is its total distance, the stations its goal slots.
    plain = plain_twin(formation)
    assert plain.outbound_distance == plain.total_distance
    assert np.allclose(plain.station_slots, plain.goal_slots)


def test_phases_of_one_uav():
    c = 10 * SQRT2
    # UAV 2: leaves its slot at 40 - c, reaches A at 40, its station 70 m on at 110.
    samples = {
        0.0: 0,
        40.0 - c: 0,
        40.0 - c + 0.1: 1,
        40.0: 1,
        40.1: 2,
        110.0: 2,
        110.1: 4,
        119.9: 4,
    }
    formation = station_formation(STRAIGHT, HAND_STATIONS)
    for s, phase in (samples | {120.1: 4, 500.0: 4}).items():
        assert formation.phases(s)[1] == phase, s
    # Home: UAV 3 leaves at 115, UAV 2 at 230 - 110 = 120, back on A at 190, parked at 230 - L_0.
    home = station_formation(STRAIGHT, HAND_STATIONS, returns=True)
    back = {120.0: 4, 120.1: 2, 190.0: 2, 190.1: 1, 230.0 - (40.0 - c) - 0.1: 1}
    back |= {230.0 - (40.0 - c) + 0.1: 0, 230.0: 0, 1e4: 0}
    for s, phase in (samples | back).items():
        assert home.phases(s)[1] == phase, s
    s = np.linspace(0.0, 240.0, 2401)
    sequence = [
        int(p)
        for i, p in enumerate(home.phases(s)[:, 1])
        if i == 0 or p != home.phases(s)[i - 1, 1]
    ]
    assert sequence == [0, 1, 2, 4, 2, 1, 0]
    assert [int(p) for p in home.phases(116.0)] == [4, 4, 2]  # UAV 3 already homewards
    # Right derivatives at the kinks themselves: UAV 3 turns back on its station at S_out.
    assert np.allclose(formation.directions(115.0), 0.0)
    assert np.allclose(home.directions(115.0), [[0, 0], [0, 0], [-1, 0]])
    assert np.allclose(home.directions(120.0), [[0, 0], [-1, 0], [-1, 0]])
    assert np.allclose(home.directions(230.0), 0.0)
    directions = home.directions(np.array([105.0, 116.0, 125.0]))
    assert np.allclose(directions[0], [[0, 0], [1, 0], [1, 0]])
    assert np.allclose(directions[1], [[0, 0], [0, 0], [-1, 0]])
    assert np.allclose(directions[2], [[0, 0], [-1, 0], [-1, 0]])


def test_a_station_on_a_bend_and_one_just_beyond_the_end():
    # UAV 1 holds within the tolerance past B (clipped onto B), UAV 2 on the bend P_2.
    formation = station_formation(
        [[0, 0], [60, 0], [60, 60]], [120.0 + 5e-7, 60.0, 25.0], returns=True, rho_r=80.0
    )
    assert formation.stations[0] == 120.0
    assert np.allclose(formation.station_slots, [[60, 60], [60, 0], [25, 0]])
    s = np.linspace(0.0, formation.total_distance + 5.0, 4001)
    expected, _ = literal_positions(formation, s)
    assert np.allclose(formation.positions(s), expected, atol=1e-9)


# ----- smoothed reference, error bound, safe speed --------------------------------------------


def station_profile(formation, hold=7.0):
    """6 m/s, 9 m/s from t = 8, the hold at S_out, 4 m/s for the return's second half."""
    base = SpeedProfile.from_changes(6.0, [(8.0, 9.0)])
    reached = float(base.time_at_distance(formation.outbound_distance))
    home = reached + 0.5 * formation.outbound_distance / 9.0
    base = SpeedProfile.from_changes(6.0, [(8.0, 9.0), (home, 4.0)])
    return base.with_pause(reached, hold)


def moving_average(formation, profile, t, window, points=20_001):
    """Trapezoid over the window: V(t) is piecewise linear, a kink inside a cell of width h
    costs at most |dv| h^2 / 8, here below 1e-7 m."""
    u = np.linspace(-window / 2, window / 2, points)
    samples = formation.positions(profile.distance(t + u))
    return np.trapezoid(samples, u, axis=0) / window


CASES = [
    (STRAIGHT, HAND_STATIONS, 0.0, 0.0),
    (ELL, [290.0, 240.0, 205.0, 160.0, 120.0, 85.0, 45.0], 30.0, -45.0),
    ([[0, 0], [40, 0], [47, 7], [47, 60]], [100.0, 62.0, 40.0, 26.0], 60.0, 0.0),
]


@pytest.mark.parametrize("returns", [False, True])
@pytest.mark.parametrize("case", range(len(CASES)))
@pytest.mark.parametrize("window", [0.8, 3.0, 9.0])
def test_smoothed_reference_is_the_moving_average(case, returns, window):
    path, stations, theta_a, theta_b = CASES[case]
    formation = station_formation(path, stations, returns, theta_a=theta_a, theta_b=theta_b)
    profile = station_profile(formation)
    end = formation.duration(profile)
    rng = np.random.default_rng(10 * case + returns)
    random = rng.uniform(-3.0, end + 3.0, 16)
    # and where the window's edges meet kinks: the stops, the hold, the speed steps
    edges = np.concatenate(
        [formation.threshold_times(profile).ravel() + window / 2, profile.times[1:] - window / 2]
    )
    times = np.concatenate([random, edges[np.isfinite(edges)]])
    reference = smoothed_reference(formation, profile, times, window)
    expected = np.array([moving_average(formation, profile, t, window) for t in times])
    assert np.allclose(reference.positions, expected, atol=1e-6, rtol=0)
    h = 1e-6
    ahead = smoothed_reference(formation, profile, times + h, window)
    behind = smoothed_reference(formation, profile, times - h, window)
    slope = (ahead.positions - behind.positions) / (2 * h)
    assert np.allclose(reference.velocities, slope, atol=1e-4, rtol=0)
    # The acceleration, where no step of it is near (at random times).
    change = (ahead.velocities - behind.velocities)[: len(random)] / (2 * h)
    assert np.allclose(change, reference.accelerations[: len(random)], atol=1e-3, rtol=0)


@pytest.mark.parametrize("returns", [False, True])
def test_smoothed_reference_rests_on_the_slots(returns):
    formation = station_formation(ELL, CASES[1][1], returns, theta_a=30.0, theta_b=-45.0)
    profile = station_profile(formation)
    end = formation.duration(profile)
    reference = smoothed_reference(formation, profile, np.array([-2.5, end + 2.5]), 4.0)
    assert np.allclose(reference.positions[0], formation.start_slots)
    assert np.allclose(reference.positions[1], formation.goal_slots)
    assert np.allclose(reference.velocities, 0.0)
    # The hold: the middle of a 7 s pause is still for a window of 4 s.
    middle = float(profile.times[np.flatnonzero(profile.speeds == 0)[0]]) + 3.5
    held = smoothed_reference(formation, profile, [middle], 4.0)
    assert np.allclose(held.positions[0], formation.station_slots)
    assert np.allclose(held.velocities, 0.0)


@pytest.mark.parametrize("returns", [False, True])
@pytest.mark.parametrize("case", range(len(CASES)))
@pytest.mark.parametrize(("window", "hold"), [(0.7, 7.0), (2.5, 7.0), (6.0, 2.0), (6.0, 7.0)])
def test_smoothing_error_stays_within_the_bound(case, returns, window, hold):
    path, stations, theta_a, theta_b = CASES[case]
    formation = station_formation(path, stations, returns, theta_a=theta_a, theta_b=theta_b)
    profile = station_profile(formation, hold)
    end = formation.duration(profile)
    times = np.linspace(-window, end + window, 40_001)
    reference = smoothed_reference(formation, profile, times, window)
    error = norms(reference.positions - formation.positions(profile.distance(times)))
    bound = smoothing_error_bound(formation, profile, window)
    assert error.max() <= bound + 1e-9
    assert error.max() >= 0.45 * bound  # the bound is not vacuous


def test_a_hold_counts_one_stop_and_one_start():
    # Straight route, rows continuing it: every kink is a start or a stop, |dv| = v; the hold
    # of 10 s at S_out separates UAV 3's stop from its restart: v w / 8, attained.
    formation = station_formation(STRAIGHT, HAND_STATIONS, returns=True)
    profile = SpeedProfile.constant(5.0).with_pause(23.0, 10.0)
    window = 2.0
    assert smoothing_error_bound(formation, profile, window) == pytest.approx(5.0 * window / 8)
    times = np.linspace(-window, formation.duration(profile) + window, 40_001)
    reference = smoothed_reference(formation, profile, times, window)
    error = norms(reference.positions - formation.positions(profile.distance(times)))
    assert error.max() == pytest.approx(5.0 * window / 8, rel=1e-2)
    # Without the hold UAV 3 turns back at once: a jump of 2 v.
    constant = SpeedProfile.constant(5.0)
    assert smoothing_error_bound(formation, constant, window) == pytest.approx(10.0 * window / 8)


def test_safe_speed_counts_the_stops_and_the_turn_back():
    a_max, budget = 5.0, 2.5
    lone_start = math.sqrt(8 * a_max * budget)  # |dv| = v: v^2 / (8 a_max) <= budget
    outbound = station_formation(STRAIGHT, HAND_STATIONS)
    assert safe_speed(outbound, a_max, budget) == pytest.approx(lone_start, rel=1e-6)
    # Flying home at constant speed, UAV N turns back on its station: |dv| = 2 v.
    home = station_formation(STRAIGHT, HAND_STATIONS, returns=True)
    assert safe_speed(home, a_max, budget) == pytest.approx(lone_start / 2, rel=1e-6)


@pytest.mark.parametrize("returns", [False, True])
@pytest.mark.parametrize("case", [1, 2])
def test_safe_speed_and_window_keep_the_budget_and_the_acceleration(case, returns):
    path, stations, theta_a, theta_b = CASES[case]
    formation = station_formation(path, stations, returns, theta_a=theta_a, theta_b=theta_b)
    a_max, budget = 5.0, 2.0
    speed = safe_speed(formation, a_max, budget)
    window = recommended_window(speed, a_max, formation)
    profile = SpeedProfile.constant(speed)
    assert smoothing_error_bound(formation, profile, window) <= budget * (1 + 1e-6)
    times = np.linspace(-window, formation.duration(profile) + window, 40_001)
    reference = smoothed_reference(formation, profile, times, window)
    assert norms(reference.accelerations).max() <= a_max * (1 + 1e-6)
    error = norms(reference.positions - formation.positions(profile.distance(times)))
    assert error.max() <= budget * (1 + 1e-6)
    faster = speed * 1.02
    faster_window = recommended_window(faster, a_max, formation)
    assert smoothing_error_bound(formation, SpeedProfile.constant(faster), faster_window) > budget


# ----- validation ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("stations", "return_distance"),
    [
        ([70.0, 100.0, 35.0], None),  # not decreasing
        ([100.0, 70.0, 70.0], None),  # not strictly
        ([100.0, 70.0], None),  # wrong length
        ([100.0, 70.0, 35.0, 10.0], None),
        ([[100.0, 70.0, 35.0]], None),  # wrong shape
        ([100.1, 70.0, 35.0], None),  # beyond the path
        ([100.0, 70.0, 0.0], None),  # at A
        ([100.0, 70.0, -5.0], None),
        ([100.0, math.nan, 35.0], None),
        ([math.inf, 70.0, 35.0], None),
        (None, 115.0),  # a return without stations
        ([100.0, 70.0, 35.0], -1.0),  # a return before the start
        ([100.0, 70.0, 35.0], math.inf),
        ([100.0, 70.0, 35.0], True),
    ],
)
def test_bad_stations_are_refused(stations, return_distance):
    path = np.array(STRAIGHT)
    rows = parking_rows(path[0], path[-1], 0.0, 0.0, 3, 5.0)
    with pytest.raises(ValueError):
        LineFormation(path, 3, 5.0, 50.0, rows, stations, return_distance)


def test_a_return_before_the_hold_plays_the_flight_so_far_backwards():
    """Returning from M < S_out: V(M + x) = V(M - x), everyone ends on its start slot at 2 M,
    and nobody goes beyond where it was at M."""
    out = station_formation(ELL, [300.0, 260.0, 220.0, 180.0, 140.0, 100.0, 60.0, 20.0])
    early = 0.6 * out.outbound_distance
    home = out.with_return(early)
    x = np.linspace(0.0, early, 301)
    np.testing.assert_allclose(home.positions(early + x), home.positions(early - x), atol=1e-9)
    np.testing.assert_allclose(home.positions(early - x), out.positions(early - x), atol=1e-9)
    np.testing.assert_allclose(home.positions(2 * early + 5.0), out.start_slots, atol=1e-9)
    np.testing.assert_allclose(home.goal_slots, out.start_slots)
    assert home.total_distance == 2 * early
    reached = out.distance_beyond_start(early)
    assert np.all(home.distance_beyond_start(early + x) <= reached + 1e-9)


def test_stations_are_stored_read_only():
    formation = station_formation(STRAIGHT, (100, 70, 35))
    assert formation.stations.dtype == float
    with pytest.raises(ValueError):
        formation.stations[0] = 1.0
    plain = plain_twin(formation)
    assert plain.stations is None and plain.returning is False


def test_a_return_after_a_long_hold_mirrors_about_its_own_distance():
    """M beyond S_out (the fleet held while S kept growing): on station from S_out to M, then
    the outbound flight backwards, V(M + x) = V(M - x); the smoothed reference still matches
    the moving average across the turn."""
    out = station_formation(ELL, [300.0, 260.0, 220.0, 180.0, 140.0, 100.0, 60.0, 20.0])
    mirror = out.outbound_distance + 123.4
    home = out.with_return(mirror)
    held = np.linspace(out.outbound_distance, mirror, 50)
    np.testing.assert_allclose(
        home.positions(held), np.broadcast_to(out.station_slots, (50, 8, 2)), atol=1e-9
    )
    x = np.linspace(0.0, mirror, 401)
    np.testing.assert_allclose(home.positions(mirror + x), home.positions(mirror - x), atol=1e-9)
    profile = SpeedProfile.constant(5.0)
    window = 3.0
    times = np.linspace(mirror / 5.0 - 20.0, mirror / 5.0 + 20.0, 81)
    reference = smoothed_reference(home, profile, times, window)
    fine = np.linspace(-window / 2, window / 2, 3001)
    samples = home.positions(profile.distance(times[:, None] + fine[None, :]))
    average = np.trapezoid(samples, fine, axis=1) / window
    np.testing.assert_allclose(reference.positions, average, atol=1e-6)
