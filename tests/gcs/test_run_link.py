"""The per-UAV link over real loopback UDP: liveness by system id, garbage, raw capture."""

from __future__ import annotations

import random
import socket
import time

import pytest

from gcs.transport.link import BACKLOG_DATAGRAMS, Link, mavutil
from tests.links import drain

# Every test here starts a process or flies over UDP.
pytestmark = pytest.mark.slow

mavlink = mavutil.mavlink


def vehicle_message(sysid: int):
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=1)
    msg = mav.heartbeat_encode(2, 3, 217, 4, 4)
    return msg.pack(mav)


def test_liveness_counts_only_the_expected_system_and_survives_garbage():
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    captured = []
    link = Link(
        f"udpout:127.0.0.1:{vehicle.getsockname()[1]}",
        system_id=1,
        capture=lambda direction, raw, msg, now: captured.append((direction, msg.get_type())),
    )
    try:
        # the GCS speaks first (a vehicle answers the last sender)
        mav = link.mav
        link.send(mav.heartbeat_encode(6, 8, 0, 0, 4), time.monotonic())
        data, gcs_address = vehicle.recvfrom(2048)
        assert data[0] == 0xFD  # MAVLink 2 from the first packet
        assert captured == [("tx", "HEARTBEAT")]

        rng = random.Random(4)
        sent = 0
        for _ in range(20):  # in bursts below a backlog (`gcs.transport.link.BACKLOG_DATAGRAMS`)
            for _ in range(BACKLOG_DATAGRAMS // 2 - 1):
                size = rng.randrange(1, 300)
                vehicle.sendto(bytes(rng.randrange(256) for _ in range(size)), gcs_address)
                # right after garbage, a valid datagram from another system: not our UAV
                vehicle.sendto(vehicle_message(9), gcs_address)
                sent += 1
            assert drain(link, lambda got, n=sent: link.counters.foreign >= n) == []
        # every garbage datagram was refused, and none swallowed the valid one behind it
        assert link.counters.foreign == sent and link.counters.bad >= sent
        assert link.last_valid_time is None and link.silent_for(time.monotonic()) == float("inf")
        assert link.seen_system_ids == {9}

        vehicle.sendto(vehicle_message(1), gcs_address)
        (message,) = drain(link, lambda got: got)
        assert message.get_srcSystem() == 1 and message.get_type() == "HEARTBEAT"
        assert link.silent_for(time.monotonic()) < 1.0
        assert link.counters.received == 1
        assert ("rx", "HEARTBEAT") in captured
    finally:
        link.close()
        vehicle.close()


def test_a_udpout_link_hears_only_its_peer_on_the_loopback():
    """Bound to 127.0.0.1 (not every interface) and connected to its UAV: a datagram from any
    other port is dropped by the kernel, even a valid message of the UAV's system id (a forged
    LAND heartbeat), while the UAV's own are received."""
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    intruder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    intruder.bind(("127.0.0.1", 0))
    link = Link(f"udpout:127.0.0.1:{vehicle.getsockname()[1]}", system_id=1)
    try:
        link.send(link.mav.heartbeat_encode(6, 8, 0, 0, 4), time.monotonic())
        _, gcs_address = vehicle.recvfrom(2048)
        assert gcs_address[0] == "127.0.0.1"
        for _ in range(20):
            intruder.sendto(vehicle_message(1), gcs_address)
        vehicle.sendto(vehicle_message(1), gcs_address)  # the last one sent
        got = drain(link, lambda got: got)
        assert len(got) == 1 and link.counters.received == 1  # only the UAV's
    finally:
        link.close()
        vehicle.close()
        intruder.close()
