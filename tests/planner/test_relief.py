"""Relief of one UAV on a monitoring-station chain (`planner.relief`), pure.

The layout rule (the gap keeps its point, re-spaced evenly without the UAV, refused when the
gap holds the fewest UAVs already), the minimum-jerk motions, and whole manoeuvres on a
planned mission checked independently at every sampled instant: 3-D distances >= 2 rho_c,
every UAV chained to A through links <= dS_r, everyone ending where the formation of the
UAVs left on station holds them.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.mission import load_mission
from gcs.planning import plan_json, plan_mission
from planner.formation import collision_spacing, radio_spacing
from planner.relief import Motion, ReliefRefused, plan_relief, relief_layout
from planner.stations import station_layout
from tests.conftest import EXAMPLES, MISSIONS

RHO, RADIO = 5.0, 100.0
DSC, DSR = collision_spacing(RHO), radio_spacing(RHO, RADIO)


def test_a_relay_leaves_and_its_gap_closes_evenly_on_the_same_point():
    # two points at 100 and 250 m; 5 UAVs: gap 1 (0-100) holds 2, gap 2 (100-250) holds 3
    layout = station_layout(np.array([100.0, 250.0]), RHO, RADIO, fleet_size=5)
    assert layout.stations.tolist() == pytest.approx([250, 200, 150, 100, 50])
    after = relief_layout(layout.stations, [100.0, 250.0], 2, RHO, RADIO, ("a", "b"))
    assert after.stations[1] != after.stations[1]  # NaN: relieved
    assert after.stations[[0, 2, 3, 4]].tolist() == pytest.approx([250, 175, 100, 50])
    assert after.members.tolist() == [1, 3, 4, 5] and after.holders.tolist() == [4, 1]
    assert after.gap == 1


def test_a_holder_leaves_and_the_uav_behind_it_takes_its_point():
    layout = station_layout(np.array([100.0, 250.0]), RHO, RADIO, fleet_size=5)
    after = relief_layout(layout.stations, [100.0, 250.0], 1, RHO, RADIO, ("a", "b"))
    assert after.stations[1:].tolist() == pytest.approx([250, 175, 100, 50])
    assert after.holders.tolist() == [4, 2]


def test_a_gap_that_holds_the_fewest_uavs_refuses_with_the_numbers():
    layout = station_layout(np.array([100.0, 250.0]), RHO, RADIO, fleet_size=5)
    with pytest.raises(ReliefRefused) as refused:
        relief_layout(layout.stations, [100.0, 250.0], 5, RHO, RADIO, ("a", "b"))
    text = str(refused.value)
    assert "UAV 5 cannot leave" in text and "between A and 'a' (100.00 m)" in text
    assert "100.00 m apart, more than dS_r = 90.00 m" in text and "fleet.size" in text
    with pytest.raises(ReliefRefused, match="no UAV left on it"):
        relief_layout(np.array([50.0]), [50.0], 1, RHO, RADIO)
    with pytest.raises(ReliefRefused, match="there is no UAV 6"):
        relief_layout(layout.stations, [100.0, 250.0], 6, RHO, RADIO)
    gone = layout.stations.copy()
    gone[1] = np.nan
    with pytest.raises(ReliefRefused, match="UAV 2 was relieved already"):
        relief_layout(gone, [100.0, 250.0], 2, RHO, RADIO)


@settings(max_examples=200, deadline=None)
@given(
    gaps=st.lists(st.floats(20.0, 400.0), min_size=1, max_size=5),
    extra=st.integers(0, 6),
    pick=st.integers(0, 1000),
)
def test_every_relief_keeps_the_station_rules_or_is_refused_rightly(gaps, extra, pick):
    """Stations decreasing, consecutive ones dS_c to dS_r apart, the last within dS_r of A,
    one on every point; refused exactly when the UAV's gap would need more than dS_r."""
    points = np.cumsum(gaps)
    try:
        minimum = station_layout(points, RHO, RADIO).fleet_size
        layout = station_layout(points, RHO, RADIO, fleet_size=minimum + extra)
    except ValueError:
        return  # a gap too short for its stations, or more UAVs than fit: not this test's
    uav = pick % layout.fleet_size + 1
    s = layout.stations
    gap = int(np.searchsorted(points + 1e-6, s[uav - 1]))
    count = int(np.count_nonzero((s > (points[gap - 1] if gap else 0.0) + 1e-6)
                                 & (s <= points[gap] + 1e-6)))  # fmt: skip
    length = gaps[gap]
    fits = count > 1 and length / (count - 1) <= DSR + 1e-6
    try:
        after = relief_layout(s, points, uav, RHO, RADIO)
    except ReliefRefused:
        assert not fits
        return
    assert fits
    kept = after.stations[after.members - 1]
    assert len(kept) == layout.fleet_size - 1 and np.isnan(after.stations[uav - 1])
    steps = -np.diff(np.concatenate([kept, [0.0]]))
    assert (steps >= DSC - 1e-6).all() and (steps <= DSR + 1e-6).all()
    for point, holder in zip(points, after.holders, strict=True):
        assert after.stations[holder - 1] == pytest.approx(point)
    outside = np.isfinite(s) & ~np.isin(np.arange(len(s)), np.flatnonzero(
        (s > (points[gap - 1] if gap else 0.0) + 1e-6) & (s <= points[gap] + 1e-6)))  # fmt: skip
    assert after.stations[outside] == pytest.approx(s[outside])  # other gaps stay


