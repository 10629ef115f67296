"""The radio model (pure): unit-disk hop counts against networkx, per-hop delay and loss,
in-order delivery, constant-bit-rate sources, the medium's decisions and its counters, and
reading the true position out of a vehicle's SIM_STATE frames."""

from __future__ import annotations

import math

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.geodesy import Origin
from medium.ground_users import CbrTraffic, GroundUser
from medium.medium import MediumModel, frames, sim_state_position
from medium.radio import Channel, DelayLine, RadioConfig, topology
from medium.radio_stats import RadioStats

ORIGIN = Origin(45.7640, 4.8357, 170.0)
coordinate = st.floats(-300, 300, allow_nan=False)
points = st.lists(st.tuples(coordinate, coordinate), min_size=0, max_size=12)


def reference_hops(stations, uavs, radio_range):
    """Hops by networkx: shortest path from a super-source wired to every station."""
    graph = nx.Graph()
    nodes = [("s", i) for i in range(len(stations))] + [("u", i) for i in range(len(uavs))]
    xy = {
        **{("s", i): p for i, p in enumerate(stations)},
        **{("u", i): p for i, p in enumerate(uavs)},
    }
    graph.add_nodes_from(nodes + ["gcs"])
    graph.add_edges_from(("gcs", ("s", i)) for i in range(len(stations)))
    for a in nodes:
        for b in nodes:
            if a < b and not (a[0] == b[0] == "s"):
                if math.dist(xy[a], xy[b]) <= radio_range + 1e-6:
                    graph.add_edge(a, b)
    lengths = nx.single_source_shortest_path_length(graph, "gcs")
    return [lengths[("u", i)] - 1 if ("u", i) in lengths else -1 for i in range(len(uavs))]


@settings(max_examples=60, deadline=None, derandomize=True)
@given(stations=points.filter(bool), uavs=points, radio_range=st.floats(20, 200))
def test_hop_counts_are_the_shortest_chains_of_the_unit_disk_graph(stations, uavs, radio_range):
    current = topology(np.array(stations), np.array(uavs).reshape(-1, 2), radio_range)
    assert current.hops.tolist() == reference_hops(stations, uavs, radio_range)
    assert current.connected == all(h >= 0 for h in current.hops)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(stations=points.filter(bool), uavs=points, users=points, radio_range=st.floats(20, 200))
def test_a_ground_user_reaches_a_station_directly_or_through_one_connected_uav(
    stations, uavs, users, radio_range
):
    current = topology(np.array(stations), np.array(uavs).reshape(-1, 2), radio_range)
    hops = current.hops_of_ground_nodes(np.array(users).reshape(-1, 2))
    for user, got in zip(users, hops.tolist(), strict=True):
        direct = any(math.dist(user, s) <= radio_range + 1e-6 for s in stations)
        relays = [
            h for uav, h in zip(uavs, current.hops.tolist(), strict=True)
            if h > 0 and math.dist(user, uav) <= radio_range + 1e-6
        ]  # fmt: skip
        expected = 1 if direct else (min(relays) + 1 if relays else -1)
        assert got == expected


def test_the_range_is_inclusive_and_infinite_range_is_one_hop():
    stations = np.array([[0.0, 0.0]])
    chain = np.array([[100.0, 0.0], [200.0, 0.0], [300.0000001, 0.0]])
    assert topology(stations, chain, 100.0).hops.tolist() == [1, 2, 3]
    assert topology(stations, chain, 99.9).hops.tolist() == [-1, -1, -1]
    assert topology(stations, chain * 1e4, math.inf).hops.tolist() == [1, 1, 1]


def test_delay_is_the_hop_latency_per_hop_and_jitter_stays_in_its_band():
    exact = Channel(RadioConfig(100.0, hop_latency_s=0.002, jitter_s=0.0))
    assert [exact.transit(h) for h in (1, 2, 5)] == pytest.approx([0.002, 0.004, 0.010])
    noisy = Channel(RadioConfig(100.0, hop_latency_s=0.002, jitter_s=0.001, seed=3))
    for hops in (1, 3, 6):
        delays = np.array([noisy.transit(hops) for _ in range(2000)])
        assert (delays >= hops * 0.001 - 1e-12).all() and (delays <= hops * 0.003 + 1e-12).all()
        assert delays.mean() == pytest.approx(hops * 0.002, rel=0.03)
    many = noisy.transit_many(np.array([1, 3, 6] * 1000))
    assert many.reshape(-1, 3).mean(axis=0) == pytest.approx([0.002, 0.006, 0.012], rel=0.03)


def test_each_hop_loses_a_packet_with_the_loss_probability():
    channel = Channel(RadioConfig(100.0, loss=0.2, seed=7))
    for hops in (1, 3):
        lost = np.mean([channel.transit(hops) is None for _ in range(4000)])
        assert lost == pytest.approx(1 - 0.8**hops, abs=0.03)
    lost = np.isnan(channel.transit_many(np.full(4000, 2))).mean()
    assert lost == pytest.approx(1 - 0.8**2, abs=0.03)


