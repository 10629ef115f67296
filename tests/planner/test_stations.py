"""Monitoring stations (docs/design.md 7): every layout `station_layout` returns keeps the station
rules, checked here from the rules themselves, with the fewest UAVs found by an independent dynamic
programme; every refusal is confirmed infeasible by it. `visit_order` is checked against brute
force and the nearest-neighbour route."""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planner.formation import min_radio_range
from planner.stations import (
    StationError,
    StationLayout,
    route_length,
    station_layout,
    visit_order,
)

TOL = 1e-6
SETTINGS = dict(
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)


def spacings(rho_c: float, rho_r: float) -> tuple[float, float]:
    """dS_c and dS_r written out from the paper (eqs. 9, 28), not taken from the planner."""
    return 2 * math.sqrt(2) * rho_c, rho_r - 2 * rho_c


def fewest_stations(gap: float, dsc: float, dsr: float) -> int | None:
    """Fewest stations in (d_{i-1}, d_i], the last on d_i, each at most dS_r and at least dS_c
    after the one before: c steps reach exactly [c dS_c, c dS_r] (dynamic programme over c,
    interval by interval); None when no count reaches `gap`."""
    lo = hi = 0.0
    count = 0
    while lo <= gap + TOL:
        count, lo, hi = count + 1, lo + dsc, hi + dsr
        if lo - TOL <= gap <= hi + TOL:
            return count
    return None


def rule_breaches(layout: StationLayout, d: np.ndarray, dsc: float, dsr: float) -> list:
    """The station rules of docs/design.md 7, one by one."""
    s, n = layout.stations, layout.fleet_size
    errors = []
    if len(s) != n or len(layout.relays) != n or len(layout.holders) != len(d):
        errors.append("shapes")
        return errors
    steps = -np.diff(s)
    if not (steps > 0).all():
        errors.append("not decreasing")
    if not ((steps >= dsc - TOL) & (steps <= dsr + TOL)).all():
        errors.append(("spacing", steps))
    if not dsc - TOL <= s[-1] <= dsr + TOL:
        errors.append(("last station", s[-1]))
    if not (np.abs(s[layout.holders - 1] - d) <= 1e-9).all():
        errors.append("point off its station")
    if layout.holders[-1] != 1 or not (np.diff(layout.holders) < 0).all():
        errors.append(("holders", layout.holders))
    holding = np.isin(np.arange(1, n + 1), layout.holders)
    if not np.array_equal(layout.relays, ~holding) or layout.relays.sum() != n - len(d):
        errors.append("relays")
    return errors


radii = st.tuples(
    st.floats(0.5, 20.0),  # rho_c
    st.floats(1.0, 4.0),  # rho_R as a multiple of its least value (eq. 9)
)
gap_kinds = st.tuples(
    st.sampled_from(["uniform", "dsr", "dsc"]), st.floats(0.0, 4.0), st.integers(1, 4)
)


def gap_value(kind: tuple, dsc: float, dsr: float) -> float:
    """A gap of one kind: anywhere up to 4 dS_r, or exactly k dS_r, or exactly k dS_c."""
    name, u, k = kind
    return {"uniform": u * dsr, "dsr": k * dsr, "dsc": k * dsc}[name]


@settings(max_examples=400, **SETTINGS)
@given(radii, st.lists(gap_kinds, min_size=1, max_size=6))
def test_layouts_keep_the_rules_with_the_fewest_uavs(radius, kinds):
    rho_c = radius[0]
    rho_r = radius[1] * min_radio_range(rho_c)
    dsc, dsr = spacings(rho_c, rho_r)
    gaps = np.array([gap_value(k, dsc, dsr) for k in kinds])
    d = np.cumsum(gaps)
    gaps = np.diff(d, prepend=0.0)  # the gaps as the layout sees them
    fewest = [fewest_stations(float(g), dsc, dsr) for g in gaps]
    try:
        layout = station_layout(d, rho_c, rho_r)
    except StationError as e:
        assert fewest[e.point] is None, (e, fewest)
        assert None not in fewest[: e.point]  # the first gap that cannot be split
        assert str(e).startswith(f"point {e.point} is ")
        assert_message_consistent(str(e))
        return
    assert rule_breaches(layout, d, dsc, dsr) == []
    assert layout.fleet_size == sum(fewest)


