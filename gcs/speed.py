"""Time-stamped speed changes (docs/design.md 4): who may ask, when they take effect, who
acknowledged.

A change is (effective mission time, new speed, sequence number). The formation's speed
profile changes at the effective time for every UAV at once (`SpeedProfile.with_change`), so
the line never compresses or stretches; each change is also broadcast to every UAV as
`COMMAND_INT MAV_CMD_DO_CHANGE_SPEED` (x = effective ms, y = seq), retransmitted by the driver
until that UAV's `COMMAND_ACK`; the time from the request to each receipt is the UAV's reaction
time T_dv.

Requests come from the mission's schedule (`at` is the effective time; broadcast ahead of it),
from the operator (`gcs speed V [--at T]` over `OperatorSocket`, or typed in the live view), and
from a UAV acting as leader (effective = arrival of its request + the lead time). The lead time
is the smallest advance every UAV can honour: at least half the smoothing window (the reference
at t looks w/2 ahead, docs/design.md 3.5), at least twice the worst reaction time seen so far,
and at least `min_lead_s`.

`OperatorSocket` is a Unix stream socket next to the run's log (`<log>.sock`, owner-only); one
JSON line in, one JSON line out. A speed change (`gcs speed`): `{"speed": 5, "at": 120}` (`at`
optional; `"command": "speed"` may be added) -> `{"ok": true, "seq": 3, "effective_s": 123.4,
"speed": 5}`; a stations mission's return home (`gcs return`): `{"command": "return", "at":
300}` (`at` optional) -> `{"ok": true, "effective_s": 300.0, "distance": 812.5}`; the relief
of one UAV of a stations mission (`gcs relieve N`): `{"command": "relieve", "uav": 2}` ->
`{"ok": true, "uav": 2, "effective_s": 123.4, "landing_xy": [x, y]}`; a refusal
`{"ok": false, "reason": "..."}`. Every answer also says `"result"`: `accepted`, or why not
(`bad_request`, `not_flying`, `landing`, `holding`, `refused`; `gcs.flight.answers`, where the
core's typed answers become these lines). `ask_running_mission` is the client side of these
commands.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import socket
from dataclasses import dataclass, field
from pathlib import Path

from fleetline.errors import FleetlineError
from gcs.flight.answers import OperatorAnswer
from gcs.mission import ScheduledChange

log = logging.getLogger(__name__)

#: Longest path a Unix socket address may have (Linux sun_path is 108 bytes with the NUL).
UNIX_PATH_MAX = 100
#: What the operator socket may be asked (the request's `command`, "speed" when absent).
OPERATOR_COMMANDS = ("speed", "return", "relieve")


@dataclass(frozen=True)
class SpeedChange:
    """A time-stamped speed change: the formation's speed becomes `speed` at `effective_s`.

    `effective_s` and `requested_s` are mission times (s); `seq` numbers changes from 1 so that
    vehicles drop duplicates; `source` says who asked ("schedule", "operator", "leader:<n>",
    "freeze:<why>" with why one of operator, takeoff, link; "resume").
    """

    seq: int
    effective_s: float
    speed: float
    source: str
    requested_s: float


@dataclass
class SpeedBroadcast:
    """A change as broadcast, and each UAV's receipt."""

    change: SpeedChange
    broadcast_wall: float
    acks: dict[int, float] = field(default_factory=dict)  # UAV id -> T_dv, mission seconds
    refused: dict[int, str] = field(default_factory=dict)  # UAV id -> why

    def as_json(self) -> dict:
        c = self.change
        return {
            "seq": c.seq,
            "effective_s": c.effective_s,
            "speed": c.speed,
            "source": c.source,
            "requested_s": c.requested_s,
            "acks": {str(uav): delay for uav, delay in sorted(self.acks.items())},
            **({"refused": {str(u): r for u, r in self.refused.items()}} if self.refused else {}),
        }


class SpeedRefused(FleetlineError, ValueError):
    """A speed request that cannot be honoured (the reason is the message)."""


