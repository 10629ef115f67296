"""`gcs mission run` through the radio medium, end to end (real processes, loopback UDP), and
the fast in-process mode against it.

* The small mission with the planned fleet stays connected the whole mission: the run JSON's
  `radio.connected_fraction` is 1.0 and no packet is dropped.
* The fast mode flies the same mission to the same fleet size, connectivity and distances.
* A fleet forced too small (a test-only override of the plan) is cut off: the medium drops
  packets, the run JSON shows a connected fraction below 1, the link is lost, exit status 1.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.sim.fastsim import fly_fast
from tests.flying import flight_speedup

REPO = Path(__file__).resolve().parents[2]
MISSION = REPO / "examples" / "small.yaml"
pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

#: `gcs` with one test-only hook: FLEETLINE_TEST_FLEET_SIZE forcing the plan's fleet size (the
#: radio medium itself is the one `gcs mission run` starts).
LAUNCH = """
import os, sys
import gcs.cli, gcs.cli.cmd_mission as planning_cli
from gcs.sim.fastsim import with_fleet_size
plan = planning_cli.plan_mission
def plan_mission(mission, **kwargs):
    p = plan(mission, **kwargs)
    size = os.environ.get("FLEETLINE_TEST_FLEET_SIZE")
    return with_fleet_size(p, int(size)) if size else p
planning_cli.plan_mission = plan_mission
sys.exit(gcs.cli.main(sys.argv[1:]))
"""


def fly(tmp_path: Path, *extra: str, fleet_size: int | None = None) -> tuple[int, dict, Path]:
    log = tmp_path / "run.mcap"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    if fleet_size is not None:
        env["FLEETLINE_TEST_FLEET_SIZE"] = str(fleet_size)
    args = ["mission", "run", str(MISSION), "--speedup", str(flight_speedup(5)), "--vehicles-per-process", "4",
            "--json", "--log", str(log), *extra]  # fmt: skip
    done = subprocess.run(
        [sys.executable, "-c", LAUNCH, *args],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
        timeout=110,
    )
    assert done.stdout.count("\n") == 1, done.stderr[-3000:]
    return done.returncode, json.loads(done.stdout), log


def radio_topic(log: Path) -> list[dict]:
    with open(log, "rb") as handle:
        return [
            json.loads(message.data)
            for _, channel, message in make_reader(handle).iter_messages(topics=["/radio"])
        ]


@pytest.fixture(scope="module")
def networked(tmp_path_factory) -> tuple[int, dict, Path]:
    return fly(tmp_path_factory.mktemp("radio-run"))


def test_the_planned_fleet_stays_connected_through_the_medium(networked):
    code, run, log = networked
    assert code == 0, run.get("reason")
    radio = run["radio"]
    assert radio["connected_fraction"] == 1.0
    assert run["connected_fraction"] == 1.0
    packets = radio["packets"]
    assert packets["sent"] > 1000 and packets["dropped"] == 0
    assert packets["received"] == packets["sent"]
    assert radio["delay_ms"]["mean"] >= 2.0  # 2 ms per hop, at least one hop
    assert radio["hops"]["max"] >= 2  # the line relays for the UAVs far from A and B
    assert radio["ground_users"]["sent"] > 0
    reports = radio_topic(log)
    assert len(reports) > 20
    times = [r["t"] for r in reports]
    assert times == sorted(times)
    received = [r["packets"]["received"] for r in reports]
    assert received == sorted(received) and received[-1] > received[0]  # BS_con never flat
    # the speed changes reached every UAV through the medium, the leader's too
    for change in run["speed_changes"]:
        assert sorted(change["acks"]) == ["1", "2", "3", "4"]


def test_the_fast_mode_agrees_with_the_networked_run(networked):
    _, run, _ = networked
    fast = fly_fast(plan_mission(load_mission(MISSION))).run_json
    assert fast["completed"] is True
    assert fast["fleet_size"] == run["fleet_size"]
    assert fast["connected_fraction"] == run["connected_fraction"] == 1.0
    assert fast["radio"]["connected_fraction"] == run["radio"]["connected_fraction"] == 1.0
    assert fast["min_uav_uav_m"] == pytest.approx(run["min_uav_uav_m"], abs=1.5)
    assert fast["min_uav_obstacle_m"] == pytest.approx(run["min_uav_obstacle_m"], abs=1.5)
    assert fast["duration_s"] == pytest.approx(run["duration_s"], rel=0.1)
    rho = 5.0
    assert fast["max_tracking_error_m"] < rho and run["max_tracking_error_m"] < rho
    assert [c["source"] for c in fast["speed_changes"]] == [
        c["source"] for c in run["speed_changes"]
    ]
    assert fast["radio"]["ground_users"]["sent"] > 0


def test_a_fleet_forced_too_small_is_cut_off(tmp_path):
    code, run, _ = fly(tmp_path, "--link-wait", "1", fleet_size=1)
    assert code == 1
    assert run["completed"] is False and run["fleet_size"] == 1
    radio = run["radio"]
    # cut off: not always connected (how long it flew before the cut depends on the load)
    assert radio["connected_fraction"] < 1.0
    assert radio["packets"]["dropped"] > 0
    assert any(e["kind"] == "link_lost" for e in run["events"])
