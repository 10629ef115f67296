"""A real flight's recording, read back: schemas, channels, counts, time base, attachments,
positions against the run JSON; `gcs log info|report|replay` on it; the live Foxglove server.

One flight of the small mission (real `gcs` and `vehicles` processes, loopback UDP, speedup
5, served live with `--foxglove 0`) is shared by every test of this module.
"""

from __future__ import annotations

import base64
import json
import socket
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory
from pymavlink.dialects.v20 import ardupilotmega

from gcs.mission import load_mission
from planner.formation import ParkingRows
from planner.guarantees import check_positions
from planner.kinematics import LineFormation, SpeedProfile
from tests.flying import Flight, environment, flight_speedup, gcs_command
from tests.foxglove_client import (
    foxglove_channels,
    foxglove_connect,
    foxglove_receive,
    foxglove_send,
)

REPO = Path(__file__).resolve().parents[2]
MISSION = REPO / "examples" / "small.yaml"
SPEEDUP = str(flight_speedup(5))  # lower on a busy machine (tests/flying.py)
pytestmark = [pytest.mark.slow, pytest.mark.timeout(180)]

#: Topics every UAV has, and the fleet-wide ones (docs/outputs.md, MCAP; gcs.recording.recording).
UAV_TOPICS = ("/uav{n}/fix", "/uav{n}/target", "/uav{n}/setpoint", "/uav{n}/state",
              "/mavlink/{n}/rx", "/mavlink/{n}/tx")  # fmt: skip
FLEET_TOPICS = ("/plan", "/scene", "/tf", "/events", "/speed", "/metrics", "/fleet",
                "/map/obstacles", "/map/plan", "/radio")  # fmt: skip
FOXGLOVE_SCHEMAS = {
    "/scene": "foxglove.SceneUpdate",
    "/tf": "foxglove.FrameTransforms",
    "/events": "foxglove.Log",
    "/map/obstacles": "foxglove.GeoJSON",
    "/map/plan": "foxglove.GeoJSON",
}


@dataclass(frozen=True)
class Flown:
    log: Path
    run: dict
    stderr: str
    live_channels: dict
    live_fix: object


def _watch_live(port: int, deadline: float) -> tuple[dict, object]:
    """Connect to the live server while the mission flies; get one fix of UAV 1."""
    sock = foxglove_connect(port)
    try:
        wanted = {"/uav1/fix", "/scene", "/tf", "/metrics", "/mavlink/1/rx"}
        channels = foxglove_channels(sock, wanted, deadline)
        fix = channels["/uav1/fix"]
        foxglove_send(
            sock, {"op": "subscribe", "subscriptions": [{"id": 3, "channelId": fix["id"]}]}
        )
        while True:
            assert time.monotonic() < deadline, "no live fix of UAV 1"
            opcode, payload = foxglove_receive(sock)
            if opcode == 2 and payload[0] == 1:
                break
        schema = Schema(
            id=0,
            name=fix["schemaName"],
            encoding=fix["schemaEncoding"],
            data=base64.b64decode(fix["schema"]),
        )
        decode = DecoderFactory().decoder_for(fix["encoding"], schema)
        return channels, decode(payload[13:])
    finally:
        sock.close()


@pytest.fixture(scope="module")
def flown(tmp_path_factory) -> Flown:
    folder = tmp_path_factory.mktemp("flight")
    log = folder / "small.mcap"
    flight = Flight(
        ["mission", "run", str(MISSION), "--speedup", SPEEDUP, "--vehicles-per-process", "4",
         "--json", "--log", str(log), "--foxglove", "0"],
        folder,
    )  # fmt: skip
    try:
        line = flight.lines[flight.wait_for("Foxglove: live on ws://")]
        port = int(line.strip().rsplit(":", 1)[1])
        channels, fix = _watch_live(port, time.monotonic() + 60)
        code, out, err = flight.finish(timeout=120)
    finally:
        flight.stop()  # SIGTERM: the GCS stops its vehicles on the way out
    assert out.count("\n") == 1, err[-3000:]
    run = json.loads(out)
    assert code == 0, (run.get("reason"), err[-3000:])
    return Flown(log, run, err, channels, fix)