def test_the_channel_is_seeded():
    draws = [
        Channel(RadioConfig(100.0, loss=0.3, seed=5)).transit_many(np.arange(1, 50))
        for _ in range(2)
    ]
    np.testing.assert_array_equal(draws[0], draws[1])


def test_the_channel_draws_what_one_numpy_call_per_packet_draws():
    """The channel takes its draws a block at a time; each packet's fate is still the one
    numpy's generator gives packet by packet (`random` for the loss, `uniform` per hop), so
    seeded runs keep their delays."""
    config = RadioConfig(100.0, hop_latency_s=0.002, jitter_s=0.001, loss=0.1, seed=11)
    channel = Channel(config)
    rng = np.random.default_rng([config.seed, 0])
    hop_counts = np.random.default_rng(1).integers(1, 12, 3000)
    for k, hops in enumerate(hop_counts.tolist()):
        if k % 500 == 499:  # the ground users' batches share the stream
            batch = hop_counts[k : k + 7]
            per_hop = np.full((len(batch), batch.max()), config.hop_latency_s)
            per_hop += rng.uniform(-config.jitter_s, config.jitter_s, per_hop.shape)
            np.maximum(per_hop, 0.0, out=per_hop)
            per_hop[np.arange(batch.max())[None, :] >= batch[:, None]] = 0.0
            expected = per_hop.sum(axis=1)
            expected[rng.random(len(batch)) >= (1.0 - config.loss) ** batch] = np.nan
            np.testing.assert_array_equal(channel.transit_many(batch), expected)
        if rng.random() >= (1.0 - config.loss) ** hops:
            assert channel.transit(hops) is None
            continue
        draws = rng.uniform(-config.jitter_s, config.jitter_s, hops)
        assert channel.transit(hops) == float(np.maximum(config.hop_latency_s + draws, 0.0).sum())


def test_a_stream_is_delivered_in_order_even_when_a_later_packet_is_faster():
    line = DelayLine()
    assert line.put("a", 0.010, "a1") == 0.010
    assert line.put("a", 0.004, "a2") == 0.010  # would overtake a1: waits for it
    assert line.put("b", 0.002, "b1") == 0.002  # another stream is independent
    assert line.next_due() == 0.002
    assert line.pop_due(0.005) == [(0.002, "b1")]
    assert [item for _, item in line.pop_due(0.010)] == ["a1", "a2"]
    assert len(line) == 0 and line.next_due() == math.inf


def test_constant_bit_rate_sources_send_at_their_rate_without_repeats():
    traffic = CbrTraffic([800.0, 1600.0], packet_bytes=200)  # every 2 s and every 1 s
    first, times_a = traffic.due(9.99)
    second, times_b = traffic.due(20.0)
    sources = np.concatenate([first, second])
    times = np.concatenate([times_a, times_b])
    assert np.all(np.diff(times_a) >= 0) and np.all(np.diff(times_b) >= 0)
    assert (sources == 0).sum() == 11  # 0, 2, ..., 20
    assert (sources == 1).sum() == 20  # 0.5, 1.5, ..., 19.5 (staggered by half a period)
    assert times[sources == 1][0] == pytest.approx(0.5)
    assert len(set(zip(sources.tolist(), times.tolist(), strict=True))) == len(sources)


def test_the_medium_drops_what_has_no_path_and_counts_everything():
    model = MediumModel(
        RadioConfig(60.0, hop_latency_s=0.002, jitter_s=0.0),
        np.array([[0.0, 0.0]]),
        np.array([[50.0, 0.0], [100.0, 0.0], [500.0, 0.0]]),
        ground_users=(GroundUser(140.0, 0.0, 800.0), GroundUser(900.0, 0.0, 800.0)),
        uav_data_bps=800.0,
    )
    assert model.route("downlink", 0, 0.0) == (1, pytest.approx(0.002))
    assert model.route("uplink", 1, 0.0) == (2, pytest.approx(0.004))
    assert model.route("downlink", 2, 0.0) == (-1, None)
    for step in range(101):  # 10 s of samples
        model.periodic(step * 0.1)
    summary = model.stats.summary()
    assert summary["connected_fraction"] == 0.0  # UAV 3 is never reachable
    assert [u["connected_fraction"] for u in summary["per_uav"]] == [1.0, 1.0, 0.0]
    assert summary["packets"]["dropped"] == 1 + summary["kinds"]["uav_data"]["dropped"]
    # every 2 s, UAVs staggered by 2/3 s: 6 + 5 + 5 packets in [0, 10] s
    assert summary["kinds"]["uav_data"]["sent"] == 16
    assert summary["kinds"]["uav_data"]["dropped"] == 5
    users = summary["ground_users"]
    assert users["sent"] == users["received"] + users["dropped"]
    assert (users["received"], users["dropped"]) == (6, 5)  # the first heard by UAV 2 only
    assert users["hops"]["max"] == 3
    # a UAV moving away is cut off as soon as the range is crossed
    model.observe(0, np.array([61.0, 0.0]), np.zeros(2), 10.0)
    assert model.route("downlink", 0, 10.0)[0] == -1


