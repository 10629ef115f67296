"""A WebSocket client of Foxglove's protocol (stdlib only) for the tests of the live recording:
the upgrade handshake, frames from the server, masked text frames to it, advertised channels."""

from __future__ import annotations

import base64
import hashlib
import json
import os
import socket
import struct
import time


def send_upgrade(
    sock: socket.socket, port: int, subprotocol: str, origin: str | None = None
) -> str:
    """Send a WebSocket upgrade request for `subprotocol` (from `origin`: a browser page's
    header); returns the client key."""
    key = base64.b64encode(os.urandom(16)).decode()
    header = f"Origin: {origin}\r\n" if origin is not None else ""
    sock.sendall(
        (
            f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
            f"Sec-WebSocket-Protocol: {subprotocol}\r\n{header}\r\n"
        ).encode()
    )
    return key


def foxglove_connect(
    port: int, timeout: float = 10.0, subprotocol: str = "foxglove.sdk.v1"
) -> socket.socket:
    """A WebSocket client of Foxglove's protocol (stdlib only): the upgrade handshake, which
    must name the subprotocol the client asked for."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    key = send_upgrade(sock, port, subprotocol)
    head = b""
    while b"\r\n\r\n" not in head:
        byte = sock.recv(1)
        assert byte, "the server closed the connection during the handshake"
        head += byte
    assert head.startswith(b"HTTP/1.1 101"), head
    accept = base64.b64encode(
        hashlib.sha1((key + "258EAFA5-E914-47DA-95CA-C5AB0DC85B11").encode()).digest()
    )
    assert f"sec-websocket-protocol: {subprotocol}".encode() in head.lower()
    assert b"sec-websocket-accept: " + accept.lower() in head.lower()
    return sock


def _recv_exact(sock: socket.socket, count: int) -> bytes:
    out = b""
    while len(out) < count:
        chunk = sock.recv(count - len(out))
        if not chunk:
            raise EOFError("connection closed")
        out += chunk
    return out


def foxglove_receive(sock: socket.socket) -> tuple[int, bytes]:
    """One WebSocket frame from the server (unmasked): (opcode, payload)."""
    first, second = _recv_exact(sock, 2)
    size = second & 0x7F
    if size == 126:
        size = struct.unpack(">H", _recv_exact(sock, 2))[0]
    elif size == 127:
        size = struct.unpack(">Q", _recv_exact(sock, 8))[0]
    return first & 0x0F, _recv_exact(sock, size)


def foxglove_send(sock: socket.socket, message: dict) -> None:
    """One masked text frame (clients must mask)."""
    data = json.dumps(message).encode()
    mask = os.urandom(4)
    size = len(data)
    head = bytes([0x81]) + (
        bytes([0x80 | size]) if size < 126 else bytes([0x80 | 126]) + struct.pack(">H", size)
    )
    sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))


def foxglove_channels(sock: socket.socket, wanted: set[str], deadline: float) -> dict:
    """Read server messages until every topic of `wanted` was advertised: topic -> channel."""
    channels: dict[str, dict] = {}
    while not wanted <= set(channels):
        assert time.monotonic() < deadline, f"never advertised: {wanted - set(channels)}"
        opcode, payload = foxglove_receive(sock)
        if opcode == 1:
            message = json.loads(payload)
            if message.get("op") == "advertise":
                channels.update({c["topic"]: c for c in message["channels"]})
    return channels
