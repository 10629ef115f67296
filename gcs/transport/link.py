"""One UAV's MAVLink link: a pymavlink `mavutil` connection, non-blocking, with raw capture.

The runtime's single scheduler loop owns every link: it waits on `fileno()` of all of them at
once (`selectors`), then calls `receive(now)` to drain what arrived. Nothing here blocks or
starts a thread. Each datagram received and each message sent is handed, raw bytes plus the
decoded message, to an optional `capture` callback (the recorder's `/mavlink/<n>/rx|tx`).

A link is *alive* while any valid MAVLink message arrives from the expected system id
(docs/outputs.md, MAVLink), not only heartbeats: `last_valid_time` is the wall-clock time of the
last such message.
"""

from __future__ import annotations

import logging
import os
import re
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass

# MAVLink 2 from the first packet sent (pymavlink reads this once, when mavutil is imported).
os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink2  # noqa: E402

from fleetwire.frames import newest_telemetry  # noqa: E402

# The ground station's MAVLink identity (docs/outputs.md: the GCS is system 255): the fleet's.
from fleetwire.messages import GCS_COMPONENT_ID, GCS_SYSTEM_ID  # noqa: E402

log = logging.getLogger(__name__)

#: Bound on the messages one `receive` call drains (the scheduler must get back to its tick).
MAX_MESSAGES_PER_RECEIVE = 10_000
#: More datagrams than this waiting on one link is a backlog: only its newest telemetry is
#: decoded (at 10-20 telemetry messages per vehicle second, a few ticks' worth).
BACKLOG_DATAGRAMS = 64
#: ... the newest this many of each streamed message.
STALE_KEEP = 2
#: A `tcp:` endpoint that refuses (an autopilot still starting) is tried this many times, this
#: far apart, before the refusal is the answer. pymavlink's own retries print to stdout, which
#: `--json` keeps for JSON alone, so they are off.
CONNECT_ATTEMPTS = 3
CONNECT_RETRY_S = 1.0

#: Called for every message in or out: (direction "rx" | "tx", raw bytes, message, wall time).
Capture = Callable[[str, bytes, object, float], None]


def _reset_parser(mav) -> None:
    """Forget a partial frame (pymavlink's initial parser state)."""
    mav.buf = bytearray()
    mav.buf_index = 0
    mav.expected_length = mavutil.mavlink.HEADER_LEN_V1 + 2


@dataclass
class LinkCounters:
    """Traffic counters of one link."""

    received: int = 0  # valid messages from the expected system
    foreign: int = 0  # valid messages from another system id (ignored)
    bad: int = 0  # bytes that were not MAVLink
    stale: int = 0  # telemetry datagrams of a backlog, superseded and not decoded
    sent: int = 0


class _Liveness:
    """What every link keeps of what it receives: counters, the system ids heard, and the time
    of the last valid message of the expected system (docs/outputs.md: a link is alive while any
    valid message arrives from that system id)."""

    def __init__(self, url: str, system_id: int) -> None:
        self.url = url
        self.system_id = system_id
        self.counters = LinkCounters()
        self.last_valid_time: float | None = None
        self.seen_system_ids: set[int] = set()

    def _admit(self, message, now: float) -> bool:
        """Whether a valid `message` is from this UAV; counts it and keeps the link alive."""
        source = message.get_srcSystem()
        self.seen_system_ids.add(source)
        if source != self.system_id:
            self.counters.foreign += 1
            return False
        self.counters.received += 1
        self.last_valid_time = now
        return True

    def silent_for(self, now: float) -> float:
        """Seconds since the last valid message; infinite before the first one."""
        return float("inf") if self.last_valid_time is None else now - self.last_valid_time