def test_the_counters_sum_up_per_kind_and_per_uav():
    stats = RadioStats(2, keep_packets=True)
    stats.packet("uplink", 0, 0.0, 1, 0.002)
    stats.packet("downlink", 1, 0.1, 2, 0.004)
    stats.packet("uav_data", 1, 0.2, -1, None)
    stats.packet("ground", 0, 0.3, 3, 0.006)
    summary = stats.summary()
    assert summary["packets"] == {"sent": 3, "received": 2, "dropped": 1}
    assert summary["delay_ms"]["mean"] == pytest.approx(3.0)
    assert summary["ground_users"]["received"] == 1
    assert summary["per_uav"][1]["uav_data"] == {"sent": 1, "received": 0, "dropped": 1}
    seen, recent = stats.recent(0)  # what a report lists: the delivered fleet packets
    assert (seen, recent) == (2, {"delay_ms": [2.0, 4.0], "hops": [1, 2]})
    assert stats.recent(seen) == (2, {"delay_ms": [], "hops": []})
    columns = stats.log.columns()
    assert columns["hops"].tolist() == [1, 2, -1, 3]
    assert np.isnan(columns["delay_s"][2])


@pytest.mark.parametrize("signed", [False, True])
def test_the_true_position_is_read_from_sim_state_frames_in_a_batch(signed):
    codec = mavlink.MAVLink(None, srcSystem=7, srcComponent=1)
    if signed:
        codec.signing.secret_key = bytes(range(32))
        codec.signing.sign_outgoing = True
    enu = np.array([[123.4, -56.7, 30.0]])
    lat, lon, alt = ORIGIN.to_geodetic(enu)
    sim_state = mavlink.MAVLink_sim_state_message(
        1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, float(lat[0]), float(lon[0]), float(alt[0]),
        0.2, 0.3, 4.0, -3.0, 0.0, int(round(lat[0] * 1e7)), int(round(lon[0] * 1e7)),
    )  # fmt: skip
    heartbeat = mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3)
    datagram = heartbeat.pack(codec) + sim_state.pack(codec) + heartbeat.pack(codec)
    parsed = frames(datagram)
    assert [(m, s) for m, s, _ in parsed] == [(0, 7), (108, 7), (0, 7)]
    xy, velocity = sim_state_position(parsed[1][2], ORIGIN)
    np.testing.assert_allclose(xy, enu[0, :2], atol=0.02)
    np.testing.assert_allclose(velocity, [-3.0, 4.0])  # east, north
    assert frames(b"not mavlink") == []


def test_with_buildings_a_pair_in_range_behind_one_hears_nothing():
    """`radio.buildings`: a station and a UAV in range with a block between them are not
    linked; the UAV then reaches the station through a second one that sees round the block;
    a ground user behind the block is reached only through a UAV (the one it sees round it)."""
    from planner.obstacles import Obstacles
    from planner.sight import Sight, sight_from_json, sight_json

    block = Obstacles(
        polygons=(np.array([[40.0, -20.0], [60.0, -20.0], [60.0, 20.0], [40.0, 20.0]]),)
    )
    sight = sight_from_json(sight_json(block))  # the medium process reads it back so
    assert isinstance(sight, Sight)
    stations = np.array([[0.0, 0.0]])
    uavs = np.array([[100.0, 0.0], [50.0, 60.0]])  # behind the block; above it, seen by both
    disk = topology(stations, uavs, 120.0)
    walled = topology(stations, uavs, 120.0, sight=sight)
    assert disk.hops.tolist() == [1, 1]
    assert walled.hops.tolist() == [2, 1]
    assert not walled.hears_station[0, 0] and walled.hears_uav[0, 1]
    ground = np.array([[100.0, 10.0]])  # behind the block: the station is hidden
    assert disk.hops_of_ground_nodes(ground).tolist() == [1]
    assert walled.hops_of_ground_nodes(ground).tolist() == [2]  # through UAV 2, above it


def test_a_buildings_file_that_is_not_one_is_refused_in_one_line(tmp_path, capsys):
    from medium.cli import main

    bad = tmp_path / "buildings.json"
    bad.write_text('{"polygons": [[[0, 0], [1, 1]]], "walls": []}')
    code = main(["--count", "1", "--base-port", "15000", "--vehicle-ports", "15100",
                 "--positions", "0,0", "--stations", "0,0", "--range", "100",
                 "--buildings", str(bad)])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--buildings" in err
    assert "at least 3 points" in err and "Traceback" not in err
