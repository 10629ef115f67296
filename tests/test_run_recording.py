"""The flight recorder writes an MCAP file that the `mcap` reader (and Foxglove) understands."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from gcs.link import mavutil
from gcs.recording import FlightRecorder
from gcs.runtime import MissionClock

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
    recorder.setpoint(2, {"t": 0.0, "uav": 2, "position": [1.0, 2.0, 30.0]}, 100.5)
    recorder.state(2, {"t": 0.0, "uav": 2, "phase": "following"}, 100.5)
    recorder.fix(2, 45.76, 4.83, 200.0, 100.6)
    recorder.event("warning", "UAV 2: something", 100.7)
    recorder.speed({"t": 1.0, "kind": "request", "seq": 1}, 100.8)
    recorder.metrics({"t": 1.0, "min_uav_uav_m": 14.1}, 100.9)
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
