"""One live Foxglove port for clients of every generation.

foxglove-sdk's WebSocket server (the one `FlightRecorder` starts) accepts only the subprotocol
`foxglove.sdk.v1`; Foxglove apps before it, Lichtblick and most third-party clients ask for
`foxglove.websocket.v1` and get HTTP 400. The two are the same protocol under two names
(Foxglove's stated position; the SDK's own bridge made the rename without a message change).
So this front owns the public port: it reads the client's upgrade request, and when the client
asks for `foxglove.websocket.v1` it asks the SDK server (on a private loopback port) for
`foxglove.sdk.v1` and answers the client with the name it asked for. After the handshake it
relays bytes both ways untouched. The WebSocket accept key depends only on the client's key,
so it stays valid.

Browsers let any web page open a WebSocket to 127.0.0.1 and send its own `Origin`: a page the
operator has open must not stream the fleet's positions. So the front answers 403 to an
upgrade whose `Origin` is neither a local one (`http(s)://localhost`, `127.0.0.1`, `[::1]`,
any port; a file's, `null` or `file://`) nor one the operator allowed
(`gcs mission run --foxglove-allow-origin https://app.foxglove.dev`). A client that sends no
`Origin` (the Foxglove desktop app, scripts) is no page: it is let in.
"""

from __future__ import annotations

import logging
import socket
import threading
from collections.abc import Iterable
from urllib.parse import urlsplit

log = logging.getLogger(__name__)

#: What the SDK server speaks, and the older names of the same protocol this front accepts.
SDK_SUBPROTOCOL = "foxglove.sdk.v1"
LEGACY_SUBPROTOCOLS = ("foxglove.websocket.v1",)
#: An upgrade request or response head larger than this is not a Foxglove client's.
MAX_HEAD_BYTES = 16_384
HEAD_TIMEOUT_S = 5.0
RELAY_CHUNK = 65_536

_PROTOCOL_HEADER = b"sec-websocket-protocol:"
_ORIGIN_HEADER = b"origin:"
_LOCAL_HOSTS = frozenset({"localhost", "127.0.0.1", "::1"})
_FORBIDDEN = b"HTTP/1.1 403 Forbidden\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"


def refused_origin(request: bytes, allowed: Iterable[str] = ()) -> str | None:
    """The `Origin` of an upgrade request that may not connect (see the module docstring),
    None when it may (no Origin, a local or file one, or one of `allowed`, compared without a
    trailing slash and case-insensitively)."""
    for line in request.split(b"\r\n")[1:]:
        if not line.lower().startswith(_ORIGIN_HEADER):
            continue
        origin = line.split(b":", 1)[1].strip().decode("latin-1")
        if origin in ("null", "") or origin.startswith("file://"):
            return None
        if origin.rstrip("/").lower() in {a.rstrip("/").lower() for a in allowed}:
            return None
        try:
            parts = urlsplit(origin)
            host = parts.hostname
        except ValueError:
            return origin
        if parts.scheme in ("http", "https") and host in _LOCAL_HOSTS:
            return None
        return origin
    return None