class Link(_Liveness):
    """A per-UAV MAVLink connection (any mavutil connection string, e.g. `udpout:127.0.0.1:P`).

    `system_id` is the UAV's expected system id: messages from other systems are counted and
    dropped, so they never keep a dead link alive.
    """

    def __init__(
        self,
        url: str,
        system_id: int,
        *,
        capture: Capture | None = None,
        source_system: int = GCS_SYSTEM_ID,
        source_component: int = GCS_COMPONENT_ID,
    ) -> None:
        super().__init__(url, system_id)
        self.capture = capture
        self._now = 0.0
        self._conn = open_connection(url, source_system, source_component)
        self._conn.mav.robust_parsing = True
        self._conn.mav.set_send_callback(self._on_sent)

    @property
    def mav(self):
        """The pymavlink `MAVLink` object: its `*_encode` methods build messages."""
        return self._conn.mav

    def fileno(self) -> int:
        """Descriptor to wait on (selectors)."""
        return self._conn.fd

    def setup_signing(self, secret_key: bytes, **options) -> None:
        """MAVLink 2 signing, pymavlink's `mavfile.setup_signing`: sign what is sent and refuse
        unsigned input unless `allow_unsigned_callback` accepts it (see `gcs.transport.signing`);
        refused frames are bad data, never a sign of life."""
        self._conn.setup_signing(secret_key, **options)

    def send(self, message, now: float) -> None:
        """Send one message now (never blocks; a full socket buffer drops it, as UDP would)."""
        self._now = now
        try:
            self._conn.mav.send(message)
        except OSError as error:  # pragma: no cover - a vanished peer on a connected socket
            log.debug("send on %s failed: %s", self.url, error)

    def write_raw(self, data: bytes) -> None:
        """Send bytes as they are: a message another tool sent (`gcs.transport.forward`), neither
        signed with the fleet's key nor counted as this station's."""
        try:
            self._conn.write(data)
        except OSError as error:  # pragma: no cover - a vanished peer on a connected socket
            log.debug("forward on %s failed: %s", self.url, error)

    def receive(self, now: float) -> list:
        """Drain what is waiting on the socket; return the valid messages of this UAV."""
        if isinstance(self._conn, mavutil.mavudp):
            candidates = self._receive_datagrams()
        else:
            candidates = self._receive_stream()
        messages = []
        for message in candidates:
            kind = message.get_type()
            if kind == "BAD_DATA" or kind.startswith("UNKNOWN_"):
                # an unknown message id cannot be checked (no CRC extra): not valid MAVLink
                self.counters.bad += 1
                continue
            if self.capture is not None:
                self.capture("rx", bytes(message.get_msgbuf()), message, now)
            if self._admit(message, now):
                messages.append(message)
        return messages

    def _receive_datagrams(self) -> list:
        """UDP: each datagram parsed on its own. A MAVLink frame never spans datagrams, so an
        incomplete frame left at a datagram's end (garbage, truncation) is dropped instead of
        swallowing the valid datagrams that follow.

        Every waiting datagram is read (cheap), but of a backlog (a ground station that fell
        behind: a busy machine, a stall) only the newest telemetry is decoded: what the vehicle
        streams is superseded by its next sample, and decoding seconds of stale samples is
        what would keep the loop behind. Acknowledgements, texts and commands are all kept.
        Shed datagrams are counted in `counters.stale`."""
        conn = self._conn
        datagrams = []
        for _ in range(MAX_MESSAGES_PER_RECEIVE):
            try:
                data = conn.recv()
            except OSError as error:  # the socket itself failed: try again on the next call
                log.debug("receive on %s failed: %s", self.url, error)
                break
            if not data:
                break
            datagrams.append(data)
        if len(datagrams) > BACKLOG_DATAGRAMS:
            kept = newest_telemetry(datagrams, STALE_KEEP)
            self.counters.stale += len(datagrams) - len(kept)
            datagrams = kept
        out = []
        mav = conn.mav
        for data in datagrams:
            try:
                parsed = mav.parse_buffer(data) or []
            except Exception as error:  # noqa: BLE001 - pymavlink raises bare errors on garbage
                log.debug("undecodable datagram on %s: %s", self.url, error)
                parsed = []
                self.counters.bad += 1
            if mav.buf_len() > 0:
                self.counters.bad += 1
                _reset_parser(mav)
            for message in parsed:
                conn.post_message(message)
                out.append(message)
        return out

    def _receive_stream(self) -> list:
        """TCP, serial...: pymavlink's own framing of the byte stream."""
        conn = self._conn
        out = []
        for _ in range(MAX_MESSAGES_PER_RECEIVE):
            try:
                message = conn.recv_msg()
            except OSError as error:
                log.debug("receive on %s failed: %s", self.url, error)
                break
            except Exception as error:  # noqa: BLE001 - pymavlink raises bare errors on garbage
                self.counters.bad += 1
                log.debug("undecodable data on %s: %s", self.url, error)
                continue
            if message is None:
                break
            out.append(message)
        return out

    def close(self) -> None:
        """Close the socket (idempotent)."""
        try:
            self._conn.close()
        except OSError:  # pragma: no cover
            pass

    def _on_sent(self, message) -> None:
        self.counters.sent += 1
        if self.capture is not None:
            self.capture("tx", bytes(message.get_msgbuf()), message, self._now)


