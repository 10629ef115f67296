"""The flight recorder writes an MCAP file that the `mcap` reader (and Foxglove) understands."""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from gcs.flight.clock import MissionClock
from gcs.flight.records import (
    MetricsRecord,
    RadioRecord,
    ReturnRecord,
    SetpointRecord,
    SpeedRecord,
    SpeedRecordKind,
    UavStateRecord,
)
from gcs.recording.recording import SCHEMAS, FlightRecorder
from gcs.transport.link import mavutil
from tests.foxglove_client import (
    foxglove_channels,
    foxglove_connect,
    foxglove_receive,
    foxglove_send,
    send_upgrade,
)

mavlink = mavutil.mavlink


class FakeWall:
    """A wall clock the test moves by hand (the recorder's time base, not a mock of I/O)."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class JsonDecoderFactory(McapDecoderFactory):
    """Decodes the JSON channels (the protobuf ones go to mcap-protobuf-support)."""

    def decoder_for(self, message_encoding, schema):
        return json.loads if message_encoding == "json" else None


def _metrics(t: float, **figures) -> MetricsRecord:
    """A /metrics record at `t` with nothing measured yet except `figures`."""
    empty = dict(
        formation_speed=5.0,
        distance=0.0,
        min_uav_uav_m=None,
        min_uav_obstacle_m=None,
        max_tracking_error_m=None,
        tracking_error_m=[],
        connected=None,
        positions=[],
    )
    return MetricsRecord(t=t, **{**empty, **figures})


def read(path: Path):
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        summary = reader.get_summary()
        messages = [
            (channel.topic, schema.name, schema.encoding, message.log_time, decoded)
            for schema, channel, message, decoded in reader.iter_decoded_messages()
        ]
        attachments = [a.name for a in reader.iter_attachments()]
        header = reader.get_header()
    return summary, messages, attachments, header


def test_topics_schemas_and_the_shared_time_base(tmp_path: Path):
    wall = FakeWall()
    clock = MissionClock(speedup=10.0, monotonic=wall, unix_ns=lambda: 1_700_000_000_000_000_000)
    path = tmp_path / "run.mcap"
    recorder = FlightRecorder(path, clock)
    mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    heartbeat = mav.heartbeat_encode(6, 8, 0, 0, 4)
    raw = heartbeat.pack(mav)
    recorder.mavlink(1, "tx", raw, heartbeat, 99.0)  # before the clock is anchored: kept
    recorder.plan({"path": [[0, 0], [1, 1]], "fleet_size": 2}, 99.5)
    clock.anchor(100.0, -5.0)  # mission time -5 s now, at speedup 10
    recorder.setpoint(
        SetpointRecord(0.0, 2, [1.0, 2.0, 30.0], [0.0] * 3, [0.0] * 3, [1.0, 2.0], 5.0, 0.0,
                       45.76, 4.83, 230.0, 30.0),
        100.5,
    )  # fmt: skip
    recorder.state(UavStateRecord(0.0, 2, "following", None, None, True, 4, 2), 100.5)
    recorder.fix(2, 45.76, 4.83, 200.0, 100.6)
    recorder.event("warning", "UAV 2: something", 100.7)
    recorder.speed(SpeedRecord(1.0, SpeedRecordKind.REQUEST, 1, 2.0, 8.0, "operator"), 100.8)
    recorder.metrics(_metrics(1.0, min_uav_uav_m=14.1), 100.9)
    text = mav.statustext_encode(4, b"Arm: Need Position Estimate")
    recorder.mavlink(2, "rx", text.pack(mav), text, 101.0)
    recorder.attach("mission.yaml", "application/yaml", b"version: 1\n")
    recorder.close()

    summary, messages, attachments, header = read(path)
    assert header.profile == "fleetline"
    assert attachments == ["mission.yaml"]
    topics = {m[0]: m for m in messages}
    assert set(topics) == {
        "/mavlink/1/tx",
        "/plan",
        "/uav2/setpoint",
        "/uav2/target",
        "/uav2/state",
        "/uav2/fix",
        "/events",
        "/speed",
        "/metrics",
        "/mavlink/2/rx",
    }
    schemas = {topic: (m[1], m[2]) for topic, m in topics.items()}
    assert schemas["/uav2/fix"] == ("foxglove.LocationFix", "protobuf")
    assert schemas["/events"] == ("foxglove.Log", "protobuf")
    assert schemas["/uav2/setpoint"] == ("fleetline.Setpoint", "jsonschema")
    assert schemas["/mavlink/1/tx"] == ("fleetline.MavlinkMessage", "jsonschema")
    for channel in summary.channels.values():
        assert channel.message_encoding in ("json", "protobuf")

    # log time = Unix ns at mission time 0 + mission time; mission time = (wall - 100.5) * 10
    epoch = 1_700_000_000_000_000_000 - int(100.0 * 1e9) + int(100.5 * 1e9)

    def expected(wall_s: float) -> int:
        return epoch + round((wall_s - 100.5) * 10 * 1e9)

    assert topics["/mavlink/1/tx"][3] == expected(99.0)  # recorded before the anchor
    assert topics["/uav2/setpoint"][3] == expected(100.5) == epoch
    assert topics["/metrics"][3] == expected(100.9)
    times = [m[3] for m in messages]
    assert times == sorted(times)

    fix = topics["/uav2/fix"][4]
    assert (fix.latitude, fix.longitude, fix.altitude) == (45.76, 4.83, 200.0)
    assert topics["/events"][4].message == "UAV 2: something"
    rx = topics["/mavlink/2/rx"][4]
    assert rx["type"] == "STATUSTEXT" and rx["direction"] == "rx"
    assert rx["fields"]["text"].startswith("Arm: Need Position")
    tx = topics["/mavlink/1/tx"][4]
    assert tx["t"] is None and tx["sysid"] == 255 and tx["fields"]["type"] == 6
    parsed = mav.parse_buffer(__import__("base64").b64decode(tx["raw"]))
    assert parsed[0].get_type() == "HEARTBEAT"


@pytest.mark.parametrize(
    ("record", "schema_key"),
    [
        (SetpointRecord, "setpoint"),
        (UavStateRecord, "state"),
        (SpeedRecord, "speed"),
        (MetricsRecord, "metrics"),
        (ReturnRecord, "return"),
    ],
)
def test_the_core_records_and_the_topic_schemas_name_the_same_fields(record, schema_key):
    schema = SCHEMAS[schema_key]
    assert set(record._FIELDS) == set(schema["properties"])
    assert set(schema.get("required", [])) <= record.ALWAYS


def test_speed_record_kinds_are_the_schema_kinds():
    kinds = SCHEMAS["speed"]["properties"]["kind"]["enum"]
    assert sorted(kind.value for kind in SpeedRecordKind) == sorted(kinds)


def test_an_existing_file_is_refused_unless_forced(tmp_path: Path):
    path = tmp_path / "run.mcap"
    path.write_bytes(b"not mine")
    clock = MissionClock()
    with pytest.raises(FileExistsError):
        FlightRecorder(path, clock)
    assert path.read_bytes() == b"not mine"
    FlightRecorder(path, clock, force=True).close()
    _, messages, _, _ = read(path)
    assert messages == []


def test_never_anchored_records_are_still_written(tmp_path: Path):
    path = tmp_path / "run.mcap"
    recorder = FlightRecorder(path, MissionClock())
    recorder.event("error", "no heartbeat from system 1", 5.0)
    recorder.close()
    _, messages, _, _ = read(path)
    assert [m[0] for m in messages] == ["/events"]


# --------------------------------------------------------------------------- the run's context
SMALL = Path(__file__).resolve().parents[2] / "examples" / "small.yaml"
#: A building south-east of the small mission's path, as lon/lat (a 25 m square).
BUILDING = [
    [4.838270849664592, 45.763100283261664],
    [4.8385922058725255, 45.76310027557895],
    [4.8385922174947344, 45.763325197545974],
    [4.838270859995443, 45.76332520522871],
    [4.838270849664592, 45.763100283261664],
]


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """The small mission plus a GeoJSON building, planned (the recorder's `describe` input)."""
    from gcs.mission import load_mission
    from gcs.planning import plan_json, plan_mission

    folder = tmp_path_factory.mktemp("mission")
    building = {
        "type": "FeatureCollection",
        "features": [
            {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [BUILDING]}}
        ],
    }
    (folder / "blocks.geojson").write_text(json.dumps(building))
    text = SMALL.read_text().replace("obstacles:\n", "obstacles:\n  - geojson: blocks.geojson\n", 1)
    (folder / "mission.yaml").write_text(text)
    mission = load_mission(folder / "mission.yaml")
    plan = plan_mission(mission)
    assert plan.valid, plan.reason
    return mission, plan, plan_json(plan), folder


