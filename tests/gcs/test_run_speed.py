"""Speed changes (docs/design.md 4): effective times, refusals, the schedule, the operator
socket."""

from __future__ import annotations

import json
import os
import socket
import stat
import threading
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.flight.answers import AnswerResult, OperatorAnswer, OperatorCommand
from gcs.mission import ScheduledChange
from gcs.speed import (
    OperatorSocket,
    SpeedChanges,
    SpeedRefused,
    find_running_sockets,
    send_operator_request,
    socket_path_for,
)


def changes(window_s: float = 2.0, schedule=()) -> SpeedChanges:
    return SpeedChanges(max_speed=10.0, window_s=window_s, schedule=list(schedule))


def test_lead_is_half_the_window_at_least():
    speeds = changes(window_s=3.0)
    assert speeds.lead_s == pytest.approx(1.5)
    change = speeds.request(5.0, 10.0, "operator")
    assert change.effective_s == pytest.approx(11.5)
    assert change.seq == 1


def test_lead_grows_with_the_worst_reaction_time():
    speeds = changes(window_s=0.2)
    record = speeds.record(speeds.request(5.0, 0.0, "operator"), 0.0)
    speeds.acknowledge(record, 1, 0.9)
    assert speeds.lead_s == pytest.approx(1.8)
    assert record.as_json()["acks"] == {"1": 0.9}


def test_too_soon_or_too_fast_is_refused():
    speeds = changes(window_s=2.0)
    with pytest.raises(SpeedRefused, match="too soon"):
        speeds.request(5.0, 10.0, "operator", at=10.5)
    with pytest.raises(SpeedRefused, match=r"\[0, 10\]"):
        speeds.request(11.0, 10.0, "operator")
    with pytest.raises(SpeedRefused):
        speeds.request(-1.0, 10.0, "operator")
    assert speeds.request(5.0, 10.0, "operator", at=20.0).effective_s == 20.0


def test_scheduled_changes_are_due_ahead_of_their_effective_time():
    speeds = changes(
        window_s=2.0,
        schedule=[ScheduledChange(20.0, 5.0), ScheduledChange(35.0, 8.0, leader=2)],
    )
    assert speeds.due(10.0) == []
    due = speeds.due(20.0 - speeds.lead_s - speeds.announce_s)
    assert [c.at for c in due] == [20.0]
    assert speeds.due(100.0) == []  # the leader's change is the leader's to send


@settings(max_examples=60, derandomize=True, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(0, 10), st.floats(0, 5), st.one_of(st.none(), st.floats(0, 30))),
        min_size=1,
        max_size=12,
    )
)
def test_effective_times_always_leave_the_lead_and_increase(requests):
    speeds = changes(window_s=1.0)
    now, last = 0.0, -1.0
    for speed, step, at in requests:
        now += step
        try:
            change = speeds.request(speed, now, "operator", at)
        except SpeedRefused:
            continue
        assert change.effective_s >= now + speeds.lead_s - 1e-9
        assert change.effective_s > last
        last = change.effective_s


def _poll_until_request(server: OperatorSocket, seconds: float = 5.0):
    """Poll the (non-blocking) server until a complete request arrived, with a deadline."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        requests = server.poll()
        if requests:
            return requests
    raise AssertionError("no request arrived before the deadline")


def test_operator_socket_round_trip(tmp_path: Path):
    log = tmp_path / "run.mcap"
    server = OperatorSocket(socket_path_for(log))
    try:
        mode = stat.S_IMODE(os.stat(socket_path_for(log)).st_mode)
        assert mode & 0o077 == 0, "only the owner may command the fleet"
        answers = {}

        def client():
            answers["reply"] = send_operator_request(socket_path_for(log), 4.5, 30.0)

        thread = threading.Thread(target=client)
        thread.start()
        (request,) = _poll_until_request(server)
        assert (request.speed, request.at, request.error) == (4.5, 30.0, None)
        request.reply(
            OperatorAnswer(
                OperatorCommand.SPEED, AnswerResult.ACCEPTED, seq=1, effective_s=30.0, speed=4.5
            )
        )
        thread.join(5)
        assert answers["reply"] == {
            "ok": True, "result": "accepted", "seq": 1, "effective_s": 30.0, "speed": 4.5
        }  # fmt: skip
        assert find_running_sockets(tmp_path) == [socket_path_for(log)]
    finally:
        server.close()
    assert not socket_path_for(log).exists()


def test_operator_socket_with_a_path_too_long_for_sun_path(tmp_path: Path):
    deep = tmp_path / ("d" * 60) / ("e" * 60)
    deep.mkdir(parents=True)
    path = socket_path_for(deep / "mission-20250101T000000Z.mcap")
    assert len(str(path)) > 108
    server = OperatorSocket(path)
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as raw:
            fd = os.open(path.parent, os.O_RDONLY)
            try:
                raw.connect(f"/proc/self/fd/{fd}/{path.name}")
            finally:
                os.close(fd)
            raw.sendall(b'{"speed": "fast"}\n')
            (request,) = _poll_until_request(server)
            assert request.error and "speed must be a number" in request.error
            request.reply(
                OperatorAnswer.refused(
                    OperatorCommand.SPEED, AnswerResult.BAD_REQUEST, request.error
                )
            )
            assert json.loads(raw.makefile().readline())["ok"] is False
    finally:
        server.close()
