"""Simulated vehicles: fleet size one core keeps in real time, and the speedup reached for 9.

Each run starts a real ``vehicles sim --count N`` process (100 Hz dynamics, 10 Hz position
telemetry plus the 1 Hz status messages) and drives it like a GCS over UDP: GUIDED, arm,
take off, then a setpoint (GLOBAL_INT, relative altitude) to every vehicle at 10 Hz and a
heartbeat at 1 Hz, both in simulated time. Measured: the CPU the vehicle process uses, the
telemetry received against what the rates promise, and whether the simulated clock kept up
(it slips, and says so, when it falls more than 1 s of wall clock behind).
"""

from __future__ import annotations

import os
import re
import socket
import time
from dataclasses import dataclass

import pymap3d
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from rich.console import Console
from rich.table import Table

from vehicles.sim import DEFAULT_ORIGIN
from vehicles.testing import VehicleProcess

SPACING_M = 5.0  # the default start row of `vehicles sim`
WARM_UP_S = 4.0  # boot, arm and climb (simulated seconds)
TELEMETRY_PER_SIM_S = 10 * 4 + 4 + 1  # 10 Hz x 4 + 1 Hz x 4 + heartbeat (see TelemetryRates)


@dataclass(frozen=True)
class Run:
    count: int
    speedup: float
    cpu_fraction: float  # of one core, while measuring
    achieved_speedup: float  # simulated / wall seconds while measuring (from telemetry time stamps)
    slipped_s: float
    telemetry_fraction: float  # received / promised by the rates at the achieved speedup

    @property
    def real_time(self) -> bool:
        kept_pace = self.achieved_speedup >= 0.97 * min(self.speedup, 1e9)
        return self.slipped_s == 0.0 and kept_pace and self.telemetry_fraction > 0.95


def _cpu_seconds(pid: int) -> float:
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _frames(count: int) -> tuple[bytes, list[list[bytes]], list[bytes]]:
    """Pre-packed GCS frames: heartbeat, per-vehicle set-up commands, per-vehicle setpoint."""
    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    heartbeat = mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(gcs)
    setup, setpoints = [], []
    origin = (DEFAULT_ORIGIN.lat, DEFAULT_ORIGIN.lon, DEFAULT_ORIGIN.alt)
    for k in range(count):
        sysid = k + 1
        setup.append(
            [
                mavlink.MAVLink_command_long_message(sysid, 1, 176, 0, 1, 4, 0, 0, 0, 0, 0).pack(
                    gcs
                ),
                mavlink.MAVLink_command_long_message(sysid, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(
                    gcs
                ),
                mavlink.MAVLink_command_long_message(sysid, 1, 22, 0, 0, 0, 0, 0, 0, 0, 10.0).pack(
                    gcs
                ),
            ]
        )
        lat, lon, _ = pymap3d.enu2geodetic(k * SPACING_M, 0.0, 0.0, *origin)
        setpoints.append(
            mavlink.MAVLink_set_position_target_global_int_message(
                0, sysid, 1, 6, 3520, int(lat * 1e7), int(lon * 1e7), 10.0, 0, 0, 0, 0, 0, 0, 0, 0
            ).pack(gcs)
        )
    return heartbeat, setup, setpoints


def measure(  # noqa: C901 (over 15 branches: to split)
    count: int, speedup: float, measure_s: float, drive_speedup: float | None = None
) -> Run:
    """Drive ``count`` vehicles at ``speedup`` for ``measure_s`` wall seconds after a warm-up
    (the GCS side paces its heartbeats and setpoints for ``drive_speedup``, default the same)."""
    drive = speedup if drive_speedup is None else drive_speedup
    heartbeat, setup, setpoints = _frames(count)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # bound first: its ephemeral port
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 23)  # cannot land in the range
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    process = VehicleProcess(count=count, speedup=speedup, args=["--boot-time", "0.5"])
    ports = [("127.0.0.1", process.port(k)) for k in range(count)]
    received = 0
    decoder = mavlink.MAVLink(None)
    decoder.robust_parsing = True
    clock: list[tuple[float, float]] = []  # (wall, vehicle time) samples from the telemetry

    def drain() -> None:
        nonlocal received
        while True:
            try:
                data = sock.recv(65535)
            except BlockingIOError:
                return
            messages = decoder.parse_buffer(data) or []  # a datagram holds a tick's messages
            received += len(messages)
            boot_ms = getattr(messages[0], "time_boot_ms", None) if messages else None
            if boot_ms is not None:
                clock.append((time.monotonic(), boot_ms / 1000.0))

    def send_all(frame_of) -> None:
        for k, address in enumerate(ports):
            try:
                sock.sendto(frame_of(k), address)
            except OSError:
                pass

    try:
        start = time.monotonic()
        setup_at = start + 1.0 / drive + 0.3  # after the vehicles' boot time
        phase = 0
        next_setpoint = next_heartbeat = start
        measure_from = start + WARM_UP_S / drive + 1.0
        cpu0 = wall0 = received0 = None
        while True:
            now = time.monotonic()
            if now >= next_heartbeat:
                send_all(lambda k: heartbeat)
                next_heartbeat += 1.0 / drive
            if phase < 3 and now >= setup_at:
                send_all(lambda k, p=phase: setup[k][p])
                phase += 1
                setup_at = now + 0.2 / drive + 0.02
            if phase == 3 and now >= next_setpoint:
                send_all(lambda k: setpoints[k])
                next_setpoint += 0.1 / drive
                if next_setpoint < now:
                    next_setpoint = now + 0.1 / drive
            drain()
            if cpu0 is None and now >= measure_from:
                cpu0, wall0, received0 = _cpu_seconds(process.pid()), now, received
            if cpu0 is not None and now - wall0 >= measure_s:
                cpu = _cpu_seconds(process.pid()) - cpu0
                wall = now - wall0
                got = received - received0
                break
            time.sleep(min(0.0005, max(0.0, min(next_heartbeat, next_setpoint) - time.monotonic())))
    finally:
        sock.close()
        code, stderr = process.stop()
    if code != 0:
        raise RuntimeError(f"vehicles sim --count {count} exited with {code}: {stderr.strip()}")
    _, slipped = _parse_summary(stderr)
    window = [(w, v) for w, v in clock if wall0 <= w <= wall0 + wall]
    achieved = (
        (window[-1][1] - window[0][1]) / (window[-1][0] - window[0][0]) if len(window) > 1 else 0.0
    )
    expected = count * TELEMETRY_PER_SIM_S * achieved * wall
    return Run(count, speedup, cpu / wall, achieved, slipped, min(got / max(expected, 1.0), 9.99))


