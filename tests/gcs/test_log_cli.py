"""`gcs log info|report|replay`: bad input is one line and exit 2; small logs written here."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import pytest

from gcs.flight.clock import MissionClock
from gcs.recording.recording import FlightRecorder
from gcs.transport.link import mavutil
from tests.cli_refusals import one_line_exit_2


@pytest.fixture
def gcs_log(gcs_main):
    """`gcs ARGS` in this process (conftest's `gcs_main`)."""
    return gcs_main


@pytest.fixture
def events_only(tmp_path: Path) -> Path:
    """A valid MCAP recording with no plan and no MAVLink (a GCS that never connected)."""
    path = tmp_path / "events.mcap"
    recorder = FlightRecorder(path, MissionClock())
    recorder.event("error", "no heartbeat from system 1", 5.0)
    recorder.close()
    return path


@pytest.fixture
def tiny_flight(tmp_path: Path) -> Path:
    """A recording with three MAVLink frames from UAV 1, 0.1 s apart."""
    path = tmp_path / "tiny.mcap"
    wall = [100.0]
    clock = MissionClock(monotonic=lambda: wall[0], unix_ns=lambda: 1_700_000_000_000_000_000)
    clock.anchor(100.0, 0.0)
    recorder = FlightRecorder(path, clock)
    mav = mavutil.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    for k in range(3):
        message = mav.heartbeat_encode(2, 3, 0, k, 4)
        recorder.mavlink(1, "rx", message.pack(mav), message, 100.0 + 0.1 * k)
    recorder.close()
    return path


@pytest.mark.parametrize("command", ["info", "report", "replay"])
def test_a_file_that_is_not_mcap_is_refused(gcs_log, tmp_path, command):
    bad = tmp_path / "notes.mcap"
    bad.write_text("version: 1\n")
    extra = {"info": [], "report": ["--out", tmp_path / "r"], "replay": ["--to", "udpout:x:1"]}
    one_line_exit_2(gcs_log("log", command, bad, *extra[command]), str(bad), "MCAP")
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    one_line_exit_2(gcs_log("log", command, empty, *extra[command]), str(empty), "MCAP")


def test_a_missing_file_or_a_folder_is_refused(gcs_log, tmp_path):
    one_line_exit_2(gcs_log("log", "info", tmp_path / "nowhere.mcap"), "nowhere.mcap")
    one_line_exit_2(gcs_log("log", "info", tmp_path), str(tmp_path))


def test_info_of_a_recording_that_never_flew(gcs_log, events_only):
    code, out, err = gcs_log("log", "info", events_only, "--json")
    assert code == 0, err
    info = json.loads(out)
    assert info["truncated"] is False and info["uavs"] == [] and info["mission"] is None
    assert info["topics"]["/events"]["count"] == 1


def test_report_needs_a_recording_of_a_mission_run(gcs_log, events_only, tmp_path):
    one_line_exit_2(
        gcs_log("log", "report", events_only, "--out", tmp_path / "r"), "events.mcap", "plan"
    )
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    one_line_exit_2(gcs_log("log", "report", events_only, "--out", a_file), "--out")


def test_replay_refusals(gcs_log, events_only, tiny_flight):
    one_line_exit_2(gcs_log("log", "replay", events_only, "--to", "udpout:127.0.0.1:9"), "MAVLink")
    for rate in ("0", "-1", "nan", "inf"):
        one_line_exit_2(
            gcs_log("log", "replay", tiny_flight, "--to", "udpout:127.0.0.1:9", "--rate", rate),
            "--rate",
        )
    one_line_exit_2(
        gcs_log("log", "replay", tiny_flight, "--to", "udpout:127.0.0.1:9", "--uav", "7"), "UAV 7"
    )
    one_line_exit_2(gcs_log("log", "replay", tiny_flight, "--to", "nonsense"), "--to")
    one_line_exit_2(gcs_log("log", "replay", tiny_flight, "--to", "udpout:127.0.0.1:99999"), "--to")
    one_line_exit_2(gcs_log("log", "replay", tiny_flight), "--to")  # required


@pytest.mark.slow
def test_replay_keeps_the_recorded_spacing_divided_by_the_rate(gcs_log, tiny_flight):
    from gcs.recording.logreader import read_recording
    from gcs.recording.replay import open_output, recorded_frames, replay

    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.settimeout(5.0)
    url = f"udpout:127.0.0.1:{sink.getsockname()[1]}"
    try:
        code, _, err = gcs_log("log", "replay", tiny_flight, "--to", url, "--rate", "20")
        assert code == 0, err
        frames = [sink.recv(1024) for _ in range(3)]
        # the schedule, on a clock the test moves (the frames still go through the socket)
        now, slept = [0.0], []

        def sleep(seconds: float) -> None:
            slept.append(seconds)
            now[0] += seconds

        recorded = recorded_frames(read_recording(tiny_flight))
        stats = replay(recorded, open_output(url), 2.0, monotonic=lambda: now[0], sleep=sleep)
        again = [sink.recv(1024) for _ in range(3)]
    finally:
        sink.close()
    parser = mavutil.mavlink.MAVLink(None)
    assert [parser.parse_buffer(f)[0].custom_mode for f in frames] == [0, 1, 2]
    assert again == frames
    assert slept == pytest.approx([0.05, 0.05])  # 0.1 s apart when recorded, at 2x
    assert (stats.frames, stats.recorded_s) == (3, pytest.approx(0.2))
