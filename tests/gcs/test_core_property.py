"""Property: random feasible missions, flown by the ground-station core in the fast mode, keep
every guarantee the plan promises (tracking error below rho_c, the distances that follow from
it, every UAV chained to a base station) and land every UAV on its slot."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gcs.mission import parse_mission
from gcs.planning import plan_mission
from gcs.sim.fastsim import FastOptions, fly_fast


@st.composite
def missions(draw):
    rho = draw(st.sampled_from([3.0, 4.0, 5.0]))
    length = draw(st.floats(90.0, 140.0))
    heading = draw(st.floats(-math.pi, math.pi))
    goal = [length * math.cos(heading), length * math.sin(heading)]
    middle = np.array(goal) / 2
    side = np.array([-goal[1], goal[0]]) / length  # to the left of A->B
    offset = draw(st.floats(-25.0, 25.0))
    center = middle + side * offset
    data = {
        "version": 1,
        "name": "property",
        "start": {"x": 0.0, "y": 0.0, "theta_deg": draw(st.sampled_from([0, 30, -30]))},
        "goal": {"x": goal[0], "y": goal[1], "theta_deg": draw(st.sampled_from([0, 45, -45]))},
        "safety_margin": rho,
        "radio_range": draw(st.floats(2 * (1 + math.sqrt(2)) * rho + 5, 80.0)),
        "altitude": draw(st.sampled_from([8.0, 12.0])),
        "speed": {"max": draw(st.floats(4.0, 8.0)), "cap_to_safe": True},
        "vehicle": {"max_speed": 12, "max_acceleration": 8, "radius": 0.5},
        "obstacles": [{"rectangle": {"center": center.tolist(), "size": [20, 20]}}],
        "sim": {"seed": draw(st.integers(0, 1000))},
    }
    return parse_mission(data, Path("property.yaml"))


@settings(
    max_examples=3,
    derandomize=True,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(missions())
def test_random_feasible_missions_flown_through_the_core_keep_the_guarantees(mission):
    plan = plan_mission(mission)
    if not plan.valid:  # an infeasible draw (an end inside the obstacle's margin...)
        return
    flown = fly_fast(plan, FastOptions(uav_data_bps=None))
    run = flown.run_json
    rho = mission.safety_margin
    assert run["completed"] is True, run["reason"]
    assert run["max_tracking_error_m"] < rho
    tracking = run["max_tracking_error_m"]
    assert run["min_uav_uav_m"] >= 2 * rho - 2 * tracking - 1e-6
    assert run["min_uav_obstacle_m"] >= rho - tracking - 1e-6
    assert run["connected_fraction"] == 1.0
    assert flown.checks.connected.all()  # the true positions, every 0.1 s
    final = flown.positions[-1]
    assert np.hypot(*(final[:, :2] - flown.formation.goal_slots).T).max() < rho