def _anchored_clock() -> tuple[MissionClock, FakeWall]:
    wall = FakeWall()
    clock = MissionClock(speedup=1.0, monotonic=wall, unix_ns=lambda: 1_700_000_000_000_000_000)
    clock.anchor(wall.now, 0.0)
    return clock, wall


def test_describe_makes_the_recording_self_contained(tmp_path: Path, planned):
    from gcs.geodesy import lonlat_to_local
    from gcs.recording.scene import DISPLAY_HEIGHT_FACTOR

    mission, plan, plan_data, folder = planned
    clock, wall = _anchored_clock()
    path = tmp_path / "run.mcap"
    recorder = FlightRecorder(path, clock)
    recorder.describe(plan, plan_data, wall.now)
    recorder.outcome({"completed": True, "exit_status": 0, "reason": None, "fleet_size": 4})
    recorder.close()

    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        decoded = {}
        for schema, channel, _, message in reader.iter_decoded_messages():
            decoded.setdefault(channel.topic, (schema.name, schema.encoding, message))
    assert attachments["mission.yaml"] == mission.text.encode()
    assert attachments["geojson/blocks.geojson"] == (folder / "blocks.geojson").read_bytes()
    assert json.loads(attachments["plan.json"]) == plan_data
    assert json.loads(attachments["run.json"])["completed"] is True
    assert metadata["mission"]["name"] == "small"
    assert metadata["mission"]["fleet_size"] == str(plan.fleet_size)
    assert json.loads(metadata["outcome"]["completed"]) is True
    assert decoded["/plan"][:2] == ("fleetline.Plan", "jsonschema")

    # the 3-D scene: every part, obstacles extruded over their whole footprint
    name, encoding, update = decoded["/scene"]
    assert (name, encoding) == ("foxglove.SceneUpdate", "protobuf")
    entities = {e.id: e for e in update.entities}
    size = plan.fleet_size
    expected = {"obstacles", "plan", "station/A", "station/B"}
    expected |= {f"uav{n}" for n in range(1, size + 1)}
    expected |= {f"uav{n}/target" for n in range(1, size + 1)}
    assert expected <= set(entities)
    assert all(entities[f"uav{n}"].frame_locked for n in range(1, size + 1))
    triangles = np.array(
        [[p.x, p.y, p.z] for p in entities["obstacles"].triangles[0].points]
    ).reshape(-1, 3, 3)
    height = DISPLAY_HEIGHT_FACTOR * mission.altitude
    tops = triangles[np.all(triangles[:, :, 2] == height, axis=1)]
    edge1, edge2 = tops[:, 1, :2] - tops[:, 0, :2], tops[:, 2, :2] - tops[:, 0, :2]
    top_area = np.abs(edge1[:, 0] * edge2[:, 1] - edge1[:, 1] * edge2[:, 0]).sum() / 2
    footprint = sum(g.area for g in mission.obstacles.geometries)
    assert top_area == pytest.approx(footprint, rel=1e-9)
    margin = np.array([[p.x, p.y] for p in entities["obstacles"].lines[0].points])
    assert mission.obstacles.distance_to_points(margin).min() == pytest.approx(
        mission.safety_margin, abs=1e-6
    )
    path = np.array([[p.x, p.y] for p in entities["plan"].lines[0].points])
    assert np.array_equal(path, np.array(plan_data["path"]))

    # the Map panel's layers: footprints back in lon/lat, the mission's own building exactly
    name, encoding, layer = decoded["/map/obstacles"]
    assert (name, encoding) == ("foxglove.GeoJSON", "protobuf")
    features = json.loads(layer.geojson)["features"]
    assert len(features) == len(mission.obstacles.geometries)
    by_name = {f["properties"]["name"]: f["geometry"] for f in features}
    (key,) = [k for k in by_name if "features[0]" in k]
    assert np.allclose(by_name[key]["coordinates"][0], BUILDING, atol=1e-9)
    (rectangle,) = [k for k in by_name if "rectangle" in k]
    corners = lonlat_to_local(np.array(by_name[rectangle]["coordinates"][0]), mission.origin)
    assert np.allclose(corners[:-1], mission.obstacles.polygons[1], atol=1e-6)
    plan_layer = json.loads(decoded["/map/plan"][2].geojson)["features"]
    assert plan_layer[0]["geometry"]["type"] == "LineString"


