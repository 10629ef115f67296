"""Issue 2, "Done when": planned formations keep theorems 3-5 on sampled virtual trajectories.

For random maps (hypothesis) the planner's path, flown as the line formation of eq. 27 with
speed changes that include zero-speed stretches, is sampled at 10 Hz over the whole mission
(plus every threshold crossing, where the bends are) and checked: >= 2 rho_c between UAVs,
>= rho_c to obstacles, every UAV with a multi-hop radio path to A or B.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from hypothesis import HealthCheck, assume, event, given, note, settings
from hypothesis import strategies as st

from planner.formation import DISTANCE_TOLERANCE, min_radio_range
from planner.guarantees import check_positions
from planner.kinematics import LineFormation, SpeedProfile
from planner.obstacles import Obstacles
from planner.search import plan_path
from planner.types import PathProblem
from tests.planner_maps import rectangle

SAMPLE_RATE_HZ = 10.0


@st.composite
def missions(draw):
    """A 400 m x 300 m map: A on the left, B on the right, up to 6 rectangles in between."""
    safety_margin = draw(st.floats(2.0, 6.0))
    radio_range = draw(st.floats(min_radio_range(safety_margin) + 1.0, 120.0))
    start = np.array([draw(st.floats(0.0, 40.0)), draw(st.floats(0.0, 300.0))])
    goal = np.array([draw(st.floats(360.0, 400.0)), draw(st.floats(0.0, 300.0))])
    count = draw(st.integers(0, 7))
    middle = (start + goal) / 2
    blocker = rectangle(  # across the straight line A-B, so that most paths bend
        middle + [draw(st.floats(-20.0, 20.0)), draw(st.floats(-20.0, 20.0))],
        (draw(st.floats(5.0, 60.0)), draw(st.floats(40.0, 160.0))),
        draw(st.floats(-30.0, 30.0)) + math.degrees(math.atan2(*(goal - start)[::-1])),
    )
    polygons = (blocker,) + tuple(
        rectangle(
            (draw(st.floats(80.0, 320.0)), draw(st.floats(0.0, 300.0))),
            (draw(st.floats(5.0, 80.0)), draw(st.floats(5.0, 120.0))),
            draw(st.floats(0.0, 90.0)),
        )
        for _ in range(count)
    )
    walls = np.array(
        [
            [[draw(st.floats(80.0, 320.0)), draw(st.floats(0.0, 300.0))] for _ in range(2)]
            for _ in range(draw(st.integers(0, 2)))
        ]
    ).reshape(-1, 2, 2)
    problem = PathProblem(
        start=start,
        goal=goal,
        start_angle_deg=draw(st.floats(-60.0, 60.0)),
        goal_angle_deg=draw(st.floats(-60.0, 60.0)),
        safety_margin=safety_margin,
        radio_range=radio_range,
        obstacles=Obstacles(polygons=polygons, walls=walls),
        fleet_size=None,
    )
    extra_uavs = draw(st.integers(0, 2))
    # Speeds: an initial one, a stop, a restart, a change; times as fractions of the mission.
    speeds = [
        draw(st.floats(2.0, 15.0)),
        0.0,
        draw(st.floats(1.0, 15.0)),
        draw(st.floats(1.0, 15.0)),
    ]
    fractions = np.cumsum(draw(st.lists(st.floats(0.05, 0.3), min_size=3, max_size=3))).tolist()
    pause = draw(st.floats(0.5, 20.0))
    return problem, extra_uavs, speeds, fractions, pause


def profile_for(formation, speeds, fractions, pause):
    """Speed changes placed along the mission flown at the initial speed, with a stop of `pause`."""
    nominal = formation.duration(SpeedProfile.constant(speeds[0]))
    stop, restart, change = (f * nominal for f in fractions)
    restart = max(restart, stop + pause)
    change = max(change, restart + 1.0)
    return SpeedProfile.from_changes(
        speeds[0], [(stop, speeds[1]), (restart, speeds[2]), (change, speeds[3])]
    )


@settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow],
)
@given(missions())
def test_planned_formations_keep_the_guarantees_when_sampled(mission):
    problem, extra_uavs, speeds, fractions, pause = mission
    plan = plan_path(problem)
    assume(plan.valid)
    if extra_uavs:  # a user asking for more UAVs than eq. 28 (rows grow, so re-plan)
        problem = dataclasses.replace(problem, fleet_size=plan.min_fleet_size + extra_uavs)
        plan = plan_path(problem)
        assume(plan.valid)
        assert plan.fleet_size == problem.fleet_size
    obstacles = problem.obstacles
    rows = plan.rows
    # Eqs. 14-15 are the mission's preconditions (refused before planning): skip maps breaking them.
    assume(
        np.all(
            obstacles.distance_to_segments(np.array([rows.start_row, rows.goal_row]))
            >= problem.safety_margin - DISTANCE_TOLERANCE
        )
    )
    formation = LineFormation(
        path=plan.path,
        fleet_size=plan.fleet_size,
        safety_margin=problem.safety_margin,
        radio_range=problem.radio_range,
        rows=rows,
    )
    profile = profile_for(formation, speeds, fractions, pause)
    duration = formation.duration(profile)
    assert math.isfinite(duration)
    crossings = formation.threshold_times(profile).ravel()
    times = np.union1d(
        np.arange(0.0, duration + 1.0 / SAMPLE_RATE_HZ, 1.0 / SAMPLE_RATE_HZ), crossings
    )
    positions = formation.positions(profile.distance(times))
    samples = check_positions(
        positions, obstacles, np.array([problem.start, problem.goal]), problem.radio_range
    )
    event(f"path points: {min(len(plan.path), 6)}{'+' if len(plan.path) > 6 else ''}")
    note(f"path={plan.path.tolist()} N={formation.fleet_size} summary={samples.summary()}")
    rho_c = problem.safety_margin
    assert samples.min_uav_uav_m.min() >= 2 * rho_c - 1e-6
    assert samples.min_uav_obstacle_m.min() >= rho_c - 1e-6
    assert samples.connected.all()
    # The mission really ended: everyone parked on the arrival row.
    assert np.allclose(positions[-1], formation.goal_slots)
