"""GCS streaming capacity: how many UAVs one GCS process streams setpoints to at 50 Hz.

For fleet sizes N, the real scheduler loop (`GroundStation.fly`) streams
SET_POSITION_TARGET_GLOBAL_INT with feed-forward from the smoothed reference to N plain UDP
sinks on loopback (bound sockets nobody reads: no simulated vehicle competes for the CPU),
with the MCAP recording on (every setpoint and every MAVLink message recorded). Reported: the
achieved rate, the p99 of |period - 20 ms|, and the GCS's CPU time per UAV. The fleet size
is the largest N whose p99 jitter stays under 5 ms (target: at least 100 UAVs).

    .venv/bin/python -m bench gcs
"""

from __future__ import annotations

import os
import socket
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from gcs.drivers.base import DriverTiming, Phase
from gcs.drivers.sim import SimDriver
from gcs.flight.assembly import assemble
from gcs.flight.clock import MissionClock
from gcs.flight.core import RunOptions
from gcs.flight.live import LiveLoop
from gcs.mission import parse_mission
from gcs.recording.recording import FlightRecorder
from gcs.transport.link import Link
from planner.formation import min_fleet_size, parking_rows
from planner.kinematics import LineFormation, SpeedProfile

RATE_HZ = 50.0
JITTER_TARGET_MS = 5.0
SIZES = (25, 50, 100, 150, 200, 250)
SECONDS = 4.0


@dataclass(frozen=True, eq=False)
class _Speeds:
    max: float
    initial: float
    changes: tuple = ()


@dataclass(frozen=True, eq=False)
class _Plan:
    """What `GroundStation` reads of a `MissionPlan`: a straight path, no planner search needed."""

    mission: object
    formation: LineFormation
    speeds: _Speeds
    profile: SpeedProfile
    smoothing_error_m: float = 0.0


def _plan(size: int) -> _Plan:
    length = 200.0 * size  # eq. 28 then asks for at most `size` UAVs
    mission = parse_mission(
        {
            "version": 1,
            "name": "bench",
            "start": {"x": 0, "y": 0},
            "goal": {"x": length, "y": 0},
            "safety_margin": 5,
            "radio_range": 220,
            "altitude": 30,
            "speed": {"max": 10},
            "sim": {"setpoint_rate_hz": RATE_HZ},
        },
        Path("bench.yaml"),
    )
    assert size >= min_fleet_size(length, 5, 220)
    rows = parking_rows(np.zeros(2), np.array([length, 0.0]), 0, 0, size, 5.0)
    formation = LineFormation(
        path=np.array([[0.0, 0.0], [length, 0.0]]),
        fleet_size=size,
        safety_margin=5.0,
        radio_range=220.0,
        rows=rows,
    )
    return _Plan(mission, formation, _Speeds(10.0, 10.0), SpeedProfile.constant(10.0))


def measure(size: int, seconds: float, directory: Path) -> dict:
    """Stream to `size` sinks for `seconds`; return rate, jitter, CPU per UAV."""
    plan = _plan(size)
    sinks = []
    for _ in range(size):
        sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sink.bind(("127.0.0.1", 0))
        sinks.append(sink)
    clock = MissionClock(1.0)
    recorder = FlightRecorder(directory / f"bench-{size}.mcap", clock, force=True)
    options = RunOptions(
        setpoint_rate_hz=RATE_HZ, link_timeout_s=1e9, link_wall_floor_s=1e9, takeoff_lead_s=1.0
    )
    links = [
        Link(f"udpout:127.0.0.1:{sink.getsockname()[1]}", uav, capture=_capture(recorder, uav))
        for uav, sink in enumerate(sinks, start=1)
    ]
    run = assemble(plan, links, SimDriver, DriverTiming(), clock, recorder, options)
    drivers = run.drivers
    for driver in drivers:
        driver.phase = Phase.FOLLOWING  # airborne from the start: streaming only
    loop = LiveLoop(run)
    for track in run.tracks:
        track.takeoff_sent = True
    began = time.monotonic()
    for link in links:
        link.last_valid_time = began  # sinks never answer: keep the link monitor quiet
    clock.anchor(began, 10.0)
    cpu = time.process_time()
    loop.fly(until=lambda wall: wall - began >= seconds)
    cpu = time.process_time() - cpu
    elapsed = time.monotonic() - began
    walls = np.array(run._tick_walls)
    periods = np.diff(walls)
    jitter = np.abs(periods - 1.0 / RATE_HZ) * 1000
    recorder.close()
    for link in links:
        link.close()
    for sink in sinks:
        sink.close()
    work = np.array(loop.tick_work) * 1000
    return {
        "size": size,
        "work_p99_ms": float(np.percentile(work, 99)),
        "rate_hz": float(1.0 / periods.mean()),
        "jitter_p50_ms": float(np.percentile(jitter, 50)),
        "jitter_p99_ms": float(np.percentile(jitter, 99)),
        "cpu_percent": 100.0 * cpu / elapsed,
        "cpu_per_uav_ms_s": 1000.0 * cpu / elapsed / size,
        "setpoints": sum(d.setpoints_sent for d in drivers),
        "recorded": recorder.messages,
        "log_mb": os.path.getsize(directory / f"bench-{size}.mcap") / 1e6,
    }


def _capture(recorder: FlightRecorder, uav: int):
    def capture(direction: str, raw: bytes, message, wall: float) -> None:
        recorder.mavlink(uav, direction, raw, message, wall)

    return capture


def main() -> None:
    console = Console()
    table = Table(
        title=f"GCS streaming at {RATE_HZ:g} Hz to N UDP sinks, recording on ({SECONDS:g} s each)"
    )
    # jitter: |period - 20 ms| (ms); tick: wall time one tick took (ms); CPU/UAV in ms per s
    for name in (
        "UAVs",
        "rate Hz",
        "jitter p50",
        "jitter p99",
        "tick p99",
        "CPU %",
        "CPU/UAV",
        "records",
        "MB",
    ):
        table.add_column(name, justify="right")
    best = 0
    with tempfile.TemporaryDirectory() as tmp:
        for size in SIZES:
            row = measure(size, SECONDS, Path(tmp))
            ok = row["jitter_p99_ms"] < JITTER_TARGET_MS
            if ok:
                best = size
            table.add_row(
                str(size),
                f"{row['rate_hz']:.2f}",
                f"{row['jitter_p50_ms']:.2f}",
                f"[{'green' if ok else 'red'}]{row['jitter_p99_ms']:.2f}[/]",
                f"{row['work_p99_ms']:.2f}",
                f"{row['cpu_percent']:.0f}",
                f"{row['cpu_per_uav_ms_s']:.2f}",
                str(row["recorded"]),
                f"{row['log_mb']:.1f}",
            )
            if row["jitter_p99_ms"] > 4 * JITTER_TARGET_MS:
                break  # far beyond: larger fleets only take longer to fail
    console.print(table)
    console.print(
        f"fleet size streamed at {RATE_HZ:g} Hz with p99 jitter < {JITTER_TARGET_MS:g} ms: "
        f"[bold]{best}[/] UAVs (target >= 100). jitter = |period - {1000 / RATE_HZ:g} ms| and "
        "tick = wall time of one scheduler tick, in ms; CPU/UAV = ms of GCS CPU per second per "
        "UAV. Jitter also counts other processes taking the CPU: run it on a quiet machine."
    )


if __name__ == "__main__":
    main()
