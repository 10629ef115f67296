"""Elastic spacing for line of sight (`planner.elastic`, `LineFormation.warp`): the UAVs close
up at the corners and spread out on the straights, one formation distance for the whole
fleet. Checked by an oracle that shares no code with `planner.sight` (shapely on every pair of
UAVs, networkx for the hops) at every 0.5 m of formation distance: every UAV reaches a base
station by line-of-sight links within rho_R, consecutive UAVs stay 2 rho_c apart and every UAV
rho_c from the buildings (theorems 3-5), and no UAV flies faster than the formation."""

from __future__ import annotations

import math

import networkx as nx
import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planner.elastic import elastic_warp
from planner.formation import DISTANCE_TOLERANCE, collision_spacing, radio_spacing
from planner.kinematics import LineFormation
from planner.scenarios import city_grid, random_buildings, scenario_problem
from planner.search import plan_path
from planner.sight import Sight
from tests.planner_maps import square


def elastic_formation(path, obstacles, rows, safety_margin, radio_range, fleet_size):
    """The elastic formation on `path` with the fleet it needs (grown with its rows), or None."""
    spacing_c = collision_spacing(safety_margin)
    spacing_r = radio_spacing(safety_margin, radio_range)
    size = fleet_size
    for _ in range(4):
        disk = LineFormation(path, size, safety_margin, radio_range, rows(size))
        row = (size - 1) * spacing_c
        warp = elastic_warp(
            disk.flown_polyline, Sight(obstacles), row, row + disk.path_length, spacing_r, spacing_c
        )
        if warp is None:
            return None
        if warp.fleet_size <= size:
            return LineFormation(
                path, size, safety_margin, radio_range, rows(size), warp=warp.knots
            )
        size = warp.fleet_size
    return None


def oracle_violations(formation: LineFormation, obstacles, radio_range: float, step=0.5):
    """Formation distances (every `step`) at which a guarantee breaks, by kind."""
    solid = shapely.union_all(
        [shapely.Polygon(p) for p in obstacles.polygons]
        + [shapely.LineString(w) for w in obstacles.walls]
    )
    shapely.prepare(solid)
    stations = formation.path[[0, -1]]
    rho = formation.safety_margin
    broken = {"cut off": [], "too close": [], "near a building": []}
    count = formation.fleet_size
    for distance in np.arange(0.0, formation.total_distance + step, step):
        xy = formation.positions(np.array([distance]))[0]
        nodes = np.vstack([xy, stations])
        i, j = np.triu_indices(len(nodes), 1)
        keep = (np.hypot(*(nodes[i] - nodes[j]).T) <= radio_range + 1e-6) & ~(
            (i >= count) & (j >= count)
        )
        i, j = i[keep], j[keep]
        lines = shapely.linestrings(np.stack([nodes[i], nodes[j]], axis=1))
        clear = ~shapely.intersects(lines, solid)
        graph = nx.Graph()
        graph.add_nodes_from(range(len(nodes)))
        graph.add_edges_from(zip(i[clear].tolist(), j[clear].tolist(), strict=True))
        reached = nx.node_connected_component(graph, count) | nx.node_connected_component(
            graph, count + 1
        )
        if not all(n in reached for n in range(count)):
            broken["cut off"].append(distance)
        a, b = np.triu_indices(count, 1)
        if count > 1 and np.hypot(*(xy[a] - xy[b]).T).min() < 2 * rho - 1e-6:
            broken["too close"].append(distance)
        if shapely.distance(shapely.points(xy), solid).min() < rho - 1e-6:
            broken["near a building"].append(distance)
    return {kind: at for kind, at in broken.items() if at}


def planned(scenario, radio_range: float = 220.0):
    problem = scenario_problem(scenario, radio_range=radio_range)
    plan = plan_path(problem)
    assert plan.valid, plan.reason
    return problem, plan


def test_the_elastic_formation_on_a_city_grid_keeps_every_guarantee_with_fewer_uavs():
    """A 4 x 3 city grid at rho_R = 120 m: the shortest path's corners allow a rigid spacing
    of a few tens of metres; the elastic formation needs about eq. 28's fleet and keeps
    every link clear, 2 rho_c between UAVs and rho_c from the buildings."""
    problem, plan = planned(city_grid(4, 3), radio_range=120.0)
    rho = problem.safety_margin
    formation = elastic_formation(
        plan.path, problem.obstacles, problem.rows, rho, 120.0, int(plan.fleet_size)
    )
    assert formation is not None
    spacing_r = radio_spacing(rho, 120.0)
    assert formation.fleet_size <= math.ceil(formation.formation_length / spacing_r) + 1
    assert formation.formation_length > formation.path_length  # it waits somewhere
    assert oracle_violations(formation, problem.obstacles, 120.0) == {}