class SpeedChanges:
    """Issues speed changes with a safe effective time and keeps their acknowledgements."""

    def __init__(
        self,
        *,
        max_speed: float,
        window_s: float,
        schedule: list[ScheduledChange],
        min_lead_s: float = 0.5,
        announce_s: float = 2.0,
    ) -> None:
        self.max_speed = max_speed
        self.window_s = window_s
        self.min_lead_s = min_lead_s
        self.announce_s = announce_s
        self.records: list[SpeedBroadcast] = []
        self.worst_reaction_s = 0.0
        self._scheduled = sorted((c for c in schedule if c.leader is None), key=lambda c: c.at)
        self._next_seq = 1
        self._last_effective = -math.inf

    @property
    def lead_s(self) -> float:
        """Smallest advance of an effective time over the request (docs/design.md 4)."""
        return max(self.window_s / 2, 2 * self.worst_reaction_s, self.min_lead_s)

    def earliest(self, now_s: float) -> float:
        """The earliest effective time a change requested at `now_s` may have."""
        return max(now_s + self.lead_s, self._last_effective + 1e-3, 0.0)

    def due(self, now_s: float) -> list[ScheduledChange]:
        """Scheduled changes to broadcast now (their effective time is close enough)."""
        out = []
        while self._scheduled and self._scheduled[0].at - self.lead_s - self.announce_s <= now_s:
            out.append(self._scheduled.pop(0))
        return out

    def request(
        self, speed: float, now_s: float, source: str, at: float | None = None
    ) -> SpeedChange:
        """A new change; `at` (effective) must leave the lead time, else `SpeedRefused`."""
        if not (isinstance(speed, int | float) and math.isfinite(speed)):
            raise SpeedRefused(f"speed must be a number, got {speed!r}")
        if not 0 <= speed <= self.max_speed + 1e-9:
            raise SpeedRefused(f"speed must be in [0, {self.max_speed:g}] m/s, got {speed:g}")
        earliest = self.earliest(now_s)
        if at is None:
            effective = earliest
        elif not math.isfinite(at):
            raise SpeedRefused(f"--at must be a finite mission time, got {at!r}")
        elif at < earliest - 1e-9:
            raise SpeedRefused(
                f"effective time {at:g} s is too soon: the earliest is {earliest:.2f} s "
                f"(now {now_s:.2f} s + lead {self.lead_s:.2f} s, after the last change)"
            )
        else:
            effective = float(at)
        change = SpeedChange(self._next_seq, float(effective), float(speed), source, now_s)
        self._next_seq += 1
        self._last_effective = change.effective_s
        return change

    def record(self, change: SpeedChange, broadcast_wall: float) -> SpeedBroadcast:
        record = SpeedBroadcast(change, broadcast_wall)
        self.records.append(record)
        return record

    def acknowledge(
        self, record: SpeedBroadcast, uav: int, reaction_s: float, sets_lead: bool = True
    ) -> None:
        """UAV `uav` acknowledged `record` after `reaction_s` (T_dv). `sets_lead` False: its
        link was lost meanwhile, so the delay measures the outage, not the protocol's
        reaction, and does not raise the lead of later changes (a vehicle process stopped
        9 s once pushed a resume 18 s into the future)."""
        record.acks[uav] = reaction_s
        if sets_lead:
            self.worst_reaction_s = max(self.worst_reaction_s, reaction_s)

    def as_json(self) -> list[dict]:
        return [r.as_json() for r in self.records]


# ---------------------------------------------------------------------- operator socket
def socket_path_for(log_path: Path) -> Path:
    """Where the operator socket of the run logging to `log_path` lives: `<log>.sock`."""
    return log_path.with_name(log_path.name + ".sock")


@contextlib.contextmanager
def _short_address(path: Path):
    """A sun_path for `path`: itself, or through /proc/self/fd when it is too long (Linux)."""
    if len(os.fsencode(str(path))) <= UNIX_PATH_MAX:
        yield str(path)
        return
    fd = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
    try:
        yield f"/proc/self/fd/{fd}/{path.name}"
    finally:
        os.close(fd)


@dataclass
class OperatorRequest:
    """A request read from the operator socket, answered with `reply`: `command` is one of
    `OPERATOR_COMMANDS` ("speed": `speed` is set; "return": it is None; "relieve": `uav` is
    set, `speed` and `at` are None)."""

    speed: float | None
    at: float | None
    error: str | None
    connection: socket.socket
    command: str = "speed"
    uav: int | None = None

    def reply(self, answer: OperatorAnswer) -> None:
        """Send `answer` back as its JSON line and close the connection."""
        try:
            self.connection.sendall((json.dumps(answer.to_json()) + "\n").encode())
        except OSError:
            pass
        finally:
            self.connection.close()


