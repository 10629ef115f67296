"""The ground station's answers to the operator (`gcs speed`, `gcs return`, `gcs relieve`):
a typed result and its reason, as MAVSDK's `ActionResult`, serialised by the operator socket
(`gcs.speed.OperatorRequest.reply`) into the JSON line of docs/cli.md.

The core decides and fills an `OperatorAnswer`; it never builds the wire's dicts. The wire
format is `to_json`: `{"ok": true, "result": "accepted", ...the command's fields}` or
`{"ok": false, "result": "...", "reason": "..."}`.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Any


class AnswerResult(Enum):
    """What became of an operator's request."""

    ACCEPTED = "accepted"
    BAD_REQUEST = "bad_request"  # the request itself could not be read (the socket's error)
    NOT_FLYING = "not_flying"  # the fleet has not taken off yet
    LANDING = "landing"  # the fleet is landing: nothing more is taken
    HOLDING = "holding"  # every UAV holds its station until the return
    REFUSED = "refused"  # the request breaks a rule of the flight (its reason says which)


class OperatorCommand(Enum):
    """The operator socket's commands (`"command"` in the request line)."""

    SPEED = "speed"
    RETURN = "return"
    RELIEVE = "relieve"


@dataclass(frozen=True)
class OperatorAnswer:
    """One answer. Accepted speed changes carry `seq`, `effective_s` and `speed`; returns
    `effective_s` and `distance` (the formation distance M it flies home from); reliefs `uav`,
    `effective_s` and `landing_xy` (local metres)."""

    command: OperatorCommand
    result: AnswerResult
    reason: str | None = None
    seq: int | None = None
    effective_s: float | None = None
    speed: float | None = None
    distance: float | None = None
    uav: int | None = None
    landing_xy: tuple[float, float] | None = None

    @property
    def ok(self) -> bool:
        return self.result is AnswerResult.ACCEPTED

    @classmethod
    def refused(cls, command: OperatorCommand, result: AnswerResult, reason: str) -> OperatorAnswer:
        return cls(command, result, reason)

    def to_json(self) -> dict[str, Any]:
        """The JSON object the operator socket sends back."""
        if not self.ok:
            return {"ok": False, "result": self.result.value, "reason": self.reason}
        fields: dict[str, Any] = {"ok": True, "result": self.result.value}
        if self.command is OperatorCommand.SPEED:
            fields.update(seq=self.seq, effective_s=self.effective_s, speed=self.speed)
        elif self.command is OperatorCommand.RETURN:
            fields.update(effective_s=self.effective_s, distance=self.distance)
        else:
            landing = None if self.landing_xy is None else [float(v) for v in self.landing_xy]
            fields.update(uav=self.uav, effective_s=self.effective_s, landing_xy=landing)
        return fields