class JsonDecoder(McapDecoderFactory):
    def decoder_for(self, message_encoding, schema):
        return json.loads if message_encoding == "json" else None


@dataclass
class Read:
    header: object
    summary: object
    messages: list  # (topic, schema name, schema encoding, log time, decoded)
    attachments: dict
    metadata: dict

    def topic(self, name: str) -> list:
        return [m for m in self.messages if m[0] == name]


@pytest.fixture(scope="module")
def read(flown) -> Read:
    """The recording read with `mcap` and `mcap-protobuf-support` only (not gcs.recording.logreader)."""
    with open(flown.log, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory(), JsonDecoder()])
        summary = reader.get_summary()
        messages = [
            (channel.topic, schema.name, schema.encoding, message.log_time, decoded)
            for schema, channel, message, decoded in reader.iter_decoded_messages(
                log_time_order=False
            )
        ]
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        header = reader.get_header()
    return Read(header, summary, messages, attachments, metadata)


@pytest.fixture
def gcs_log(gcs_main):
    """`gcs ARGS` in this process (conftest's `gcs_main`)."""
    return gcs_main


# --------------------------------------------------------------------------- the recording
def test_schemas_channels_counts_and_the_time_base(flown, read):
    size = flown.run["fleet_size"]
    assert read.header.profile == "fleetline"
    expected = set(FLEET_TOPICS)
    expected |= {t.format(n=n) for t in UAV_TOPICS for n in range(1, size + 1)}
    channels = {c.topic: c for c in read.summary.channels.values()}
    assert set(channels) == expected

    # schemas Foxglove recognises: its own (protobuf) and titled JSON schemas
    for topic, channel in channels.items():
        schema = read.summary.schemas[channel.schema_id]
        if topic in FOXGLOVE_SCHEMAS or topic.endswith(("/fix", "/target")):
            wanted = FOXGLOVE_SCHEMAS.get(topic, "foxglove.LocationFix")
            assert (schema.name, schema.encoding, channel.message_encoding) == (
                wanted, "protobuf", "protobuf",
            )  # fmt: skip
        else:
            assert (schema.encoding, channel.message_encoding) == ("jsonschema", "json")
            assert json.loads(schema.data)["title"] == schema.name
            assert schema.name.startswith("fleetline.")

    # counts per UAV: telemetry at 10 Hz over the whole recording, one target per setpoint,
    # and every setpoint is a SET_POSITION_TARGET_GLOBAL_INT sent
    counts = read.summary.statistics.channel_message_counts
    count = {c.topic: counts[c.id] for c in read.summary.channels.values()}
    metrics_t = [m[4]["t"] for m in read.topic("/metrics")]
    span = metrics_t[-1] - metrics_t[0]
    for n in range(1, size + 1):
        assert count[f"/uav{n}/fix"] >= 0.8 * 10 * span
        assert count[f"/uav{n}/setpoint"] == count[f"/uav{n}/target"] > 100
        sent = [
            m for m in read.topic(f"/mavlink/{n}/tx") if m[4]["type"].startswith("SET_POSITION")
        ]
        assert len(sent) == count[f"/uav{n}/setpoint"]
        # per fix (GLOBAL_POSITION_INT, 10 Hz): SIM_STATE at 10 Hz, the 1 Hz status messages,
        # acks (the GCS turns off ATTITUDE and LOCAL_POSITION_NED, which it never reads)
        assert count[f"/mavlink/{n}/rx"] > 2.2 * count[f"/uav{n}/fix"]
    assert len(metrics_t) >= 0.9 * 10 * span  # /metrics at every tick

    # one clock: log times never go back; log time = Unix ns at mission time 0 + mission time
    times = [m[3] for m in read.messages]
    assert times == sorted(times)
    epoch = int(read.metadata["clock"]["epoch_ns"])
    for topic in ("/metrics", "/uav1/setpoint"):
        for _, _, _, log_time, message in read.topic(topic):
            assert abs(log_time - epoch - round(message["t"] * 1e9)) <= 1
    first_fix = read.topic("/uav1/fix")[0]
    stamp = first_fix[4].timestamp
    assert stamp.seconds * 1_000_000_000 + stamp.nanos == first_fix[3]

    # self-contained: the mission file, the plan, the run JSON, how it ended
    assert read.attachments["mission.yaml"] == MISSION.read_bytes()
    plan = json.loads(read.attachments["plan.json"])
    assert plan == read.topic("/plan")[0][4]
    assert json.loads(read.attachments["run.json"]) == flown.run
    assert read.metadata["mission"]["name"] == "small"
    assert json.loads(read.metadata["outcome"]["completed"]) is True

    # the 3-D scene is complete in every message; the transforms move every UAV
    scene = read.topic("/scene")
    ids = {e.id for e in scene[-1][4].entities}
    assert {"obstacles", "plan", "station/A", "station/B", "radio_links"} <= ids
    assert {f"uav{n}" for n in range(1, size + 1)} <= ids
    transforms = read.topic("/tf")[len(read.topic("/tf")) // 2][4].transforms
    assert {t.child_frame_id for t in transforms} >= {f"uav{n}" for n in range(1, size + 1)}


def _formation(plan: dict) -> LineFormation:
    start, goal = np.array(plan["parking_rows"]["A"]), np.array(plan["parking_rows"]["B"])
    e0, ek = start[0] - start[1], goal[1] - goal[0]
    rows = ParkingRows(start, goal, e0 / np.hypot(*e0), ek / np.hypot(*ek))
    return LineFormation(np.array(plan["path"]), plan["fleet_size"], plan["safety_margin_m"],
                         plan["radio_range_m"], rows)  # fmt: skip


def test_positions_in_the_log_match_the_run_json(flown, read):
    run = flown.run
    size = run["fleet_size"]
    mission = load_mission(MISSION)
    stations = np.array([mission.start.xy, mission.goal.xy])

    # the fleet samples the monitors checked, checked again by the planner's guarantees
    samples = [m[4]["positions"] for m in read.topic("/metrics")]
    full = np.array([[p for p in s] for s in samples if all(p is not None for p in s)], float)
    assert len(full) > 0.95 * len(samples)  # every UAV known almost always
    checked = check_positions(full, mission.obstacles, stations, mission.radio_range)
    partial = [np.array([p for p in s if p is not None]) for s in samples if None in s]
    pair = [checked.min_uav_uav_m.min()]
    obstacle = [checked.min_uav_obstacle_m.min()]
    for xy in partial:
        if len(xy):
            one = check_positions(xy[None], mission.obstacles, stations, mission.radio_range)
            pair.append(one.min_uav_uav_m[0])
            obstacle.append(one.min_uav_obstacle_m[0])
    assert min(pair) == pytest.approx(run["min_uav_uav_m"], rel=1e-12)
    assert min(obstacle) == pytest.approx(run["min_uav_obstacle_m"], rel=1e-12)
    assert checked.connected.mean() == run["connected_fraction"]

    # tracking errors: logged per sample, and recomputed from the true positions and V_n(t)
    plan = read.topic("/plan")[0][4]
    formation = _formation(plan)
    profile = SpeedProfile.constant(plan["initial_speed_mps"])
    for request in (m[4] for m in read.topic("/speed") if m[4]["kind"] == "request"):
        profile = profile.with_change(request["effective_s"], request["speed"])
    worst = []
    for n in range(1, size + 1):
        states = [m[4] for m in read.topic(f"/uav{n}/state") if m[4]["t"] is not None]
        t = np.array([s["t"] for s in states])
        xy = np.array([s["true_position"][:2] for s in states])
        logged = np.array([s["tracking_error_m"] for s in states])
        virtual = formation.positions(profile.distance(t))[:, n - 1]
        assert np.allclose(np.hypot(*(xy - virtual).T), logged, atol=1e-9)
        assert logged.max() == pytest.approx(run["per_uav"][n - 1]["max_tracking_error_m"])
        worst.append(logged.max())
    assert max(worst) == pytest.approx(run["max_tracking_error_m"])


# --------------------------------------------------------------------------- gcs log info
def test_log_info_summarises_the_flight(flown, read, gcs_log):
    code, out, err = gcs_log("log", "info", flown.log, "--json")
    assert code == 0, err
    info = json.loads(out)
    size = flown.run["fleet_size"]
    stats = read.summary.statistics
    assert info["mission"] == "small"
    assert info["outcome"]["completed"] is True and info["outcome"]["exit_status"] == 0
    assert info["uavs"] == list(range(1, size + 1))
    assert info["truncated"] is False
    assert info["messages"] == stats.message_count
    assert info["duration_s"] == pytest.approx(
        (stats.message_end_time - stats.message_start_time) / 1e9
    )
    counts = {c.topic: stats.channel_message_counts[c.id] for c in read.summary.channels.values()}
    assert {t: v["count"] for t, v in info["topics"].items()} == counts
    assert set(info["attachments"]) == {"mission.yaml", "plan.json", "run.json"}
    start, end = info["mission_time_s"]
    assert start < 0 < end  # take-offs before mission time 0 are in the log

    code, out, _ = gcs_log("log", "info", flown.log)
    assert code == 0
    assert "small" in out and "completed" in out and "truncated" not in out


@pytest.mark.parametrize("fraction", [0.0004, 0.37, 0.61, 0.9])
def test_log_info_reads_a_cut_recording_and_says_so(flown, read, gcs_log, tmp_path, fraction):
    data = flown.log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * fraction) + 13])
    code, out, err = gcs_log("log", "info", cut, "--json")
    assert code == 0, err
    info = json.loads(out)
    assert info["truncated"] is True and info["truncation"]
    assert info["outcome"] is None  # written at the very end
    assert info["messages"] < read.summary.statistics.message_count
    assert info["bytes_read"] <= int(len(data) * fraction) + 13
    if fraction > 0.1:
        assert info["mission"] == "small"
        assert 0 < info["messages"] and info["duration_s"] > 0
    code, out, _ = gcs_log("log", "info", cut)
    assert code == 0 and "truncated" in out


