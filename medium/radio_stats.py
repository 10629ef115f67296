"""Counters of the emulated radio (pure): packets sent, received and dropped, delays, hops,
connectivity samples; the `radio` object of the run JSON (docs/outputs.md) and the paper's
network metrics (sec. V-A: BS_con, T_BS, S_r-d) come from here.

Packet kinds: `uplink` (MAVLink from a UAV to the ground station), `downlink` (MAVLink from the
ground station to a UAV), `uav_data` (data a UAV sends to a base station, the paper's sec. VI-A)
and `ground` (data of a ground user, sec. VI-B). `packets` in the summary counts the first
three; `ground_users` the last. A packet is dropped when no path exists at the instant it is
sent, or when a hop loses it.
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass, field

import numpy as np

from medium.radio import Topology

KINDS = ("uplink", "downlink", "uav_data", "ground")
_KIND_CODE = {kind: code for code, kind in enumerate(KINDS)}
FLEET_KINDS = ("uplink", "downlink", "uav_data")


@dataclass
class Counter:
    sent: int = 0
    received: int = 0
    dropped: int = 0

    def as_json(self) -> dict:
        return {"sent": self.sent, "received": self.received, "dropped": self.dropped}


@dataclass
class PacketLog:
    """Every packet, column-wise (for figures): send time (s), kind code, source/UAV index,
    hops (-1: no path), delay (s, NaN: dropped)."""

    time_s: array = field(default_factory=lambda: array("d"))
    kind: array = field(default_factory=lambda: array("b"))
    node: array = field(default_factory=lambda: array("h"))
    hops: array = field(default_factory=lambda: array("h"))
    delay_s: array = field(default_factory=lambda: array("d"))

    def columns(self) -> dict[str, np.ndarray]:
        return {
            "time_s": np.frombuffer(self.time_s, dtype=float).copy(),
            "kind": np.frombuffer(self.kind, dtype=np.int8).copy(),
            "node": np.frombuffer(self.node, dtype=np.int16).copy(),
            "hops": np.frombuffer(self.hops, dtype=np.int16).copy(),
            "delay_s": np.frombuffer(self.delay_s, dtype=float).copy(),
        }


class RadioStats:
    """Running counters of one medium; `summary()` is the run JSON's `radio` object."""

    def __init__(self, fleet_size: int, keep_packets: bool = False) -> None:
        self.fleet_size = fleet_size
        self.counters = {kind: Counter() for kind in KINDS}
        self.per_uav = {kind: [Counter() for _ in range(fleet_size)] for kind in FLEET_KINDS}
        self._delays = {"fleet": array("d"), "ground": array("d")}
        self._hops = {"fleet": array("h"), "ground": array("h")}
        self.samples = 0
        self.connected_samples = 0
        self.uav_connected_samples = np.zeros(fleet_size, dtype=int)
        self.last_hops = np.full(fleet_size, -1, dtype=int)
        self.log = PacketLog() if keep_packets else None

    def packet(self, kind: str, node: int, t: float, hops: int, delay_s: float | None) -> None:
        """One packet of `kind` from/to UAV (or ground user) `node`, sent at `t` over `hops`
        hops (-1: no path); `delay_s` None = dropped."""
        counter = self.counters[kind]
        counter.sent += 1
        if kind == "ground":
            per, group = None, "ground"
        else:
            per, group = self.per_uav[kind][node], "fleet"
            per.sent += 1
        if delay_s is None:
            counter.dropped += 1
            if per is not None:
                per.dropped += 1
        else:
            counter.received += 1
            if per is not None:
                per.received += 1
            self._delays[group].append(delay_s)
            self._hops[group].append(hops)
        log = self.log
        if log is not None:
            log.time_s.append(t)
            log.kind.append(_KIND_CODE[kind])
            log.node.append(node)
            log.hops.append(hops)
            log.delay_s.append(math.nan if delay_s is None else delay_s)

    def packets(
        self, kind: str, nodes: np.ndarray, t: np.ndarray, hops: np.ndarray, delays: np.ndarray
    ) -> None:
        """Many packets at once (`delays` NaN = dropped); same meaning as `packet`."""
        for node, when, hop, delay in zip(
            np.asarray(nodes).tolist(),
            np.asarray(t).tolist(),
            np.asarray(hops).tolist(),
            np.asarray(delays).tolist(),
            strict=True,
        ):
            self.packet(kind, int(node), float(when), int(hop), None if delay != delay else delay)

    def recent(self, since: int, limit: int = 2000) -> tuple[int, dict]:
        """Delays (ms) and hops of the delivered fleet packets after the first `since` ones
        (at most `limit`, evenly picked), and the count to pass next time."""
        delays = np.frombuffer(self._delays["fleet"], dtype=float)[since:]
        hops = np.frombuffer(self._hops["fleet"], dtype=np.int16)[since:]
        pick = np.linspace(0, len(delays) - 1, min(limit, len(delays))).astype(int)
        recent = {
            "delay_ms": np.round(delays[pick] * 1000.0, 3).tolist(),
            "hops": hops[pick].tolist(),
        }
        return since + len(delays), recent

    def sample(self, topology: Topology) -> None:
        """One connectivity sample of the whole fleet (the paper's eq. 8 at one instant)."""
        self.samples += 1
        connected = topology.hops >= 0
        self.connected_samples += int(connected.all())
        self.uav_connected_samples += connected
        self.last_hops = topology.hops.copy()

    # ------------------------------------------------------------------ summaries
    def fleet_counter(self) -> Counter:
        total = Counter()
        for kind in FLEET_KINDS:
            c = self.counters[kind]
            total.sent += c.sent
            total.received += c.received
            total.dropped += c.dropped
        return total

    def summary(self) -> dict:
        """The run JSON's `radio` object (docs/outputs.md) plus per-kind and per-UAV detail."""
        ground = self.counters["ground"]
        return {
            "connected_fraction": (self.connected_samples / self.samples if self.samples else None),
            "packets": self.fleet_counter().as_json(),
            "delay_ms": _delay_summary(self._delays["fleet"]),
            "hops": _hop_summary(self._hops["fleet"]),
            "ground_users": {
                **ground.as_json(),
                "delay_ms": _delay_summary(self._delays["ground"]),
                "hops": _hop_summary(self._hops["ground"]),
            },
            "kinds": {kind: self.counters[kind].as_json() for kind in FLEET_KINDS},
            "per_uav": [
                {
                    "uav": k + 1,
                    "hops": int(self.last_hops[k]),
                    "connected_fraction": (
                        float(self.uav_connected_samples[k] / self.samples)
                        if self.samples
                        else None
                    ),
                    **{kind: self.per_uav[kind][k].as_json() for kind in FLEET_KINDS},
                }
                for k in range(self.fleet_size)
            ],
        }


def _delay_summary(delays: array) -> dict:
    if not len(delays):
        return {"mean": None, "p95": None, "max": None}
    values = np.frombuffer(delays, dtype=float) * 1000.0
    return {
        "mean": float(values.mean()),
        "p95": float(np.percentile(values, 95)),
        "max": float(values.max()),
    }


def _hop_summary(hops: array) -> dict:
    if not len(hops):
        return {"mean": None, "max": None}
    values = np.frombuffer(hops, dtype=np.int16)
    return {"mean": float(values.mean()), "max": int(values.max())}