def test_the_fleet_moves_frames_and_links_at_every_tick(tmp_path: Path, planned):
    from gcs.recording.scene import MAST_HEIGHT_M

    _, plan, plan_data, _ = planned
    clock, wall = _anchored_clock()
    path = tmp_path / "run.mcap"
    recorder = FlightRecorder(path, clock)
    recorder.describe(plan, plan_data, wall.now)
    size = plan.fleet_size
    positions = np.full((size, 3), np.nan)
    positions[0] = [0.0, 0.0, 20.0]  # at A
    positions[1] = [100.0, 0.0, 20.0]  # 100 m from UAV 1, 100 m from A: within 120 m
    positions[2] = [350.0, 100.0, 20.0]  # 50 m beyond B, alone with it
    targets = np.zeros((size, 2))
    recorder.fleet(1.0, positions, targets, wall.now + 1.0)
    recorder.close()
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        last = {}
        for _, channel, _, message in reader.iter_decoded_messages():
            last[channel.topic] = message
    frames = {t.child_frame_id: t for t in last["/tf"].transforms}
    assert set(frames) == {"uav1", "uav2", "uav3"} | {f"uav{n}/target" for n in range(1, size + 1)}
    assert (frames["uav2"].translation.x, frames["uav2"].translation.z) == (100.0, 20.0)
    assert all(t.rotation.w == 1.0 for t in frames.values())  # a rotation, not the zero default
    entities = {e.id: e for e in last["/scene"].entities}
    assert "obstacles" in entities  # every /scene message is complete
    points = [(p.x, p.y, p.z) for p in entities["radio_links"].lines[0].points]
    links = sorted(tuple(sorted(points[k : k + 2])) for k in range(0, len(points), 2))
    mast = MAST_HEIGHT_M
    assert links == sorted(
        [
            ((0.0, 0.0, 20.0), (100.0, 0.0, 20.0)),  # UAV 1 - UAV 2
            ((0.0, 0.0, mast), (0.0, 0.0, 20.0)),  # UAV 1 - A
            ((0.0, 0.0, mast), (100.0, 0.0, 20.0)),  # UAV 2 - A
            ((300.0, 100.0, mast), (350.0, 100.0, 20.0)),  # UAV 3 - B
        ]
    )
    fleet = last["/fleet"]
    assert fleet["uav_uav_m"] == 100.0
    assert fleet["uav_obstacle_m"] == pytest.approx(
        float(plan.mission.obstacles.distance_to_points(positions[:3, :2]).min())
    )
    assert fleet["radio_links"] == 4
    assert fleet["uav_links"] == [[1, 2]]
    assert sorted(map(tuple, fleet["station_links"])) == [(1, 0), (2, 0), (3, 1)]


