"""A recording that cannot be written (a full disk: /dev/full, an I/O error) stops where it is;
it never stops the flight. The recorder alone here (no process, no socket); the flight is
test_log_flight.py's."""

from __future__ import annotations

from pathlib import Path

import pytest

from gcs.flight.clock import MissionClock
from gcs.recording.recording import FlightRecorder

FULL = Path("/dev/full")


@pytest.fixture
def full_disk(tmp_path):
    if not FULL.exists():
        pytest.skip("no /dev/full on this system")
    link = tmp_path / "full.mcap"
    link.symlink_to(FULL)
    return link


def test_a_full_disk_stops_the_file_not_the_caller(full_disk):
    clock = MissionClock(1.0, monotonic=lambda: 0.0, unix_ns=lambda: 0)
    clock.anchor(0.0, 0.0)
    told = []
    recorder = FlightRecorder(full_disk, clock, force=True)
    recorder.on_error = told.append
    for k in range(20_000):  # enough for several chunks: every write and flush must fail
        recorder.event("info", "x" * 100, 0.01 * k)
    recorder.outcome({"completed": True})
    recorder.close()
    assert recorder.error is not None and "full.mcap" in recorder.error
    assert told == [recorder.error]  # told once
    assert recorder.messages == 20_000  # every record was handed over; none raised
