"""Helpers of the tests that fly missions over real loopback UDP with real `gcs` and `vehicles`
processes: start the ground station, read its output while it flies, find its processes and
their sockets (as an attacker on the same host would: /proc), read its recording, put a lossy
or tampering UDP proxy between the ground station and the vehicles.
"""

from __future__ import annotations

import json
import os
import random
import selectors
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import yaml
from mcap.reader import make_reader

from gcs.sim.cpu import affordable_speedup
from gcs.sim.cpu import spare_cores as measure_spare_cores

REPO = Path(__file__).resolve().parents[1]
MISSION = REPO / "examples" / "small.yaml"


def flight_speedup(nominal: float) -> float:
    """The speed-up a test flight asks for: `nominal` when the machine has a core to spare,
    lower when it has not (`gcs.sim.cpu.affordable_speedup`, from `spare_cores`): on a busy
    machine a flight slows down, its guarantees (rho_c) stay what they are."""
    return affordable_speedup(nominal, spare_cores())


_SPARE_CORES: list[tuple[float, float]] = []  # (when measured, spare cores): one per minute


def spare_cores(window_s: float = 0.5, reuse_s: float = 60.0) -> float:
    """Cores idle now (`gcs.sim.cpu.spare_cores`). One measurement serves every flight of the
    next `reuse_s` (a module's constants, its tests)."""
    now = time.monotonic()
    if _SPARE_CORES and now - _SPARE_CORES[-1][0] < reuse_s:
        return _SPARE_CORES[-1][1]
    spare = measure_spare_cores(window_s)
    _SPARE_CORES.append((now, spare))
    return spare


def gcs_command(*args: str) -> list[str]:
    """`python -m gcs ARGS` (the console script's code) as a real subprocess command line."""
    return [sys.executable, "-m", "gcs", *args]


def environment() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return env


def read_log(path: Path) -> dict[str, list[tuple[int, dict]]]:
    """JSON topics of a recording: topic -> [(log_time, message)]."""
    topics: dict[str, list[tuple[int, dict]]] = {}
    with open(path, "rb") as handle:
        for _, channel, message in make_reader(handle).iter_messages():
            if channel.message_encoding == "json":
                topics.setdefault(channel.topic, []).append(
                    (message.log_time, json.loads(message.data))
                )
    return topics


def _parent_of(pid: int) -> int | None:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    return next(int(x.split()[1]) for x in status.splitlines() if x.startswith("PPid:"))


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def children_running(pid: int, needle: str) -> list[int]:
    """Processes whose parent is `pid` and whose command line contains `needle` (Linux)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and _parent_of(int(entry.name)) == pid:
            if needle in _cmdline(int(entry.name)):
                found.append(int(entry.name))
    return found


def alive(pid: int) -> bool:
    """The process exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def udp_ports(pid: int) -> list[int]:
    """Local ports of the UDP sockets process `pid` holds (its /proc fds -> /proc/net/udp),
    what `ss -ulpn` shows an attacker on the same host."""
    inodes = set()
    fd_dir = Path(f"/proc/{pid}/fd")
    try:
        for fd in fd_dir.iterdir():
            try:
                target = os.readlink(fd)
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[len("socket:[") : -1])
    except OSError:
        return []
    ports = []
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        parts = line.split()
        if parts[9] in inodes:
            ports.append(int(parts[1].split(":")[1], 16))
    return sorted(ports)


