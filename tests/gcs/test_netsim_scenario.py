"""`gcs.netsim.scenario`: a flight as the network scenario ns-3 replays (no ns-3 needed here).

The flight is `tests/missions/core.yaml` in the fast mode (4 UAVs, a scheduled change at 8 s,
UAV 2 asking for 8 m/s as leader at 16 s), recorded to an MCAP file as `gcs mission run
--log` would. `gcs log netsim`'s refusals of bad input come before ns-3 is needed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs.errors import InputError
from gcs.mission import load_mission
from gcs.netsim.ns3 import NetOptions, data_schedule, log_distance_exponent
from gcs.netsim.scenario import (
    FLYING_ABOVE_M,
    NetScenario,
    SpeedRequest,
    scenario_from_fast_run,
    scenario_from_recording,
    station_table,
)
from gcs.planning import plan_mission
from gcs.sim.fastsim import FastOptions, fly_fast
from tests.cli_refusals import one_line_exit_2

MISSION = Path(__file__).resolve().parents[1] / "missions" / "core.yaml"


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    """The core mission flown once in the fast mode, recorded: (mission, run, recording)."""
    mission = load_mission(MISSION)
    path = tmp_path_factory.mktemp("netsim") / "core.mcap"
    run = fly_fast(plan_mission(mission), FastOptions(log=path))
    return mission, run, path


@pytest.fixture(scope="module")
def from_run(flown):
    mission, run, _ = flown
    return scenario_from_fast_run(run, mission)


def line(count: int = 3, spacing: float = 80.0, seconds: float = 10.0) -> NetScenario:
    """`count` UAVs standing on the x axis `spacing` apart from A at (0, 0), 30 m up."""
    times = np.round(np.arange(0.0, seconds + 1e-9, 0.1), 6)
    positions = np.zeros((len(times), count, 3))
    positions[:, :, 0] = spacing * np.arange(1, count + 1)
    positions[:, :, 2] = 30.0
    return NetScenario("line", times, positions, np.array([[0.0, 0.0]]), np.zeros((0, 2)),
                       100.0, 30.0, ())  # fmt: skip


def test_a_fast_run_becomes_10_hz_trajectories_with_its_leaders_request(flown, from_run):
    mission, run, _ = flown
    scenario = from_run
    steps = np.diff(scenario.times)
    assert np.allclose(steps, 0.1, atol=1e-9)
    assert scenario.times[0] <= run.times[0] + 1e-9 and scenario.times[-1] >= run.times[-1] - 0.1
    assert scenario.uav_positions.shape == (len(scenario.times), 4, 3)
    assert np.isfinite(scenario.uav_positions).all()
    # the samples are the run's true positions, linear in between
    for k in range(4):
        for axis in range(3):
            flown_axis = np.interp(run.times, scenario.times, scenario.uav_positions[:, k, axis])
            assert np.abs(flown_axis - run.positions[:, k, axis]).max() < 1e-6
    assert np.array_equal(scenario.base_stations, mission.base_station_points)
    assert np.array_equal(scenario.base_stations[0], [mission.start.x, mission.start.y])
    assert scenario.ground_users.shape == (0, 2)
    assert scenario.radio_range == mission.radio_range == 60
    assert scenario.altitude == mission.altitude
    # only the leader's change is a request (the scheduled one comes from the ground station),
    # sent when UAV 2 sent it
    (leader,) = [c for c in run.speed_changes if c["source"] == "leader:2"]
    assert scenario.requests == (SpeedRequest(leader["leader_sent_s"], 2),)
    assert 16.0 <= scenario.requests[0].t < 16.2
    # every UAV takes off and lands: it flies between, above FLYING_ABOVE_M
    flying = scenario.flying
    assert flying.any(axis=0).all() and not flying[0].any() and not flying[-1].any()
    assert (scenario.uav_positions[..., 2][flying] > FLYING_ABOVE_M).all()


def test_a_recording_gives_the_fast_runs_trajectories_within_half_a_metre(flown, from_run):
    _, _, path = flown
    recorded = scenario_from_recording(path)
    assert recorded.name == from_run.name == "core"
    common, mine, theirs = np.intersect1d(
        np.round(recorded.times, 3), np.round(from_run.times, 3), return_indices=True
    )
    assert len(common) > 0.95 * len(from_run.times)
    gap = np.linalg.norm(
        recorded.uav_positions[mine] - from_run.uav_positions[theirs], axis=-1
    ).max()
    assert gap < 0.5
    assert np.array_equal(recorded.base_stations, from_run.base_stations)
    assert recorded.radio_range == from_run.radio_range and recorded.altitude == 10
    (request,) = recorded.requests
    assert request.leader == 2 and abs(request.t - from_run.requests[0].t) < 0.2


def test_a_file_that_is_not_a_recording_is_refused(tmp_path):
    notes = tmp_path / "notes.mcap"
    notes.write_text("not a recording\n")
    with pytest.raises(InputError, match="notes.mcap"):
        scenario_from_recording(notes)


def test_a_scenario_refuses_unknown_positions_and_a_leader_outside_the_fleet():
    good = line()
    positions = good.uav_positions.copy()
    positions[0, 1, 0] = np.nan
    with pytest.raises(ValueError, match="uav_positions"):
        NetScenario("x", good.times, positions, good.base_stations, good.ground_users, 100.0,
                    30.0, ())  # fmt: skip
    with pytest.raises(ValueError, match="leader 4"):
        NetScenario("x", good.times, good.uav_positions, good.base_stations, good.ground_users,
                    100.0, 30.0, (SpeedRequest(1.0, 4),))  # fmt: skip


def test_each_node_sends_to_the_station_it_reaches_in_fewest_hops_not_the_closest():
    """Range 100 m, A at x = 0, B at x = 330. UAV 2 (x = 175) is closer to B (155 m) than to
    A, but B hears no UAV: UAV 2 reaches A through UAV 1 (x = 90) and sends to A; the ground
    user next to B (x = 400) sends to B."""
    times = np.array([0.0, 0.1])
    positions = np.zeros((2, 2, 3))
    positions[:, 0, 0], positions[:, 1, 0] = 90.0, 175.0
    scenario = NetScenario("x", times, positions, np.array([[0.0, 0.0], [330.0, 0.0]]),
                           np.array([[400.0, 0.0]]), 100.0, 30.0, ())  # fmt: skip
    table = station_table(scenario)
    assert table.shape == (2, 3)
    assert table[0].tolist() == [0, 0, 1]
    # out of every station's reach, a node falls back on the closest
    lone = NetScenario("x", times, positions + [1000.0, 0.0, 0.0], scenario.base_stations,
                       scenario.ground_users, 100.0, 30.0, ())  # fmt: skip
    assert station_table(lone)[0, :2].tolist() == [1, 1]


def test_the_data_schedule_is_seeded_and_at_the_scenarios_rate():
    scenario = line(count=2, seconds=60.0)
    sent, kinds, ids = data_schedule(scenario, seed=1)
    again, _, _ = data_schedule(scenario, seed=1)
    other, _, _ = data_schedule(scenario, seed=2)
    assert np.array_equal(sent, again) and not np.array_equal(sent, other)
    assert (np.diff(sent) >= 0).all()
    for uav in (1, 2):
        mine = sent[(kinds == "uav") & (ids == uav)]
        assert len(mine) == 60  # 800 bit/s in 100-byte packets: one a second
        assert np.allclose(np.diff(mine), scenario.packet_interval_s)


def test_options_are_checked_and_the_log_distance_threshold_falls_at_the_range():
    with pytest.raises(ValueError, match="propagation"):
        NetOptions(propagation="friis")
    with pytest.raises(ValueError, match="routing"):
        NetOptions(routing="dsdv")
    with pytest.raises(ValueError, match="seed"):
        NetOptions(seed=0)
    for radio_range in (60.0, 100.0, 220.0):
        exponent = log_distance_exponent(radio_range)
        received = 16.0206 - 40.05 - 10 * exponent * np.log10(radio_range)
        assert received == pytest.approx(-76.0)
        assert 2.0 < exponent < 3.5


# --------------------------------------------------------------------------- the command
def test_gcs_log_netsim_refuses_bad_input_on_one_line_before_ns3(gcs_main, tmp_path, flown):
    _, _, path = flown
    missing = tmp_path / "missing.mcap"
    one_line_exit_2(gcs_main("log", "netsim", missing), str(missing))
    notes = tmp_path / "notes.mcap"
    notes.write_text("hello\n")
    one_line_exit_2(gcs_main("log", "netsim", notes), str(notes))
    one_line_exit_2(gcs_main("log", "netsim", path, "--propagation", "friis"), "--propagation")
    one_line_exit_2(gcs_main("log", "netsim", path, "--routing", "dsr"), "--routing")
    one_line_exit_2(gcs_main("log", "netsim", path, "--seed", "0"), "--seed")
    one_line_exit_2(gcs_main("log", "netsim", path, "--seed", "one"), "--seed")
    afile = tmp_path / "afile"
    afile.write_text("")
    one_line_exit_2(gcs_main("log", "netsim", path, "--out", afile), "--out")