def test_a_motion_stops_on_every_waypoint_within_its_speed_and_acceleration():
    points = np.array([[0.0, 0.0, 0.0], [30.0, 0.0, 0.0], [30.0, 40.0, 0.0], [30.0, 40.0, 9.0]])
    motion = Motion.through(points, 10.0, speed=4.0, max_acceleration=2.0)
    times = np.linspace(5.0, motion.end_s + 5.0, 20001)
    position, velocity, acceleration = motion.state(times)
    assert np.linalg.norm(velocity, axis=1).max() <= 4.0 + 1e-9
    assert np.linalg.norm(acceleration, axis=1).max() <= 2.0 + 1e-6
    ends = np.concatenate([motion.starts, [motion.end_s]])
    p, v, _ = motion.state(ends)
    assert p == pytest.approx(points) and np.abs(v).max() < 1e-12
    assert position[0] == pytest.approx(points[0]) and position[-1] == pytest.approx(points[-1])
    # the velocity is the derivative of the position
    step = times[1] - times[0]
    numeric = np.gradient(position, step, axis=0)
    assert np.abs(numeric - velocity)[1:-1].max() < 1e-3
    # between waypoints it stays on the segment (never cuts a corner)
    assert ((position[:, 0] >= -1e-9) & (position[:, 0] <= 30 + 1e-9)).all()


@pytest.fixture(scope="module")
def planned():
    return plan_mission(load_mission(MISSIONS / "stations-relief.yaml"))


@pytest.mark.parametrize("uav", [1, 2, 3, 4, 5])
def test_a_whole_relief_keeps_every_guarantee_at_every_sampled_instant(planned, uav):
    formation, route = planned.formation, planned.route
    base = np.array(planned.mission.base_station_points)
    plan = plan_relief(
        formation, formation.stations, route.point_distance, uav, 50.0, 6.0, 4.0, base,
        climb_speed=2.5,
    )  # fmt: skip
    xy = formation.station_slots
    times = np.arange(plan.start_s - 1.0, plan.home_s + 1.0, 0.05)
    positions = plan.positions(times, xy)  # (T, N, 3)
    # 3-D distances between UAVs, independently of the planner's check
    gap = positions[:, :, None, :] - positions[:, None, :, :]
    distance = np.linalg.norm(gap, axis=3)
    distance[:, np.arange(5), np.arange(5)] = np.inf
    assert distance.min() >= 2 * RHO - 1e-6
    # every UAV chained to A (links <= dS_r, 3-D between UAVs, horizontal to A)
    for k in range(0, len(times), 7):
        reached = np.linalg.norm(positions[k, :, :2] - base[0], axis=1) <= DSR + 1e-6
        while True:
            more = reached | (distance[k][:, reached] <= DSR + 1e-6).any(axis=1)
            if (more == reached).all():
                break
            reached = more
        assert reached.all(), (uav, times[k])
    # the relieved UAV climbed dS_c, and ends above its landing slot, the last of the row
    lane = positions[:, uav - 1, 2]
    assert lane.max() == pytest.approx(DSC)
    end = plan.relieved.state(plan.home_s)[0]
    assert end[:2] == pytest.approx(formation.start_slots[-1]) and end[2] == pytest.approx(DSC)
    # everyone left ends where the formation of one UAV fewer holds them at the hold
    members = plan.layout.members
    fewer = replace(formation, fleet_size=len(members), stations=plan.layout.stations[members - 1])
    final = plan.positions(plan.home_s, xy)[members - 1, :2]
    assert final == pytest.approx(fewer.positions(formation.outbound_distance), abs=1e-9)
    assert plan.min_separation_m >= 2 * RHO


def test_a_start_row_beyond_radio_reach_refuses_the_relief():
    """tests/missions/stations.yaml with 6 UAVs: the last slot of the start row is 70.7 m from
    A, beyond dS_r = 50 m; the relieved UAV would land out of the chain's reach."""
    mission = load_mission(MISSIONS / "stations.yaml")
    planned = plan_mission(replace(mission, fleet=replace(mission.fleet, size=6)))
    formation, route = planned.formation, planned.route
    with pytest.raises(ReliefRefused, match=r"UAV 3 would land .* is 70.71 m from"):
        plan_relief(
            formation, formation.stations, route.point_distance, 3, 50.0, 6.0, 4.0,
            np.array(planned.mission.base_station_points),
        )  # fmt: skip
    assert math.isfinite(formation.stations[2])


def test_the_plan_json_names_the_uavs_that_can_be_relieved(planned):
    stations = plan_json(planned)["stations"]
    assert stations["relievable"] == [1, 2, 3, 4, 5] and stations["relieve_below_pct"] is None
    fewest = plan_json(plan_mission(load_mission(MISSIONS / "stations.yaml")))["stations"]
    assert fewest["relievable"] == []


def test_the_relief_example_plans_with_uavs_to_spare():
    """examples/relief.yaml: 11 UAVs where 9 would do; UAVs 5-11 can be relieved, the small
    battery (UAV 6) among them."""
    plan = plan_mission(load_mission(EXAMPLES / "relief.yaml"))
    stations = plan_json(plan)["stations"]
    assert plan.formation.fleet_size == 11
    assert stations["relievable"] == [5, 6, 7, 8, 9, 10, 11]
    assert stations["relieve_below_pct"] == 50
    assert plan.mission.sim.battery_capacities(11)[5] < plan.mission.sim.battery_capacities(11)[0]
