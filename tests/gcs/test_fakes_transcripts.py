"""The fake autopilots are faithful to the recorded SITL sessions of `shared/sitl/` (the copy in
`tests/sitl/`, checked against the original when `../shared/sitl` is beside the repository).

1. Every recorded message re-encodes with pymavlink from its `fields` and decodes back to the
   same values (so the fakes and these tests speak the recorded bytes).
2. Replay: the ground-station side of each transcript is fed to the fake's model at the
   recorded times, in simulated time; what the fake answers is compared with what the real
   autopilot answered: every COMMAND_ACK (command, result, and within 50 ms), the sequence of
   HEARTBEAT states (base_mode, custom_mode, system_status), the STATUSTEXTs and EVENTs the
   fake models, the SYS_STATUS pre-arm bit and the landed state, each in the same order and
   close in time (1.2 s for 1-2 Hz telemetry, more for flight phases whose kinematics the fake
   only approximates).
"""

from __future__ import annotations

import functools
import gzip
from pathlib import Path

import pytest

from tests.fakes.ardupilot import ArduCopterModel
from tests.fakes.common import PREARM_CHECK
from tests.fakes.px4 import Px4Model
from tests.fakes.replay import (
    COMMAND_TYPES,
    SITL_DIR,
    encodable,
    load,
    reencode,
    replay,
    same_value,
)

TRANSCRIPTS = (
    "ardupilot-session.jsonl",
    "ardupilot-refusals.jsonl",
    "px4-session.jsonl.gz",
    "px4-refusals.jsonl",
)

#: The project's original recordings, when the repository sits beside `shared/`.
SHARED_SITL = Path(__file__).resolve().parents[3] / "shared" / "sitl"


@pytest.mark.skipif(not SHARED_SITL.is_dir(), reason="no ../shared/sitl beside the repository")
def test_the_copied_transcripts_are_the_recorded_ones():
    for name in (*TRANSCRIPTS, "README.md"):
        original = (SHARED_SITL / name).read_bytes()
        copy = SITL_DIR / name
        if not copy.exists():
            copy = SITL_DIR / f"{name}.gz"
        data = copy.read_bytes()
        if copy.suffix == ".gz" and not name.endswith(".gz"):
            data = gzip.decompress(data)
        assert data == original, name


#: STATUSTEXTs the ArduPilot fake reproduces (others are SITL boot chatter).
ARDUPILOT_TEXTS = {
    "Calibrating barometer",
    "ArduPilot Ready",
    "GPS 1: detected u-blox",
    "EKF3 IMU0 origin set",
    "EKF3 IMU0 is using GPS",
    "Arm: System not initialised",
    "Arm: Accels inconsistent",
    "Arm: Need Position Estimate",
    "PreArm: Need Position Estimate",
    "Arming motors",
    "Disarming motors",
    "No such mode 99",
}
#: Texts whose timing depends on the fake's approximate kinematics or report schedule (s).
LOOSE = {
    "Disarming motors": 2.5,
    "PreArm: Need Position Estimate": 2.5,
    "Takeoff detected\t": 1.0,
    "Landing detected\t": 2.5,
}


def _model(name: str):
    return ArduCopterModel() if name.startswith("ardupilot") else Px4Model()


@functools.cache
def _replayed(name: str):
    """(transcript records, fake outputs) of one replayed transcript."""
    records = load(name)
    first_heartbeat = next(r.t for r in records if r.direction == "rx" and r.type == "HEARTBEAT")
    outputs = replay(_model(name), records, first_heartbeat, records[-1].t)
    return name, records, outputs


@pytest.fixture(params=TRANSCRIPTS)
def session(request):
    return _replayed(request.param)


def _recorded(records, type_name: str):
    return [(r.t, r.fields) for r in records if r.direction == "rx" and r.type == type_name]


def _faked(outputs, type_name: str):
    return [
        (o.t, {k: getattr(o.message, k) for k in o.message.get_fieldnames()})
        for o in outputs
        if o.message.get_type() == type_name
    ]


def _changes(samples, key) -> list[tuple[float, object]]:
    """(time, value) at each change of `key(fields)`, the first sample excluded."""
    changes, previous = [], None
    for i, (t, fields) in enumerate(samples):
        value = key(fields)
        if i and value != previous:
            changes.append((t, value))
        previous = value
    return changes


def _assert_same_sequence(recorded, faked, tolerance, what: str, loose=None) -> None:
    assert [v for _, v in faked] == [v for _, v in recorded], what
    for (t_rec, value), (t_fake, _) in zip(recorded, faked, strict=True):
        allowed = (loose or {}).get(value, tolerance)
        assert abs(t_fake - t_rec) <= allowed, (
            f"{what}: {value!r} at {t_fake:.3f}, recorded {t_rec:.3f}"
        )