# --------------------------------------------------------------------------- gcs log report
def test_log_report_writes_every_figure_and_the_numbers(flown, read, gcs_log, tmp_path):
    from gcs.recording.report import FIGURES

    out_dir = tmp_path / "report"
    code, out, err = gcs_log("log", "report", flown.log, "--out", out_dir)
    assert code == 0, err
    for name in FIGURES:
        png = (out_dir / name).read_bytes()
        assert png.startswith(b"\x89PNG\r\n\x1a\n") and len(png) > 20_000, name
        width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
        assert width > 500 and height > 400
    summary = json.loads((out_dir / "summary.json").read_text())
    run = flown.run
    size = run["fleet_size"]
    for key in ("min_uav_uav_m", "min_uav_obstacle_m", "max_tracking_error_m"):
        assert summary[key] == pytest.approx(run[key], rel=1e-12), key
    assert summary["connected_fraction"] == run["connected_fraction"]
    # by line of sight: the small mission's chain passes behind its block for a while
    assert summary["los_connected_fraction"] == pytest.approx(run["los_connected_fraction"])
    assert 0.5 < summary["los_connected_fraction"] < 1.0
    assert summary["tracking_error_m"] == pytest.approx(
        [u["max_tracking_error_m"] for u in run["per_uav"]], rel=1e-12
    )
    # reaction times (fig. 10): the acknowledgements of every change, as in the run JSON
    assert [c["seq"] for c in summary["speed_changes"]] == [c["seq"] for c in run["speed_changes"]]
    for mine, theirs in zip(summary["speed_changes"], run["speed_changes"], strict=True):
        assert mine["reaction_s"] == pytest.approx(theirs["acks"])
        assert mine["effective_s"] == pytest.approx(theirs["effective_s"])
    # packets received at the base stations: every recorded telemetry message
    rx = [len(read.topic(f"/mavlink/{n}/rx")) for n in range(1, size + 1)]
    assert summary["telemetry_received"] == rx
    # fig. 3: each UAV flew about its planned distance (slot -> path -> slot)
    formation = _formation(read.topic("/plan")[0][4])
    planned = formation.arrival_distance - formation.departure_distance
    assert np.allclose(summary["distance_travelled_m"], planned, rtol=0.05)
    markdown = (out_dir / "summary.md").read_text()
    assert "# Flight report: small" in markdown and "completed" in markdown
    assert all(f"]({name})" in markdown for name in FIGURES)


