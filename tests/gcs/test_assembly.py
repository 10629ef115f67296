"""One assembly (`gcs.flight.assembly`): the live command, the fast mode and the streaming
benchmark build their drivers and ground station there, so what the fast mode shows is what a
live run flies. UAV n is system n, homed on start slot n, landing on landing slot n."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs.flight.assembly import uav_specs
from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.sim.fastsim import FastOptions, fly_fast

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize("name", ["small.yaml", "stations.yaml"])
def test_each_uav_is_told_its_system_id_slots_and_altitude(name):
    plan = plan_mission(load_mission(EXAMPLES / name))
    formation = plan.formation
    urls = [f"udpout:127.0.0.1:{14560 + k}" for k in range(formation.fleet_size)]
    specs = uav_specs(plan, urls)
    assert [s.uav_id for s in specs] == [s.system_id for s in specs]
    assert [s.uav_id for s in specs] == list(range(1, formation.fleet_size + 1))
    assert [s.url for s in specs] == urls
    assert np.array_equal([s.start_slot for s in specs], formation.start_slots)
    # a stations mission comes home to where it took off; a crossing lands beyond B
    landing = formation.start_slots if formation.stations is not None else formation.goal_slots
    assert np.array_equal([s.goal_slot for s in specs], landing)
    assert all(s.altitude == plan.mission.altitude and s.origin == plan.mission.origin
               for s in specs)  # fmt: skip


def test_the_fast_mode_reports_a_failed_recording_as_the_live_run_does(tmp_path):
    """The assembly hooks the recorder's failure into the run's events for every caller: the
    fast mode on a full disk completes its flight and says the recording stopped (it used to
    say nothing)."""
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full on this system")
    log = tmp_path / "full.mcap"
    log.symlink_to("/dev/full")
    plan = plan_mission(load_mission(EXAMPLES / "small.yaml"))
    run = fly_fast(plan, FastOptions(log=log))
    assert run.run_json["completed"]
    (event,) = [e for e in run.run_json["events"] if e["kind"] == "recording"]
    assert event["level"] == "error" and "full.mcap" in event["text"]