class FoxgloveFront:
    """Listens on `host:port` (0: a free one, `port`; taken: `OSError` at once) and, once
    `start(backend_port)` is called, joins every client to the SDK server on
    `127.0.0.1:backend_port` (see the module docstring). `close()` ends every relay."""

    def __init__(self, host: str, port: int, allowed_origins: Iterable[str] = ()) -> None:
        self.backend_port: int | None = None
        self.allowed_origins = tuple(allowed_origins)
        self._listener = socket.create_server((host, port))
        self.port: int = self._listener.getsockname()[1]
        self._lock = threading.Lock()
        self._sockets: set[socket.socket] = set()
        self._closed = False
        self._thread = threading.Thread(target=self._accept, name="foxglove-front", daemon=True)

    def start(self, backend_port: int) -> None:
        """Accept clients (those who came earlier wait in the listen backlog)."""
        self.backend_port = backend_port
        self._thread.start()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            sockets, self._sockets = list(self._sockets), set()
        try:
            self._listener.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._listener.close()
        for sock in sockets:
            _close(sock)
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)

    def _keep(self, *socks: socket.socket) -> bool:
        with self._lock:
            if self._closed:
                return False
            self._sockets.update(socks)
            return True

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self._listener.accept()
            except OSError:
                return  # closed
            if not self._keep(client):
                _close(client)
                return
            threading.Thread(
                target=self._join, args=(client,), name="foxglove-front-client", daemon=True
            ).start()

    def _join(self, client: socket.socket) -> None:
        backend = None
        try:
            client.settimeout(HEAD_TIMEOUT_S)
            request = _read_head(client)
            origin = refused_origin(request, self.allowed_origins)
            if origin is not None:
                log.warning("Foxglove client from %s refused (not a local origin)", origin)
                client.sendall(_FORBIDDEN)
                _close(client)
                return
            request, asked = _translate_request(request)
            backend = socket.create_connection(("127.0.0.1", self.backend_port), HEAD_TIMEOUT_S)
            if not self._keep(backend):
                return
            backend.sendall(request)
            response = _read_head(backend)
            if asked is not None:
                response = _rename_protocol(response, asked)
            client.sendall(response)
            client.settimeout(None)
            backend.settimeout(None)
        except (OSError, ValueError) as error:
            log.info("Foxglove client refused at the handshake: %s", error)
            _close(client)
            if backend is not None:
                _close(backend)
            return
        threading.Thread(
            target=_pump, args=(backend, client), name="foxglove-front-down", daemon=True
        ).start()
        _pump(client, backend)
        with self._lock:
            self._sockets.difference_update((client, backend))


def _read_head(sock: socket.socket) -> bytes:
    """An HTTP head, up to and including the blank line, read byte by byte so that nothing of
    what follows (WebSocket frames) is taken from the socket."""
    head = bytearray()
    while not head.endswith(b"\r\n\r\n"):
        byte = sock.recv(1)
        if not byte:
            raise ValueError("closed during the handshake")
        head += byte
        if len(head) > MAX_HEAD_BYTES:
            raise ValueError("handshake head too long")
    return bytes(head)


def _translate_request(request: bytes) -> tuple[bytes, str | None]:
    """The request for the SDK server, and the legacy subprotocol the client asked for (None:
    it asked for the SDK's, or for none, and the request goes through unchanged)."""
    lines = request.split(b"\r\n")
    for index, line in enumerate(lines):
        if not line.lower().startswith(_PROTOCOL_HEADER):
            continue
        offered = [p.strip() for p in line.split(b":", 1)[1].decode("latin-1").split(",")]
        if SDK_SUBPROTOCOL in offered:
            return request, None
        legacy = next((p for p in offered if p in LEGACY_SUBPROTOCOLS), None)
        if legacy is None:
            return request, None
        lines[index] = f"Sec-WebSocket-Protocol: {SDK_SUBPROTOCOL}".encode()
        return b"\r\n".join(lines), legacy
    return request, None


def _rename_protocol(response: bytes, asked: str) -> bytes:
    """The SDK server's answer with the subprotocol named as the client asked."""
    lines = response.split(b"\r\n")
    for index, line in enumerate(lines):
        if line.lower().startswith(_PROTOCOL_HEADER):
            lines[index] = f"Sec-WebSocket-Protocol: {asked}".encode()
    return b"\r\n".join(lines)


def _pump(source: socket.socket, sink: socket.socket) -> None:
    """Copy until either side ends, then end both."""
    try:
        while chunk := source.recv(RELAY_CHUNK):
            sink.sendall(chunk)
    except OSError:
        pass
    finally:
        _close(source)
        _close(sink)


def _close(sock: socket.socket) -> None:
    try:
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    sock.close()