def test_log_report_on_a_cut_recording(flown, gcs_log, tmp_path):
    from gcs.recording.report import FIGURES

    data = flown.log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    code, out, err = gcs_log("log", "report", cut, "--out", tmp_path / "report")
    assert code == 0, err
    assert "truncated" in out
    assert all((tmp_path / "report" / name).stat().st_size > 20_000 for name in FIGURES)
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    assert summary["truncated"] is True and summary["outcome"] is None
    assert summary["min_uav_uav_m"] >= flown.run["min_uav_uav_m"]  # a part of the flight
    assert "no outcome" in (tmp_path / "report" / "summary.md").read_text()


# --------------------------------------------------------------------------- gcs log replay
def _frames(read: Read, direction: str, uavs: range) -> list[bytes]:
    topics = {f"/mavlink/{n}/{direction}" for n in uavs}
    return [base64.b64decode(m[4]["raw"]) for m in read.messages if m[0] in topics]


def _replay_and_receive(log: Path, *args: str) -> tuple[subprocess.CompletedProcess, list]:
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sink.bind(("127.0.0.1", 0))
    sink.settimeout(0.2)
    url = f"udpout:127.0.0.1:{sink.getsockname()[1]}"
    process = subprocess.Popen(
        gcs_command("log", "replay", str(log), "--to", url, *args),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=environment(),
    )  # fmt: skip
    received = []
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline:
            try:
                received.append(sink.recv(65536))
            except TimeoutError:
                if process.poll() is not None:
                    break  # finished, and nothing more in flight
    finally:
        if process.poll() is None:
            process.kill()
        out, err = process.communicate()
        sink.close()
    return subprocess.CompletedProcess(process.args, process.returncode, out, err), received


