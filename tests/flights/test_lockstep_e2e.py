"""Lockstep end to end (real `gcs`, `vehicles` and radio medium processes over loopback UDP):
one process of the simulated world stopped (SIGSTOP) pauses all of it, the ground station
included, and the flight goes on as if nothing happened: no setpoint timeout, no lost link,
no stall, no hold, tracking within rho_c (docs/ARCHITECTURE.md, "Time on a busy machine").

One flight of the small mission with its radio medium: once every UAV follows the formation,
one vehicle process is stopped for 0.5 s, the medium for 2 s, the same vehicle process for 6 s
and the ground station for 2 s (wall), one after the other."""

from __future__ import annotations

import json
import os
import signal
import time

import pytest

from gcs.recording.logreader import read_recording
from tests.flying import Flight, children_running, flight_speedup, mission_file

pytestmark = [pytest.mark.slow, pytest.mark.timeout(180)]

SPEEDUP = flight_speedup(5)
ALL_FOLLOWING = "UAV 4: taking_off -> following"
#: (what, wall seconds): the processes stopped, in this order
STOPS = (("vehicles", 0.5), ("medium", 2.0), ("vehicles", 6.0), ("gcs", 2.0))


@pytest.fixture(scope="module")
def stopped(tmp_path_factory):
    folder = tmp_path_factory.mktemp("lockstep")
    mission = mission_file(folder, radio={"enabled": True})
    log = folder / "lockstep.mcap"
    flight = Flight(
        ["-v", "mission", "run", str(mission), "--speedup", str(SPEEDUP),
         "--vehicles-per-process", "4", "--json", "--log", str(log)],
        folder,
    )  # fmt: skip
    try:
        flight.wait_for(ALL_FOLLOWING, timeout=90)
        pids = {
            # one of the vehicle processes (the leader, UAV 2, flies in one of its own)
            "vehicles": children_running(flight.pid, "-m vehicles sim")[-1:],
            "medium": children_running(flight.pid, "medium.cli"),
            "gcs": [flight.pid],
        }
        assert len(pids["vehicles"]) == 1 and len(pids["medium"]) == 1, pids
        for what, seconds in STOPS:
            (pid,) = pids[what]
            os.kill(pid, signal.SIGSTOP)
            time.sleep(seconds)  # the fault itself: the process stays stopped this long
            os.kill(pid, signal.SIGCONT)
        code, out, err = flight.finish(timeout=120)
    finally:
        flight.kill()
    return {"code": code, "run": json.loads(out) if out.strip() else {}, "err": err, "log": log}


def test_the_stopped_world_flies_on_as_if_nothing_happened(stopped):
    run = stopped["run"]
    assert stopped["code"] == 0, stopped["err"][-3000:]
    assert run["completed"] is True
    assert run["max_tracking_error_m"] < 5.0  # rho_c of the small mission
    assert run["holds"] == []  # no UAV fell behind: the world waited
    assert run["stalls"] == []  # the ground station's stop was the world's
    kinds = {event["kind"] for event in run["events"]}
    assert "link_lost" not in kinds and "tracking" not in kinds


def test_the_ground_station_waited_for_the_world_as_long_as_it_stood_still(stopped):
    lockstep = stopped["run"]["lockstep"]
    assert lockstep["enabled"] is True and lockstep["released"] == []
    stopped_s = sum(seconds for _, seconds in STOPS) * SPEEDUP  # mission seconds not flown
    assert 0.9 * stopped_s <= lockstep["held_s"] <= 1.1 * stopped_s + 2.0
    recording = read_recording(stopped["log"], keep=lambda t: t in ("/metrics", "/events"))
    *_, (_, metrics) = recording.messages("/metrics")
    assert metrics["world_held_s"] == pytest.approx(lockstep["held_s"], abs=0.5)


def test_no_vehicle_saw_its_setpoints_stop(stopped):
    """The vehicles' own setpoint timeout never fired: they stood still with the world."""
    recording = read_recording(stopped["log"], keep=lambda topic: topic == "/events")
    texts = [message.message for _, message in recording.messages("/events")]
    assert texts and not any("no setpoint" in text for text in texts)
    assert not any("GCS Failsafe" in text for text in texts)
