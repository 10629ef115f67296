"""Lockstep with the simulated world: the ground station's side of `fleetwire.worldclock`.

The live loop calls `WorldSync.step(now, clock)` before it reads its links and after each tick.
Once the mission clock is anchored it publishes the world: world time 0 where mission time 0
is, and the cap its followers (the vehicle processes, the radio medium) may not pass, the last
tick plus `WORLD_LEAD_S`. When the slowest follower is more than `WORLD_LAG_S` behind the
mission clock, the clock is held back to it (never below the last tick): a starved vehicle
process or medium pauses the world, the ground station included, instead of the formation
flying on without it. A follower that has not moved for `STUCK_WALL_S` while it holds
everyone back (a process stopped for good, hung) is no longer waited for: its UAVs then fall
behind and the hold and link policies (`gcs.flight.hold`, `gcs.flight.core`) take over.

What each mechanism covers (docs/ARCHITECTURE.md, "Time on a busy machine"): lockstep covers
the simulated world's own processes starving or stopping; the core's stall hold-back covers
the ground station's own stalls against a world that runs on (SITL, real vehicles, no
lockstep); the hold policy covers a UAV that falls behind for any reason.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

from fleetwire.worldclock import WORLD_LAG_S, WORLD_LEAD_S, WorldClockMaster
from gcs.flight.clock import MissionClock

log = logging.getLogger(__name__)

#: Wall seconds a follower may hold the world back without moving before it is given up on.
STUCK_WALL_S = 30.0


class WorldSync:
    """Publishes the mission clock to the world's followers and holds it for the slowest."""

    def __init__(
        self,
        master: WorldClockMaster,
        names: Sequence[str],
        *,
        lead_s: float = WORLD_LEAD_S,
        lag_s: float = WORLD_LAG_S,
        stuck_wall_s: float = STUCK_WALL_S,
    ) -> None:
        self.master = master
        self.names = list(names)
        self.lead_s = lead_s
        self.lag_s = lag_s
        self.stuck_wall_s = stuck_wall_s
        self.holds = 0  # how many times the clock was held back
        self._ticked: float | None = None  # mission time of the last tick
        self._cap = -math.inf
        self._moved: dict[int, tuple[float, float]] = {}  # slot -> (progress, wall it moved)
        self.released: list[str] = []  # followers given up on (what they were)

    def step(self, now: float, clock: MissionClock) -> list[str]:
        """Hold the clock for the slowest follower, publish the bounds; returns what was given
        up on just now (text for the events)."""
        if not clock.anchored:
            return []
        released = self._hold(now, clock)
        t = clock.peek(now)
        base = self._ticked if self._ticked is not None else t
        self._cap = max(self._cap, base + self.lead_s)
        self.master.publish(clock.wall_at(0.0), clock.speedup, self._cap)
        return released

    def ticked(self, t: float) -> None:
        """The core ticked at mission time `t` (setpoints for `t` are out)."""
        self._ticked = t if self._ticked is None else max(self._ticked, t)

    def _hold(self, now: float, clock: MissionClock) -> list[str]:
        progress = self.master.progress()
        joined = {slot: p for slot, p in enumerate(progress) if math.isfinite(p)}
        released = []
        for slot, p in joined.items():
            last = self._moved.get(slot)
            if last is None or p > last[0]:
                self._moved[slot] = (p, now)
        if not joined:
            return released
        t = clock.peek(now)
        slowest = min(joined, key=joined.get)
        if t <= joined[slowest] + self.lag_s:
            return released
        since = self._moved[slowest][1]
        if now - since >= self.stuck_wall_s:
            name = self.names[slowest] if slowest < len(self.names) else f"follower {slowest}"
            text = (
                f"{name}: no progress for {now - since:.0f} s (wall), no longer waited for: "
                "the simulated world runs on without it"
            )
            log.warning("%s", text)
            self.master.release(slowest)
            self.released.append(name)
            return [text]
        floor = self._ticked if self._ticked is not None else -math.inf
        if clock.hold_back(now, max(joined[slowest] + self.lag_s, floor)) > 0:
            self.holds += 1
        return released

    def summary(self, clock: MissionClock) -> dict:
        """The run JSON's `lockstep` object (the seconds held are the clock's own count)."""
        return {
            "enabled": True,
            "held_s": clock.held_back_s,
            "holds": self.holds,
            "released": list(self.released),
        }