@pytest.mark.slow
def test_a_killed_writer_leaves_a_file_readable_up_to_the_last_second(tmp_path: Path):
    from gcs.recording.logreader import read_recording

    path = tmp_path / "killed.mcap"
    script = f"""
import sys, time
from gcs.recording.recording import FlightRecorder
from gcs.flight.clock import MissionClock
from gcs.flight.records import MetricsRecord
clock = MissionClock()
clock.anchor(time.monotonic(), 0.0)
recorder = FlightRecorder({str(path)!r}, clock)
began = time.monotonic()
last_said = 0.0
while True:
    now = time.monotonic()
    t = clock.mission_time(now)
    recorder.metrics(MetricsRecord(t, 5.0, 0.0, None, None, None, [], None, []), now)
    if t - last_said >= 0.2:
        last_said = t
        print(t, flush=True)
    time.sleep(0.005)
"""
    child = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, cwd=tmp_path
    )
    try:
        said = 0.0
        deadline = time.monotonic() + 30
        while said < 2.5 and time.monotonic() < deadline:
            line = child.stdout.readline()
            assert line, "the writer died"
            said = float(line)
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.kill()
        child.wait()
    recording = read_recording(path)
    assert recording.truncated
    times = [m["t"] for _, m in recording.messages("/metrics")]
    assert times == sorted(times)
    assert times[-1] >= said - 1.1  # flushed at least every second


