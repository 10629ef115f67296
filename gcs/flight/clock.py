"""The mission clock and the vehicles' clocks, as functions of the time the loop passes in.

The loop that drives the ground-station core (the live loop's `time.monotonic()`, the fast
mode's simulated seconds) passes its time `now` to every call; the only clock read is the
epoch of the recording, once, when the mission clock is anchored.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable


class MissionClock:
    """Mission time from the driving loop's time: `mission = (now - zero) * speedup`, never
    decreasing.

    Anchored once (`anchor`). A stall of the loop is handled in two steps: `freeze(now_last)`
    makes the clock stand still at the last instant the loop ran (so that nothing read while the
    backlog is processed is stamped later than what follows), and `resume(now, at)` restarts it
    from mission time `at`, which is never earlier than where it stood. `log_time_ns` is the
    Unix time (ns) at mission time 0 plus the mission time, the recording's time base
    (docs/outputs.md, MCAP); the epoch never changes, so log times stay monotonic too.
    """

    def __init__(
        self,
        speedup: float = 1.0,
        monotonic: Callable[[], float] = time.monotonic,
        unix_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        self.speedup = float(speedup)
        self._monotonic = monotonic  # read once, by `anchor`, to place the epoch
        self._unix_ns = unix_ns
        self._zero: float | None = None
        self._floor = -float("inf")  # the clock never reads below this again
        self._frozen_at: float | None = None  # mission time it stands at, while frozen
        self.epoch_ns: int | None = None  # Unix ns at mission time 0
        self.held_back_s = 0.0  # mission seconds `hold_back` took off the clock, in all
        self._seen = -float("inf")  # the latest mission time read (`mission_time`)

    @property
    def anchored(self) -> bool:
        return self._zero is not None

    @property
    def frozen(self) -> bool:
        return self._frozen_at is not None

    def anchor(self, now: float, mission_time: float) -> None:
        """Fix the clock so that `mission_time(now) == mission_time`. The epoch is the Unix
        time of the loop's time at mission time 0 (the loop's `monotonic` and `unix_ns`, given
        at construction, relate its time to Unix time; the fast mode passes fixed ones)."""
        self._zero = now - mission_time / self.speedup
        offset_ns = self._unix_ns() - int(self._monotonic() * 1e9)
        self.epoch_ns = offset_ns + int(self._zero * 1e9)

    def raw_mission_time(self, now: float) -> float:
        """The mission time `now` would have without freezes and floors (to map the vehicles'
        samples to the instant they were taken, before a pause is decided)."""
        return (now - self._zero) * self.speedup

    def mission_time(self, now: float) -> float:
        """The mission time at `now` (what the loop, the recorder and the drivers use: noted, so
        that `hold_back` never goes below anything already read, written or sent)."""
        t = self.peek(now)
        if t > self._seen:
            self._seen = t
        return t

    def peek(self, now: float) -> float:
        """`mission_time(now)` without noting it (to decide whether to hold the clock back)."""
        if self._frozen_at is not None:
            return self._frozen_at
        return max((now - self._zero) * self.speedup, self._floor)

    def wall_at(self, mission_time: float) -> float:
        return self._zero + mission_time / self.speedup

    def freeze(self, now: float) -> float:
        """Stand still at `mission_time(now)` until `resume`; returns that mission time."""
        if self._frozen_at is None:
            self._frozen_at = self.mission_time(now)
        return self._frozen_at

    def resume(self, now: float, mission_time: float) -> float:
        """Run again from `mission_time` at `now` (never below where the clock stood: the
        mission pauses, it never rewinds); returns the mission time it resumed from."""
        stood = self._frozen_at if self._frozen_at is not None else self.mission_time(now)
        resumed = max(mission_time, stood)
        self._zero = now - resumed / self.speedup
        self._floor = resumed
        self._frozen_at = None
        return resumed

    def hold_back(self, now: float, mission_time: float) -> float:
        """Make the clock read `mission_time` at `now` and run on from there (lockstep: the
        world it drives is behind). Never below what it read at its last use (the floor of a
        resume, or what the caller passes: its last tick); returns the mission seconds taken
        off the clock."""
        if self._frozen_at is not None:
            return 0.0
        before = self.peek(now)
        value = max(mission_time, self._floor, self._seen)  # log times stay monotonic
        if value >= before:
            return 0.0
        self._zero = now - value / self.speedup
        self._floor = value
        self.held_back_s += before - value
        return before - value

    def log_time_ns(self, now: float) -> int:
        return self.epoch_ns + int(round(self.mission_time(now) * 1e9))


def paused(t: float, at: float, length: float) -> float:
    """Mission time `t` (as the clock read before it was held back by `length` at `at`) as it
    reads after: unchanged before the pause, the pause itself during it, `length` earlier after
    it."""
    return min(t, max(t - length, at))


class VehicleClock:
    """Maps one vehicle's clock (time_boot_ms) to mission time, so that samples keep the time
    they were taken even when the ground station read them late (a busy machine, a stall).

    offset = min over recent samples of (mission time at receipt - vehicle time): the least delayed
    sample bounds the offset best. Both clocks run at the same speedup. A vehicle clock that goes
    back more than `reboot_jump_s` (a reboot) starts the estimate over; a smaller step back is a
    sample overtaken on the way (a reordering network), mapped like any other. One that fell behind
    (a simulator that could not keep up and says its clock slipped: `slipped`) moves every offset by
    the slip: without it the minimum keeps the old offset and maps every sample the slip too early
    for a whole window. After the mission clock was held back (`pause`), a sample taken while the
    mission stood still maps to the instant it paused.

    A vehicle whose telemetry is late and one whose clock fell behind look the same from here
    (steadily larger offsets): only the vehicle can tell, so only its report moves the offsets.
    """

    def __init__(self, reboot_jump_s: float, window: int = 50) -> None:
        self._reboot_jump_s = reboot_jump_s
        self._offsets: deque[float] = deque(maxlen=window)
        self._last: float | None = None
        self._pause: tuple[float, float] | None = None  # (mission time it paused at, length)

    def pause(self, at: float, length: float) -> None:
        """The mission clock stood still at mission time `at` for `length` vehicle seconds."""
        self._offsets = deque((o - length for o in self._offsets), maxlen=self._offsets.maxlen)
        self._pause = (at, length)

    def slipped(self, seconds: float) -> None:
        """The vehicle's clock fell `seconds` behind the mission clock (its report)."""
        self._offsets = deque((o + seconds for o in self._offsets), maxlen=self._offsets.maxlen)

    def mission_time(self, vehicle_s: float | None, received_s: float) -> float:
        if vehicle_s is None:
            return received_s
        if self._last is not None and vehicle_s < self._last - self._reboot_jump_s:
            self._offsets.clear()
            self._pause = None
            self._last = None
        self._last = vehicle_s if self._last is None else max(self._last, vehicle_s)
        self._offsets.append(received_s - vehicle_s)
        mapped = vehicle_s + min(self._offsets)
        if self._pause is not None:
            at, length = self._pause
            mapped = paused(mapped + length, at, length)  # the offsets are after the pause
        return min(mapped, received_s)
