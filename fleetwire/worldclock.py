"""The simulated world's clock, shared by the ground station, the vehicle processes and the radio
medium of one run (lockstep, as ArduPilot SITL's physics advances only as its frames arrive).

One small file, mapped into every process (`mmap`), written by the ground station (the
*master*) and read by the others (the *followers*), each of which also writes its own progress
into its slot. No datagram carries it: the emulated radio can cut or delay every MAVLink link
and the world still keeps one time.

World time is the ground station's mission time. The master publishes `zero` (the
`time.monotonic()` instant of world time 0: CLOCK_MONOTONIC is one clock for every process of
the machine), the speed-up, and `cap`, the world time no follower may pass (its last tick plus
a lead). A follower's world time at wall instant `now` is

    max(its last, min((now - zero) * speedup, cap))

so it never runs backwards, never runs ahead of the ground station by more than the lead (a
stopped or starved ground station pauses the world: the vehicles never see a setpoint gap it
did not decide), and stays on the wall clock while everyone keeps up. Each follower writes how
far it has got (world time); the master holds its own clock when the slowest is more than a
lag behind, so one starved process pauses the world instead of tearing it. A follower that
joins maps its own simulated clock onto world time with a fixed offset (its clock is its own:
time_boot_ms stays continuous). `zero` NaN: no world yet (before take-off the vehicles run on
their own wall clock). A slot written +inf is released: nobody waits for it (a process that
exited). A follower whose master is gone (the ground station killed) leaves the world and runs
on its own wall clock again, so its vehicles' failsafes bring them down.

Layout (little-endian): magic (8 bytes), sequence (u64; odd while the master writes), zero,
speedup, cap (f64), slot count (u32), 4 bytes padding, then one f64 per slot.
"""

from __future__ import annotations

import math
import mmap
import os
import struct
from dataclasses import dataclass
from pathlib import Path

from fleetline.errors import EXIT_BAD_INPUT, FleetlineError

MAGIC = b"FLWCLK01"
_HEADER = struct.Struct("<8sQdddI4x")
_SEQ_OFFSET = 8
_BODY = struct.Struct("<ddd")  # zero, speedup, cap (after magic and sequence)
_BODY_OFFSET = 16
_SLOT = struct.Struct("<d")

#: Mission seconds a follower may run ahead of the ground station's last tick.
WORLD_LEAD_S = 0.3
#: Mission seconds the ground station may run ahead of the slowest follower.
WORLD_LAG_S = 0.3


class WorldClockError(FleetlineError, ValueError):
    """The file is not a world clock (or not the one expected)."""

    exit_status = EXIT_BAD_INPUT


@dataclass(frozen=True)
class WorldBounds:
    """What the master published: world time 0 at monotonic `zero` (NaN: no world yet), the
    speed-up, and the world time no follower may pass."""

    zero: float
    speedup: float
    cap: float

    @property
    def running(self) -> bool:
        """The world runs: its zero is set and its speed-up is a positive number. (A body of
        zeros, as a file read while it is created or cut short holds, is not a world.)"""
        return math.isfinite(self.zero) and math.isfinite(self.speedup) and self.speedup > 0

    def world_time(self, wall: float) -> float:
        """The world time at monotonic `wall` (capped; NaN before the world runs)."""
        return min((wall - self.zero) * self.speedup, self.cap)

    def wall_at(self, world: float) -> float:
        """The monotonic instant the world reaches `world` (inf: not before the cap rises)."""
        if world > self.cap or not self.running:
            return math.inf
        return self.zero + world / self.speedup


def _slot_offset(slot: int) -> int:
    return _HEADER.size + slot * _SLOT.size


class _Mapped:
    def __init__(self, path: Path, size: int, fd: int) -> None:
        self.path = path
        try:
            self._map = mmap.mmap(fd, size)
        finally:
            os.close(fd)
        self.slots = (size - _HEADER.size) // _SLOT.size

    def close(self) -> None:
        self._map.close()

    def _read_slot(self, slot: int) -> float:
        return _SLOT.unpack_from(self._map, _slot_offset(slot))[0]

    def _write_slot(self, slot: int, value: float) -> None:
        _SLOT.pack_into(self._map, _slot_offset(slot), value)


class WorldClockMaster(_Mapped):
    """The ground station's side: creates the file (owner-only), publishes the bounds, reads
    the followers' progress."""

    def __init__(self, path: Path, slots: int, speedup: float) -> None:
        size = _slot_offset(slots)
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o600)
        os.ftruncate(fd, size)
        super().__init__(Path(path), size, fd)
        self._seq = 0
        _HEADER.pack_into(self._map, 0, MAGIC, 0, math.nan, float(speedup), math.inf, slots)
        for slot in range(slots):
            self._write_slot(slot, math.nan)

    def publish(self, zero: float, speedup: float, cap: float) -> None:
        """New bounds, atomically for every reader (a sequence lock)."""
        self._seq += 1
        struct.pack_into("<Q", self._map, _SEQ_OFFSET, self._seq)  # odd: writing
        _BODY.pack_into(self._map, _BODY_OFFSET, zero, speedup, cap)
        self._seq += 1
        struct.pack_into("<Q", self._map, _SEQ_OFFSET, self._seq)

    def progress(self) -> list[float]:
        """Each slot's world time reached (NaN: not joined; inf: released)."""
        return [self._read_slot(slot) for slot in range(self.slots)]

    def release(self, slot: int) -> None:
        """Nobody waits for `slot` any more (its process exited or stopped answering)."""
        self._write_slot(slot, math.inf)


