"""Flight recording: CPU cost per message, and per UAV at the 10 Hz setpoint rate.

The recorder (`gcs.recording.recording.FlightRecorder`) is fed what a flight of the simulated backend
produces, per UAV and per 0.1 s tick (counted in a recording of `examples/small.yaml`): four
telemetry messages received (GLOBAL_POSITION_INT, LOCAL_POSITION_NED, ATTITUDE, SIM_STATE),
six more once a second (HEARTBEAT, SYS_STATUS, ...), one setpoint sent (and two more messages
once a second), plus the fix, the state sample, the setpoint and its target fix; per tick for
the fleet `/metrics`, `/tf`, `/scene` and `/fleet`. The scene is the Table II map
(`examples/table-ii.yaml`, fleet size forced to N). CPU time is `time.process_time()`,
everything else (building the MAVLink messages and payloads) is done beforehand.

Targets (issue 5): at most 20 us per message on average.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from gcs.errors import InputError
from gcs.flight.clock import MissionClock
from gcs.flight.records import MetricsRecord, SetpointRecord, UavStateRecord
from gcs.mission import load_mission
from gcs.planning import plan_json, plan_mission
from gcs.recording.recording import FlightRecorder
from gcs.transport.link import mavutil

MISSION = Path(__file__).resolve().parents[1] / "examples" / "table-ii.yaml"
RATE_HZ = 10.0
TARGET_US = 20.0
SECONDS = 20.0  # mission seconds recorded per fleet size
FLEET_SIZES = (5, 9, 25, 50)  # Table II needs at least 5 (eq. 28)


class Wall:
    """The recorder's wall clock, moved by the benchmark (1x: mission time = wall time)."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def _messages(uav: int) -> dict[str, list]:
    """Pre-built MAVLink frames of UAV `uav`: (raw bytes, message) per kind."""
    mav = mavutil.mavlink.MAVLink(None, srcSystem=uav, srcComponent=1)
    gcs = mavutil.mavlink.MAVLink(None, srcSystem=255, srcComponent=190)

    def frame(link, message):
        return message.pack(link), message

    every_tick = [
        frame(mav, mav.global_position_int_encode(1000, 457640000, 48357000, 200000, 30000,
                                                  800, 300, 0, 9000)),
        frame(mav, mav.local_position_ned_encode(1000, 10.0, 20.0, -30.0, 8.0, 3.0, 0.0)),
        frame(mav, mav.attitude_encode(1000, 0.01, 0.02, 1.2, 0.0, 0.0, 0.1)),
        frame(mav, mav.sim_state_encode(1.0, 0.0, 0.0, 0.0, 0.01, 0.02, 1.2, 0.0, 0.0, 9.81,
                                        0.0, 0.0, 0.0, 45.764, 4.8357, 200.0, 1.0, 1.0,
                                        8.0, 3.0, 0.0)),
    ]  # fmt: skip
    every_second = [
        frame(mav, mav.heartbeat_encode(2, 3, 217, 4, 4)),
        frame(mav, mav.sys_status_encode(0, 0, 0, 500, 12600, 1000, 90, 0, 0, 0, 0, 0, 0)),
        frame(mav, mav.battery_status_encode(0, 1, 1, 3000, [4200] * 10, 1000, 500, 500, 90)),
        frame(mav, mav.extended_sys_state_encode(0, 2)),
        frame(mav, mav.vfr_hud_encode(8.0, 8.0, 90, 50, 30.0, 0.0)),
        frame(mav, mav.named_value_int_encode(1000, b"MSN_TIME", 12345)),
    ]
    sent = [frame(gcs, gcs.set_position_target_global_int_encode(
        1000, uav, 1, 6, 3520, 457640000, 48357000, 30.0, 8.0, 3.0, 0.0, 0, 0, 0, 0, 0))]  # fmt: skip
    sent_second = [
        frame(gcs, gcs.heartbeat_encode(6, 8, 0, 0, 4)),
        frame(gcs, gcs.named_value_int_encode(1000, b"MSN_TIME", 12345)),
    ]
    return {"rx": every_tick, "rx_1hz": every_second, "tx": sent, "tx_1hz": sent_second}


