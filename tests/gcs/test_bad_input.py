"""Bad input everywhere: every flag of every `gcs` and `vehicles` command (exit 2, one line naming
the flag, no traceback, nothing started), the fleet's key file, hostile datagrams at the ground
station's signed links (hypothesis), and recordings cut at any byte.

Elsewhere: mission files, the corpus `tests/missions/bad/` (test_cli_plan.py); files that are
not MCAP (test_log_cli.py); hostile datagrams at a flying vehicle (test_vehicles_fuzz.py) and,
in flight, at every vehicle and ground-station port (the attacker, test_faults_e2e.py).
"""

from __future__ import annotations

import argparse
import io
import json
import random
import socket
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.records import DataEnd
from mcap.stream_reader import StreamReader

import gcs.cli
import vehicles.cli
from fleetline.errors import UsageError
from gcs.flight.clock import MissionClock
from gcs.flight.records import MetricsRecord
from gcs.recording.logreader import read_recording
from gcs.recording.recording import FlightRecorder
from gcs.transport.link import Link
from gcs.transport.signing import FleetSigning
from tests.attacker import codec, mutate, timestamp_now
from tests.conftest import MISSIONS
from tests.flying import MISSION, Flight, mission_file
from tests.links import drain

RNG = random.Random(20)


# --------------------------------------------------------------------------- flags
def leaves(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()):
    """(command words, parser) of every leaf command."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield prefix, parser
        return
    for name, sub in subs[0].choices.items():
        yield from leaves(sub, (*prefix, name))


@pytest.fixture(scope="module")
def tiny_log(tmp_path_factory) -> Path:
    """A recording with three MAVLink frames from UAV 1."""
    path = tmp_path_factory.mktemp("log") / "tiny.mcap"
    clock = MissionClock(monotonic=lambda: 100.0, unix_ns=lambda: 1_700_000_000_000_000_000)
    clock.anchor(100.0, 0.0)
    recorder = FlightRecorder(path, clock)
    mav = codec(1, 1, None)
    for k in range(3):
        message = mav.heartbeat_encode(2, 3, 0, k, 4)
        recorder.mavlink(1, "rx", bytes(message.pack(mav)), message, 100.0 + 0.1 * k)
    recorder.close()
    return path


def valid_values(tiny_log: Path, folder: Path) -> dict[str, str]:
    """A valid value for each positional or required option, by its dest."""
    return {
        "file": str(MISSION),
        "log": str(tiny_log),
        "speed": "5",
        "uav": "2",
        "out": str(folder / "out"),
        "to": "udpout:127.0.0.1:9",
        "autopilot": "ardupilot",
        "study": str(MISSIONS / "study-tiny.yaml"),
        "dir": str(folder / "study"),
    }


def invocation(action: argparse.Action, values: dict[str, str]) -> list[str]:
    if action.option_strings:
        return [action.option_strings[0], values[action.dest]]
    return [values[action.dest]]


def bad_flag_cases(parser: argparse.ArgumentParser) -> list[tuple[list[str], str]]:
    """(arguments, flag named in the message) refused by argparse itself: an unknown flag, a
    number that is not one, a choice that is not one, a flag without its value."""
    cases = [(["--no-such-flag"], "--no-such-flag")]
    for action in parser._actions:
        if not action.option_strings or isinstance(action, argparse._HelpAction):
            continue
        flag = action.option_strings[0]
        if action.type in (int, float):
            cases.append(([flag, "not-a-number"], flag))
        if action.choices:
            cases.append(([flag, "bogus"], flag))
        if action.nargs is None and action.type in (int, float):
            cases.append(([flag], flag))  # the value is missing
    return cases


def one_line_exit_2(code: int, out: str, err: str, names: str) -> None:
    assert code == 2, err
    assert out == ""
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert names in err, err


def run_gcs(capsys, args: list[str]) -> tuple[int, str, str]:
    capsys.readouterr()
    code = gcs.cli.main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_every_gcs_command_refuses_bad_flags_on_one_line(capsys, tiny_log, tmp_path):
    values = valid_values(tiny_log, tmp_path)
    checked = 0
    for words, parser in leaves(gcs.cli.build_parser()):
        required = [
            a
            for a in parser._actions
            if (not a.option_strings or a.required) and not isinstance(a, argparse._HelpAction)
        ]
        base = [*words, *(arg for a in required for arg in invocation(a, values))]
        # a missing positional or required option
        if required:
            missing = required[-1]
            rest = [arg for a in required[:-1] for arg in invocation(a, values)]
            # a positional is named by its metavar (`gcs relieve N`), else by its dest
            name = missing.option_strings[0] if missing.option_strings else missing.metavar
            name = name or missing.dest
            code, out, err = run_gcs(capsys, [*words, *rest])
            one_line_exit_2(code, out, err.lower(), name.lower())
        for args, flag in bad_flag_cases(parser):
            one_line_exit_2(*run_gcs(capsys, [*base, *args]), flag)
            checked += 1
    assert checked >= 20


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["mission", "run", "{file}", "--speedup", "nan"], "--speedup"),
        (["mission", "run", "{file}", "--speedup", "-1"], "--speedup"),
        (["mission", "run", "{file}", "--speedup", "1e9"], "--speedup"),
        (["mission", "run", "{file}", "--link-wait", "inf"], "--link-wait"),
        (["mission", "run", "{file}", "--takeoff-lead", "0"], "--takeoff-lead"),
        (["mission", "run", "{file}", "--vehicles-per-process", "0"], "--vehicles-per-process"),
        (["mission", "run", "{file}", "--foxglove", "-5"], "--foxglove"),
        (["mission", "run", "{file}", "--log", "x.txt"], "--log"),
        (["mission", "plan", "{file}", "--connect", "udpout:h:1"], "--connect"),
        (["log", "replay", "{log}", "--to", "udpout:127.0.0.1:9", "--rate", "0"], "--rate"),
        (["log", "replay", "{log}", "--to", "udpout:127.0.0.1:9", "--rate", "nan"], "--rate"),
        (["log", "replay", "{log}", "--to", "nonsense"], "--to"),
        (["log", "replay", "{log}", "--to", "udpout:127.0.0.1:9", "--uav", "0"], "UAV 0"),
        (["sitl", "launch-plan", "{file}", "--autopilot", "px4", "--speedup", "0"], "--speedup"),
        (["log", "report", "{log}", "--out", "/proc/fleetline-report"], "/proc/fleetline-report"),
        (["log", "report", "{log}", "--out", "/sys/fleetline-report"], "/sys/fleetline-report"),
        (["eval", "paper", "--out", "/proc/fleetline-eval"], "/proc/fleetline-eval"),
        (["mission", "plan", "{file}", "--out", "/proc/fleetline.json"], "/proc/fleetline.json"),
    ],
)
def test_bad_flag_values_are_refused_before_anything_starts(capsys, tiny_log, args, flag):
    args = [a.format(file=MISSION, log=tiny_log) for a in args]
    one_line_exit_2(*run_gcs(capsys, args), flag)


def test_every_vehicles_flag_is_refused_on_one_line(capsys):
    (words, parser), *_ = [(w, p) for w, p in leaves(vehicles.cli.build_parser()) if w == ("sim",)]
    cases = bad_flag_cases(parser)
    for action in parser._actions:  # its flags parse with their own functions
        if action.option_strings and callable(action.type) and action.type not in (int, float):
            flag = action.option_strings[0]
            named = "1e999x" if action.dest == "positions_file" else flag  # names the file
            cases.append(([flag, "1e999x"], named))
    cases += [
        (["--exit-when-orphaned", "-3"], "--exit-when-orphaned"),
        (["--count", "3", "--positions", "0,0;1,1"], "--positions"),
        (["--count", "0"], "--count"),
        (["--speedup", "nan"], "--speedup"),
        (["--wind", "1,2,3,4"], "--wind"),
    ]
    for args, flag in cases:
        argv = ["sim", "--base-port", "14560", *args]
        with pytest.raises(UsageError):  # refused while parsing: nothing starts
            vehicles.cli.config_from_args(vehicles.cli.build_parser().parse_args(argv))
        capsys.readouterr()
        code = vehicles.cli.main(argv)
        out, err = capsys.readouterr()
        one_line_exit_2(code, out, err, flag)
    assert len(cases) >= 30


@pytest.mark.parametrize("log", ["/proc/fleetline.mcap", "/sys/fleetline.mcap"])
def test_a_log_path_the_system_refuses_is_one_line(capsys, tmp_path, monkeypatch, log):
    """A folder that exists but takes no file (virtual, read-only): the recorder cannot
    create it, and nothing has started yet."""
    monkeypatch.chdir(tmp_path)
    code, out, err = run_gcs(capsys, ["mission", "run", str(MISSION), "--json", "--log", log])
    one_line_exit_2(code, out, err, "--log")
    assert log in err


def test_no_log_folder_where_one_cannot_be_made_is_one_line(capsys, monkeypatch):
    monkeypatch.chdir("/proc")  # logs/ cannot be created here
    code, out, err = run_gcs(capsys, ["mission", "run", str(MISSION), "--json"])
    one_line_exit_2(code, out, err, "--log")


@pytest.mark.slow
def test_a_connection_refused_at_start_is_one_line_naming_the_endpoint(capsys, tmp_path):
    closed = socket.socket()  # a port nobody listens on
    closed.bind(("127.0.0.1", 0))
    port = closed.getsockname()[1]
    closed.close()
    urls = [f"tcp:127.0.0.1:{port}", *(f"udpout:127.0.0.1:{port + k}" for k in (1, 2, 3))]
    log = str(tmp_path / "run.mcap")
    args = ["mission", "run", str(MISSION), "--json", "--log", log, "--connect", *urls]
    code, out, err = run_gcs(capsys, args)
    assert code == 2 and out == "", err
    refusal = err.splitlines()[-1]
    assert refusal.startswith("--connect: ") and urls[0] in refusal and "refused" in refusal
    assert "Traceback" not in err
    assert all("gcs.transport.link" in line for line in err.splitlines()[:-1] if "refused" in line)


def test_an_unknown_host_in_the_mission_names_the_connection(capsys, tmp_path):
    mission = mission_file(
        tmp_path,
        fleet={"connections": [f"udpout:nohost.invalid:{14550 + k}" for k in range(4)]},
    )
    log = str(tmp_path / "run.mcap")
    code, out, err = run_gcs(capsys, ["mission", "run", str(mission), "--json", "--log", log])
    assert code == 2 and out == "" and "Traceback" not in err, err
    refusal = err.splitlines()[-1]
    assert refusal.startswith(f"{mission}: fleet.connections[0]: ") and "nohost.invalid" in refusal


# --------------------------------------------------------------------------- the key file
def test_a_bad_key_file_is_refused_before_anything_flies(tmp_path, monkeypatch, capsys):
    mission = mission_file(tmp_path, signing={"key_file": "fleet.key"})
    (tmp_path / "fleet.key").write_text("a" * 64 + "\n")
    (tmp_path / "fleet.key").chmod(0o644)
    monkeypatch.chdir(tmp_path)
    code, out, err = run_gcs(capsys, ["mission", "run", str(mission), "--log", "run.mcap"])
    one_line_exit_2(code, out, err, "signing.key_file")
    assert "chmod 600" in err and str(mission) in err
    assert not (tmp_path / "run.mcap").exists()  # nothing started, nothing recorded


@pytest.mark.slow
def test_insecure_says_so_loudly_and_in_the_log(tmp_path):
    """`--insecure` on a fleet that never answers (then Ctrl-C): a warning line at once and a
    warning event in the recording."""
    dead = []
    for _ in range(4):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        dead.append(sock)
    urls = [f"udpout:127.0.0.1:{sock.getsockname()[1]}" for sock in dead]
    log = tmp_path / "insecure.mcap"
    flight = Flight(
        ["mission", "run", str(MISSION), "--insecure", "--connect", *urls, "--log", str(log)],
        tmp_path,
    )
    try:
        line = flight.lines[flight.wait_for("--insecure", timeout=30)]
        assert "NOT signed" in line
        dead[0].settimeout(30)
        data, _ = dead[0].recvfrom(2048)  # the GCS is talking: unsigned
        assert data[0] == 0xFD and not data[2] & 1
        flight.process.send_signal(2)  # Ctrl-C while connecting
        code, _, _ = flight.finish(timeout=30)
    finally:
        flight.kill()
        for sock in dead:
            sock.close()
    assert code == 1
    recording = read_recording(log, keep=lambda topic: topic == "/events")
    texts = [m.message for _, m in recording.messages("/events")]
    assert any(t.startswith("--insecure: MAVLink is NOT signed") for t in texts)


# --------------------------------------------------------------------------- datagrams
KEY = RNG.randbytes(32)


@pytest.fixture(scope="module")
def signed_link():
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    link = Link(f"udpout:127.0.0.1:{vehicle.getsockname()[1]}", system_id=1)
    FleetSigning(KEY).apply(link, 1)
    link.send(link.mav.heartbeat_encode(6, 8, 0, 0, 4), time.monotonic())
    _, gcs_address = vehicle.recvfrom(2048)
    yield link, vehicle, gcs_address
    link.close()
    vehicle.close()


def genuine_frame(kind: int, age_s: float = 0.0) -> bytes:
    """A frame UAV 1 signs with the fleet key, `age_s` old."""
    mav = codec(1, 1, KEY, timestamp_now(-age_s))
    message = [
        mav.heartbeat_encode(2, 3, 217, 4, 4),
        mav.global_position_int_encode(1, 457640000, 48357000, 190000, 20000, 0, 0, 0, 0),
        mav.statustext_encode(4, b"hello"),
    ][kind % 3]
    return bytes(message.pack(mav))


#: Genuine frames recorded 100 s ago (older than anything the link has heard: replays).
RECORDED = [genuine_frame(kind, age_s=100.0) for kind in range(3)]


def forged(key: bytes | None) -> bytes:
    """A well-formed LAND heartbeat from UAV 1: unsigned (no key) or signed with another key."""
    mav = codec(1, 1, key, timestamp_now())
    return bytes(mav.heartbeat_encode(2, 3, 81, 9, 5).pack(mav))


hostile = st.one_of(
    st.binary(max_size=300),
    st.sampled_from(RECORDED),
    st.builds(
        lambda frame, seed: mutate(random.Random(seed), frame),
        st.sampled_from(RECORDED),
        st.integers(0, 2**32),
    ),
    st.builds(forged, st.one_of(st.none(), st.binary(min_size=32, max_size=32))),
)


@settings(
    max_examples=80,
    derandomize=True,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(datagrams=st.lists(hostile, min_size=1, max_size=30), kind=st.integers(0, 2))
def test_hostile_datagrams_never_reach_the_ground_station_nor_keep_a_link_alive(
    signed_link, datagrams, kind
):
    link, vehicle, gcs_address = signed_link
    before = link.counters.received
    for data in datagrams:
        vehicle.sendto(data, gcs_address)
    genuine = genuine_frame(kind)
    vehicle.sendto(genuine, gcs_address)
    received = drain(link, lambda got: got)
    # only the genuine frame came through (a mutated copy of an old frame is refused)
    assert [bytes(m.get_msgbuf()) for m in received] == [genuine]
    assert link.counters.received == before + 1


# --------------------------------------------------------------------------- cut recordings
@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """A small complete recording: MAVLink frames and metrics, flushed every 50 frames."""
    path = tmp_path_factory.mktemp("cut") / "whole.mcap"
    wall = [100.0]
    clock = MissionClock(monotonic=lambda: wall[0], unix_ns=lambda: 1_700_000_000_000_000_000)
    clock.anchor(100.0, 0.0)
    recorder = FlightRecorder(path, clock)
    mav = codec(1, 1, None)
    for k in range(300):
        wall[0] = 100.0 + 0.01 * k
        message = mav.heartbeat_encode(2, 3, 0, k, 4)
        recorder.mavlink(1, "rx", bytes(message.pack(mav)), message, wall[0])
        metrics = MetricsRecord(0.01 * k, 5.0, 0.0, None, None, None, [], None, [])
        recorder.metrics(metrics, wall[0])
        if k % 50 == 0:
            recorder.flush(wall[0])
    recorder.close()
    return path


@settings(max_examples=40, derandomize=True, deadline=None)
@given(fraction=st.floats(0.0, 0.999))
def test_a_recording_cut_anywhere_is_read_up_to_the_cut(recording, tmp_path_factory, fraction):
    """What a GCS killed at any instant leaves: `gcs log info` reads it and says it is cut;
    what is read is the beginning of the recording, in order."""
    data = recording.read_bytes()
    cut = tmp_path_factory.mktemp("c") / "cut.mcap"
    cut.write_bytes(data[: max(8, int(len(data) * fraction))])
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = gcs.cli.main(["log", "info", str(cut), "--json"])
    assert code == 0 and err.getvalue() == ""
    info = json.loads(out.getvalue())
    assert info["truncated"] is True and info["truncation"]
    kept = read_recording(cut).topics.get("/mavlink/1/rx")
    whole = read_recording(recording).topics["/mavlink/1/rx"]
    times = kept.times if kept else []
    assert times == whole.times[: len(times)]


def _data_end(path) -> int:
    """Where the data section of an MCAP file ends (its DataEnd record starts)."""
    with open(path, "rb") as handle:
        for record in StreamReader(handle).records:
            if isinstance(record, DataEnd):
                return handle.tell() - 13  # DataEnd: opcode, length, crc
    raise AssertionError("no DataEnd")


@settings(max_examples=40, derandomize=True, deadline=None)
@given(fraction=st.floats(0.0, 0.999))
def test_a_byte_flipped_anywhere_in_the_data_is_never_read_silently(
    recording, tmp_path_factory, fraction
):
    """A flipped byte (a bad sector, a bad copy) anywhere in the data section: `gcs log info`
    says the file is damaged or cut, never reads it as whole (CRCs checked)."""
    data = bytearray(recording.read_bytes())
    at = 8 + int((_data_end(recording) - 8) * fraction)
    data[at] ^= 0x5A
    flipped = tmp_path_factory.mktemp("f") / "flipped.mcap"
    flipped.write_bytes(bytes(data))
    out = io.StringIO()
    with redirect_stdout(out), redirect_stderr(io.StringIO()):
        code = gcs.cli.main(["log", "info", str(flipped), "--json"])
    info = json.loads(out.getvalue())
    assert code == 0 and info["truncated"] is True and info["truncation"], at
