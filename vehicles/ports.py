"""Free UDP ports for processes started later (vehicles, the radio medium, a GCS's `udpin`).

A port the OS hands out for `bind(0)` comes from the ephemeral range, the same range it draws
from when any socket sends without binding first (every `udpout` link): between picking a port
and the process that binds it getting there (a Python start-up on a busy machine takes a
second), another socket can autobind to it. Ports are therefore drawn at random *below* the
ephemeral range, where no autobind ever goes, and checked free by binding them.
"""

from __future__ import annotations

import random
import socket
from pathlib import Path

#: The lowest port drawn (well above the registered services that ship listening by default).
LOWEST_PORT = 20000
_EPHEMERAL_RANGE = Path("/proc/sys/net/ipv4/ip_local_port_range")
_DEFAULT_EPHEMERAL_FLOOR = 32768  # Linux's default; BSD and macOS start at 49152


def ephemeral_floor() -> int:
    """The lowest port the OS autobinds to (Linux reads it from /proc)."""
    try:
        return int(_EPHEMERAL_RANGE.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return _DEFAULT_EPHEMERAL_FLOOR


def free_udp_ports(count: int = 1, host: str = "127.0.0.1", attempts: int = 200) -> int:
    """A base port such that `count` consecutive UDP ports on `host` are free right now and
    outside the ephemeral range (see the module docstring)."""
    rng = random.SystemRandom()
    highest = ephemeral_floor() - count
    for _ in range(attempts):
        if highest > LOWEST_PORT:
            base = rng.randrange(LOWEST_PORT, highest)
        else:  # an unusual ephemeral range: take what the OS offers
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                probe.bind((host, 0))
                base = probe.getsockname()[1]
            if base + count > 65536:
                continue
        if _all_free(host, range(base, base + count)):
            return base
    raise OSError(f"no {count} consecutive free UDP ports on {host}")


def _all_free(host: str, ports: range) -> bool:
    held: list[socket.socket] = []
    try:
        for port in ports:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            held.append(sock)
            sock.bind((host, port))
    except OSError:
        return False
    finally:
        for sock in held:
            sock.close()
    return True