@dataclass
class Flight:
    """A `gcs mission run` process whose stderr is read all the time (so it never blocks on a
    full pipe) and searched for lines; stdout is kept for the end."""

    args: list[str]
    cwd: Path
    process: subprocess.Popen = field(init=False)
    lines: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.process = subprocess.Popen(
            gcs_command(*self.args),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=self.cwd,
            env=environment(),
        )
        self._changed = threading.Condition()
        self._stdout: list[str] = []
        self._readers = [
            threading.Thread(target=self._read, args=(self.process.stderr, self.lines)),
            threading.Thread(target=self._read, args=(self.process.stdout, self._stdout)),
        ]
        for reader in self._readers:
            reader.daemon = True
            reader.start()

    def _read(self, stream, into: list[str]) -> None:
        for line in stream:
            with self._changed:
                into.append(line)
                self._changed.notify_all()
        with self._changed:
            self._changed.notify_all()

    @property
    def pid(self) -> int:
        return self.process.pid

    def wait_for(self, needle: str | tuple[str, ...], timeout: float = 60.0, start: int = 0) -> int:
        """Index of the first stderr line from `start` on containing `needle` (or any of a
        tuple of needles)."""
        needles = (needle,) if isinstance(needle, str) else needle
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                for index in range(start, len(self.lines)):
                    if any(n in self.lines[index] for n in needles):
                        return index
                start = len(self.lines)
                remaining = deadline - time.monotonic()
                if remaining <= 0 or (self.process.poll() is not None and not self._reading()):
                    tail = "".join(self.lines[-30:])
                    raise AssertionError(f"never saw {needle!r}; last lines:\n{tail}")
                self._changed.wait(min(remaining, 0.5))

    def _reading(self) -> bool:
        return any(reader.is_alive() for reader in self._readers)

    def finish(self, timeout: float = 90.0) -> tuple[int, str, str]:
        """Wait for the end: (exit status, stdout, stderr)."""
        try:
            code = self.process.wait(timeout=timeout)
        finally:
            self.kill()
        for reader in self._readers:
            reader.join(timeout=10)
        return code, "".join(self._stdout), "".join(self.lines)

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()

    def stop(self, grace_s: float = 30.0) -> None:
        """SIGTERM (the GCS stops its vehicles on the way out), SIGKILL after `grace_s`."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=grace_s)
            except subprocess.TimeoutExpired:
                self.kill()


def mission_file(folder: Path, **changes) -> Path:
    """examples/small.yaml with top-level keys changed (a dict value is merged one level)."""
    data = yaml.safe_load(MISSION.read_text())
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(data.get(key), dict):
            data[key] = {**data[key], **value}
        else:
            data[key] = value
    path = folder / "mission.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def simulated_fleet(mission_path: Path, speedup: float, extra: tuple[str, ...] = ()):
    """The simulated vehicles `gcs mission run` would start for this mission (same homes,
    limits, noise, leaders), started by the test instead: a `SimFleet`, not yet started."""
    from gcs.cli.cmd_run import sim_setup
    from gcs.drivers.sim import SimFleet
    from gcs.mission import load_mission
    from gcs.planning import plan_mission

    mission = load_mission(mission_path)
    plan = plan_mission(mission)
    leaders: dict[int, list[tuple[float, float]]] = {}
    for change in mission.speed.changes:
        if change.leader is not None:
            leaders.setdefault(change.leader, []).append((change.at, change.speed))
    args = SimpleNamespace(speedup=speedup, vehicles_per_process=len(plan.formation.start_slots))
    setup = sim_setup(mission, plan.formation, args, leaders, mission_path.with_suffix(".mcap"))
    setup.extra_args = (*setup.extra_args, *extra)
    return SimFleet(setup)


#: Rewrites one datagram (direction "up" GCS->vehicle or "down", UAV id, bytes) -> bytes.
Rewrite = Callable[[str, int, bytes], bytes]


class UdpProxy:
    """Between the ground station and each vehicle: one loopback socket per UAV that the ground
    station's link points to; datagrams to the vehicle and back are forwarded, after dropping a
    fraction `loss` and reordering a fraction `reorder` (held back until the next datagram of the
    same direction, or 20 ms), both seeded; `rewrite` may change a datagram on the way."""

    def __init__(
        self,
        vehicle_ports: list[int],
        *,
        loss: float = 0.0,
        reorder: float = 0.0,
        seed: int = 1,
        rewrite: Rewrite | None = None,
    ) -> None:
        self.loss, self.reorder, self.rewrite = loss, reorder, rewrite
        self.random = random.Random(seed)
        self.sockets: list[socket.socket] = []
        self.vehicles = [("127.0.0.1", port) for port in vehicle_ports]
        self.gcs: list[tuple[str, int] | None] = [None] * len(vehicle_ports)
        self.counts = {"forwarded": 0, "dropped": 0, "reordered": 0}
        self._held: dict[tuple[int, str], tuple[float, bytes, tuple[str, int]]] = {}
        self._selector = selectors.DefaultSelector()
        for index in range(len(vehicle_ports)):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            sock.bind(("127.0.0.1", 0))
            sock.setblocking(False)
            self.sockets.append(sock)
            self._selector.register(sock, selectors.EVENT_READ, index)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    @property
    def urls(self) -> list[str]:
        return [f"udpout:127.0.0.1:{sock.getsockname()[1]}" for sock in self.sockets]

    def __enter__(self) -> UdpProxy:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self._selector.close()
        for sock in self.sockets:
            sock.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            for key, _ in self._selector.select(0.01):
                index = key.data
                sock = self.sockets[index]
                for _ in range(256):
                    try:
                        data, source = sock.recvfrom(65535)
                    except (BlockingIOError, InterruptedError):
                        break
                    except OSError:
                        continue
                    if source == self.vehicles[index]:
                        direction, target = "down", self.gcs[index]
                    else:
                        self.gcs[index] = source
                        direction, target = "up", self.vehicles[index]
                    if target is not None:
                        self._forward(index, direction, data, target)
            now = time.monotonic()
            for (index, direction), (since, data, target) in list(self._held.items()):
                if now - since > 0.02:
                    del self._held[(index, direction)]
                    self._send(index, data, target)

    def _forward(self, index: int, direction: str, data: bytes, target) -> None:
        if self.random.random() < self.loss:
            self.counts["dropped"] += 1
            return
        if self.rewrite is not None:
            data = self.rewrite(direction, index + 1, data)
        held = self._held.pop((index, direction), None)
        if held is None and self.random.random() < self.reorder:
            self._held[(index, direction)] = (time.monotonic(), data, target)
            self.counts["reordered"] += 1
            return
        self._send(index, data, target)
        if held is not None:  # the held one goes after the one that came later
            self._send(index, held[1], held[2])

    def _send(self, index: int, data: bytes, target) -> None:
        try:
            self.sockets[index].sendto(data, target)
            self.counts["forwarded"] += 1
        except OSError:
            self.counts["dropped"] += 1
