"""Data sources of the emulated network (pure): ground users, and UAVs sending data.

The paper's sec. VI: ground users (and, in sec. VI-A, the UAVs) send constant-bit-rate data
(0.8 kbps) to a base station; a packet reaches the nearest reachable base station through the
fleet if a path exists at the instant it is sent, and is dropped otherwise (S_r-d). Packets are
`packet_bytes` long (default 200 bytes: at 0.8 kbps one packet every 2 s per source, about the
rate of the paper's counts, 5250 packets from 6 users over its 1800 s mission). Source i of M
starts i/M of a period late, so sources do not all send at the same instant.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from medium.radio import Channel, Topology
from medium.radio_stats import RadioStats

DEFAULT_PACKET_BYTES = 200
DEFAULT_RATE_BPS = 800.0


@dataclass(frozen=True)
class GroundUser:
    """A data source on the ground: position (local x east, y north, m) and rate (bit/s)."""

    x: float
    y: float
    rate_bps: float = DEFAULT_RATE_BPS


class CbrTraffic:
    """Send times of constant-bit-rate sources (one packet every packet_bits / rate seconds)."""

    def __init__(
        self,
        rates_bps: Sequence[float],
        packet_bytes: int = DEFAULT_PACKET_BYTES,
        start_s: float = 0.0,
    ) -> None:
        rates = np.asarray(rates_bps, dtype=float).reshape(-1)
        if np.any(~np.isfinite(rates)) or np.any(rates <= 0):
            raise ValueError("rates must be finite and > 0")
        if packet_bytes <= 0:
            raise ValueError("packet_bytes must be > 0")
        self.period_s = packet_bytes * 8.0 / rates
        count = len(rates)
        self._next = start_s + self.period_s * np.arange(count) / max(count, 1)
        self.next_due_s = float(self._next.min()) if count else math.inf

    def __len__(self) -> int:
        return len(self.period_s)

    def due(self, until_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Sources and send times of every packet sent at or before `until_s` (in time order)."""
        if until_s < self.next_due_s:  # nothing due (always so without sources)
            return np.zeros(0, dtype=int), np.zeros(0)
        counts = np.floor((until_s - self._next) / self.period_s).astype(int) + 1
        counts = np.maximum(counts, 0)
        if not counts.any():
            return np.zeros(0, dtype=int), np.zeros(0)
        sources = np.repeat(np.arange(len(counts)), counts)
        first = np.repeat(self._next, counts)
        index = np.arange(len(sources)) - np.repeat(np.cumsum(counts) - counts, counts)
        times = first + index * np.repeat(self.period_s, counts)
        self._next = self._next + counts * self.period_s
        self.next_due_s = float(self._next.min())
        order = np.argsort(times, kind="stable")
        return sources[order], times[order]


def offer(
    traffic: CbrTraffic,
    now_s: float,
    hops: np.ndarray,
    kind: str,
    channel: Channel,
    stats: RadioStats,
) -> int:
    """Send every packet of `traffic` due by `now_s`, each source over its `hops` (-1: no path:
    dropped) at this instant; record them in `stats` as `kind`. Returns the packets sent."""
    sources, times = traffic.due(now_s)
    if not len(sources):
        return 0
    source_hops = np.asarray(hops, dtype=int)[sources]
    delays = np.full(len(sources), np.nan)
    reachable = source_hops >= 0
    if reachable.any():
        delays[reachable] = channel.transit_many(source_hops[reachable])
    stats.packets(kind, sources, times, source_hops, delays)
    return len(sources)


class GroundUsers:
    """The mission's ground users and their traffic."""

    def __init__(
        self,
        users: Sequence[GroundUser],
        packet_bytes: int = DEFAULT_PACKET_BYTES,
        start_s: float = 0.0,
    ) -> None:
        self.users = tuple(users)
        self.positions = np.array([(u.x, u.y) for u in self.users], dtype=float).reshape(-1, 2)
        self.traffic = CbrTraffic([u.rate_bps for u in self.users], packet_bytes, start_s)

    def send_due(
        self, now_s: float, topology: Topology, channel: Channel, stats: RadioStats
    ) -> int:
        """Every ground-user packet due by `now_s`, routed on `topology` (this instant)."""
        if not self.users or now_s < self.traffic.next_due_s:
            return 0
        hops = topology.hops_of_ground_nodes(self.positions)
        return offer(self.traffic, now_s, hops, "ground", channel, stats)
