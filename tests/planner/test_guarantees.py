"""Sampled guarantee checks (planner.guarantees) on hand-made configurations."""

from __future__ import annotations

import math

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import planner.guarantees as guarantees
from planner.guarantees import check_positions
from planner.obstacles import Obstacles

NONE = Obstacles()
SQUARE = Obstacles(polygons=(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]),))


def test_pairwise_and_obstacle_distances():
    positions = np.array(
        [
            [[13.0, 5.0], [16.0, 9.0], [40.0, 40.0]],  # 3 from the square; a 3-4-5 pair
            [[5.0, 5.0], [30.0, 5.0], [30.0, 6.5]],  # one inside the (solid) square
        ]
    )
    result = check_positions(positions, SQUARE, np.array([[20.0, 5.0]]), 100.0)
    assert np.allclose(result.min_uav_uav_m, [5.0, 1.5])
    assert np.allclose(result.min_uav_obstacle_m, [3.0, 0.0])
    walls = Obstacles(walls=np.array([[[0.0, 20.0], [100.0, 20.0]]]))
    assert np.allclose(
        check_positions(positions, walls, np.zeros((1, 2)), 100.0).min_uav_obstacle_m, [11.0, 13.5]
    )


def test_without_obstacles_or_partners_the_minima_are_infinite():
    result = check_positions(np.zeros((4, 1, 2)), NONE, np.zeros((1, 2)), 1.0)
    assert np.all(np.isinf(result.min_uav_uav_m)) and np.all(np.isinf(result.min_uav_obstacle_m))
    summary = result.summary()
    assert summary["min_uav_uav_m"] is None and summary["min_uav_obstacle_m"] is None
    assert summary["connected_fraction"] == 1.0 and summary["samples"] == 4


def test_multi_hop_chain_exactly_at_range():
    # Base at 0; UAVs 0.1 apart with range 0.1 (not exact in binary): a chain of 4 hops.
    chain = np.array([[[0.1 * k, 0.0] for k in range(4, 0, -1)]])
    result = check_positions(chain, NONE, np.array([[0.0, 0.0]]), 0.1)
    assert result.connected.tolist() == [True]
    assert result.hops.tolist() == [[4, 3, 2, 1]]
    assert result.max_hops.tolist() == [4]
    # A millimetre more on the last hop and the end of the chain is cut off.
    stretched = chain.copy()
    stretched[0, 0, 0] += 1e-3
    result = check_positions(stretched, NONE, np.array([[0.0, 0.0]]), 0.1)
    assert result.connected.tolist() == [False]
    assert result.hops.tolist() == [[-1, 3, 2, 1]]
    assert result.max_hops.tolist() == [-1]


def test_a_disconnected_uav_and_a_second_base_station():
    a, b = np.array([0.0, 0.0]), np.array([1000.0, 0.0])
    positions = np.array(
        [
            [[100.0, 0.0], [200.0, 0.0], [500.0, 0.0], [900.0, 0.0]],  # 500 is 300 from all
            [[100.0, 0.0], [200.0, 0.0], [350.0, 0.0], [900.0, 0.0]],  # chain A-100-200-350
            [[100.0, 0.0], [200.0, 0.0], [500.0, 0.0], [900.0, 0.0]],
        ]
    )
    stations = np.array([a, b])
    result = check_positions(positions, NONE, stations, 150.0)
    assert result.connected.tolist() == [False, True, False]
    assert result.hops[0].tolist() == [1, 2, -1, 1]
    assert result.hops[1].tolist() == [1, 2, 3, 1]
    assert result.max_hops.tolist() == [-1, 3, -1]
    assert result.summary()["connected_fraction"] == pytest.approx(1 / 3)
    # An extra base station next to the stray UAV reconnects it (eq. 3 with more stations).
    result = check_positions(positions, NONE, np.vstack([stations, [[500.0, 100.0]]]), 150.0)
    assert result.connected.all()


def test_uavs_relay_for_each_other_but_base_stations_do_not_need_to():
    # Two base stations 1000 m apart are wired; each UAV hears only its own.
    positions = np.array([[[50.0, 0.0], [950.0, 0.0]]])
    result = check_positions(positions, NONE, np.array([[0.0, 0.0], [1000.0, 0.0]]), 60.0)
    assert result.connected.tolist() == [True]
    assert result.hops.tolist() == [[1, 1]]


def hops_by_networkx(positions, stations, radio_range):
    """Reference: shortest hop counts in the unit-disk graph from a super-source of stations."""
    graph = nx.Graph()
    nodes = list(range(len(positions)))
    graph.add_nodes_from(nodes + ["bs"])
    for i in nodes:
        if np.any(np.hypot(*(stations - positions[i]).T) <= radio_range + 1e-6):
            graph.add_edge("bs", i)
        for j in nodes[i + 1 :]:
            if math.dist(positions[i], positions[j]) <= radio_range + 1e-6:
                graph.add_edge(i, j)
    lengths = nx.single_source_shortest_path_length(graph, "bs")
    return [lengths.get(i, -1) for i in nodes]


@settings(max_examples=30, deadline=None, derandomize=True)
@given(
    st.integers(1, 12),
    st.integers(1, 3),
    st.integers(1, 6),
    st.floats(50.0, 400.0),
    st.integers(0, 2**31),
)
def test_hops_agree_with_networkx(count, station_count, samples, radio_range, seed):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(0.0, 1000.0, (samples, count, 2))
    stations = rng.uniform(0.0, 1000.0, (station_count, 2))
    result = check_positions(positions, NONE, stations, radio_range)
    expected = [hops_by_networkx(p, stations, radio_range) for p in positions]
    assert result.hops.tolist() == expected
    pairs = np.hypot(*(positions[:, :, None] - positions[:, None, :]).transpose(3, 0, 1, 2))
    pairs[:, np.arange(count), np.arange(count)] = np.inf
    assert np.allclose(result.min_uav_uav_m, pairs.min(axis=(1, 2)))


def test_chunks_give_the_same_answer(monkeypatch):
    rng = np.random.default_rng(7)
    positions = rng.uniform(0.0, 500.0, (50, 6, 2))
    stations = np.array([[0.0, 0.0], [500.0, 500.0]])
    whole = check_positions(positions, SQUARE, stations, 150.0)
    monkeypatch.setattr(guarantees, "_CHUNK_CELLS", 40)  # a few samples per chunk
    chunked = check_positions(positions, SQUARE, stations, 150.0)
    assert np.array_equal(whole.hops, chunked.hops)
    assert np.array_equal(whole.min_uav_uav_m, chunked.min_uav_uav_m)
    assert np.array_equal(whole.connected, chunked.connected)


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError):
        check_positions(np.zeros((3,)), NONE, np.zeros((1, 2)), 10.0)
    with pytest.raises(ValueError):
        check_positions(np.zeros((1, 2, 2)), NONE, np.zeros((1, 2)), 0.0)
