"""Theorems 3-5 for monitoring stations (docs/design.md 7), sampled: on random maps with 1-8 points,
the route planned through them and its stations, flown with eq. 27 capped at each station,
held, and flown home (the return decided at a random formation distance, during the hold or
before everyone is on station), keeps every sampled instant at least 2 rho_c between UAVs,
rho_c from every obstacle and every UAV chained by radio to A, and ends with everyone on its
parking slot at A."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, assume, event, given, note, settings
from hypothesis import strategies as st

from planner.formation import DISTANCE_TOLERANCE, collision_spacing
from planner.guarantees import check_positions
from planner.kinematics import LineFormation, SpeedProfile
from planner.route import plan_route
from tests.planner_maps import route_maps

SAMPLE_RATE_HZ = 10.0


@settings(
    max_examples=80,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow],
)
@given(
    route_maps(),
    st.floats(0.3, 1.6),
    st.lists(st.floats(4.0, 12.0), min_size=3, max_size=3),
    st.floats(0.1, 0.9),
)
def test_station_formations_keep_the_guarantees_out_on_station_and_home(
    problem, return_fraction, speeds, change_fraction
):
    points = problem.points
    rho = problem.safety_margin
    apart = np.hypot(*(points[:, None] - points[None]).T)
    np.fill_diagonal(apart, np.inf)
    assume(apart.min() > 2 * collision_spacing(rho))
    assume(np.all(np.hypot(*(points - problem.start).T) > 2 * collision_spacing(rho)))
    if len(problem.obstacles):
        assume(np.all(problem.obstacles.distance_to_points(points) > rho + DISTANCE_TOLERANCE))
    plan = plan_route(problem)
    assume(plan.valid)
    rows = plan.rows
    # eq. 14, the mission's precondition (refused before planning): Delta_A clear of obstacles
    assume(
        problem.obstacles.distance_to_segments(rows.start_row[None]).min()
        >= rho - DISTANCE_TOLERANCE
        if len(problem.obstacles)
        else True
    )
    out = LineFormation(
        path=plan.path,
        fleet_size=plan.fleet_size,
        safety_margin=rho,
        radio_range=problem.radio_range,
        rows=rows,
        stations=plan.layout.stations,
    )
    mirror = return_fraction * out.outbound_distance
    home = out.with_return(mirror)
    nominal = mirror / speeds[0]
    profile = SpeedProfile.from_changes(
        speeds[0], [(change_fraction * nominal, speeds[1]), (1.1 * nominal, speeds[2])]
    )
    duration = home.duration(profile)
    assert math.isfinite(duration)
    crossings = home.threshold_times(profile).ravel()
    times = np.union1d(np.arange(0.0, duration + 0.1, 1.0 / SAMPLE_RATE_HZ), crossings)
    positions = home.positions(profile.distance(times))
    samples = check_positions(
        positions, problem.obstacles, problem.start[None], problem.radio_range
    )
    event("returned from the hold" if return_fraction >= 1 else "returned early")
    event(f"points: {len(points)}")
    note(f"N={home.fleet_size} stations={plan.layout.stations.tolist()} {samples.summary()}")
    assert samples.min_uav_uav_m.min() >= 2 * rho - 1e-6
    assert samples.min_uav_obstacle_m.min() >= rho - 1e-6
    assert samples.connected.all()
    np.testing.assert_allclose(positions[-1], home.start_slots, atol=1e-6)
    if return_fraction >= 1:  # everyone held its station before the return
        at_hold = home.positions(out.outbound_distance)
        np.testing.assert_allclose(at_hold, out.station_slots, atol=1e-6)
