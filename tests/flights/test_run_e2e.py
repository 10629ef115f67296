"""`gcs mission run` end to end: real `gcs` and `vehicles` processes over loopback UDP.

The small mission (examples/small.yaml: 4 UAVs, two speed changes, the second one asked by
UAV 2 as leader) flies at speedup 10 and must complete within the guarantees; a second run
loses a vehicle process mid-flight and must freeze, report it, land the others and exit 1.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.flying import (
    Flight,
    children_running,
    environment,
    flight_speedup,
    gcs_command,
    read_log,
)

REPO = Path(__file__).resolve().parents[2]
MISSION = REPO / "examples" / "small.yaml"
SPEEDUP = str(flight_speedup(5))  # lower on a busy machine (tests/flying.py)
#: UAV 2 (the leader) gets a process of its own anyway: [1], [2], [3, 4]
PER_PROCESS = ("--vehicles-per-process", "4")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]


def test_the_small_mission_flies_end_to_end(tmp_path: Path):
    log = tmp_path / "small.mcap"
    done = subprocess.run(
        gcs_command(
            "mission",
            "run",
            str(MISSION),
            "--speedup",
            SPEEDUP,
            *PER_PROCESS,
            "--json",
            "--log",
            str(log),
        ),  # fmt: skip
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=environment(),
        timeout=110,
    )
    assert done.stdout.count("\n") == 1, done.stderr  # exactly one JSON object on stdout
    run = json.loads(done.stdout)
    assert done.returncode == 0, (run.get("reason"), done.stderr[-3000:])
    assert run["completed"] is True
    assert run["log"] == str(log)
    size = run["fleet_size"]
    topics = read_log(log)
    plan = topics["/plan"][0][1]
    rho = plan["safety_margin_m"]

    # the guarantees, with the measured tracking error
    tracking = run["max_tracking_error_m"]
    assert tracking < rho
    assert run["min_uav_uav_m"] >= 2 * rho - 2 * tracking
    assert run["min_uav_obstacle_m"] >= rho - tracking
    assert run["connected_fraction"] == 1.0
    assert run["duration_s"] > plan["duration_s"]

    # every UAV landed on its arrival slot (true positions, from the recording)
    slots = np.array(plan["parking_slots"]["B"])
    for uav in range(1, size + 1):
        last = topics[f"/uav{uav}/state"][-1][1]
        assert last["phase"] == "landed"
        x, y, z = last["true_position"]
        assert np.hypot(x - slots[uav - 1][0], y - slots[uav - 1][1]) < 1.5
        assert z < 0.5
        assert run["per_uav"][uav - 1]["phase"] == "landed"

    # two speed changes, the second asked by UAV 2 as leader; every UAV acknowledged both
    changes = run["speed_changes"]
    assert [c["source"] for c in changes] == ["schedule", "leader:2"]
    assert changes[0]["effective_s"] == pytest.approx(20.0)
    assert changes[1]["effective_s"] > 35.0  # the request's arrival + the lead time
    for change in changes:
        assert sorted(change["acks"]) == [str(u) for u in range(1, size + 1)]
        assert all(0 <= delay < 1.0 for delay in change["acks"].values())
        assert (
            change["effective_s"] - change["requested_s"] >= run["budget"]["smoothing_window_s"] / 2
        )

    # every UAV's target changes speed at the same effective time: each UAV in the air then
    # switches between the two setpoints around it; the formation's metrics switch there too
    period = 1.0 / 10.0
    metrics = [m for _, m in topics["/metrics"]]
    for change in changes:
        switch = []
        for uav in range(1, size + 1):
            points = [m for _, m in topics[f"/uav{uav}/setpoint"]]
            times = np.array([m["t"] for m in points])
            near = np.abs(times - change["effective_s"]) < 2 * period
            if near.sum() < 2:
                continue  # on the ground then: no setpoints
            speeds = np.array([m["formation_speed"] for m in points])
            after = int(np.argmax(times >= change["effective_s"]))
            assert speeds[after] == change["speed"] != speeds[after - 1]
            assert times[after - 1] < change["effective_s"] <= times[after]
            assert times[after] - times[after - 1] < 2 * period
            switch.append(times[after])
            # its virtual target moves at the new speed right after (unless parked)
            targets = np.array([m["virtual_target"] for m in points])
            moved = np.hypot(*(targets[after + 3] - targets[after + 1]))
            moved /= times[after + 3] - times[after + 1]
            assert moved == pytest.approx(change["speed"], abs=0.05) or moved < 1e-6
        assert len(switch) >= 2
        assert max(switch) - min(switch) < period
        t = np.array([m["t"] for m in metrics])
        v = np.array([m["formation_speed"] for m in metrics])
        first = int(np.argmax(t >= change["effective_s"]))
        assert v[first] == change["speed"] != v[first - 1]

    # the recording holds every UAV's telemetry and the MAVLink both ways
    for uav in range(1, size + 1):
        assert len(topics[f"/mavlink/{uav}/rx"]) > 100
        assert len(topics[f"/mavlink/{uav}/tx"]) > 100
    times = [t for t, _ in topics["/uav1/setpoint"]]
    assert times == sorted(times)


def test_losing_a_vehicle_freezes_reports_and_lands_the_others(tmp_path: Path):
    log = tmp_path / "kill.mcap"
    flight = Flight(
        ["-v", "mission", "run", str(MISSION), "--speedup", SPEEDUP, *PER_PROCESS, "--json",
         "--log", str(log), "--link-wait", "3"],
        tmp_path,
    )  # fmt: skip
    try:
        flight.wait_for("UAV 2: taking_off -> following")

        # the operator, from another terminal: one change accepted, one refused
        speed = subprocess.run(
            gcs_command("speed", "6", "--log", str(log)),
            capture_output=True, text=True, cwd=tmp_path, env=environment(), timeout=20,
        )  # fmt: skip
        assert speed.returncode == 0, speed.stderr
        assert "6 m/s at mission time" in speed.stdout
        too_fast = subprocess.run(
            gcs_command("speed", "99", "--log", str(log)),
            capture_output=True, text=True, cwd=tmp_path, env=environment(), timeout=20,
        )  # fmt: skip
        assert too_fast.returncode == 1 and "refused" in too_fast.stderr

        # every UAV following first: a formation already frozen for a late take-off stays
        # frozen (relabelled "link") and broadcasts no freeze of its own
        flight.wait_for("UAV 4: taking_off -> following")
        vehicles = children_running(flight.pid, "-m vehicles sim")
        assert len(vehicles) == 3
        (vehicle,) = children_running(flight.pid, "--sysid-base 2 ")
        os.kill(vehicle, signal.SIGKILL)
        code, out, err = flight.finish(timeout=60)
    finally:
        flight.kill()
    assert code == 1, err[-3000:]
    run = json.loads(out)
    assert run["completed"] is False
    assert "UAV 2" in run["reason"]
    kinds = [(e["kind"], e["uav"]) for e in run["events"]]
    assert ("link_lost", 2) in kinds
    sources = [c["source"] for c in run["speed_changes"]]
    assert "operator" in sources
    operator = run["speed_changes"][sources.index("operator")]
    assert operator["speed"] == 6 and len(operator["acks"]) == run["fleet_size"]
    assert "freeze:link" in sources, (sources, [e["text"] for e in run["events"]])
    freeze = run["speed_changes"][sources.index("freeze:link")]
    assert freeze["speed"] == 0 and freeze["effective_s"] > freeze["requested_s"]
    assert "2" not in freeze["acks"] and len(freeze["acks"]) == run["fleet_size"] - 1
    phases = [u["phase"] for u in run["per_uav"]]
    assert phases[1] != "landed" and all(p == "landed" for i, p in enumerate(phases) if i != 1)
    # the vehicles were all stopped, and the log is readable, with the events
    for pid in vehicles:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    events = [m for _, m in read_log(log).get("/speed", [])]
    assert any(m.get("source") == "freeze:link" for m in events)


def test_ctrl_c_once_freezes_twice_lands_everyone_where_they_are(tmp_path: Path):
    log = tmp_path / "interrupted.mcap"
    flight = Flight(
        ["-v", "mission", "run", str(MISSION), "--speedup", SPEEDUP, *PER_PROCESS, "--json",
         "--log", str(log)],
        tmp_path,
    )  # fmt: skip
    try:
        flight.wait_for("UAV 1: taking_off -> following")
        os.kill(flight.pid, signal.SIGINT)
        flight.wait_for("(freeze:operator)")
        os.kill(flight.pid, signal.SIGINT)
        code, out, err = flight.finish(timeout=60)
    finally:
        flight.kill()
    assert code == 1, err[-3000:]
    run = json.loads(out)
    assert run["completed"] is False and "interrupted" in run["reason"]
    freeze = [c for c in run["speed_changes"] if c["source"] == "freeze:operator"]
    assert len(freeze) == 1 and freeze[0]["speed"] == 0
    assert len(freeze[0]["acks"]) == run["fleet_size"]
    kinds = [e["kind"] for e in run["events"]]
    assert kinds.index("interrupt") < kinds.index("abort")
    # everyone is down; UAV 1 landed where it was, far from its arrival slot
    assert all(u["phase"] == "landed" for u in run["per_uav"])
    assert run["per_uav"][0]["landing_error_m"] > 20
