"""Measure per-hop delay and loss in ns-3 for the live medium (`gcs eval calibrate`).

The live medium (`medium.radio.Channel`) gives a packet over h hops h x (hop latency +- jitter);
its `radio.model: calibrated` draws instead from a table measured here, in ns-3, by
`gcs.netsim.ns3.run_network` (802.11b ad hoc at 11 Mbit/s, AODV, the range disk: the same
network as `gcs log netsim`). docs/calibration.md is the user's account.

Scenarios (`line_scenario`): per load level, a static line of `max_hops` UAVs spaced
`spacing_fraction` x rho_R apart from the one base station A at (0, 0): UAV k stands at
k x spacing, exactly k hops from A (the next-but-one node is 2 x spacing > rho_R away). Every
UAV sends `rate_bps` of UDP data to A in packets of `packet_bytes` (the live medium's data
packet, `medium.ground_users.DEFAULT_PACKET_BYTES`): the level's offered load is
`max_hops x rate_bps`, every sender of the line together, the number the medium matches its
own data sources against. No ground user, no speed request.

Each level is flown `runs` times with different seeds, and the runs pooled: a source sends at
a constant rate from a seeded random phase, so within one run its packets meet the other
sources' at the same instants every period, and one run shows one arrangement of phases
only; the medium's packets meet at any instant.

Reduction (`level_summary`, pure): per hop count k, the packets of UAV k sent after the first
`settle_s` of each run (AODV's first route discovery of each source is a start-up transient,
not a property of the link): sent, lost, loss ratio and the `QUANTILES` of the delays of the
delivered ones (p0 the smallest, p100 the largest). The table (`calibration_table`) adds what
made it: the command, ns-3's version and options, the seeds, the scenario and each run's
simulated duration; nothing that changes from one execution to the next (no wall time, no
date), so the same seed writes the same file.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from gcs.netsim.scenario import SAMPLE_HZ, NetScenario
from medium.ground_users import DEFAULT_PACKET_BYTES

#: The delay quantiles of the table (probabilities; 0: the smallest, 1: the largest).
QUANTILES = (0.0, 0.05, 0.25, 0.5, 0.75, 0.95, 0.99, 1.0)
#: The paper's data rate of every node (sec. VI, bit/s) and the default levels: x1, x4, x16, x64.
PAPER_RATE_BPS = 800.0
DEFAULT_RATES_BPS = (800.0, 3200.0, 12800.0, 51200.0)
#: The table's `format` and `version` (`medium.calibration` reads them).
FORMAT = "fleetline-radio-calibration"
VERSION = 1
#: Digits kept in the file: delays to 0.1 us, ratios to 1e-6.
DELAY_DIGITS = 7
RATIO_DIGITS = 6


@dataclass(frozen=True)
class CalibrationPlan:
    """What to measure: per-node data rates (bit/s, one load level each), the line's length
    (hop counts 1..`max_hops`), the spacing (fraction of rho_R, < 1 and > 0.5: one hop per
    UAV), rho_R (m), the packet size (bytes, the live medium's), the runs of each level
    (pooled, each with its own seed), the packets per source and run to aim for after the
    `settle_s` discarded at each run's start (`duration_s` None: a run lasts `settle_s` + that
    many packet intervals; a number: every run lasts that long)."""

    rates_bps: tuple[float, ...] = DEFAULT_RATES_BPS
    max_hops: int = 10
    spacing_fraction: float = 0.8
    radio_range_m: float = 100.0
    altitude_m: float = 30.0
    packet_bytes: int = DEFAULT_PACKET_BYTES
    runs: int = 8
    packets_per_source: int = 50
    settle_s: float = 2.0
    duration_s: float | None = None

    def __post_init__(self) -> None:
        if not self.rates_bps or not all(math.isfinite(r) and r > 0 for r in self.rates_bps):
            raise ValueError(f"rates_bps: expected rates > 0 bit/s, got {self.rates_bps}")
        if list(self.rates_bps) != sorted(set(self.rates_bps)):
            raise ValueError(f"rates_bps: expected increasing rates, got {self.rates_bps}")
        if not 1 <= self.max_hops <= 64:
            raise ValueError(f"max_hops: expected 1 to 64, got {self.max_hops}")
        if not 0.5 < self.spacing_fraction < 1.0:
            raise ValueError(
                f"spacing_fraction: expected in (0.5, 1): one hop per UAV, got "
                f"{self.spacing_fraction}"
            )
        if not 1 <= self.runs <= 1000:
            raise ValueError(f"runs: expected 1 to 1000, got {self.runs}")
        if not self.packets_per_source >= 1:
            raise ValueError(f"packets_per_source: expected >= 1, got {self.packets_per_source}")
        if self.duration_s is not None and not self.duration_s > self.settle_s:
            raise ValueError(f"duration_s: expected more than settle_s, got {self.duration_s}")

    @property
    def spacing_m(self) -> float:
        return self.spacing_fraction * self.radio_range_m

    def interval_s(self, rate_bps: float) -> float:
        """Seconds between two packets of one source at `rate_bps`."""
        return 8.0 * self.packet_bytes / rate_bps

    def run_seeds(self, seed: int) -> tuple[int, ...]:
        """The ns-3 seeds (`NetOptions.seed`) of a level's runs for the calibration's `seed`:
        `runs` consecutive ones, disjoint for different seeds."""
        return tuple((seed - 1) * self.runs + run + 1 for run in range(self.runs))

    def level_duration_s(self, rate_bps: float) -> float:
        """Simulated seconds of one run at `rate_bps` (a whole number of 10 Hz samples)."""
        if self.duration_s is not None:
            return float(self.duration_s)
        wanted = self.settle_s + self.packets_per_source * self.interval_s(rate_bps)
        return math.ceil(wanted * SAMPLE_HZ) / SAMPLE_HZ

    def describe(self) -> dict[str, Any]:
        """The scenario in the table's `scenario` key."""
        return {
            "topology": "static line of UAVs, one base station A at one end, 2-D distances",
            "uavs": self.max_hops,
            "spacing_m": self.spacing_m,
            "radio_range_m": self.radio_range_m,
            "altitude_m": self.altitude_m,
            "packet_bytes": self.packet_bytes,
            "senders": "every UAV, to A",
            "settle_s": self.settle_s,
            "hop_count": "UAV k is k hops from A",
        }


