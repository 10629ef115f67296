"""`gcs.netsim.ns3`: scenarios flown in ns-3 (the `ns3` extra; importing it takes ~10 s).

A line of 3 UAVs standing 80 m apart from A at (0, 0), radio range 100 m, 30 m up: UAV k is
k hops from A, every packet takes exactly k hops, and a request from UAV 1 reaches UAV 3 by
the paper's chain after two relays. Moving UAV 3 out of range for 20 s cuts its packets for
20 s. The same scenario and seed give the same numbers twice in one process.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gcs.mission import load_mission
from gcs.netsim.ns3 import MISSING_EXTRA, NetOptions, NetResult, run_network
from gcs.netsim.scenario import NetScenario, SpeedRequest
from gcs.planning import plan_mission
from gcs.sim.fastsim import FastOptions, fly_fast

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
MISSION = REPO / "tests" / "missions" / "core.yaml"
SECONDS = 60.0
REQUEST_AT = 20.0


def line(cut: tuple[float, float] | None = None) -> NetScenario:
    """The 3-UAV line, 60 s; `cut`: UAV 3 stands 500 m off the line between those times."""
    times = np.round(np.arange(0.0, SECONDS + 1e-9, 0.1), 6)
    positions = np.zeros((len(times), 3, 3))
    positions[:, :, 0] = 80.0 * np.arange(1, 4)
    positions[:, :, 2] = 30.0
    if cut is not None:
        away = (times >= cut[0]) & (times < cut[1])
        positions[away, 2, 1] = 500.0
    return NetScenario(
        name="line",
        times=times,
        uav_positions=positions,
        base_stations=np.array([[0.0, 0.0]]),
        ground_users=np.zeros((0, 2)),
        radio_range=100.0,
        altitude=30.0,
        requests=(SpeedRequest(REQUEST_AT, 1),),
    )


#: A block between UAV 1 (x 80 m) and UAV 2 (x 160 m): their 80 m link crosses it.
BLOCK = {"polygons": [[[110.0, -20.0], [130.0, -20.0], [130.0, 20.0], [110.0, 20.0]]], "walls": []}


def test_the_footprint_model_blocks_exactly_the_chords_planner_sight_blocks():
    """ns-3's footprint loss (C++) and `planner.sight.Sight` (shapely) agree on random chords
    over blocks and walls, touching included."""
    from gcs.netsim.ns3 import footprint_blocked
    from planner.sight import Sight, sight_from_json

    buildings = {
        "polygons": [
            [[40.0, -20.0], [60.0, -20.0], [60.0, 20.0], [40.0, 20.0]],
            [[0.0, 60.0], [30.0, 90.0], [0.0, 100.0], [10.0, 80.0]],  # not convex
        ],
        "walls": [[[70.0, 50.0], [100.0, 50.0]]],
    }
    rng = np.random.default_rng(5)
    starts, ends = rng.uniform(-10, 110, (3000, 2)), rng.uniform(-10, 110, (3000, 2))
    ends[:50] = [40.0, 0.0]  # ending on an outline: touching blocks
    expected = ~sight_from_json(buildings).clear(starts, ends)
    assert isinstance(sight_from_json(buildings), Sight)
    assert expected.sum() > 500
    assert (footprint_blocked(buildings, starts, ends) == expected).all()


@pytest.mark.parametrize(("nlos_range", "reached"), [(0.0, {1}), (90.0, {1, 2, 3})])
def test_a_building_on_a_link_cuts_it_beyond_the_nlos_range(nlos_range, reached):
    """UAV 1 - UAV 2 (80 m) crosses the block: cut (`radio.buildings: cut`), UAVs 2 and 3
    deliver nothing; kept within an NLOS range of 90 m (`3gpp-umi`), every UAV delivers."""
    from dataclasses import replace

    result = run_network(replace(line(), buildings=BLOCK, nlos_range_m=nlos_range), NetOptions())
    delivered = {uav for uav in (1, 2, 3) if result.source_summary("uav", uav)["received"]}
    assert delivered == reached
    assert result.to_json()["ns3"]["buildings"]["footprints"] == 1


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """The core mission flown in the fast mode, recorded."""
    log = tmp_path_factory.mktemp("netsim") / "core.mcap"
    fly_fast(plan_mission(load_mission(MISSION)), FastOptions(log=log))
    return log


@pytest.fixture(scope="module")
def still() -> NetResult:
    return run_network(line(), NetOptions(seed=1))


def arrays(result: NetResult) -> list[np.ndarray]:
    return [
        result.sent_s,
        result.received_s,
        result.hops,
        result.station,
        result.paper_received_s,
        result.paper_hops,
        result.gcs_received_s,
        result.gcs_hops,
        result.uplink_received_s,
    ]


def test_every_uav_delivers_its_data_in_exactly_its_hops_to_a(still):
    assert len(still.sent_s) == 3 * 60  # one 100-byte packet a second per UAV
    assert (still.station == 0).all()
    for uav in (1, 2, 3):
        row = still.source_summary("uav", uav)
        assert row["sent"] == 60
        assert row["delivery_ratio"] >= 0.95
        mine = (still.source_id == uav) & still.delivered
        assert set(still.hops[mine].tolist()) == {uav}  # UAV k at 80 k m: k hops
        assert row["t_bs_p95_s"] < 0.05 * uav
    gaps = still.handover_gaps()
    assert (gaps <= 2.5).all()


def test_a_request_from_uav_1_reaches_uav_3_by_the_chain_after_two_relays(still):
    (paper,) = still.t_dv("paper")
    assert paper[0] == 0.0  # the leader
    assert 0.0 < paper[1] < paper[2] < 1.0
    assert still.paper_relays[0].tolist() == [0, 1, 2]
    assert still.paper_hops[0].tolist() == [0, 1, 2]  # one radio hop per relay
    # through the ground station: UAV 1 -> A (1 hop), then A -> UAV 2 (2), A -> UAV 3 (3)
    (gcs,) = still.t_dv("gcs")
    assert gcs[0] == 0.0 and (gcs[1:] > 0).all() and (gcs < 1.0).all()
    assert still.uplink_hops.tolist() == [1]
    assert still.gcs_hops[0].tolist() == [0, 2, 3]
    rows = still.per_uav()
    assert rows[2]["t_dv_paper_worst_s"] == pytest.approx(paper[2])


def test_the_same_scenario_and_seed_give_the_same_numbers(still):
    again = run_network(line(), NetOptions(seed=1))
    for mine, theirs in zip(arrays(still), arrays(again), strict=True):
        assert np.array_equal(mine, theirs, equal_nan=True)
    assert again.to_json()["uavs"] == still.to_json()["uavs"]
    other = run_network(line(), NetOptions(seed=2))
    assert not np.array_equal(other.sent_s, still.sent_s)  # the phases follow the seed


def test_a_uav_out_of_range_for_20_s_has_a_20_s_gap():
    result = run_network(line(cut=(20.0, 40.0)), NetOptions(seed=1))
    gaps = result.handover_gaps()
    # 20 s, and AODV's route discovery once UAV 3 is back (its queued requests backed off)
    assert 19.0 <= gaps[2] <= 25.0, gaps
    assert (gaps[:2] <= 2.5).all(), gaps
    mine = (result.source_id == 3) & result.delivered
    received = result.received_s[mine]
    assert not ((received > 20.5) & (received < 39.5)).any()
    assert result.source_summary("uav", 3)["delivery_ratio"] == pytest.approx(40 / 60, abs=0.05)


def test_the_log_distance_range_and_olsr_keep_the_line_at_1_2_3_hops():
    for options in (NetOptions(propagation="logdistance"), NetOptions(routing="olsr")):
        result = run_network(line(), options)
        for uav in (1, 2, 3):
            mine = (result.source_id == uav) & result.delivered
            assert set(result.hops[mine].tolist()) == {uav}, options
            assert mine.sum() >= 0.8 * 60, options


def test_gcs_log_netsim_writes_its_json_and_figures(gcs_main, tmp_path, recording):
    out = tmp_path / "netsim"
    code, stdout, stderr = gcs_main("log", "netsim", recording, "--out", out, "--json")
    assert code == 0, stderr
    printed = json.loads(stdout)
    written = json.loads((out / "netsim.json").read_text())
    assert written["uavs"] == printed["uavs"] and len(written["uavs"]) == 4
    assert written["scenario"]["name"] == "core" and written["options"]["routing"] == "aodv"
    assert written["packets_sent"] > 4 * 60 and written["delivery_ratio"] > 0.9
    (request,) = written["requests"]
    assert request["leader"] == 2 and request["t_dv_paper_s"][1] == 0.0
    assert (out / "t_bs.png").stat().st_size > 0 and (out / "bs_con.png").stat().st_size > 0
    assert "UAV 4" in stderr and "Traceback" not in stderr


@pytest.mark.parametrize("command", ["log netsim", "eval paper", "eval calibrate"])
def test_without_the_ns3_extra_the_command_says_so_on_one_line(recording, tmp_path, command):
    """`ns` unimportable (the extra missing): one line, exit 2; importing gcs.netsim and
    reading the recording never imported ns-3; `gcs eval paper --network ns3` and `gcs eval
    calibrate` say so before they fly or write anything."""
    out = tmp_path / "out.json"
    args = {
        "log netsim": ["log", "netsim", str(recording)],
        "eval paper": ["eval", "paper", "--network", "ns3", "--out", str(out)],
        "eval calibrate": ["eval", "calibrate", "--quick", "--out", str(out)],
    }[command]
    code = (
        "import sys\n"
        "sys.modules['ns'] = None\n"
        "import gcs.netsim, gcs.netsim.ns3\n"
        "assert 'cppyy' not in sys.modules\n"
        "from gcs.cli import main\n"
        f"status = main({args!r})\n"
        "assert 'cppyy' not in sys.modules\n"
        "sys.exit(status)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO, timeout=120)  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert done.stdout == ""
    assert done.stderr == MISSING_EXTRA + "\n"
    assert not out.exists()


def test_gcs_eval_paper_replays_every_flight_in_ns3_next_to_the_medium(gcs_main, tmp_path):
    """The reduced paper evaluation (one fixed speed, one leader) with `--network ns3`: the
    table gains an ns-3 column, results.json an "ns3" section per flight, DIR/ns3 the
    network figures; every follower hears the leader's request by both relays."""
    out = tmp_path / "eval"
    code, stdout, stderr = gcs_main("eval", "paper", "--mission", MISSION, "--speeds", "8",
                                    "--leaders", "2", "--network", "ns3", "--out", out,
                                    "--json")  # fmt: skip
    assert code == 0, stderr
    assert json.loads(stdout)["ok"] is True
    results = json.loads((out / "results.json").read_text())
    network = results["ns3"]
    assert network["options"]["routing"] == "aodv" and network["options"]["seed"] == 1
    walled = {"buildings: the paper's formation", "buildings: line-of-sight formation"}
    assert set(network["runs"]) == {"8 m/s", "leader UAV 2"} | walled
    # through the same footprints in ns-3: the paper's formation loses a UAV behind the
    # block, the line-of-sight formation does not
    paper = network["runs"]["buildings: the paper's formation"]["uav_data"]
    ours = network["runs"]["buildings: line-of-sight formation"]["uav_data"]
    assert ours["ratio"] > 0.9 and paper["ratio"] < ours["ratio"], (paper, ours)
    medium = {run["label"]: run for run in results["runs"]}
    for label, run in ((k, v) for k, v in network["runs"].items() if k not in walled):
        data = run["uav_data"]
        assert data["sent"] > 4 * 40 and data["ratio"] > 0.9, (label, data)
        assert 0.1 < data["delay_mean_ms"] < 100 and data["max_hops"] >= 1
        assert data["sent"] == data["received"] + data["dropped"]
        # the same offered load (0.8 kbit/s a UAV): 100-byte packets every second in ns-3,
        # 200-byte packets every 2 s in the medium, over the same flight (ns-3 from the
        # first sample, the medium from each take-off)
        assert data["sent"] >= 2 * medium[label]["uav_data"]["sent"] - 4
    fixed = network["runs"]["8 m/s"]["reactions"]
    assert fixed["chain"] == {"worst_s": None, "mean_s": None, "lost": 0}  # no leader
    led = network["runs"]["leader UAV 2"]["reactions"]
    for relay in ("chain", "gcs"):
        assert led[relay]["lost"] == 0 and 0 < led[relay]["mean_s"] <= led[relay]["worst_s"] < 1
    rows = {row["quantity"]: row for row in results["table"]}
    assert rows["T_dv, leader UAV 2: worst / mean"]["ns3"].startswith("chain ")
    assert "% delivered" in rows["connectivity (8 m/s)"]["ns3"]
    assert (out / "table.md").read_text().startswith("| quantity | paper | ours | ns-3 | note |")
    for name in ("fig10_reaction_time.png", "fig11_delay_to_bs.png", "fig12_packets_at_bs.png",
                 "fig13_packets_at_bs_speeds.png", "fig14_reaction_time_leaders.png",
                 "fig14_reaction_time_leaders_gcs.png", "fig15_ground_users_leaders.png",
                 "fig16_ground_users_speeds.png"):  # fmt: skip
        assert (out / "ns3" / name).read_bytes()[:4] == b"\x89PNG", name
    assert "ns-3: import" in stderr and "Traceback" not in stderr
