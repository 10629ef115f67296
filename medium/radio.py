"""The emulated radio (pure, seeded): unit-disk graph, multi-hop paths, per-hop delay and loss.

The network of the paper's sec. III (eqs. 3, 7-8): base stations (A, B and the mission's extra
ones, all wired to the ground station) and UAVs are nodes; two nodes hear each other when their
horizontal distance is at most the radio range rho_R (a unit disk, with DISTANCE_TOLERANCE,
as the planner's guarantee checks). A UAV reaches the ground station when a chain of such hops
joins it to any base station; its hop count is the length of the shortest such chain (1: a
base station hears it directly). A ground node (a ground user) relays nothing: it reaches a
base station directly or through the UAV it hears that has the shortest chain.

Two models of a packet's fate over its hops (`RadioConfig.model`):

* "simple" (the default): every packet crosses its hops one after the other: each hop takes
  `hop_latency_s` plus a uniform jitter in [-jitter_s, +jitter_s] (never negative) and is lost
  with probability `loss`;
* "calibrated": the delay and the loss of the whole path are drawn from a table measured in
  ns-3 (`medium.calibration`, made by `gcs eval calibrate`), at the load level nearest the
  offered load (`RadioConfig.offered_load_bps`, or the data sources of the medium that owns
  the channel: `medium.medium.MediumModel`). `hop_latency_s`, `jitter_s` and `loss` are not
  used.

A `DelayLine` hands packets over in order per stream (a radio link layer keeps its queue in
order, and MAVLink 2 signing refuses a timestamp older than the last one).
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Hashable
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Protocol

import numpy as np

from medium.calibration import CalibrationTable, LoadLevel

#: The models of a packet's fate (module docstring).
MODELS = ("simple", "calibrated")
#: Distances equal to the range count as links (the planner's tolerance, 1e-6 m).
DISTANCE_TOLERANCE = 1e-6
_NO_RELAY = np.iinfo(int).max  # a ground node no connected UAV hears


class LineOfSight(Protocol):
    """What blocks radio (`planner.sight.Sight`): whether each chord starts[i] -> ends[i]
    ((n, 2) each) is clear of every building."""

    def clear(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class RadioConfig:
    """The radio: range (m, may be infinite), per-hop latency and jitter (s), per-hop loss,
    the channel's seed, and the model (module docstring). "calibrated" draws from
    `calibration` (`medium.calibration.load_calibration`; the medium ships
    `medium/calibration_ns3.json`) at `offered_load_bps` (bit/s of data of every sender together; None: what the medium
    owning the channel offers, `medium.medium.MediumModel`)."""

    range_m: float
    hop_latency_s: float = 0.002
    jitter_s: float = 0.001
    loss: float = 0.0
    seed: int = 0
    model: str = "simple"
    calibration: CalibrationTable | None = None
    offered_load_bps: float | None = None
    #: buildings: a link whose chord meets one is cut (None: the paper's disk, through walls)
    sight: LineOfSight | None = None

    def __post_init__(self) -> None:
        if not self.range_m > 0:
            raise ValueError("range_m must be > 0")
        if not (math.isfinite(self.hop_latency_s) and self.hop_latency_s >= 0):
            raise ValueError("hop_latency_s must be finite and >= 0")
        if not (math.isfinite(self.jitter_s) and self.jitter_s >= 0):
            raise ValueError("jitter_s must be finite and >= 0")
        if not 0 <= self.loss < 1:
            raise ValueError("loss must be in [0, 1)")
        if self.model not in MODELS:
            raise ValueError(f"model must be one of {', '.join(MODELS)}, got {self.model!r}")
        if self.offered_load_bps is not None and not (
            math.isfinite(self.offered_load_bps) and self.offered_load_bps >= 0
        ):
            raise ValueError("offered_load_bps must be finite and >= 0")
        if self.model == "calibrated" and self.calibration is None:
            raise ValueError("the calibrated model needs its table (medium.calibration)")


@dataclass(frozen=True, eq=False)
class Topology:
    """The radio graph at one instant.

    `hops[k]`: hops from UAV k to its nearest base station (-1: no path, eq. 8 broken);
    `hears` (N, B + N): which stations, then which other UAVs, each UAV is in range of;
    `uav_links` (L, 2): UAV index pairs i < j in range; `station_links` (M, 2): (UAV, station).
    """

    stations: np.ndarray  # (B, 2)
    uav_xy: np.ndarray  # (N, 2)
    range_m: float
    hops: np.ndarray  # (N,) int
    hears: np.ndarray  # (N, B + N) bool; the UAV block is symmetric, False on its diagonal
    sight: LineOfSight | None = None  # buildings: in range and a clear chord

    @property
    def hears_station(self) -> np.ndarray:
        """(N, B) bool: the stations each UAV is in range of."""
        return self.hears[:, : len(self.stations)]

    @property
    def hears_uav(self) -> np.ndarray:
        """(N, N) bool: the UAVs each UAV is in range of (not itself)."""
        return self.hears[:, len(self.stations) :]

    @cached_property
    def hop_counts(self) -> list[int]:
        """`hops` as a list (one packet's lookup, without numpy)."""
        return self.hops.tolist()

    @cached_property
    def uav_links(self) -> np.ndarray:
        """(L, 2) int: UAV index pairs i < j in range."""
        return np.argwhere(np.triu(self.hears_uav, 1)).reshape(-1, 2)

    @cached_property
    def station_links(self) -> np.ndarray:
        """(M, 2) int: (UAV, station) pairs in range."""
        return np.argwhere(self.hears_station).reshape(-1, 2)

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
        station_count = len(self.stations)
        # (M, B + N): the stations, then the UAVs, each ground node is in range of
        nodes = np.concatenate([self.stations, self.uav_xy])
        hears = _squared(points, nodes) <= _limit(self.range_m)
        _cut_through_buildings(hears, points, nodes, self.sight)
        out[np.logical_or.reduce(hears[:, :station_count], axis=1)] = 1
        if len(self.uav_xy):
            relay = np.where(hears[:, station_count:] & (self.hops >= 0), self.hops, _NO_RELAY)
            best = np.minimum.reduce(relay, axis=1)
            via = (out < 0) & (best < _NO_RELAY)
            out[via] = best[via] + 1
        return out


def _limit(range_m: float) -> float:
    return math.inf if math.isinf(range_m) else (range_m + DISTANCE_TOLERANCE) ** 2


def _squared(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    gap = a[:, None, :] - b[None, :, :]
    return np.einsum("ijd,ijd->ij", gap, gap)


def _cut_through_buildings(
    hears: np.ndarray, points: np.ndarray, nodes: np.ndarray, sight: LineOfSight | None
) -> None:
    """`hears` (len(points), len(nodes)) without the pairs whose chord meets a building."""
    if sight is None:
        return
    row, col = np.nonzero(hears)
    known = np.isfinite(points[row]).all(axis=1) & np.isfinite(nodes[col]).all(axis=1)
    row, col = row[known], col[known]
    blocked = ~sight.clear(points[row], nodes[col])
    hears[row[blocked], col[blocked]] = False


def topology(
    stations: np.ndarray,
    uav_xy: np.ndarray,
    range_m: float,
    previous: Topology | None = None,
    sight: LineOfSight | None = None,
) -> Topology:
    """The unit-disk graph of base stations and UAVs (horizontal positions, (B, 2) and (N, 2));
    with `sight`, a pair in range whose chord meets a building hears nothing. Hop counts by a
    breadth-first search from every station at once (vectorised). When the nodes in range are
    those of `previous` (the same stations and range a moment before: the graph seldom changes
    between two positions of a fleet), its hop counts are kept."""
    stations = np.asarray(stations, dtype=float)
    if stations.ndim != 2 or stations.shape[1] != 2:
        stations = stations.reshape(-1, 2)
    uav_xy = np.asarray(uav_xy, dtype=float).reshape(-1, 2)
    count, station_count = len(uav_xy), len(stations)
    limit = _limit(range_m)
    # one (N, B + N) table of squared distances: UAVs to stations, then to UAVs
    hears = _squared(uav_xy, np.concatenate([stations, uav_xy])) <= limit
    _cut_through_buildings(hears, uav_xy, np.concatenate([stations, uav_xy]), sight)
    if math.isinf(limit):  # (a finite range already hears nothing at an unknown position)
        known = np.isfinite(uav_xy).all(axis=1)
        hears &= known[:, None]
        hears[:, station_count:] &= known[None, :]
    between = hears[:, station_count:]
    between.flat[:: count + 1] = False  # the diagonal
    if (
        previous is not None
        and previous.hears.shape == hears.shape
        and previous.range_m == range_m
        and (previous.stations is stations or np.array_equal(previous.stations, stations))
        and not np.count_nonzero(previous.hears != hears)
    ):
        hops = previous.hops
    else:
        hops = _hops(hears[:, :station_count], between)
    return Topology(
        stations=stations, uav_xy=uav_xy, range_m=float(range_m), hops=hops, hears=hears,
        sight=sight,
    )  # fmt: skip


def _hops(to_station: np.ndarray, between: np.ndarray) -> np.ndarray:
    """Hops of each UAV to its nearest station (-1: none): breadth-first search from every
    station at once over the UAVs in range of each other."""
    hops = np.full(len(between), -1, dtype=int)
    frontier = np.logical_or.reduce(to_station, axis=1)
    hops[frontier] = 1
    reached = frontier.copy()
    level = 1
    while np.count_nonzero(frontier):
        level += 1
        frontier = np.logical_or.reduce(between[frontier], axis=0)
        frontier &= ~reached
        reached |= frontier
        hops[frontier] = level
    return hops


class Channel:
    """Draws each packet's fate over its hops: delay (s) or lost (None). Seeded.

    The draws are numpy's (`Generator.random`, and `Generator.uniform` = low + (high - low) x
    a `random` draw) taken from one stream in the same order, a block at a time: a packet costs
    a few float operations instead of a numpy call per packet. The calibrated model takes two
    draws per packet (loss, then delay: `medium.calibration`) from the same stream, at the
    load level nearest `config.offered_load_bps`, else `offered_load_bps` (the data the
    medium's sources offer, bit/s), else the table's lowest."""

    _BLOCK = 4096  # uniform draws fetched from the generator at once

    def __init__(
        self, config: RadioConfig, stream: int = 0, offered_load_bps: float | None = None
    ) -> None:
        self.config = config
        self._rng = np.random.default_rng([config.seed, stream])
        self._block: list[float] = []
        self._next = 0  # index in `_block` of the next draw
        self.level: LoadLevel | None = None  # the calibrated model's load level
        if config.model == "calibrated":
            load = config.offered_load_bps
            self.offered_load_bps = load if load is not None else offered_load_bps
            self.level = config.calibration.level(self.offered_load_bps)
        else:
            self.offered_load_bps = offered_load_bps

    def _draws(self, count: int) -> list[float]:
        """The next `count` uniform draws in [0, 1) of the stream."""
        start, end = self._next, self._next + count
        if end > len(self._block):
            rest = self._block[start:]
            more = max(self._BLOCK, count - len(rest))
            self._block = rest + self._rng.random(more).tolist()
            start, end = 0, count
        self._next = end
        return self._block[start:end]

    def transit(self, hops: int) -> float | None:
        """Delay of one packet over `hops` hops (> 0), or None if a hop lost it."""
        if self.level is not None:
            loss_draw, delay_draw = self._draws(2)
            return self.level.delay(hops, loss_draw, delay_draw)
        cfg = self.config
        if cfg.loss > 0 and self._draws(1)[0] >= (1.0 - cfg.loss) ** hops:
            return None
        if cfg.jitter_s == 0:
            return hops * cfg.hop_latency_s
        low, span, latency = -cfg.jitter_s, cfg.jitter_s - -cfg.jitter_s, cfg.hop_latency_s
        per_hop = [max(latency + (low + span * u), 0.0) for u in self._draws(hops)]
        if hops >= 8:  # numpy's pairwise summation order, as the delays always were summed
            return float(np.sum(np.array(per_hop)))
        total = 0.0
        for delay in per_hop:
            total += delay
        return total

    def transit_many(self, hops: np.ndarray) -> np.ndarray:
        """Delays (s) of packets over `hops` (M,) hops each (> 0); NaN where a hop lost it."""
        hops = np.asarray(hops, dtype=int).reshape(-1)
        cfg = self.config
        if not len(hops):
            return np.zeros(0)
        if self.level is not None:  # two draws per packet, as `transit` takes them
            draws = np.array(self._draws(2 * len(hops))).reshape(-1, 2)
            return self.level.delays(hops, draws[:, 0], draws[:, 1])
        most = int(hops.max())
        per_hop = np.full((len(hops), most), cfg.hop_latency_s)
        if cfg.jitter_s > 0:
            draws = np.array(self._draws(per_hop.size)).reshape(per_hop.shape)
            per_hop += -cfg.jitter_s + (cfg.jitter_s - -cfg.jitter_s) * draws
            np.maximum(per_hop, 0.0, out=per_hop)
        per_hop[np.arange(most)[None, :] >= hops[:, None]] = 0.0
        delays = per_hop.sum(axis=1)
        if cfg.loss > 0:
            lost = np.array(self._draws(len(hops))) >= (1.0 - cfg.loss) ** hops
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