#: `gcs eval calibrate --quick`: 1-3 hops, the paper's load, one run of 30 s (tests).
QUICK_PLAN = CalibrationPlan(rates_bps=(PAPER_RATE_BPS,), max_hops=3, runs=1, duration_s=30.0)


def line_scenario(plan: CalibrationPlan, rate_bps: float) -> NetScenario:
    """The static line of `plan` at `rate_bps` per UAV (module docstring)."""
    duration = plan.level_duration_s(rate_bps)
    count = int(round(duration * SAMPLE_HZ)) + 1
    times = np.round(np.arange(count) / SAMPLE_HZ, 6)
    positions = np.zeros((len(times), plan.max_hops, 3))
    positions[:, :, 0] = plan.spacing_m * np.arange(1, plan.max_hops + 1)
    positions[:, :, 2] = plan.altitude_m
    return NetScenario(
        name=f"calibration line {plan.max_hops} x {rate_bps:g} bit/s",
        times=times,
        uav_positions=positions,
        base_stations=np.array([[0.0, 0.0]]),
        ground_users=np.zeros((0, 2)),
        radio_range=plan.radio_range_m,
        altitude=plan.altitude_m,
        requests=(),
        data_rate_bps=rate_bps,
        packet_bytes=plan.packet_bytes,
    )


# --------------------------------------------------------------------------- reduction
def hop_row(delays_s: np.ndarray, hops: np.ndarray, expected_hops: int) -> dict[str, Any]:
    """One hop count's row from its packets' delays (s, NaN: lost) and hop counts (-1: lost):
    sent, lost, loss ratio and the `QUANTILES` of the delivered delays (None when none was
    delivered), and how many were delivered over another hop count than `expected_hops` (0
    on a static line: `level_summary` adds them up as a check)."""
    delays_s = np.asarray(delays_s, dtype=float)
    delivered = np.isfinite(delays_s)
    sent, received = len(delays_s), int(delivered.sum())
    values = delays_s[delivered]
    quantiles = (
        np.round(np.quantile(values, QUANTILES), DELAY_DIGITS).tolist() if received else None
    )
    return {
        "hops": int(expected_hops),
        "sent": int(sent),
        "lost": int(sent - received),
        "loss_ratio": round(1.0 - received / sent, RATIO_DIGITS) if sent else None,
        "delay_s": quantiles,
        "other_hops": int((np.asarray(hops)[delivered] != expected_hops).sum()),
    }


def level_summary(results: Sequence, plan: CalibrationPlan, rate_bps: float) -> dict[str, Any]:
    """The table's level from the runs (`NetResult`s of `line_scenario(plan, rate_bps)`, one
    per seed) at `rate_bps`: per UAV k (k hops), its data packets sent after `plan.settle_s`
    in every run, pooled and reduced by `hop_row`."""
    delays: list[list[np.ndarray]] = [[] for _ in range(plan.max_hops)]
    hops: list[list[np.ndarray]] = [[] for _ in range(plan.max_hops)]
    for result in results:
        start = float(result.scenario.times[0])
        kept = (result.source_kind == "uav") & (result.sent_s >= start + plan.settle_s)
        for index in range(plan.max_hops):
            mine = kept & (result.source_id == index + 1)
            delays[index].append(result.delay_s[mine])
            hops[index].append(result.hops[mine])
    rows = [
        hop_row(np.concatenate(delays[k]), np.concatenate(hops[k]), k + 1)
        for k in range(plan.max_hops)
    ]
    other_hops = sum(row.pop("other_hops") for row in rows)
    return {
        "rate_bps_per_node": float(rate_bps),
        "senders": plan.max_hops,
        "offered_load_bps": float(rate_bps * plan.max_hops),
        "runs": len(results),
        "run_duration_s": plan.level_duration_s(rate_bps),
        "packets_sent": int(sum(row["sent"] for row in rows)),
        "packets_over_other_hop_counts": int(other_hops),
        "hops": rows,
    }


