"""Radio medium: latency it adds per packet at infinite range, packets per second it forwards,
and how fast the fast in-process mode flies.

Latency: a real `python -m medium.cli` process with an infinite range, 0 ms per hop
and no jitter (so only the process itself delays), between a "GCS" socket and "vehicle"
sockets of this process on loopback; one datagram at a time, each way, against the same
exchange without the medium. Throughput: bursts of 200 datagrams to every UAV's port, counted
at the vehicle sockets. Fast mode: `gcs.sim.fastsim.fly_fast` on the example missions.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from vehicles.testing import free_udp_ports

REPO = Path(__file__).resolve().parents[1]
PACKETS = 2000
BURST = 200
PAYLOAD = bytes(60)  # about a setpoint's size


def _medium(count: int, listen: int, vehicle_ports: list[int]) -> subprocess.Popen:
    positions = ";".join(f"{1000 * k},0" for k in range(count))  # far apart: range is inf
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "medium.cli",
            "--count",
            str(count),
            "--base-port",
            str(listen),
            "--vehicle-ports",
            ",".join(map(str, vehicle_ports)),
            f"--positions={positions}",
            "--stations=0,0",
            "--range",
            "inf",
            "--hop-latency-ms",
            "0",
            "--jitter-ms",
            "0",
        ],  # fmt: skip
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def _cpu_seconds(pid: int) -> float:
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _one_way(sender: socket.socket, receiver: socket.socket, address) -> float:
    began = time.perf_counter()
    sender.sendto(PAYLOAD, address)
    receiver.recvfrom(2048)
    return time.perf_counter() - began


def _round_trips(gcs, vehicles, targets, count: int) -> tuple[np.ndarray, np.ndarray]:
    """One-way times GCS -> vehicle k and vehicle k -> GCS (through `targets[k]`)."""
    down, up = [], []
    for i in range(count):
        k = i % len(vehicles)
        down.append(_one_way(gcs, vehicles[k], targets[k][0]))
        up.append(_one_way(vehicles[k], gcs, targets[k][1]))
    return np.array(down), np.array(up)


def measure(count: int) -> dict:
    vehicles = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(count)]
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for sock in [*vehicles, gcs]:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(2.0)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
    gcs_address = gcs.getsockname()
    # direct: GCS <-> vehicle sockets
    direct = [(v.getsockname(), gcs_address) for v in vehicles]
    base_down, base_up = _round_trips(gcs, vehicles, direct, PACKETS)
    listen = free_udp_ports(count)
    process = _medium(count, listen, [v.getsockname()[1] for v in vehicles])
    try:
        through = []
        for k, vehicle in enumerate(vehicles):  # wait until the medium forwards
            deadline = time.monotonic() + 20
            while True:
                gcs.sendto(PAYLOAD, ("127.0.0.1", listen + k))
                vehicle.settimeout(0.2)
                try:
                    _, medium_side = vehicle.recvfrom(2048)
                    break
                except TimeoutError:
                    if time.monotonic() > deadline:
                        raise RuntimeError("the medium did not start") from None
            vehicle.settimeout(2.0)
            through.append((("127.0.0.1", listen + k), medium_side))
        cpu0 = _cpu_seconds(process.pid)
        wall0 = time.perf_counter()
        down, up = _round_trips(gcs, vehicles, through, PACKETS)
        latency_cpu = (_cpu_seconds(process.pid) - cpu0) / (time.perf_counter() - wall0)
        # throughput: bursts to every UAV, counted where they land
        for vehicle in vehicles:
            vehicle.setblocking(False)
        sent = received = 0
        began = time.perf_counter()
        cpu0 = _cpu_seconds(process.pid)
        while time.perf_counter() - began < 3.0:
            for i in range(BURST):
                gcs.sendto(PAYLOAD, through[i % count][0])
            sent += BURST
            settle = time.perf_counter() + 0.05
            got = 0
            while got < BURST and time.perf_counter() < settle:
                for vehicle in vehicles:
                    try:
                        while True:
                            vehicle.recvfrom(2048)
                            got += 1
                    except BlockingIOError:
                        pass
            received += got
        elapsed = time.perf_counter() - began
        throughput_cpu = (_cpu_seconds(process.pid) - cpu0) / elapsed
    finally:
        process.terminate()
        process.wait(timeout=10)
        for sock in [*vehicles, gcs]:
            sock.close()
    added = np.concatenate([down - np.median(base_down), up - np.median(base_up)]) * 1000
    return {
        "count": count,
        "added_median_ms": float(np.median(added)),
        "added_p99_ms": float(np.percentile(added, 99)),
        "direct_median_ms": float(np.median(np.concatenate([base_down, base_up])) * 1000),
        "latency_cpu": latency_cpu,
        "packets_per_s": received / elapsed,
        "delivered": received / max(sent, 1),
        "throughput_cpu": throughput_cpu,
    }


def fast_mode() -> list[tuple[str, float, float]]:
    from gcs.mission import load_mission
    from gcs.planning import plan_mission
    from gcs.sim.fastsim import fly_fast

    out = []
    for name in ("small", "table-ii"):
        plan = plan_mission(load_mission(REPO / "examples" / f"{name}.yaml"))
        began = time.perf_counter()
        run = fly_fast(plan)
        wall = time.perf_counter() - began
        out.append((f"{name} ({plan.fleet_size} UAVs)", float(run.times[-1] - run.times[0]), wall))
    return out


def main() -> None:
    console = Console()
    table = Table(title="radio medium process (infinite range, 0 ms per hop: the process only)")
    for name in ("UAVs", "direct", "added p50", "added p99", "CPU", "pkt/s", "delivered",
                 "CPU flat out"):  # fmt: skip
        table.add_column(name, justify="right")
    for count in (1, 9):
        r = measure(count)
        table.add_row(
            str(r["count"]),
            f"{r['direct_median_ms']:.3f} ms",
            f"{r['added_median_ms']:.3f} ms",
            f"{r['added_p99_ms']:.3f} ms",
            f"{100 * r['latency_cpu']:.0f} %",
            f"{r['packets_per_s']:.0f}",
            f"{100 * r['delivered']:.1f} %",
            f"{100 * r['throughput_cpu']:.0f} %",
        )
    console.print(table)
    fast = Table(title="fast in-process mode (gcs.sim.fastsim)")
    for name in ("mission", "simulated", "wall", "x real time"):
        fast.add_column(name, justify="right")
    for name, simulated, wall in fast_mode():
        fast.add_row(name, f"{simulated:.0f} s", f"{wall:.1f} s", f"{simulated / wall:.0f}")
    console.print(fast)


if __name__ == "__main__":
    main()