def _parse_summary(stderr: str) -> tuple[float, float]:
    """(simulated / wall seconds, seconds slipped) from the process's own summary."""
    stopped = re.search(r"stopped after ([\d.]+) s simulated in ([\d.]+) s", stderr)
    slipped = sum(float(s) for s in re.findall(r"simulation ([\d.]+) s behind", stderr))
    slipped = max(
        slipped,
        float(re.search(r"clock slipped ([\d.]+) s", stderr).group(1))
        if "clock slipped" in stderr
        else 0.0,
    )
    ratio = float(stopped.group(1)) / max(float(stopped.group(2)), 1e-9) if stopped else 0.0
    return ratio, slipped


def main() -> None:
    console = Console()
    runs = [
        measure(count, 1.0, measure_s=5.0) for count in (100, 200, 254)
    ]  # 254: all the system ids
    runs += [measure(9, speedup, measure_s=4.0) for speedup in (20.0, 40.0)]
    runs.append(measure(9, 1000.0, measure_s=4.0, drive_speedup=30.0))  # as fast as it goes
    table = Table(
        title="vehicles sim: one process, 100 Hz dynamics, 10 Hz telemetry, 10 Hz setpoints in"
    )
    for column in (
        "vehicles",
        "speedup asked",
        "speedup reached",
        "CPU (cores)",
        "telemetry rx",
        "kept up",
    ):
        table.add_column(column, justify="right")
    for run in runs:
        table.add_row(
            str(run.count),
            f"{run.speedup:g}x" if run.speedup < 1000 else "max",
            f"{run.achieved_speedup:.1f}x",
            f"{run.cpu_fraction:.2f}",
            f"{run.telemetry_fraction:.0%}",
            "yes" if run.real_time else "no",
        )
    console.print(table)
    real_time = [r for r in runs if r.speedup == 1.0]
    per_core = (
        max(r.count / max(r.cpu_fraction, 1e-3) for r in real_time if r.real_time)
        if real_time
        else 0.0
    )
    fastest = runs[-1]
    console.print(
        f"real time on one core: about {per_core:.0f} vehicles (target >= 200); "
        f"9 vehicles: {fastest.achieved_speedup:.0f}x at most with {fastest.cpu_fraction:.2f} of a core, "
        f"about {fastest.achieved_speedup / max(fastest.cpu_fraction, 1e-3):.0f}x per full core (target >= 20x)"
    )


if __name__ == "__main__":
    main()
