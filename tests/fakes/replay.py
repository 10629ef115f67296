"""Transcripts of `tests/sitl/`: reading them, re-encoding their messages with pymavlink, and
replaying their ground-station side into a fake autopilot model in simulated time.
"""

from __future__ import annotations

import gzip
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

from tests.fakes.common import ExtraMessage, mavlink, message_from_fields

#: The recorded sessions: `tests/sitl/`, a copy of the project's `../shared/sitl` (gzipped; a
#: clean clone has no `shared/` beside it), or `$FLEETLINE_SITL_DIR` (either layout).
SITL_DIR = Path(
    os.environ.get("FLEETLINE_SITL_DIR") or Path(__file__).resolve().parents[1] / "sitl"
)

#: Commands a ground station sends (they open a response window).
COMMAND_TYPES = ("COMMAND_LONG", "COMMAND_INT", "SET_MODE")


@dataclass(frozen=True)
class Record:
    """One transcript line."""

    t: float
    direction: str  # "rx" = from the autopilot, "tx" = from the recorder (the GCS)
    system: int
    component: int
    type: str
    fields: dict


def load(name: str) -> list[Record]:
    """Read one transcript (`.jsonl` or `.jsonl.gz`; a `.jsonl` may be stored gzipped)."""
    path = SITL_DIR / name
    if not path.exists() and path.suffix == ".jsonl":
        path = path.with_name(path.name + ".gz")
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt", encoding="utf-8") as lines:
        return [
            Record(d["t"], d["dir"], d["sys"], d["comp"], d["type"], d["fields"])
            for d in map(json.loads, lines)
        ]


def encodable(record: Record) -> bool:
    """Whether pymavlink (dialect `all`) or our extra definitions can encode the record."""
    return hasattr(mavlink, f"MAVLINK_MSG_ID_{record.type}") or record.type in (
        "EVENT",
        "CURRENT_EVENT_SEQUENCE",
    )


def reencode(record: Record):
    """Pack a record with pymavlink under its recorded ids, decode it back: the message object a
    ground station would have received (header included). EVENTs come back as BAD_DATA
    (pymavlink 2.4.50 does not know id 410), exactly as they do from a real PX4."""
    if record.type in ("EVENT", "CURRENT_EVENT_SEQUENCE"):
        message = ExtraMessage(record.type, **record.fields)
    else:
        message = message_from_fields(record.type, record.fields)
    sender = mavlink.MAVLink(None, srcSystem=record.system, srcComponent=record.component)
    data = message.pack(sender)
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    decoded = parser.parse_buffer(data)
    assert decoded and len(decoded) == 1, record
    return decoded[0]


def same_value(recorded, decoded) -> bool:
    """A transcript value equals a decoded one (float32 written shortest, NaN as "NaN")."""
    if isinstance(recorded, list):
        return len(recorded) == len(decoded) and all(map(same_value, recorded, decoded))
    if recorded == "NaN":
        return isinstance(decoded, float) and math.isnan(decoded)
    if isinstance(recorded, float) or isinstance(decoded, float):
        return math.isclose(float(recorded), float(decoded), rel_tol=1e-6, abs_tol=1e-9)
    return recorded == decoded


@dataclass(frozen=True)
class Output:
    """A message the model sent, at transcript time."""

    t: float
    message: object


def replay(
    model, records: list[Record], offset: float, until: float, step: float = 0.01
) -> list[Output]:
    """Feed the transcript's ground-station messages to `model` at their times (model time =
    transcript time - `offset`, the time of the first autopilot HEARTBEAT) and collect what the
    model sends, in simulated time (no clock, no sleeping)."""
    inputs = [
        (r.t, reencode(r))
        for r in records
        if r.direction == "tx" and r.type != "HEARTBEAT" and encodable(r)
    ]
    outputs: list[Output] = []
    now, index = 0.0, 0
    end = until - offset
    while now <= end:
        while index < len(inputs) and inputs[index][0] - offset <= now:
            model.handle(inputs[index][1], now)
            index += 1
        model.tick(now)
        outputs.extend(Output(now + offset, m) for m in model.outbox.pop_due(now))
        now = round(now + step, 6)
    return outputs


def drive(driver, records: list[Record], until: float, step: float = 0.02, actions=None) -> None:
    """Feed the autopilot side of a transcript (re-encoded) to a driver at the recorded times,
    stepping it every `step` s of simulated time; `actions` maps a time to a callable run once
    when the replay reaches it (e.g. the runtime asking for a take-off)."""
    system = driver.spec.system_id
    inputs = [
        (r.t, m)
        for r in records
        if r.direction == "rx" and encodable(r)
        for m in [reencode(r)]
        if m.get_srcSystem() == system  # what `gcs.transport.link.Link` lets through
    ]
    pending = sorted((actions or {}).items())
    now, index = 0.0, 0
    while now <= until:
        while index < len(inputs) and inputs[index][0] <= now:
            driver.on_message(inputs[index][1], inputs[index][0])
            index += 1
        while pending and pending[0][0] <= now:
            pending.pop(0)[1](now)
        driver.step(now)
        now = round(now + step, 6)
