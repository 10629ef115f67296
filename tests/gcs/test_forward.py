"""`gcs mission run --out URL`: other tools watch a live mission, and what they send reaches
the UAV it names with no more authority than the tool has (gcs/transport/forward.py)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from gcs.transport.forward import Forwarder
from gcs.transport.link import Link, mavutil
from tests.flying import MISSION, Flight, flight_speedup
from vehicles.ports import free_udp_ports

pytestmark = pytest.mark.slow  # loopback UDP, and a flight


def _tool(port: int):
    """A tool listening where --out udpout:127.0.0.1:PORT sends (QGroundControl's way)."""
    return mavutil.mavlink_connection(
        f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
    )


def _wait(conn, want, deadline: float):
    """The first message from `conn` for which `want(message)` holds, or None at `deadline`."""
    while time.monotonic() < deadline:
        message = conn.recv_match(blocking=True, timeout=0.2)
        if message is not None and want(message):
            return message
    return None


class _Uav:
    """A UAV end of a real link: a loopback socket the ground station's `Link` sends to."""

    def __init__(self, system_id: int, port: int) -> None:
        self.socket = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
        self.link = Link(f"udpout:127.0.0.1:{port}", system_id)

    def close(self) -> None:
        self.socket.close()
        self.link.close()


def test_tool_messages_reach_the_named_uav_unchanged_and_never_its_heartbeat():
    base = free_udp_ports(3)
    tool_port, uav_ports = base, (base + 1, base + 2)
    uavs = {1: _Uav(1, uav_ports[0]), 2: _Uav(2, uav_ports[1])}
    tool = _tool(tool_port)
    forwarder = Forwarder([f"udpout:127.0.0.1:{tool_port}"])
    try:
        # a UAV's message reaches the tool byte for byte
        uav_mav = mavutil.mavlink.MAVLink(None, srcSystem=2, srcComponent=1)
        raw = bytes(uav_mav.heartbeat_encode(2, 3, 0, 0, 4).pack(uav_mav))
        forwarder.from_uav(raw)
        seen = _wait(tool, lambda m: m.get_type() == "HEARTBEAT", time.monotonic() + 5)
        assert seen is not None and bytes(seen.get_msgbuf()) == raw
        # the tool answers from the socket the forward came from: a heartbeat (dropped), then
        # a parameter read for UAV 2 (forwarded to UAV 2 alone, unsigned, as the tool sent it)
        tool.mav.heartbeat_send(6, 8, 0, 0, 4)
        tool.mav.param_request_read_send(2, 1, b"WPNAV_SPEED", -1)
        links = {system: uav.link for system, uav in uavs.items()}
        deadline = time.monotonic() + 5
        while forwarder.counters.to_uavs + forwarder.counters.dropped < 2:
            assert time.monotonic() < deadline, forwarder.counters
            forwarder.poll(0, links)
        assert forwarder.counters.dropped == 1  # the heartbeat
        got = _wait(uavs[2].socket, lambda m: True, time.monotonic() + 5)
        assert got.get_type() == "PARAM_REQUEST_READ" and got.get_srcSystem() == 255
        assert got.get_signed() is False  # never signed on the tool's behalf
        # nothing reached UAV 1 (a broadcast would have; the heartbeat was not forwarded)
        assert uavs[1].socket.recv_match(blocking=False) is None
    finally:
        forwarder.close()
        tool.close()
        for uav in uavs.values():
            uav.close()


def test_read_only_outputs_forward_nothing_from_the_tool():
    tool_port = free_udp_ports(2)
    uav_port = tool_port + 1
    uav = _Uav(1, uav_port)
    tool = _tool(tool_port)
    forwarder = Forwarder([f"udpout:127.0.0.1:{tool_port}"], readonly=True)
    try:
        uav_mav = mavutil.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        forwarder.from_uav(bytes(uav_mav.heartbeat_encode(2, 3, 0, 0, 4).pack(uav_mav)))
        assert _wait(tool, lambda m: m.get_type() == "HEARTBEAT", time.monotonic() + 5)
        tool.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)  # arm
        deadline = time.monotonic() + 5
        while forwarder.counters.dropped < 1:
            assert time.monotonic() < deadline, forwarder.counters
            forwarder.poll(0, {1: uav.link})
        assert forwarder.counters.to_uavs == 0
        assert uav.socket.recv_match(blocking=False) is None
    finally:
        forwarder.close()
        tool.close()
        uav.close()


def test_a_tool_watches_a_live_mission_and_reads_a_parameter_of_one_uav(tmp_path: Path):
    tool_port = free_udp_ports(1)
    tool = _tool(tool_port)
    speedup = str(flight_speedup(4))
    log = tmp_path / "run.mcap"
    flight = Flight(
        ["mission", "run", str(MISSION), "--json", "--insecure", "--log", str(log),
         "--speedup", speedup, "--out", f"udpout:127.0.0.1:{tool_port}"],
        tmp_path,
    )  # fmt: skip
    try:
        heard: set[int] = set()
        deadline = time.monotonic() + 60
        while heard != {1, 2, 3, 4}:
            message = _wait(tool, lambda m: m.get_type() == "GLOBAL_POSITION_INT", deadline)
            assert message is not None, f"positions heard from {sorted(heard)} only"
            heard.add(message.get_srcSystem())
        tool.mav.param_request_read_send(3, 1, b"", 0)  # UAV 3's first parameter
        # (the ground station's own parameter reads are forwarded to the tool too: on a busy
        # machine an answer of UAV 1's may still be on its way; only UAV 3's answers this)
        answer = _wait(
            tool,
            lambda m: m.get_type() == "PARAM_VALUE" and m.get_srcSystem() == 3,
            time.monotonic() + 20,
        )
        assert answer is not None, "UAV 3 never answered the tool's PARAM_REQUEST_READ"
        code, out, err = flight.finish(timeout=180)
    finally:
        flight.kill()
        tool.close()
    assert code == 0, err[-3000:]
    assert json.loads(out)["completed"] is True