def test_log_replay_sends_the_recorded_mavlink_in_order(flown, read):
    size = flown.run["fleet_size"]
    done, received = _replay_and_receive(flown.log, "--rate", "50")
    assert done.returncode == 0, done.stderr
    expected = _frames(read, "rx", range(1, size + 1))
    assert len(received) == len(expected) > 1000
    assert received == expected
    parser = ardupilotmega.MAVLink(None)
    parser.robust_parsing = True
    kinds = {parser.parse_buffer(frame)[0].get_type() for frame in received[:200]}
    assert "GLOBAL_POSITION_INT" in kinds


def test_log_replay_of_one_uav_in_the_other_direction(flown, read):
    done, received = _replay_and_receive(
        flown.log, "--rate", "200", "--direction", "tx", "--uav", "2"
    )
    assert done.returncode == 0, done.stderr
    assert received == _frames(read, "tx", range(2, 3))


# --------------------------------------------------------------------------- live and layout
def test_the_flight_was_served_live_with_the_same_channels(flown, read):
    schemas = {m[0]: m[1] for m in read.messages}
    for topic, channel in flown.live_channels.items():
        assert channel["schemaName"] == schemas[topic], topic
    origin = load_mission(MISSION).origin
    fix = flown.live_fix
    assert abs(fix.latitude - origin.lat) < 0.01 and abs(fix.longitude - origin.lon) < 0.01


def test_the_committed_layout_is_current_and_shows_recorded_topics(flown, read):
    from gcs.recording.layout import LAYOUT_PATH, layout_text

    assert LAYOUT_PATH.read_text() == layout_text(), "run python -m gcs.recording.layout"
    layout = json.loads(LAYOUT_PATH.read_text())
    recorded = {m[0] for m in read.messages}
    panels = []

    def walk(node):
        if node.get("type") == "split":
            for item in node["items"]:
                walk(item["content"])
        else:
            panels.append(node)

    walk(layout["content"])
    kinds = {p["panelType"] for p in panels}
    assert {"Map", "ThreeDee", "Plot", "Log"} <= kinds
    for panel in panels:
        for series in panel["config"].get("paths", []):
            assert series["value"].split(".")[0] in recorded, series["value"]
    (map_panel,) = [p for p in panels if p["panelType"] == "Map"]
    size = flown.run["fleet_size"]
    shown = {t for t in map_panel["config"]["topicColors"] if t in recorded}
    assert {f"/uav{n}/fix" for n in range(1, size + 1)} <= shown
    assert {"/map/obstacles", "/map/plan"} <= shown