def assert_message_consistent(message: str) -> None:
    """The numbers compared in a refusal read the way they compare (no rounding onto a limit)."""
    number = r"(-?[\d.e+-]+)"
    one = re.fullmatch(
        rf"point \d+ is {number} m along the route from (A|point \d+); stations must be at"
        rf" least dS_c = {number} m apart",
        message,
    )
    if one:
        assert float(one[1]) < float(one[3]), message
        return
    many = re.fullmatch(
        rf"point \d+ is {number} m along the route from (A|point \d+), more than (?:\d+ x )?"
        rf"dS_r = {number} m, so it needs (\d+) stations, and \d+ stations at least dS_c ="
        rf" {number} m apart need {number} m",
        message,
    )
    assert many, message
    gap, split, floor = float(many[1]), float(many[3]), float(many[6])
    assert split < gap < floor, message


@settings(max_examples=200, **SETTINGS)
@given(radii, st.floats(0.0, 1000.0))
def test_one_point_against_the_dynamic_programme(radius, distance):
    rho_c = radius[0]
    rho_r = radius[1] * min_radio_range(rho_c)
    dsc, dsr = spacings(rho_c, rho_r)
    fewest = fewest_stations(distance, dsc, dsr)
    if fewest is None:
        with pytest.raises(StationError):
            station_layout(np.array([distance]), rho_c, rho_r)
    else:
        layout = station_layout(np.array([distance]), rho_c, rho_r)
        assert rule_breaches(layout, np.array([distance]), dsc, dsr) == []
        assert layout.fleet_size == fewest


def test_layout_example():
    # rho_c = 5, rho_R = 220: dS_c = 14.14 m, dS_r = 210 m.
    layout = station_layout(np.array([50.0, 100.0, 350.0]), 5.0, 220.0)
    assert layout.fleet_size == 4
    np.testing.assert_array_equal(layout.stations, [350.0, 225.0, 100.0, 50.0])
    np.testing.assert_array_equal(layout.holders, [4, 3, 1])
    np.testing.assert_array_equal(layout.relays, [False, True, False, False])


def test_exact_multiple_of_radio_spacing_takes_no_extra_uav():
    layout = station_layout(np.array([210.0, 630.0]), 5.0, 220.0)
    assert layout.fleet_size == 3
    np.testing.assert_allclose(layout.stations, [630.0, 420.0, 210.0])


@pytest.mark.parametrize(
    ("distances", "rho_c", "rho_r", "point", "message"),
    [
        (
            [4.2],
            5.0,
            220.0,
            0,
            "point 0 is 4.2 m along the route from A; stations must be at least dS_c = 14.1 m"
            " apart",
        ),
        (
            [50.0, 64.14],
            5.0,
            220.0,
            1,
            "point 1 is 14.14 m along the route from point 0; stations must be at least"
            " dS_c = 14.142 m apart",
        ),
        (
            [100.0, 230.0],
            25.0,
            150.0,
            1,
            "point 1 is 130 m along the route from point 0, more than dS_r = 100 m, so it needs"
            " 2 stations, and 2 stations at least dS_c = 70.7 m apart need 141 m",
        ),
        (
            [230.0],
            30.0,
            160.0,
            0,
            "point 0 is 230 m along the route from A, more than 2 x dS_r = 200 m, so it needs"
            " 3 stations, and 3 stations at least dS_c = 84.9 m apart need 255 m",
        ),
        (
            [50.0, 50.0],
            5.0,
            220.0,
            1,
            "point 1 is 0 m along the route from point 0; stations must be at least dS_c ="
            " 14.1 m apart",
        ),
    ],
)
def test_refusals_name_the_gap(distances, rho_c, rho_r, point, message):
    with pytest.raises(StationError) as caught:
        station_layout(np.array(distances), rho_c, rho_r)
    assert caught.value.point == point
    assert str(caught.value) == message
    assert isinstance(caught.value, ValueError)