@pytest.mark.parametrize("name", TRANSCRIPTS)
def test_every_recorded_message_reencodes_to_the_same_fields(name):
    records = [r for r in load(name) if encodable(r)]
    assert len(records) > 400
    for record in records:
        decoded = reencode(record)
        if record.type in ("EVENT", "CURRENT_EVENT_SEQUENCE"):
            # pymavlink 2.4.50 does not know them: a GCS gets UNKNOWN_<id>, and from "system
            # 0" (the header is not decoded), which must not pass for another vehicle.
            assert decoded.get_type() == f"UNKNOWN_{410 if record.type == 'EVENT' else 411}"
            assert decoded.get_srcSystem() == 0
            continue
        assert decoded.get_srcSystem() == record.system
        assert decoded.get_type() == record.type
        known = set(decoded.get_fieldnames())  # PX4's dialect adds a few (TIMESYNC targets)
        for key, value in record.fields.items():
            if key in known:
                assert same_value(value, getattr(decoded, key)), (record.t, record.type, key)


def test_command_acks_match(session):
    name, records, outputs = session
    recorded = [(t, (f["command"], f["result"])) for t, f in _recorded(records, "COMMAND_ACK")]
    faked = [(t, (f["command"], f["result"])) for t, f in _faked(outputs, "COMMAND_ACK")]
    _assert_same_sequence(recorded, faked, 0.05, f"{name}: COMMAND_ACK")
    commands = [r for r in records if r.direction == "tx" and r.type in COMMAND_TYPES]
    assert commands, name


def test_heartbeat_states_match(session):
    name, records, outputs = session

    def state(f):
        return (f["base_mode"], f["custom_mode"], f["system_status"])

    recorded = _changes(_recorded(records, "HEARTBEAT"), state)
    faked = _changes(_faked(outputs, "HEARTBEAT"), state)
    flight = {(89, 9, 3): 2.5, (157, 50593792, 4): 1.2}
    _assert_same_sequence(recorded, faked, 1.2, f"{name}: HEARTBEAT", loose=flight)


def test_statustexts_and_events_match(session):
    name, records, outputs = session
    if name.startswith("ardupilot"):
        modelled = ARDUPILOT_TEXTS
    else:
        modelled = {f["text"] for _, f in _recorded(records, "STATUSTEXT")} - {
            f["text"] for _, f in _recorded(records, "STATUSTEXT") if f["text"].startswith("[")
        }
    recorded = [
        (t, f["text"]) for t, f in _recorded(records, "STATUSTEXT") if f["text"] in modelled
    ]
    faked = [(t, f["text"]) for t, f in _faked(outputs, "STATUSTEXT")]
    assert recorded
    _assert_same_sequence(recorded, faked, 1.2, f"{name}: STATUSTEXT", loose=LOOSE)
    if name.startswith("px4"):
        recorded_ids = [(t, f["id"]) for t, f in _recorded(records, "EVENT")]
        faked_ids = [(t, f["id"]) for t, f in _faked(outputs, "EVENT")]
        landed = {26622124: 2.5, 21054825: 1.0}
        _assert_same_sequence(recorded_ids, faked_ids, 1.2, f"{name}: EVENT", loose=landed)


def test_prearm_bit_and_landed_state_match(session):
    name, records, outputs = session

    def prearm(f):
        return bool(f["onboard_control_sensors_health"] & PREARM_CHECK)

    _assert_same_sequence(
        _changes(_recorded(records, "SYS_STATUS"), prearm),
        _changes(_faked(outputs, "SYS_STATUS"), prearm),
        1.2,
        f"{name}: pre-arm bit",
    )

    def landed(f):
        return f["landed_state"]

    _assert_same_sequence(
        _changes(_recorded(records, "EXTENDED_SYS_STATE"), landed),
        _changes(_faked(outputs, "EXTENDED_SYS_STATE"), landed),
        1.2,
        f"{name}: landed state",
        loose={1: 2.5, 2: 2.5},
    )


@pytest.mark.parametrize("name", TRANSCRIPTS[:2])
def test_ardupilot_streams_nothing_until_asked(name):
    _, records, outputs = _replayed(name)
    first_request = next(
        r.t for r in records if r.direction == "tx" and r.type == "COMMAND_LONG"
        and r.fields["command"] == 511
    )  # fmt: skip
    periodic = {"SYS_STATUS", "GPS_RAW_INT", "GLOBAL_POSITION_INT", "EKF_STATUS_REPORT"}
    for source in (
        [(r.t, r.type) for r in records if r.direction == "rx"],
        [(o.t, o.message.get_type()) for o in outputs],
    ):
        assert not [kind for t, kind in source if t < first_request and kind in periodic]
        assert periodic <= {kind for _, kind in source}