def _state(uav: int) -> UavStateRecord:
    """A following UAV's /uav<n>/state record, as the core writes one per position sample."""
    return UavStateRecord(t=0.0, uav=uav, phase="following", position=[1.0, 2.0, 30.0],
                          true_position=[1.0, 2.0, 30.0], armed=True, mode=4, landed_state=2,
                          velocity=[8.0, 3.0, 0.0], virtual_target=[1.0, 2.0],
                          tracking_error_m=0.4)  # fmt: skip


def _setpoint(uav: int) -> SetpointRecord:
    """A setpoint record as the core writes one per UAV and tick."""
    return SetpointRecord(t=0.0, uav=uav, position=[1.0, 2.0, 30.0], velocity=[8.0, 3.0, 0.0],
                          acceleration=[0.0, 0.0, 0.0], virtual_target=[1.0, 2.0],
                          formation_speed=10.0, distance=100.0, latitude=45.764,
                          longitude=4.8357, altitude=200.0, relative_altitude=30.0)  # fmt: skip


def _plan(size: int, folder: Path):
    """The Table II mission with `size` UAVs, planned."""
    text = MISSION.read_text().replace("size: 9 ", f"size: {size} ")
    (folder / f"mission-{size}.yaml").write_text(text)
    return plan_mission(load_mission(folder / f"mission-{size}.yaml"))


def record_fleet(size: int, seconds: float, folder: Path) -> dict:
    """Record `seconds` of a fleet of `size` at 10 Hz; CPU per message and per UAV."""
    plan = _plan(size, folder)
    wall = Wall()
    clock = MissionClock(1.0, monotonic=wall)
    path = folder / f"fleet-{size}.mcap"
    recorder = FlightRecorder(path, clock, force=True)
    recorder.describe(plan, plan_json(plan), wall.now)
    clock.anchor(wall.now, 0.0)
    frames = [_messages(uav) for uav in range(1, size + 1)]
    rng = np.random.default_rng(1)
    positions = np.column_stack([rng.uniform(0, 2000, (size, 2)), np.full(size, 30.0)])
    targets = positions[:, :2].copy()
    states = [_state(uav) for uav in range(1, size + 1)]
    setpoints = [_setpoint(uav) for uav in range(1, size + 1)]
    metrics = MetricsRecord(t=0.0, formation_speed=10.0, distance=100.0, min_uav_uav_m=14.1,
                            min_uav_obstacle_m=20.0, max_tracking_error_m=0.5,
                            tracking_error_m=[0.4] * size, connected=True,
                            positions=positions.tolist())  # fmt: skip
    ticks = int(seconds * RATE_HZ)
    before = recorder.messages
    cpu = time.process_time()
    for tick in range(ticks):
        wall.now += 1.0 / RATE_HZ
        now = wall.now
        t = tick / RATE_HZ
        second = tick % int(RATE_HZ) == 0
        for uav, kinds in enumerate(frames, start=1):
            for raw, message in kinds["rx"]:
                recorder.mavlink(uav, "rx", raw, message, now)
            recorder.fix(uav, 45.764, 4.8357, 200.0, now)
            recorder.state(states[uav - 1], now)
            for raw, message in kinds["tx"]:
                recorder.mavlink(uav, "tx", raw, message, now)
            recorder.setpoint(setpoints[uav - 1], now)
            if second:
                for raw, message in kinds["rx_1hz"]:
                    recorder.mavlink(uav, "rx", raw, message, now)
                for raw, message in kinds["tx_1hz"]:
                    recorder.mavlink(uav, "tx", raw, message, now)
        recorder.metrics(metrics, now)
        recorder.fleet(t, positions, targets, now)
    cpu = time.process_time() - cpu
    count = recorder.messages - before
    recorder.close()
    return {
        "size": size,
        "messages_per_s": count / seconds,
        "us_per_message": 1e6 * cpu / count,
        "ms_per_uav_s": 1e3 * cpu / seconds / size,
        "core_percent": 100.0 * cpu / seconds,
        "mb_per_min": path.stat().st_size / 1e6 / seconds * 60.0,
    }


