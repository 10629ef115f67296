"""Mission clock, recorded fleet speed changes and a leader's speed requests (pure, no I/O).

Contract with the ground station (docs/outputs.md, MAVLink section, and docs/design.md 4; the
messages are encoded and decoded by ``fleetwire.messages``, shared with the ground station):

* **Mission time.** The GCS tells each vehicle its mission clock with ``NAMED_VALUE_INT``
  ``name = "MSN_TIME"``, ``value`` = the GCS's mission time in milliseconds *when it sends the
  message* (signed: negative before mission time 0), from the GCS's system id. The vehicle
  anchors its mission clock on the latest one received: ``mission_time = value / 1000 +
  (simulated time now - simulated time at receipt)``. Send it at least once before the first
  leader request is due (the GCS sends it at 1 Hz with its heartbeat); the one-way loopback
  latency is the only error. Before any ``MSN_TIME`` the vehicle has no mission clock.
* **Speed changes** heard by a vehicle (``COMMAND_INT MAV_CMD_DO_CHANGE_SPEED``, ``x`` =
  effective mission time in ms, 0 = at once, ``y`` = sequence number) are recorded once per
  (sender, sequence); the fleet speed at mission time t is the speed of the latest change whose
  effective time is <= t.
* **Leader.** A vehicle given ``--leader-requests T:V,...`` sends, when its mission clock
  reaches T, ``COMMAND_INT MAV_CMD_DO_CHANGE_SPEED`` to the GCS (param1 = 1, param2 = V,
  ``x`` = 0, ``y`` = its own sequence number from 1), and repeats it every
  ``retry_interval_s`` until a ``COMMAND_ACK`` for command 178 comes back from the GCS
  (``result_param2`` = that sequence number, or 0 for the oldest pending request).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class HeardSpeedChange:
    """A fleet speed change as heard by a vehicle."""

    source_system: int
    sequence: int  # 0: unsequenced (COMMAND_LONG or y = 0), never deduplicated
    effective_s: float | None  # mission time; None: at once
    speed_mps: float
    received_sim_s: float


class MissionClock:
    """The GCS's mission time as seen by one vehicle (anchored on MSN_TIME messages)."""

    def __init__(self) -> None:
        self._anchor_mission_s: float | None = None
        self._anchor_sim_s = 0.0

    def sync(self, mission_time_s: float, sim_time_s: float) -> None:
        self._anchor_mission_s = mission_time_s
        self._anchor_sim_s = sim_time_s

    def now(self, sim_time_s: float) -> float | None:
        """Mission time at simulated time ``sim_time_s``, or None before the first sync."""
        if self._anchor_mission_s is None:
            return None
        return self._anchor_mission_s + (sim_time_s - self._anchor_sim_s)

    def sim_time_of(self, mission_time_s: float, default: float) -> float:
        """Simulated time at which the mission clock reads ``mission_time_s`` (or ``default``)."""
        if self._anchor_mission_s is None:
            return default
        return self._anchor_sim_s + (mission_time_s - self._anchor_mission_s)


class SpeedBook:
    """Speed changes recorded by one vehicle, duplicates (same sender and sequence) dropped."""

    def __init__(self) -> None:
        self.changes: list[HeardSpeedChange] = []
        self._seen: set[tuple[int, int]] = set()

    def record(self, change: HeardSpeedChange) -> bool:
        """Record ``change``; False if it duplicates one already recorded."""
        if change.sequence != 0:
            key = (change.source_system, change.sequence)
            if key in self._seen:
                return False
            self._seen.add(key)
        self.changes.append(change)
        return True

    def fleet_speed(self, sim_time_s: float, clock: MissionClock) -> float | None:
        """Speed in force at ``sim_time_s``: the change that took effect last, or None.

        An immediate change takes effect when received; a timed one when the mission clock
        reaches its effective time (without a mission clock: when received).
        """
        best: HeardSpeedChange | None = None
        best_key = (float("-inf"), float("-inf"))
        for change in self.changes:
            start = change.received_sim_s
            if change.effective_s is not None:
                start = clock.sim_time_of(change.effective_s, default=change.received_sim_s)
            key = (start, change.received_sim_s)
            if start <= sim_time_s and key >= best_key:
                best, best_key = change, key
        return None if best is None else best.speed_mps


@dataclass(frozen=True)
class LeaderRequest:
    """One scheduled request of a leader: at ``mission_time_s`` ask the GCS for ``speed_mps``."""

    mission_time_s: float
    speed_mps: float


@dataclass
class PendingRequest:
    sequence: int
    speed_mps: float
    last_sent_sim_s: float
    last_sent_wall_s: float
    tries: int


class LeaderSchedule:
    """Which leader requests are due, which wait for an acknowledgement, which gave up."""

    def __init__(
        self, requests: tuple[LeaderRequest, ...], retry_interval_s: float, max_tries: int
    ):
        self._queue = sorted(requests, key=lambda r: r.mission_time_s)
        self.retry_interval_s = retry_interval_s
        self.max_tries = max_tries
        self.pending: dict[int, PendingRequest] = {}
        self.acknowledged: list[int] = []
        self.abandoned: list[int] = []
        self._next_sequence = 1

    def active(self) -> bool:
        """Anything left to send or to wait for."""
        return bool(self._queue or self.pending)

    def due(self, mission_time_s: float | None) -> list[tuple[int, float]]:
        """New requests whose time has come: (sequence, speed) each, now pending."""
        out: list[tuple[int, float]] = []
        while (
            mission_time_s is not None
            and self._queue
            and self._queue[0].mission_time_s <= mission_time_s
        ):
            request = self._queue.pop(0)
            out.append((self._next_sequence, request.speed_mps))
            self._next_sequence += 1
        return out

    def acknowledge(self, sequence: int) -> int | None:
        """An ack for ``sequence`` (0: the oldest pending); returns the sequence settled."""
        if sequence == 0 and self.pending:
            sequence = min(self.pending)
        if self.pending.pop(sequence, None) is None:
            return None
        self.acknowledged.append(sequence)
        return sequence

    def sent(self, sequence: int, speed_mps: float, sim_s: float, wall_s: float) -> None:
        """Note that request ``sequence`` went out (first time or again)."""
        entry = self.pending.get(sequence)
        if entry is None:
            self.pending[sequence] = PendingRequest(sequence, speed_mps, sim_s, wall_s, 1)
        else:
            entry.last_sent_sim_s, entry.last_sent_wall_s = sim_s, wall_s
            entry.tries += 1

    def resend_due(
        self, sim_s: float, wall_s: float, wall_floor_s: float
    ) -> tuple[list[PendingRequest], list[int]]:
        """Pending requests to send again now, and sequences given up (removed from pending)."""
        again: list[PendingRequest] = []
        given_up: list[int] = []
        for sequence, entry in list(self.pending.items()):
            if sim_s - entry.last_sent_sim_s < self.retry_interval_s:
                continue
            if wall_s - entry.last_sent_wall_s < min(wall_floor_s, self.retry_interval_s):
                continue
            if entry.tries >= self.max_tries:
                del self.pending[sequence]
                self.abandoned.append(sequence)
                given_up.append(sequence)
            else:
                again.append(entry)
        return again, given_up