class MemoryLink(_Liveness):
    """A UAV's link inside one process (the fast mode): the same interface as `Link` for the
    drivers and the core, no socket. What the driver sends is packed (the GCS's identity and a
    sequence number, as on the wire) and queued in `outbox` for the caller to carry (through
    the radio medium model); what the caller delivers goes through `accept`, which keeps, as
    `Link.receive` does, only the valid messages of the expected system id."""

    def __init__(self, url: str, system_id: int) -> None:
        super().__init__(url, system_id)
        # MAVLink 2 whatever dialect mavutil picked when it was first imported
        self.mav = mavlink2.MAVLink(None, srcSystem=GCS_SYSTEM_ID, srcComponent=GCS_COMPONENT_ID)
        self.outbox: list = []

    def send(self, message, now: float) -> None:
        message.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        self.counters.sent += 1
        self.outbox.append(message)

    def accept(self, messages: list, now: float) -> list:
        """The messages that arrived at `now`; returns the valid ones of this UAV."""
        return [message for message in messages if self._admit(message, now)]

    def close(self) -> None:
        return None


_NETWORK_URL = re.compile(r"^(udpout|udpin|udpbcast|udp|tcpin|tcp):(.+):(\d+)$")


def _pin_to_peer(connection) -> None:
    """A `udpout:` link hears only its peer: its socket is bound to the loopback when the peer
    is on this machine (else to the address the route to the peer leaves from, never every
    interface) and connected to the peer, so the kernel drops datagrams from anyone else (a
    forged LAND on the machine's network address never reaches the ground station)."""
    if not isinstance(connection, mavutil.mavudp) or connection.udp_server:
        return
    if connection.broadcast:
        return  # udpbcast: it learns its peer from the first answer
    host, port = connection.destination_addr
    address = socket.gethostbyname(host)
    if address.startswith("127."):
        connection.port.bind(("127.0.0.1", 0))
    connection.port.connect((address, port))
    connection.destination_addr = (address, port)
    connection.resolved_destination_addr = address


def open_connection(url: str, source_system: int, source_component: int = 0):
    """pymavlink's connection for the connection string `url`, or `OSError` with the reason.

    Network strings are checked first (port range, host name: pymavlink finds those late or
    never); a refused `tcp:` connection (an autopilot still starting) is retried quietly
    (`CONNECT_ATTEMPTS`), then raised as `ConnectionRefusedError`."""
    network = _NETWORK_URL.match(url)
    if network:
        host, port = network.group(2), int(network.group(3))
        if not 0 < port < 65536:
            raise OSError(f"port {port} is not in 1..65535")
        try:
            socket.getaddrinfo(host, port)
        except OSError as error:
            raise OSError(f"host {host}: {error}") from None
    for attempt in range(1, CONNECT_ATTEMPTS + 1):
        try:
            connection = mavutil.mavlink_connection(
                url, source_system=source_system, source_component=source_component, retries=0
            )
            _pin_to_peer(connection)
            return connection
        except ConnectionRefusedError as error:
            if attempt == CONNECT_ATTEMPTS:
                raise
            log.warning("%s: %s; trying again in %g s", url, error, CONNECT_RETRY_S)
            time.sleep(CONNECT_RETRY_S)
        except OSError:
            raise
        except Exception as error:  # noqa: BLE001 - pymavlink raises ValueError, SerialException...
            raise OSError(str(error)) from None
    raise AssertionError("unreachable")
