"""Ports picked for processes started later stay out of the OS's autobind (ephemeral) range."""

from __future__ import annotations

import socket

import pytest

from vehicles.ports import LOWEST_PORT, ephemeral_floor, free_udp_ports

# Every test here starts a process or flies over UDP.
pytestmark = pytest.mark.slow


def test_a_picked_block_is_free_and_below_the_ephemeral_range():
    floor = ephemeral_floor()
    assert LOWEST_PORT < floor <= 65535
    for count in (1, 4, 9):
        base = free_udp_ports(count)
        assert LOWEST_PORT <= base and base + count <= floor
        held = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(count)]
        try:
            for k, sock in enumerate(held):
                sock.bind(("127.0.0.1", base + k))  # raises if it was not free
        finally:
            for sock in held:
                sock.close()


def test_sockets_that_send_without_binding_never_take_a_picked_port():
    """What raced before: a `udpout` socket autobinding to a vehicle's port before the vehicle
    process got to bind it."""
    picked = {free_udp_ports(1) for _ in range(50)}
    autobound = []
    try:
        for _ in range(300):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            autobound.append(sock)
            sock.sendto(b"x", ("127.0.0.1", 9))  # discard port: nothing listens
        ports = {sock.getsockname()[1] for sock in autobound}
    finally:
        for sock in autobound:
            sock.close()
    assert len(ports) == 300 and not ports & picked
    assert min(ports) >= ephemeral_floor()