@pytest.mark.parametrize(
    ("distances", "rho_c", "rho_r"),
    [([], 5.0, 220.0), ([10.0, 5.0], 5.0, 220.0), ([np.nan], 5.0, 220.0), ([50.0], 5.0, 10.0)],
)
def test_bad_input_is_a_plain_value_error(distances, rho_c, rho_r):
    with pytest.raises(ValueError) as caught:
        station_layout(np.array(distances, float), rho_c, rho_r)
    assert not isinstance(caught.value, StationError)


# ---------------------------------------------------------------- visit order


def brute_force_length(start: np.ndarray, points: np.ndarray) -> float:
    return min(
        sum(math.dist(a, b) for a, b in itertools.pairwise([start, *points[list(p)]]))
        for p in itertools.permutations(range(len(points)))
    )


def nearest_neighbour_length(start: np.ndarray, points: np.ndarray) -> float:
    here, left, total = start, list(range(len(points))), 0.0
    while left:
        nearest = min(left, key=lambda i: math.dist(here, points[i]))
        total += math.dist(here, points[nearest])
        here = points[nearest]
        left.remove(nearest)
    return total


coords = st.floats(-1000.0, 1000.0)
point_sets = st.integers(0, 7).flatmap(
    lambda m: st.lists(st.tuples(coords, coords), min_size=m, max_size=m)
)


@settings(max_examples=120, **SETTINGS)
@given(st.tuples(coords, coords), point_sets)
def test_tsp_order_is_exact_for_few_points(start, points):
    start, points = np.array(start), np.array(points, float).reshape(-1, 2)
    order = visit_order(start, points)
    assert sorted(order.tolist()) == list(range(len(points)))
    best = brute_force_length(start, points)
    assert route_length(start, points, order) <= best + 1e-9 * max(1.0, best)
    np.testing.assert_array_equal(visit_order(start, points), order)


@settings(max_examples=25, **SETTINGS)
@given(
    st.tuples(coords, coords),
    st.integers(9, 24).flatmap(
        lambda m: st.lists(st.tuples(coords, coords), min_size=m, max_size=m)
    ),
)
def test_tsp_order_for_many_points_beats_nearest_neighbour(start, points):
    start, points = np.array(start), np.array(points, float)
    order = visit_order(start, points)
    assert sorted(order.tolist()) == list(range(len(points)))
    assert route_length(start, points, order) <= nearest_neighbour_length(start, points) + 1e-9
    np.testing.assert_array_equal(visit_order(start, points), order)


def test_sixteen_points():
    rng = np.random.default_rng(7)
    start, points = np.array([200.0, 200.0]), rng.uniform(0, 2000, (16, 2))
    order = visit_order(start, points)
    assert sorted(order.tolist()) == list(range(16))
    assert route_length(start, points, order) <= nearest_neighbour_length(start, points)
    np.testing.assert_array_equal(visit_order(start.copy(), points.copy()), order)


def test_points_on_a_line_are_visited_outwards():
    points = np.array([[30.0, 0.0], [10.0, 0.0], [20.0, 0.0]])
    np.testing.assert_array_equal(visit_order(np.zeros(2), points), [1, 2, 0])
    line = np.column_stack([np.arange(12.0, 0.0, -1.0), np.zeros(12)])
    np.testing.assert_array_equal(visit_order(np.zeros(2), line), np.arange(11, -1, -1))


def test_given_order_is_the_list():
    points = np.array([[30.0, 0.0], [10.0, 0.0], [20.0, 0.0]])
    np.testing.assert_array_equal(visit_order(np.zeros(2), points, "given"), [0, 1, 2])
    assert route_length(np.zeros(2), points, visit_order(np.zeros(2), points, "given")) == 60.0
    with pytest.raises(ValueError):
        visit_order(np.zeros(2), points, "shortest")