class OperatorSocket:
    """The running mission's listening socket for `gcs speed`, `gcs return` and `gcs relieve`.
    Never blocks: the scheduler calls `poll()` every tick; it accepts clients and collects
    their complete lines."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
        old = os.umask(0o177)  # owner-only: nobody else may command the fleet
        try:
            with _short_address(self.path) as address:
                self._sock.bind(address)
        finally:
            os.umask(old)
        self._sock.listen(8)
        self._sock.setblocking(False)
        self._clients: dict[socket.socket, bytearray] = {}

    def poll(self) -> list[OperatorRequest]:
        """Requests complete since the last call."""
        while True:
            try:
                conn, _ = self._sock.accept()
            except (BlockingIOError, InterruptedError):
                break
            conn.setblocking(False)
            self._clients[conn] = bytearray()
        requests = []
        for conn, buffer in list(self._clients.items()):
            try:
                chunk = conn.recv(4096)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:
                chunk = b""
            buffer += chunk
            if b"\n" not in buffer and chunk and len(buffer) < 4096:
                continue
            del self._clients[conn]
            requests.append(_parse_request(bytes(buffer), conn))
        return requests

    def close(self) -> None:
        for conn in self._clients:
            conn.close()
        self._clients.clear()
        self._sock.close()
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()


def _parse_request(line: bytes, conn: socket.socket) -> OperatorRequest:
    conn.setblocking(True)
    conn.settimeout(1.0)  # only for the reply, a few bytes to a local peer
    command = "speed"
    try:
        data = json.loads(line.split(b"\n", 1)[0])
        command = data.get("command", "speed")
        if command not in OPERATOR_COMMANDS:
            raise ValueError(f"command must be one of {', '.join(OPERATOR_COMMANDS)}")
        if command == "relieve":
            uav = data.get("uav")
            if isinstance(uav, bool) or not isinstance(uav, int) or uav < 1:
                raise ValueError("uav must be a positive integer")
            return OperatorRequest(None, None, None, conn, command, uav)
        at = data.get("at")
        if at is not None and (isinstance(at, bool) or not isinstance(at, int | float)):
            raise ValueError("at must be a number")
        at = None if at is None else float(at)
        if command == "return":
            return OperatorRequest(None, at, None, conn, command)
        speed = data["speed"]
        if isinstance(speed, bool) or not isinstance(speed, int | float):
            raise ValueError("speed must be a number")
        return OperatorRequest(float(speed), at, None, conn)
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        command = command if command in OPERATOR_COMMANDS else "speed"
        return OperatorRequest(None, None, f"bad request: {error}", conn, command)


def send_operator_command(path: Path, request: dict, timeout_s: float = 5.0) -> dict:
    """Send one request (a JSON object) to the operator socket at `path`, return the mission's
    answer (a dict). OSError: nobody answers there; ValueError: not an answer."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(timeout_s)
        with _short_address(Path(path)) as address:
            sock.connect(address)
        sock.sendall((json.dumps(request) + "\n").encode())
        answer = sock.makefile("rb").readline(4096)
    data = json.loads(answer)
    if not isinstance(data, dict):
        raise ValueError(f"not an answer: {answer[:80]!r}")
    return data


def send_operator_request(path: Path, speed: float, at: float | None, timeout_s: float = 5.0):
    """Client side of `gcs speed`: send one request, return the mission's answer (a dict)."""
    request = {"speed": speed} if at is None else {"speed": speed, "at": at}
    return send_operator_command(path, request, timeout_s)


class NoMissionAnswered(FleetlineError):
    """No running mission answered a request (the message says where it looked)."""


def ask_running_mission(
    request: dict,
    *,
    socket_path: Path | None = None,
    log_path: Path | None = None,
    directory: Path = Path("logs"),
) -> dict:
    """Client side of `gcs speed`, `gcs return` and `gcs relieve`: send `request` to the
    running mission (its socket; the one of the run logging to `log_path`; else the newest
    socket under `directory`, then the older ones until one answers) and return its answer.
    Raises `NoMissionAnswered`."""
    if socket_path is not None:
        candidates = [socket_path]
    elif log_path is not None:
        candidates = [socket_path_for(log_path)]
    else:
        candidates = find_running_sockets(directory)
    if not candidates:
        raise NoMissionAnswered(
            f"no running mission (no socket under ./{directory}; use --socket or --log)"
        )
    errors = []
    for path in candidates:
        try:
            return send_operator_command(path, request)
        except (OSError, ValueError) as error:
            errors.append(f"{path}: {error}")
    raise NoMissionAnswered(f"no running mission answered ({'; '.join(errors)})")


def find_running_sockets(directory: Path) -> list[Path]:
    """Operator sockets under `directory` (newest first)."""
    if not directory.is_dir():
        return []
    found = [p for p in directory.glob("*.sock") if p.is_socket()]
    return sorted(found, key=lambda p: p.stat().st_mtime, reverse=True)