def calibration_table(
    levels: Sequence[dict[str, Any]],
    plan: CalibrationPlan,
    options,
    *,
    seed: int,
    ns3_version: str,
    command: str,
) -> dict[str, Any]:
    """The whole table (the JSON `medium.calibration.load_calibration` reads): the levels,
    lowest load first, and what made them (`options`: the `NetOptions` of every run but their
    seed, which is `plan.run_seeds(seed)`)."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "made_by": {"command": command, "tool": "gcs.netsim.calibrate"},
        "ns3": {
            "version": ns3_version,
            "wifi": "802.11b ad hoc (AdhocWifiMac), ConstantRateWifiManager DsssRate11Mbps "
            "data, DsssRate1Mbps control, YansWifiChannel",
            "options": {k: v for k, v in asdict(options).items() if k != "seed"},
            "run_seeds": list(plan.run_seeds(seed)),
        },
        "seed": int(seed),
        "scenario": plan.describe(),
        "quantiles": list(QUANTILES),
        "levels": sorted(levels, key=lambda level: level["offered_load_bps"]),
    }


def table_json(table: dict[str, Any]) -> str:
    """`table` as JSON text: one line per hop count's row (small, and diff-friendly)."""
    head = {key: value for key, value in table.items() if key != "levels"}
    lines = ["{"]
    for key, value in head.items():
        lines.append(f"  {_dumps(key)}: {_dumps(value)},")
    lines.append('  "levels": [')
    for index, level in enumerate(table["levels"]):
        fields = {key: value for key, value in level.items() if key != "hops"}
        lines.append("    {")
        for key, value in fields.items():
            lines.append(f"      {_dumps(key)}: {_dumps(value)},")
        lines.append('      "hops": [')
        rows = level["hops"]
        for k, row in enumerate(rows):
            lines.append(f"        {_dumps(row)}" + ("," if k < len(rows) - 1 else ""))
        lines.append("      ]")
        lines.append("    }" + ("," if index < len(table["levels"]) - 1 else ""))
    lines.append("  ]")
    lines.append("}")
    return "\n".join(lines) + "\n"


def _dumps(value: Any) -> str:
    return json.dumps(value, allow_nan=False, separators=(", ", ": "))


# --------------------------------------------------------------------------- running
@dataclass(frozen=True)
class CalibrationRun:
    """A calibration: the table, and wall seconds (ns-3's import apart) per level."""

    table: dict[str, Any]
    wall_s: dict[str, float] = field(default_factory=dict)
    import_s: float = 0.0


def ns3_version() -> str:
    """The installed ns3 distribution's version ("unknown" when it has no metadata)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ns3")
    except PackageNotFoundError:
        return "unknown"


def run_calibration(
    plan: CalibrationPlan,
    seed: int = 1,
    *,
    command: str = "",
    progress: Callable[[str], None] | None = None,
) -> CalibrationRun:
    """Fly every level of `plan` in ns-3 (`plan.runs` runs each, seeded from `seed`) and
    reduce them into the table; `NetsimUnavailable` without the ns3 extra."""
    import time

    from gcs.netsim.ns3 import IMPORT_TIMES, NetOptions, load_ns3, run_network

    load_ns3()
    levels, wall = [], {}
    seeds = plan.run_seeds(seed)
    for rate in plan.rates_bps:
        scenario = line_scenario(plan, rate)
        if progress is not None:
            progress(
                f"{plan.max_hops} UAVs x {rate:g} bit/s: {len(seeds)} run(s) of "
                f"{plan.level_duration_s(rate):g} s simulated ..."
            )
        began = time.perf_counter()
        results = [run_network(scenario, NetOptions(seed=run_seed)) for run_seed in seeds]
        wall[f"{rate:g}"] = time.perf_counter() - began
        levels.append(level_summary(results, plan, rate))
    table = calibration_table(
        levels, plan, NetOptions(), seed=seed, ns3_version=ns3_version(), command=command
    )
    return CalibrationRun(table=table, wall_s=wall, import_s=sum(IMPORT_TIMES.values()))
