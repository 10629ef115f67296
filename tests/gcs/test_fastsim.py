"""The fast in-process mode: a whole mission in lockstep, through the radio medium model.

The small mission completes connected, with the run JSON of docs/outputs.md (and its `radio`
object); latency grows with the hop count; every UAV receives every speed change, the leader's
too; two runs with the same seed are identical; a fleet forced too small is cut off; a UAV
given a small battery (`sim.battery_mah`) reports less of it left.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.sim.fastsim import FastOptions, fly_fast
from medium.radio_stats import KINDS

MISSION = Path(__file__).resolve().parents[2] / "examples" / "small.yaml"


@pytest.fixture(scope="module")
def plan():
    return plan_mission(load_mission(MISSION))


@pytest.fixture(scope="module")
def flown(plan):
    return fly_fast(plan)


def test_the_small_mission_completes_connected_with_the_run_json(flown, plan):
    run = flown.run_json
    assert run["completed"] is True and run["log"] is None
    assert run["fleet_size"] == plan.fleet_size == 4
    assert run["connected_fraction"] == 1.0
    rho = plan.mission.safety_margin
    assert run["max_tracking_error_m"] < rho
    assert run["min_uav_uav_m"] >= 2 * rho - 2 * run["max_tracking_error_m"]
    assert run["min_uav_obstacle_m"] >= rho - run["max_tracking_error_m"]
    assert run["duration_s"] > plan.duration_s
    radio = run["radio"]
    assert radio["connected_fraction"] == 1.0
    assert radio["packets"]["dropped"] == 0 and radio["packets"]["sent"] > 1000
    assert set(radio["delay_ms"]) >= {"mean", "p95"}
    assert set(radio["ground_users"]) >= {"sent", "received", "dropped"}
    assert radio["ground_users"]["sent"] > 0
    # every UAV landed on its arrival slot
    final = flown.positions[-1]
    assert np.hypot(*(final[:, :2] - flown.formation.goal_slots).T).max() < 1.5
    assert (final[:, 2] < 0.5).all()
    samples = len(flown.times)
    assert flown.positions.shape == (samples, 4, 3) and flown.hops.shape == (samples, 4)
    assert (flown.hops >= 1).all()


def test_latency_grows_with_the_hop_count(flown):
    packets = flown.packets
    delivered = np.isfinite(packets["delay_s"])
    hops = packets["hops"][delivered]
    delays = packets["delay_s"][delivered]
    counts = sorted(set(hops.tolist()))
    assert counts[0] == 1 and len(counts) >= 2
    means = [delays[hops == h].mean() for h in counts]
    assert all(a < b for a, b in zip(means, means[1:], strict=False))
    for h, mean in zip(counts, means, strict=True):
        assert mean == pytest.approx(h * 0.002, rel=0.1)  # 2 ± 1 ms per hop


def test_every_uav_receives_every_speed_change_the_leaders_too(flown):
    changes = flown.speed_changes
    assert [c["source"] for c in changes] == ["schedule", "leader:2"]
    for change in changes:
        assert sorted(change["received_s"]) == ["1", "2", "3", "4"]
        assert sorted(change["acks"]) == ["1", "2", "3", "4"]
        # received after the request, ahead of the effective time
        assert all(
            change["requested_s"] - 0.1 <= t < change["effective_s"]
            for t in change["received_s"].values()
        )
    leader = changes[1]
    assert 35.0 <= leader["leader_sent_s"] <= leader["requested_s"]
    speeds = flown.profile.speed_at(np.array([10.0, 30.0, leader["effective_s"] + 1]))
    assert speeds.tolist() == [8.0, 5.0, 8.0]


def test_two_runs_with_the_same_seed_are_identical(plan):
    first, again = (fly_fast(plan, FastOptions(time_limit_s=15.0)) for _ in range(2))
    assert again.run_json == first.run_json
    np.testing.assert_array_equal(again.positions, first.positions)
    np.testing.assert_array_equal(again.packets["delay_s"], first.packets["delay_s"])


def test_a_fleet_forced_too_small_is_cut_off(plan):
    cut = fly_fast(plan, FastOptions(fleet_size=1, time_limit_s=60.0))
    run = cut.run_json
    assert run["fleet_size"] == 1 and run["completed"] is False
    assert run["connected_fraction"] < 1.0
    assert run["radio"]["connected_fraction"] < 1.0
    assert (cut.hops == -1).any()
    dropped = cut.packets["kind"][np.isnan(cut.packets["delay_s"])]
    assert (dropped == KINDS.index("downlink")).any()  # its setpoints were lost
    assert any(e["kind"] == "link_lost" for e in run["events"])


def test_a_uav_with_a_small_battery_reports_less_left_by_the_end(tmp_path):
    """tests/missions/core.yaml with `sim.battery_mah: [8000, 1000, 8000, 8000]`: the
    SYS_STATUS battery_remaining each UAV last reported to its driver."""
    core = Path(__file__).resolve().parents[1] / "missions" / "core.yaml"
    text = core.read_text().replace(
        "sim: {setpoint_rate_hz: 10, seed: 3}",
        "sim: {setpoint_rate_hz: 10, seed: 3, battery_mah: [8000, 1000, 8000, 8000]}",
    )
    path = tmp_path / "core.yaml"
    path.write_text(text)
    run = fly_fast(plan_mission(load_mission(path)))
    assert run.run_json["completed"] is True
    full, small = np.delete(run.battery_remaining_pct, 1), run.battery_remaining_pct[1]
    assert np.isfinite(run.battery_remaining_pct).all()
    assert (full < 100).all() and full.max() - full.min() <= 2  # drained alike
    assert 10 < small < full.min() - 15  # about 8 times their drain
