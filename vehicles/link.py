"""One simulated vehicle's MAVLink 2 link over UDP: its socket, its codec and its peers.

The vehicle listens on its own UDP port (``udpin``) and sends to the last peer that sent it a
valid MAVLink message (docs/cli.md, vehicles sim: "answers whoever sent it the last valid message"),
plus, when given, a fixed ``out`` address (``udpout``, e.g. QGroundControl on 14550). The messages
of one control tick go out together, several MAVLink frames per datagram. Every received datagram is
parsed on its own (a truncated datagram never corrupts the next one); anything that is not valid
MAVLink is counted and dropped.

:func:`make_codec` is the one place where a vehicle's pymavlink codec is created; MAVLink 2
signing is ``vehicles.signing`` (``VehicleLink.signing``).
"""

from __future__ import annotations

import errno
import logging
import socket
import struct
import sys
import time
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetline.errors import EXIT_BAD_INPUT, FleetlineError
from vehicles.autopilot import AUTOPILOT_COMPONENT
from vehicles.signing import VehicleSigning

log = logging.getLogger(__name__)

Address = tuple[str, int]
MAX_DATAGRAM = 65535
RECEIVE_BUFFER_BYTES = 1 << 20
MAX_DATAGRAMS_PER_POLL = 256
MAX_BATCH_BYTES = 1400  # frames per datagram: stay below a typical path MTU
# kernel arrival timestamps: a setpoint is stamped when it arrived, not when a busy process
# got round to reading it (at a 20x speedup, 10 ms late would be 2 m at 10 m/s)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35 if sys.platform == "linux" else None)
_ANCILLARY_BYTES = socket.CMSG_SPACE(16) if hasattr(socket, "CMSG_SPACE") else 0


class PortInUseError(FleetlineError, OSError):
    """The UDP port a vehicle must listen on is taken."""

    exit_status = EXIT_BAD_INPUT

    def __init__(self, host: str, port: int, sysid: int) -> None:
        super().__init__(errno.EADDRINUSE, f"UDP {host}:{port} (sysid {sysid}) is already in use")
        self.host, self.port, self.sysid = host, port, sysid


def make_codec(sysid: int) -> mavlink.MAVLink:
    """A MAVLink 2 codec for system ``sysid``, component 1 (autopilot), unsigned (a link signs
    it with ``vehicles.signing.VehicleSigning``)."""
    codec = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=AUTOPILOT_COMPONENT)
    codec.robust_parsing = True
    return codec


@dataclass
class LinkStats:
    datagrams: int = 0
    bad_datagrams: int = 0  # not valid MAVLink at all
    messages: int = 0
    unknown_messages: int = 0  # valid framing, unknown message id
    sent: int = 0
    send_errors: int = 0