def check_world_clock(path: str | Path) -> Path:
    """`path` if it is a world clock file (its magic read), else WorldClockError."""
    path = Path(path)
    try:
        with open(path, "rb") as file:
            magic = file.read(len(MAGIC))
    except OSError as exc:
        raise WorldClockError(f"{path}: cannot open ({exc.strerror})") from exc
    if magic != MAGIC:
        raise WorldClockError(f"{path}: not a world clock file")
    return path


class WorldClockFollower(_Mapped):
    """A vehicle process's or the medium's side: reads the bounds, writes its progress."""

    def __init__(self, path: Path, slot: int) -> None:
        path = Path(path)
        try:
            fd = os.open(path, os.O_RDWR)
        except OSError as exc:
            raise WorldClockError(f"{path}: cannot open ({exc.strerror})") from exc
        size = os.fstat(fd).st_size
        if size < _HEADER.size:
            os.close(fd)
            raise WorldClockError(f"{path}: not a world clock file")
        super().__init__(path, size, fd)
        magic = self._map[:8]
        if magic != MAGIC:
            self.close()
            raise WorldClockError(f"{path}: not a world clock file")
        if not 0 <= slot < self.slots:
            self.close()
            raise WorldClockError(f"slot {slot} not in 0..{self.slots - 1}")
        self.slot = slot

    def bounds(self) -> WorldBounds:
        """The master's latest bounds, read consistently."""
        while True:
            before = struct.unpack_from("<Q", self._map, _SEQ_OFFSET)[0]
            zero, speedup, cap = _BODY.unpack_from(self._map, _BODY_OFFSET)
            after = struct.unpack_from("<Q", self._map, _SEQ_OFFSET)[0]
            if before == after and before % 2 == 0:
                return WorldBounds(zero, speedup, cap)

    def report(self, world_time: float) -> None:
        """How far this follower has got (world time)."""
        self._write_slot(self.slot, world_time)

    def leave(self) -> None:
        """Released: nobody waits for this follower any more."""
        self._write_slot(self.slot, math.inf)


class FollowerClock:
    """A follower's simulated clock (seconds since it started) on the world's time.

    Free-running on the wall clock (`speedup` times it) until the world runs; then its time is
    the world's plus the offset it had when it joined, never decreasing; on `leave` it runs on
    the wall clock again from where it stands. `now(wall)` is the simulated time at monotonic
    `wall`; `wall_at(sim)` when it will be reached (inf: not before the cap rises).
    """

    def __init__(self, speedup: float, wall0: float, world: WorldClockFollower | None) -> None:
        self.speedup = float(speedup)
        self.wall0 = wall0  # monotonic instant of simulated time 0, while free-running
        self.world = world
        self.offset: float | None = None  # simulated - world time, once joined
        self._bounds: WorldBounds | None = None
        self._last = -math.inf

    @property
    def joined(self) -> bool:
        return self.offset is not None

    def refresh(self, wall: float) -> None:
        """Read the master's bounds (join the world when it starts running)."""
        if self.world is None:
            return
        bounds = self.world.bounds()
        if not bounds.running:
            return  # not started yet, or not a world: keep the bounds read before
        if self.offset is None:
            free = (wall - self.wall0) * self.speedup
            self.offset = free - bounds.world_time(wall)
            self._last = free
        self._bounds = bounds

    def now(self, wall: float) -> float:
        if self.offset is None or self._bounds is None:
            return (wall - self.wall0) * self.speedup
        sim = self._bounds.world_time(wall) + self.offset
        return max(sim, self._last)

    def advanced_to(self, sim: float) -> None:
        """This follower's simulation has reached `sim`: never read below it again; reported."""
        self._last = max(self._last, sim)
        if self.world is not None and self.offset is not None:
            self.world.report(sim - self.offset)

    def wall_at(self, sim: float) -> float:
        if self.offset is None or self._bounds is None:
            return self.wall0 + sim / self.speedup
        return self._bounds.wall_at(sim - self.offset)

    def leave(self, wall: float) -> None:
        """Run on the wall clock again from where the simulation stands (the master is gone)."""
        if self.world is None:
            return
        if self.offset is not None and math.isfinite(self._last):
            self.wall0 = wall - self._last / self.speedup
        self.world.leave()
        self.world.close()
        self.world = None
        self.offset = None
        self._bounds = None