# --------------------------------------------------------------------------- live (WebSocket)
@pytest.mark.slow
@pytest.mark.parametrize(
    "subprotocol",
    ["foxglove.sdk.v1", "foxglove.websocket.v1"],  # today's Foxglove; Lichtblick, older apps
)
def test_the_recording_is_served_live_over_foxglove_websocket(tmp_path: Path, subprotocol):
    clock, wall = _anchored_clock()
    recorder = FlightRecorder(tmp_path / "live.mcap", clock, serve_port=0)
    try:
        recorder.event("info", "before the client", wall.now)
        sock = foxglove_connect(recorder.server_port, subprotocol=subprotocol)
        opcode, payload = foxglove_receive(sock)
        assert json.loads(payload)["op"] == "serverInfo"
        recorder.metrics(_metrics(0.0), wall.now)
        channels = foxglove_channels(sock, {"/events", "/metrics"}, time.monotonic() + 10)
        assert channels["/events"]["schemaName"] == "foxglove.Log"
        assert channels["/metrics"]["schemaName"] == "fleetline.Metrics"
        foxglove_send(
            sock,
            {
                "op": "subscribe",
                "subscriptions": [{"id": 7, "channelId": channels["/events"]["id"]}],
            },
        )
        # the subscription takes effect asynchronously: log until a message comes back
        sock.settimeout(0.05)
        deadline = time.monotonic() + 10
        received = None
        while received is None and time.monotonic() < deadline:
            recorder.event("info", "live event", wall.now)
            try:
                opcode, payload = foxglove_receive(sock)
            except TimeoutError:
                continue
            if opcode == 2 and payload[0] == 1:  # binary message data
                received = payload
        assert received is not None, "no message data within 10 s"
        assert struct.unpack("<I", received[1:5])[0] == 7  # our subscription
        assert b"live event" in received[13:]
        sock.close()
    finally:
        recorder.close()


@pytest.mark.slow
def test_a_taken_port_is_refused_before_the_file_is_created(tmp_path: Path):
    from gcs.recording.recording import LiveServerError

    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    try:
        with pytest.raises(LiveServerError, match=str(busy.getsockname()[1])):
            FlightRecorder(tmp_path / "run.mcap", MissionClock(), serve_port=busy.getsockname()[1])
    finally:
        busy.close()
    assert not (tmp_path / "run.mcap").exists()


@pytest.mark.slow
def test_mission_run_refuses_a_taken_foxglove_port_with_one_line(tmp_path, monkeypatch, capsys):
    import gcs.cli

    monkeypatch.chdir(tmp_path)
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    try:
        port = str(busy.getsockname()[1])
        code = gcs.cli.main(["mission", "run", str(SMALL), "--json", "--foxglove", port])
    finally:
        busy.close()
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "--foxglove" in err and port in err
    assert not list(tmp_path.rglob("*.mcap"))