class VehicleLink:
    """Socket and codec of one vehicle; ``receive`` parses, ``send`` encodes to every peer."""

    def __init__(
        self,
        sysid: int,
        host: str,
        port: int,
        out: Address | None = None,
        signing_key: bytes | None = None,
    ):
        self.sysid = sysid
        self.address: Address = (host, port)
        self.out = out
        self.peer: Address | None = None
        self.stats = LinkStats()
        self.codec = make_codec(sysid)
        # MAVLink 2 signing: with a key (or once SETUP_SIGNING gave one) unsigned, wrongly
        # signed and replayed input is refused before it is parsed into a message
        self.signing = VehicleSigning(self.codec, signing_key)
        self.codec.file = self  # pymavlink's send() writes the packed frame here
        self._pending: list[bytes] = []
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
            self.socket.bind(self.address)
            self._timestamps = _enable_timestamps(self.socket)
        except OSError as exc:
            self.socket.close()
            if exc.errno == errno.EADDRINUSE:
                raise PortInUseError(host, port, sysid) from exc
            raise
        self.socket.setblocking(False)

    def fileno(self) -> int:
        return self.socket.fileno()

    def close(self) -> None:
        self.socket.close()

    # pymavlink's MAVLink.send() calls write() with each packed frame: collect them
    def write(self, frame: bytes) -> None:
        self._pending.append(frame)

    def _destinations(self) -> list[Address]:
        if self.peer is None:
            return [self.out] if self.out is not None else []
        if self.out is None or self.out == self.peer:
            return [self.peer]
        return [self.peer, self.out]

    def send(self, messages: list[mavlink.MAVLink_message]) -> None:
        """Encode ``messages`` and send them, several frames per datagram (up to
        ``MAX_BATCH_BYTES``, as MAVLink over UDP allows): one system call, not one per message."""
        for message in messages:
            self.codec.send(message)
        destinations = self._destinations()
        batch = bytearray()
        for frame in self._pending:
            if batch and len(batch) + len(frame) > MAX_BATCH_BYTES:
                self._sendto(bytes(batch), destinations)
                batch.clear()
            batch += frame
        if batch:
            self._sendto(bytes(batch), destinations)
        self._pending.clear()

    def _sendto(self, datagram: bytes, destinations: list[Address]) -> None:
        for address in destinations:
            try:
                self.socket.sendto(datagram, address)
                self.stats.sent += 1
            except OSError as exc:  # unreachable peer, full buffer: UDP drops it
                self.stats.send_errors += 1
                log.debug("sysid %d: send to %s failed: %s", self.sysid, address, exc)

    def _reset_parser(self) -> None:
        """Forget any partial frame: each UDP datagram is parsed on its own."""
        codec = self.codec
        codec.buf = bytearray()
        codec.buf_index = 0
        codec.expected_length = mavlink.HEADER_LEN_V1 + 2
        codec.have_prefix_error = False

    def receive(self) -> list[tuple[mavlink.MAVLink_message, float]]:
        """Read the waiting datagrams (bounded): their valid, known messages with the
        monotonic wall-clock time each datagram arrived."""
        out: list[tuple[mavlink.MAVLink_message, float]] = []
        realtime_offset = time.time() - time.monotonic()
        for _ in range(MAX_DATAGRAMS_PER_POLL):
            try:
                if self._timestamps:
                    data, ancillary, _, address = self.socket.recvmsg(
                        MAX_DATAGRAM, _ANCILLARY_BYTES
                    )
                    arrival = _arrival(ancillary, realtime_offset)
                else:
                    data, address = self.socket.recvfrom(MAX_DATAGRAM)
                    arrival = None
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:  # e.g. ICMP port unreachable reported on this socket
                log.debug("sysid %d: receive error %s", self.sysid, exc)
                continue
            if arrival is None:
                arrival = time.monotonic()
            self.stats.datagrams += 1
            messages: list[mavlink.MAVLink_message] = []
            if self._parse(data, messages):
                if address != self.out:
                    self.peer = address
                out.extend((message, arrival) for message in messages)
            else:
                self.stats.bad_datagrams += 1
        return out

    def _parse(self, data: bytes, out: list[mavlink.MAVLink_message]) -> bool:
        self._reset_parser()
        try:
            messages = self.codec.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises on some malformed input: never fatal
            log.debug("sysid %d: unparsable datagram: %s", self.sysid, exc)
            return False
        valid = False
        for message in messages:
            kind = message.get_type()
            if kind == "BAD_DATA":
                continue
            if kind == "UNKNOWN" or isinstance(message, mavlink.MAVLink_unknown):
                self.stats.unknown_messages += 1
                continue
            valid = True
            self.stats.messages += 1
            out.append(message)
        return valid


def _enable_timestamps(sock: socket.socket) -> bool:
    if SO_TIMESTAMPNS is None or not _ANCILLARY_BYTES:
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def _arrival(ancillary: list[tuple[int, int, bytes]], realtime_offset: float) -> float | None:
    """Monotonic time of arrival from an SO_TIMESTAMPNS control message (None if absent)."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) in (8, 16):
            seconds, nanoseconds = struct.unpack("qq" if len(data) == 16 else "ii", data)
            return seconds + nanoseconds * 1e-9 - realtime_offset
    return None
