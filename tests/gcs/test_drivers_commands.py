"""The pure parts of command tracking: back-off schedules, STATUSTEXT chunks, refusal reasons.

The tracker itself is exercised through the drivers against the fake autopilots over UDP
(`test_drivers_ardupilot.py`, `test_drivers_px4.py`).
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.drivers.commands import Backoff, VehicleTexts
from gcs.transport.link import mavutil

mavlink = mavutil.mavlink
WARNING, INFO, CRITICAL = (
    mavlink.MAV_SEVERITY_WARNING,
    mavlink.MAV_SEVERITY_INFO,
    mavlink.MAV_SEVERITY_CRITICAL,
)


def statustext(severity: int, text: str, ident: int = 0, seq: int = 0):
    """A STATUSTEXT as a ground station decodes it (packed and parsed by pymavlink)."""
    message = mavlink.MAVLink_statustext_message(
        severity, text.encode("latin-1"), id=ident, chunk_seq=seq
    )
    parser = mavlink.MAVLink(None)
    (decoded,) = parser.parse_buffer(message.pack(mavlink.MAVLink(None, 1, 1)))
    return decoded


@settings(derandomize=True, max_examples=200, deadline=None)
@given(
    first=st.floats(0.01, 10.0),
    growth=st.floats(1.0, 4.0),
    ceiling=st.floats(0.01, 60.0),
    failures=st.integers(1, 40),
)
def test_backoff_grows_from_its_first_wait_up_to_its_ceiling(first, growth, ceiling, failures):
    backoff = Backoff(first, growth, ceiling)
    assert backoff.delay(1) == min(first, ceiling)
    assert backoff.delay(failures) <= backoff.delay(failures + 1) <= ceiling


def test_px4_chunks_are_joined_in_sequence_and_a_lost_last_chunk_is_flushed():
    texts = VehicleTexts()
    first = "Arming denied: Resolve system health failures firs"  # P1 7.76, 50 characters
    assert texts.add(statustext(CRITICAL, first, ident=7, seq=0), 1.0) is None
    assert texts.add(statustext(CRITICAL, "t\t", ident=7, seq=1), 1.001) == (
        CRITICAL,
        "Arming denied: Resolve system health failures first",
    )
    # A chunk out of order is placed by its chunk_seq; a text whose end never came is kept.
    assert texts.add(statustext(WARNING, "B" * 50, ident=8, seq=1), 2.0) is None
    assert texts.add(statustext(WARNING, "A" * 50, ident=8, seq=0), 2.0) is None
    assert texts.flush(2.4, max_age=0.5) == []
    assert texts.flush(2.5, max_age=0.5) == [(WARNING, "A" * 50 + "B" * 50)]
    assert [t for _, _, t in texts.entries][-1] == "A" * 50 + "B" * 50


def test_reason_is_the_nearest_warning_or_worse_around_the_ack():
    texts = VehicleTexts()
    texts.note(CRITICAL, "PreArm: Need Position Estimate", 9.5)  # periodic, too early
    texts.note(WARNING, "stale warning", 9.92)
    texts.note(INFO, "EKF3 IMU0 is using GPS", 9.999)  # nearest, but INFO
    texts.note(CRITICAL, "Arm: Need Position Estimate", 10.005)  # 5 ms after the ACK
    texts.note(CRITICAL, "too late", 10.5)
    assert texts.reason(10.0, before=0.1, until=10.3) == "Arm: Need Position Estimate"
    assert texts.reason(10.0, before=0.1, until=10.0) == "stale warning"
    assert texts.reason(10.0, before=0.05, until=10.0) is None
    assert texts.last() == "too late"
    assert texts.last(since=10.0, max_severity=INFO) == "too late"
    assert texts.last(since=10.6) is None


def test_reason_on_a_tie_is_the_later_text():
    texts = VehicleTexts()
    texts.note(CRITICAL, "before", 9.75)  # exact binary fractions: a true tie
    texts.note(WARNING, "after", 10.25)
    assert texts.reason(10.0, before=0.5, until=10.5) == "after"