def per_kind(folder: Path, count: int = 20_000) -> list[tuple[str, float]]:
    """CPU per message of each kind alone (us), on the small recorder."""
    plan = _plan(9, folder)
    wall = Wall()
    clock = MissionClock(1.0, monotonic=wall)
    recorder = FlightRecorder(folder / "kinds.mcap", clock, force=True)
    recorder.describe(plan, plan_json(plan), wall.now)
    clock.anchor(wall.now, 0.0)
    kinds = _messages(1)
    raw, message = kinds["rx"][0]
    sent, sent_message = kinds["tx"][0]
    positions = np.column_stack([np.linspace(0, 900, 9), np.zeros(9), np.full(9, 30.0)])
    state, setpoint = _state(1), _setpoint(1)
    cases = [
        ("MAVLink received (GLOBAL_POSITION_INT)", lambda: recorder.mavlink(1, "rx", raw, message, wall.now)),
        ("MAVLink sent (SET_POSITION_TARGET_GLOBAL_INT)", lambda: recorder.mavlink(1, "tx", sent, sent_message, wall.now)),
        ("foxglove.LocationFix (/uav1/fix)", lambda: recorder.fix(1, 45.764, 4.8357, 200.0, wall.now)),
        ("JSON state (/uav1/state)", lambda: recorder.state(state, wall.now)),
        ("setpoint JSON + target LocationFix (2 messages)", lambda: recorder.setpoint(setpoint, wall.now)),
        ("fleet tick, 9 UAVs: /tf + /scene + /fleet (3 messages)", lambda: recorder.fleet(1.0, positions, positions[:, :2], wall.now)),
    ]  # fmt: skip
    out = []
    for name, call in cases:
        repeat = count if "fleet" not in name else count // 20
        before = recorder.messages
        cpu = time.process_time()
        for _ in range(repeat):
            wall.now += 1e-4
            call()
        cpu = time.process_time() - cpu
        out.append((name, 1e6 * cpu / (recorder.messages - before)))
    recorder.close()
    return out


def main() -> None:
    console = Console()
    with tempfile.TemporaryDirectory(prefix="bench-recording-") as name:
        folder = Path(name)
        kinds = Table(title=f"recording: CPU per message by kind (target <= {TARGET_US:g} us)")
        kinds.add_column("message")
        kinds.add_column("us / message", justify="right")
        for label, us in per_kind(folder):
            kinds.add_row(label, f"{us:.1f}")
        console.print(kinds)
        fleet = Table(
            title=f"recording a flight at {RATE_HZ:g} Hz, real time (x K at --speedup K); "
            "Table II map"
        )
        for column in ("UAVs", "messages / s", "us / message", "CPU ms / s per UAV",
                       "% of a core", "log MB / min"):  # fmt: skip
            fleet.add_column(column, justify="right")
        for size in FLEET_SIZES:
            try:
                row = record_fleet(size, SECONDS, folder)
            except InputError as refused:  # a parking row the map cannot hold
                fleet.add_row(str(size), f"skipped: {refused}", "", "", "", "")
                continue
            mark = "" if row["us_per_message"] <= TARGET_US else " (over target)"
            fleet.add_row(
                str(size),
                f"{row['messages_per_s']:.0f}",
                f"{row['us_per_message']:.1f}{mark}",
                f"{row['ms_per_uav_s']:.2f}",
                f"{row['core_percent']:.1f}",
                f"{row['mb_per_min']:.2f}",
            )
        console.print(fleet)


if __name__ == "__main__":
    main()