def test_without_buildings_in_the_way_the_warp_is_the_identity():
    """A straight corridor past two blocks: nothing to close up for, so the formation is
    eq. 27's."""
    obstacles = shapely_free_blocks()
    path = np.array([[0.0, 0.0], [400.0, 0.0]])
    from planner.formation import parking_rows

    def rows(size):
        return parking_rows(path[0], path[-1], 0.0, 0.0, size, 5.0)

    formation = elastic_formation(path, obstacles, rows, 5.0, 120.0, 1)
    assert formation is not None
    assert len(formation.warp) == 2
    assert formation.formation_length == pytest.approx(formation.path_length)
    assert formation.fleet_size == math.ceil(400.0 / radio_spacing(5.0, 120.0))


def shapely_free_blocks():
    from planner.obstacles import Obstacles

    return Obstacles(polygons=(square(50.0, 20.0, 30.0), square(200.0, -60.0, 30.0)))


def test_a_warped_formation_never_flies_faster_than_the_formation():
    """dV_n/dS has length at most 1 everywhere: each UAV's speed is at most v (G' >= 1)."""
    problem, plan = planned(city_grid(3, 3), radio_range=120.0)
    formation = elastic_formation(
        plan.path, problem.obstacles, problem.rows, problem.safety_margin, 120.0, 2
    )
    assert formation is not None
    distances = np.linspace(0.0, formation.total_distance, 4001)
    speeds = np.hypot(*np.moveaxis(formation.directions(distances), -1, 0))
    assert speeds.max() <= 1.0 + 1e-9 and speeds.min() >= 0.0
    # and the positions are continuous: no step larger than the distance moved
    moved = np.hypot(*np.moveaxis(np.diff(formation.positions(distances), axis=0), -1, 0))
    assert moved.max() <= (distances[1] - distances[0]) * (1 + 1e-9)


@pytest.mark.parametrize(
    "knots",
    [
        [[0.0, 0.0], [100.0, 90.0], [200.0, 220.0]],  # slope below 1
        [[1.0, 0.0], [200.0, 220.0]],  # not from A
        [[0.0, 0.0], [150.0, 220.0]],  # not to B
    ],
)
def test_a_warp_that_would_make_a_uav_outrun_the_formation_is_refused(knots):
    from planner.formation import parking_rows

    path = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]])
    rows = parking_rows(path[0], path[-1], 180.0, 90.0, 3, 5.0)
    with pytest.raises(ValueError, match="warp"):
        LineFormation(path, 3, 5.0, 120.0, rows, warp=np.array(knots))


@settings(
    max_examples=12,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(seed=st.integers(0, 10_000), count=st.integers(6, 16))
def test_elastic_formations_on_random_maps_keep_every_guarantee(seed, count):
    scenario = random_buildings(count, seed=seed, size=500.0)
    problem = scenario_problem(scenario, radio_range=120.0)
    plan = plan_path(problem)
    if not plan.valid:
        return
    formation = elastic_formation(
        plan.path, problem.obstacles, problem.rows, problem.safety_margin, 120.0, 1
    )
    if formation is None:  # some sample sees back less than dS_c: no elastic formation
        return
    assert formation.formation_length >= formation.path_length - DISTANCE_TOLERANCE
    assert oracle_violations(formation, problem.obstacles, 120.0, step=1.0) == {}


def test_each_sample_sees_back_exactly_as_far_as_shapely_says():
    """`clear_gaps` against shapely one chord at a time: sample j sees every sample up to G_j
    behind it at the margin step / 2, and not the one G_j + 1 behind (when that one exists
    and is within the limit)."""
    from planner.sight import clear_gaps
    from tests.sight_checks import shapely_blocked

    problem, plan = planned(city_grid(3, 2), radio_range=120.0)
    polyline = plan.path
    polygons, walls = list(problem.obstacles.polygons), problem.obstacles.walls
    grid, gaps = clear_gaps(polyline, Sight(problem.obstacles), 60.0, step=2.0)
    arcs = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(polyline, axis=0).T))])
    points = np.column_stack([np.interp(grid, arcs, polyline[:, k]) for k in (0, 1)])
    most = int(np.ceil(60.0 / 2.0)) + 1
    assert (gaps < np.arange(len(grid))).any()  # some sample's view is cut by a corner
    for j in range(0, len(grid), 7):
        for g in range(1, int(gaps[j]) + 1):
            assert not shapely_blocked(polygons, walls, points[j - g], points[j], 1.0), (j, g)
        if gaps[j] < min(j, most):
            g = int(gaps[j]) + 1
            assert shapely_blocked(polygons, walls, points[j - g], points[j], 1.0), (j, g)
