"""Commands sent to one vehicle and what becomes of them (no sockets, no clock: `now` is passed).

Every command a driver sends goes through a `CommandTracker`, as a `Pending` entry:

    SENT ──final ACK ACCEPTED──► CONFIRMING (if it has a `confirm` test) ──test holds──► done
     │ └─non-final ACK (IN_PROGRESS, PX4's first of two)──► ANSWERED ──silence──► as if final
     ├─refusing final ACK──► EXPLAINING (the vehicle's STATUSTEXT may still come) ──► done
     └─no ACK after `max_attempts` sends, spaced by `retry`──► done (result None)

A `confirm` test that holds ends the command successfully at any stage (the heartbeat shows
the mode, or the vehicle armed, before the ACK arrived). An outcome that is not a success
(refused, unanswered, accepted but never shown) makes the command's key wait
`backoff.delay(n)` after the n-th consecutive failure before `may_send(key)` is true again.

The vehicle's reason for a refusal is the STATUSTEXT of severity WARNING or worse nearest to
the refusing ACK, from `reason_before_s` before it to `reason_after_s` after it (ArduPilot
sends its `Arm: ...` 1 ms before the ACK, PX4 its texts just after); an INFO text (`Arming
motors`, `EKF3 IMU0 is using GPS`) is never a reason.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass

from gcs.transport.link import mavutil

mavlink = mavutil.mavlink

#: The mildest STATUSTEXT severity that may explain a refusal (EMERGENCY .. WARNING).
REASON_SEVERITY = mavlink.MAV_SEVERITY_WARNING
#: A STATUSTEXT chunk this long is full: more chunks with the same id follow (MAVLink 2).
STATUSTEXT_CHUNK = 50


@dataclass(frozen=True)
class Backoff:
    """A wait that grows with consecutive failures: `first_s`, times `growth` per further
    failure, never more than `max_s` (vehicle-time seconds)."""

    first_s: float
    growth: float = 2.0
    max_s: float = 8.0

    def delay(self, failures: int) -> float:
        """Seconds to wait after the `failures`-th consecutive failure (1 = the first)."""
        return min(self.first_s * self.growth ** max(failures - 1, 0), self.max_s)


@dataclass(frozen=True)
class RetryPolicy:
    """How a family paces what it asks of its vehicle, in vehicle-time seconds.

    The driver turns each delay into wall-clock seconds with `DriverTiming.wall`, whose floor
    flattens the first steps of a back-off at a high speedup.
    """

    #: Between sends of a command nobody answered (the n-th resend waits `delay(n)`).
    retransmit: Backoff = Backoff(1.0, 2.0, 4.0)
    #: After IN_PROGRESS or PX4's first of two ACKs: this much silence ends the command.
    answer_wait_s: float = 5.0
    #: Before a command whose last try failed (refused, unanswered, not shown) is sent again.
    refusal: Backoff = Backoff(1.0, 2.0, 8.0)
    #: An accepted ARM or mode change must show in a heartbeat within this time.
    confirm_s: float = 2.5
    #: HOME_POSITION requests while the home is unknown: wait this long for the message, and
    #: as long again (growing) before the next request.
    home_request: Backoff = Backoff(1.0, 2.0, 8.0)
    #: A STATUSTEXT this long before a refusing ACK may be its reason...
    reason_before_s: float = 0.1
    #: ... or this long after it; the refusal is reported then (or at the first such text).
    reason_after_s: float = 0.3


@dataclass(frozen=True)
class CommandSpec:
    """A MAVLink command to send as COMMAND_LONG (default) or COMMAND_INT.

    For COMMAND_INT, params 5-7 are `x`, `y` (integers) and `z`. The pacing fields default to
    the driver's `RetryPolicy`.
    """

    command: int
    params: tuple[float, ...] = (0, 0, 0, 0, 0, 0, 0)
    use_int: bool = False
    frame: int = mavlink.MAV_FRAME_GLOBAL
    label: str = ""
    key: object = None  # identifies it among pending commands and back-offs (default: its id)
    acks_needed: int = 1  # PX4 answers DO_SET_MODE twice
    max_attempts: int | None = 5  # None: until answered or cancelled
    retry: Backoff | None = None  # retransmissions (None: the policy's `retransmit`)
    backoff: Backoff | None = None  # before sending the key again after a failure (`refusal`)
    confirm_s: float | None = None  # time for the effect to show (None: the policy's)

    @property
    def name(self) -> str:
        if self.label:
            return self.label
        entry = mavlink.enums["MAV_CMD"].get(self.command)
        return entry.name if entry else str(self.command)

    @property
    def pending_key(self) -> object:
        return self.key if self.key is not None else self.command


def result_name(result: int | None) -> str:
    """`MAV_RESULT_...` name of a result ("no answer" for None)."""
    if result is None:
        return "no answer"
    entry = mavlink.enums["MAV_RESULT"].get(result)
    return entry.name if entry else str(result)


@dataclass(frozen=True)
class Outcome:
    """How a command ended."""

    result: int | None  # the final MAV_RESULT; None: never (finally) answered
    answered_at: float | None = None  # wall time of the final ACK (or of the confirmation)
    reason: str | None = None  # refused: the vehicle's STATUSTEXT near the ACK, if any
    confirmed: bool = True  # False: accepted, but its effect did not show in time
    attempts: int = 1  # how many times it was sent

    @property
    def accepted(self) -> bool:
        """Accepted and, if it had a `confirm` test, confirmed."""
        return self.result == mavlink.MAV_RESULT_ACCEPTED and self.confirmed

    @property
    def refused(self) -> bool:
        return self.result is not None and self.result != mavlink.MAV_RESULT_ACCEPTED

    def describe(self) -> str:
        """The reason (refused), else what happened, for messages."""
        if self.refused:
            return self.reason or result_name(self.result)
        if self.result is None:
            return result_name(None)
        return "accepted" if self.confirmed else "accepted, but the vehicle did not show it"


#: Called once with the outcome of a command and the wall time.
CommandCallback = Callable[[Outcome, float], None]


class Stage(enum.Enum):
    """Where a pending command is (module docstring)."""

    SENT = "sent"
    ANSWERED = "answered"
    EXPLAINING = "explaining"
    CONFIRMING = "confirming"


@dataclass(eq=False)
class Pending:
    """One command in flight; `due` is when its current stage times out."""

    key: object
    spec: CommandSpec
    on_result: CommandCallback | None
    confirm: Callable[[], bool] | None
    first_sent: float
    last_sent: float
    due: float
    attempts: int = 1
    acks: int = 0  # ACCEPTED acks received so far
    in_progress: bool = False
    stage: Stage = Stage.SENT
    result: int | None = None  # the final MAV_RESULT, once answered
    answered_at: float | None = None


class VehicleTexts:
    """The STATUSTEXTs of one vehicle, with wall time and severity, oldest first.

    Long texts (PX4) come in 50-character chunks sharing an `id` (`chunk_seq` 0, 1, ...): they
    are joined once the last, shorter, chunk arrives, or given up as they are after a while.
    """

    def __init__(self) -> None:
        self.entries: list[tuple[float, int, str]] = []
        self._chunks: dict[int, tuple[float, int, dict[int, str]]] = {}  # id -> first, sev, parts

    def add(self, msg, now: float) -> tuple[int, str] | None:
        """Take one STATUSTEXT; (severity, text) once the text is complete."""
        text = msg.text.rstrip("\x00")
        chunk_id = getattr(msg, "id", 0)
        if not chunk_id:
            return self.note(msg.severity, text, now)
        _, severity, parts = self._chunks.setdefault(chunk_id, (now, msg.severity, {}))
        parts[getattr(msg, "chunk_seq", len(parts))] = text
        if len(text) >= STATUSTEXT_CHUNK:
            return None
        del self._chunks[chunk_id]
        return self.note(severity, "".join(parts[seq] for seq in sorted(parts)), now)

    def flush(self, now: float, max_age: float) -> list[tuple[int, str]]:
        """Chunked texts whose last chunk has not come `max_age` s after the first, as they are."""
        stale = [i for i, (first, _, _) in self._chunks.items() if now - first >= max_age]
        done = []
        for chunk_id in stale:
            _, severity, parts = self._chunks.pop(chunk_id)
            entry = self.note(severity, "".join(parts[seq] for seq in sorted(parts)), now)
            if entry is not None:
                done.append(entry)
        return done

    def note(self, severity: int, text: str, now: float) -> tuple[int, str] | None:
        """Record a complete text (blank ones are dropped)."""
        text = text.strip()
        if not text:
            return None
        self.entries.append((now, severity, text))
        return severity, text

    def last(self, since: float | None = None, max_severity: int = 7) -> str | None:
        """The last text (after `since`) of severity `max_severity` or worse."""
        for when, severity, text in reversed(self.entries):
            if since is not None and when < since:
                return None
            if severity <= max_severity:
                return text
        return None

    def reason(self, around: float, before: float, until: float) -> str | None:
        """The text of severity WARNING or worse nearest to `around`, within [`around` -
        `before`, `until`]; on a tie the later one."""
        best: tuple[float, str] | None = None
        for when, severity, text in reversed(self.entries):
            if when < around - before:
                break
            if when > until or severity > REASON_SEVERITY:
                continue
            distance = abs(when - around)
            if best is None or distance < best[0]:
                best = (distance, text)
        return None if best is None else best[1]


class CommandTracker:
    """Every command of one driver, from its first send to its `Outcome` (module docstring).

    `wall(seconds, floor)` turns vehicle-time seconds into wall-clock ones
    (`DriverTiming.wall`), `transmit(spec, now)` puts a command on the link, and
    `is_final(pending, ack)` says whether an ACK ends a command (the family's rule).
    """

    def __init__(
        self,
        policy: RetryPolicy,
        wall: Callable[[float, float | None], float],
        transmit: Callable[[CommandSpec, float], None],
        is_final: Callable[[Pending, object], bool],
        texts: VehicleTexts,
    ) -> None:
        self.policy = policy
        self._wall = wall
        self._transmit = transmit
        self._is_final = is_final
        self._texts = texts
        self._pending: dict[object, Pending] = {}
        self._failures: dict[object, int] = {}
        self._not_before: dict[object, float] = {}

    # ------------------------------------------------------------------ queries
    @property
    def pending(self) -> list[Pending]:
        return list(self._pending.values())

    def __contains__(self, key: object) -> bool:
        return key in self._pending

    def failures(self, key: object) -> int:
        """Consecutive failed outcomes of `key` (0 after a success)."""
        return self._failures.get(key, 0)

    def may_send(self, key: object, now: float) -> bool:
        """Nothing with this key is in flight and its back-off (if any) is over."""
        return key not in self._pending and now >= self._not_before.get(key, -math.inf)

    # ------------------------------------------------------------------ actions
    def send(
        self,
        spec: CommandSpec,
        now: float,
        on_result: CommandCallback | None = None,
        confirm: Callable[[], bool] | None = None,
    ) -> Pending:
        """Send `spec` now; a pending command with the same key is replaced (its callback is
        dropped). `confirm()` says whether the command took effect."""
        pending = Pending(
            spec.pending_key, spec, on_result, confirm, now, now, now + self._retry_wait(spec, 1)
        )
        self._pending[pending.key] = pending
        self._transmit(spec, now)
        return pending

    def forget_failures(self, key: object) -> None:
        """Start the back-off of `key` afresh (a new intent, not a retry)."""
        self._failures.pop(key, None)
        self._not_before.pop(key, None)

    def cancel(self, which: Callable[[CommandSpec], bool]) -> None:
        """Drop the pending commands `which(spec)` selects, without calling them back."""
        for key in [k for k, p in self._pending.items() if which(p.spec)]:
            del self._pending[key]

    def discard(self, key: object) -> None:
        self._pending.pop(key, None)

    def clear(self) -> None:
        self._pending.clear()

    # ------------------------------------------------------------------ inputs
    def on_ack(self, ack, now: float) -> None:
        """A COMMAND_ACK addressed to us."""
        pending = self._match(ack)
        if pending is None:
            return
        if ack.result == mavlink.MAV_RESULT_ACCEPTED:
            pending.acks += 1
        elif ack.result == mavlink.MAV_RESULT_IN_PROGRESS:
            pending.in_progress = True
        if self._is_final(pending, ack):
            pending.result = ack.result
            pending.answered_at = now
            if ack.result == mavlink.MAV_RESULT_ACCEPTED:
                self._accepted(pending, now)
            else:
                pending.stage = Stage.EXPLAINING
                pending.due = now + self._wall(self.policy.reason_after_s, 0.1)
        elif pending.acks or pending.in_progress:
            pending.stage = Stage.ANSWERED
            pending.due = now + self._wall(self.policy.answer_wait_s, None)

    def on_text(self, severity: int, now: float) -> None:
        """A complete STATUSTEXT arrived: a refusal waiting for its reason ends at the first one
        of severity WARNING or worse."""
        if severity > REASON_SEVERITY:
            return
        for pending in self.pending:
            if pending.stage is Stage.EXPLAINING and now >= pending.answered_at:
                self._explain(pending, now)

    def confirm(self, now: float) -> None:
        """End the commands whose effect now shows (called when the vehicle's state changes)."""
        for pending in self.pending:
            if pending.confirm is not None and self._pending.get(pending.key) is pending:
                if pending.confirm():
                    self._confirmed(pending, now)

    def step(self, now: float) -> None:
        """Retransmit, and end the stages that timed out."""
        self.confirm(now)
        for pending in self.pending:
            if self._pending.get(pending.key) is not pending or now < pending.due:
                continue  # replaced by a callback, or not yet due
            if pending.stage is Stage.SENT:
                limit = pending.spec.max_attempts
                if limit is not None and pending.attempts >= limit:
                    self._finish(pending, Outcome(None, attempts=pending.attempts), now)
                    continue
                pending.attempts += 1
                pending.last_sent = now
                pending.due = now + self._retry_wait(pending.spec, pending.attempts)
                self._transmit(pending.spec, now)
            elif pending.stage is Stage.ANSWERED:
                if pending.acks:
                    pending.result = mavlink.MAV_RESULT_ACCEPTED
                    pending.answered_at = now
                    self._accepted(pending, now)
                else:
                    self._finish(pending, Outcome(None, attempts=pending.attempts), now)
            elif pending.stage is Stage.EXPLAINING:
                self._explain(pending, now)
            else:  # CONFIRMING
                outcome = Outcome(
                    mavlink.MAV_RESULT_ACCEPTED,
                    pending.answered_at,
                    confirmed=False,
                    attempts=pending.attempts,
                )
                self._finish(pending, outcome, now)

    # ------------------------------------------------------------------ internals
    def _match(self, ack) -> Pending | None:
        """The pending command an ACK answers: same command id, still waiting for an answer;
        for speed changes the one whose seq the ACK echoes in `result_param2`, else the oldest."""
        candidates = [
            p
            for p in self._pending.values()
            if p.spec.command == ack.command and p.stage in (Stage.SENT, Stage.ANSWERED)
        ]
        if not candidates:
            return None
        if ack.command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            echoed = getattr(ack, "result_param2", 0)
            for pending in candidates:
                if echoed and int(pending.spec.params[5]) == echoed:
                    return pending
        return min(candidates, key=lambda p: p.first_sent)

    def _retry_wait(self, spec: CommandSpec, attempt: int) -> float:
        return self._wall((spec.retry or self.policy.retransmit).delay(attempt), 0.05)

    def _accepted(self, pending: Pending, now: float) -> None:
        if pending.confirm is None or pending.confirm():
            self._confirmed(pending, now)
            return
        pending.stage = Stage.CONFIRMING
        confirm_s = pending.spec.confirm_s
        pending.due = now + self._wall(
            self.policy.confirm_s if confirm_s is None else confirm_s, None
        )

    def _confirmed(self, pending: Pending, now: float) -> None:
        answered = pending.answered_at if pending.answered_at is not None else now
        outcome = Outcome(mavlink.MAV_RESULT_ACCEPTED, answered, attempts=pending.attempts)
        self._finish(pending, outcome, now)

    def _explain(self, pending: Pending, now: float) -> None:
        before = self._wall(self.policy.reason_before_s, 0.05)
        reason = self._texts.reason(pending.answered_at, before, now)
        outcome = Outcome(pending.result, pending.answered_at, reason, attempts=pending.attempts)
        self._finish(pending, outcome, now)

    def _finish(self, pending: Pending, outcome: Outcome, now: float) -> None:
        if self._pending.get(pending.key) is pending:
            del self._pending[pending.key]
        key = pending.key
        if outcome.accepted:
            self.forget_failures(key)
        else:
            failures = self._failures[key] = self._failures.get(key, 0) + 1
            since = outcome.answered_at if outcome.refused else now
            backoff = pending.spec.backoff or self.policy.refusal
            self._not_before[key] = since + self._wall(backoff.delay(failures), None)
        if pending.on_result is not None:
            pending.on_result(outcome, now)