def test_radio_counters_reach_the_report(tmp_path: Path, planned):
    """With a radio medium's counters in the log, the report draws them (figs. 12-13)."""
    from gcs.recording.logreader import read_recording
    from gcs.recording.report import FIGURES, write_report

    _, plan, plan_data, _ = planned
    clock, wall = _anchored_clock()
    path = tmp_path / "radio.mcap"
    recorder = FlightRecorder(path, clock)
    recorder.describe(plan, plan_data, wall.now)
    size = plan.fleet_size
    slots = plan.formation.start_slots
    for k in range(5):
        t = 0.1 * k
        recorder.metrics(_metrics(t, positions=slots.tolist()), wall.now + t)
        packets = {"sent": 10 * k, "received": 9 * k, "dropped": k}
        users = {"sent": 4 * k, "received": 3 * k, "dropped": k}
        recorder.radio(RadioRecord(t, {"packets": packets, "ground_users": users}), wall.now + t)
    recorder.close()
    report = write_report(read_recording(path), tmp_path / "report")
    assert report.summary["radio"]["packets"] == {"sent": 40, "received": 36, "dropped": 4}
    assert report.summary["samples"] == 5
    # parked on their slots: the smallest distance is the slot spacing dS_c = 2 sqrt 2 rho_c
    spacing = 2 * np.sqrt(2) * plan.mission.safety_margin
    assert report.summary["min_uav_uav_m"] == pytest.approx(spacing)
    assert report.summary["connected_fraction"] == 1.0
    assert report.summary["tracking_error_m"] == [None] * size
    for name in FIGURES:
        assert (tmp_path / "report" / name).read_bytes().startswith(b"\x89PNG")


def _upgrade_status(port: int, origin: str | None) -> bytes:
    """The status line the live port answers an upgrade request from `origin` with."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=10)
    send_upgrade(sock, port, "foxglove.sdk.v1", origin)
    head = b""
    while b"\r\n" not in head:
        byte = sock.recv(1)
        if not byte:
            break
        head += byte
    sock.close()
    return head.split(b"\r\n")[0]


@pytest.mark.slow
def test_the_live_port_refuses_web_pages_of_other_origins(tmp_path: Path):
    """Any web page the operator has open may try a WebSocket to 127.0.0.1: only local and
    file origins, clients sending none, and the origins allowed connect; others get 403."""
    clock, _ = _anchored_clock()
    allowed = ("https://app.foxglove.dev",)
    recorder = FlightRecorder(tmp_path / "o.mcap", clock, serve_port=0, allowed_origins=allowed)
    try:
        port = recorder.server_port
        assert _upgrade_status(port, "https://evil.example").startswith(b"HTTP/1.1 403")
        for origin in (None, "http://localhost:8080", "null", "https://app.foxglove.dev"):
            assert _upgrade_status(port, origin).startswith(b"HTTP/1.1 101"), origin
    finally:
        recorder.close()


def test_links_through_a_building_are_marked_and_drawn_apart(tmp_path: Path, planned):
    """`/fleet` lists the disk links whose chord meets an obstacle; `/scene` draws them in a
    red line list of their own, the clear ones green."""
    _, plan, plan_data, _ = planned
    clock, wall = _anchored_clock()
    path = tmp_path / "run.mcap"
    recorder = FlightRecorder(path, clock)
    recorder.describe(plan, plan_data, wall.now)
    positions = np.full((plan.fleet_size, 3), np.nan)
    positions[0] = [100.0, 50.0, 20.0]  # west of the 60 x 80 m block at (150, 50)
    positions[1] = [200.0, 50.0, 20.0]  # east of it: 100 m apart, in range, no sight
    positions[2] = [100.0, 130.0, 20.0]  # north of UAV 1: sees it (UAV 2 is out of range)
    recorder.fleet(1.0, positions, np.zeros((plan.fleet_size, 2)), wall.now + 1.0)
    recorder.close()
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        last = {c.topic: m for _, c, _, m in reader.iter_decoded_messages()}
    fleet = last["/fleet"]
    assert [1, 2] in fleet["uav_links"] and fleet["blocked_uav_links"] == [[1, 2]]
    assert fleet["uav_links"] == [[1, 2], [1, 3]]
    lines = {e.id: e for e in last["/scene"].entities}["radio_links"].lines
    colours = [(round(line.color.r, 2), round(line.color.g, 2)) for line in lines]
    assert colours == [(0.2, 0.85), (0.9, 0.2)]  # scene.LINK_GREEN, scene.LINK_RED
    red = [(p.x, p.y) for p in lines[1].points]
    assert sorted(red) == [(100.0, 50.0), (200.0, 50.0)]
