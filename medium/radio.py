"""The emulated radio (pure, seeded): unit-disk graph, multi-hop paths, per-hop delay and loss.

The network of the paper's sec. III (eqs. 3, 7-8): base stations (A, B and the mission's extra
ones, all wired to the ground station) and UAVs are nodes; two nodes hear each other when their
horizontal distance is at most the radio range rho_R (a unit disk, with DISTANCE_TOLERANCE,
as the planner's guarantee checks). A UAV reaches the ground station when a chain of such hops
joins it to any base station; its hop count is the length of the shortest such chain (1: a
base station hears it directly). A ground node (a ground user) relays nothing: it reaches a
base station directly or through the UAV it hears that has the shortest chain.

Every packet crosses its hops one after the other: each hop takes `hop_latency_s` plus a
uniform jitter in [-jitter_s, +jitter_s] (never negative) and is lost with probability `loss`.
A `DelayLine` hands packets over in order per stream (a radio link layer keeps its queue in
order, and MAVLink 2 signing refuses a timestamp older than the last one).
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Distances equal to the range count as links (the planner's tolerance, 1e-6 m).
DISTANCE_TOLERANCE = 1e-6


@dataclass(frozen=True)
class RadioConfig:
    """The radio: range (m, may be infinite), per-hop latency and jitter (s), per-hop loss."""

    range_m: float
    hop_latency_s: float = 0.002
    jitter_s: float = 0.001
    loss: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.range_m > 0:
            raise ValueError("range_m must be > 0")
        if not (math.isfinite(self.hop_latency_s) and self.hop_latency_s >= 0):
            raise ValueError("hop_latency_s must be finite and >= 0")
        if not (math.isfinite(self.jitter_s) and self.jitter_s >= 0):
            raise ValueError("jitter_s must be finite and >= 0")
        if not 0 <= self.loss < 1:
            raise ValueError("loss must be in [0, 1)")


@dataclass(frozen=True, eq=False)
class Topology:
    """The radio graph at one instant.

    `hops[k]`: hops from UAV k to its nearest base station (-1: no path, eq. 8 broken);
    `uav_links` (L, 2): UAV index pairs i < j in range; `station_links` (M, 2): (UAV, station).
    """

    stations: np.ndarray  # (B, 2)
    uav_xy: np.ndarray  # (N, 2)
    range_m: float
    hops: np.ndarray  # (N,) int
    uav_links: np.ndarray  # (L, 2) int
    station_links: np.ndarray  # (M, 2) int

    @property
    def connected(self) -> bool:
        """Every UAV has a path to a base station (the paper's eq. 8 for the whole fleet)."""
        return bool((self.hops >= 0).all())

    def hops_of_ground_nodes(self, points: np.ndarray) -> np.ndarray:
        """Hops from each ground node (M, 2) to its nearest base station (-1: none): 1 if a
        station hears it, else 1 + the fewest hops of a connected UAV that hears it."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        out = np.full(len(points), -1, dtype=int)
        if not len(points):
            return out
        limit = _limit(self.range_m)
        if len(self.stations):
            direct = _squared(points, self.stations) <= limit
            out[direct.any(axis=1)] = 1
        if len(self.uav_xy):
            heard = _squared(points, self.uav_xy) <= limit  # (M, N)
            relay = np.where(
                heard & (self.hops >= 0)[None, :], self.hops[None, :], np.iinfo(int).max
            )
            best = relay.min(axis=1)
            via = (out < 0) & (best < np.iinfo(int).max)
            out[via] = best[via] + 1
        return out


def _limit(range_m: float) -> float:
    return math.inf if math.isinf(range_m) else (range_m + DISTANCE_TOLERANCE) ** 2


def _squared(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    gap = a[:, None, :] - b[None, :, :]
    return np.einsum("ijd,ijd->ij", gap, gap)


def topology(stations: np.ndarray, uav_xy: np.ndarray, range_m: float) -> Topology:
    """The unit-disk graph of base stations and UAVs (horizontal positions, (B, 2) and (N, 2));
    hop counts by a breadth-first search from every station at once (vectorised)."""
    stations = np.asarray(stations, dtype=float).reshape(-1, 2)
    uav_xy = np.asarray(uav_xy, dtype=float).reshape(-1, 2)
    count = len(uav_xy)
    limit = _limit(range_m)
    known = np.isfinite(uav_xy).all(axis=1)
    to_station = (_squared(uav_xy, stations) <= limit) & known[:, None]
    between = (_squared(uav_xy, uav_xy) <= limit) & known[:, None] & known[None, :]
    np.fill_diagonal(between, False)
    hops = np.full(count, -1, dtype=int)
    frontier = to_station.any(axis=1)
    hops[frontier] = 1
    reached = frontier.copy()
    level = 1
    while frontier.any():
        level += 1
        frontier = between[frontier].any(axis=0) & ~reached
        reached |= frontier
        hops[frontier] = level
    upper = np.argwhere(np.triu(between, 1))
    return Topology(
        stations=stations,
        uav_xy=uav_xy,
        range_m=float(range_m),
        hops=hops,
        uav_links=upper.reshape(-1, 2),
        station_links=np.argwhere(to_station).reshape(-1, 2),
    )


class Channel:
    """Draws each packet's fate over its hops: delay (s) or lost (None). Seeded."""

    def __init__(self, config: RadioConfig, stream: int = 0) -> None:
        self.config = config
        self._rng = np.random.default_rng([config.seed, stream])

    def transit(self, hops: int) -> float | None:
        """Delay of one packet over `hops` hops (> 0), or None if a hop lost it."""
        cfg = self.config
        if cfg.loss > 0 and self._rng.random() >= (1.0 - cfg.loss) ** hops:
            return None
        if cfg.jitter_s == 0:
            return hops * cfg.hop_latency_s
        draws = self._rng.uniform(-cfg.jitter_s, cfg.jitter_s, hops)
        return float(np.maximum(cfg.hop_latency_s + draws, 0.0).sum())

    def transit_many(self, hops: np.ndarray) -> np.ndarray:
        """Delays (s) of packets over `hops` (M,) hops each (> 0); NaN where a hop lost it."""
        hops = np.asarray(hops, dtype=int).reshape(-1)
        cfg = self.config
        if not len(hops):
            return np.zeros(0)
        most = int(hops.max())
        per_hop = np.full((len(hops), most), cfg.hop_latency_s)
        if cfg.jitter_s > 0:
            per_hop += self._rng.uniform(-cfg.jitter_s, cfg.jitter_s, per_hop.shape)
            np.maximum(per_hop, 0.0, out=per_hop)
        per_hop[np.arange(most)[None, :] >= hops[:, None]] = 0.0
        delays = per_hop.sum(axis=1)
        if cfg.loss > 0:
            lost = self._rng.random(len(hops)) >= (1.0 - cfg.loss) ** hops
            delays[lost] = np.nan
        return delays


class DelayLine:
    """Packets in flight, handed over at their delivery time and in order per stream."""

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Any]] = []
        self._last: dict[Hashable, float] = {}
        self._order = itertools.count()

    def __len__(self) -> int:
        return len(self._heap)

    def put(self, stream: Hashable, due_s: float, item: Any) -> float:
        """Queue `item` for `due_s`, never before the previous item of `stream`; returns the
        delivery time it got."""
        due = max(due_s, self._last.get(stream, -math.inf))
        self._last[stream] = due
        heapq.heappush(self._heap, (due, next(self._order), item))
        return due

    def next_due(self) -> float:
        """Delivery time of the earliest item (infinite when empty)."""
        return self._heap[0][0] if self._heap else math.inf

    def pop_due(self, now_s: float) -> list[tuple[float, Any]]:
        """(delivery time, item) of every item due at or before `now_s`, in delivery order."""
        out = []
        heap = self._heap
        while heap and heap[0][0] <= now_s:
            due, _, item = heapq.heappop(heap)
            out.append((due, item))
        return out
