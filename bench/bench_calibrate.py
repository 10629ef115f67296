"""Calibration of the live medium from ns-3 (`python -m bench calibrate`, issue 15 item 4).

1. The default `gcs eval calibrate` (4 load levels x 8 runs of a 10-UAV line in ns-3): wall
   time per level and in all, ns-3's import (bindings and our C++, once per process) apart;
   the table is not written (the shipped one stays as it is). Skipped without the ns3 extra.
2. The medium's draws (`medium.radio.Channel`): packets per second of the simple model and of
   the calibrated one (the shipped table, the paper's load), one packet at a time
   (`transit`, as the medium routes MAVLink) and in batches (`transit_many`, as the data
   sources send), over 1 to 12 hops (beyond the table's 10: extrapolated).
"""

from __future__ import annotations

import time

import numpy as np
from rich.console import Console
from rich.table import Table

from medium.calibration import DEFAULT_CALIBRATION, load_calibration
from medium.radio import Channel, RadioConfig

PACKETS = 200_000
BATCH = 64
HOPS = np.random.default_rng(1).integers(1, 13, PACKETS)


def draw_rates(config: RadioConfig) -> tuple[float, float]:
    """Packets per second of `transit` (one at a time) and `transit_many` (BATCH at a time)."""
    channel = Channel(config, 0, 8000.0)
    hops = HOPS.tolist()
    began = time.perf_counter()
    for count in hops:
        channel.transit(count)
    single = len(hops) / (time.perf_counter() - began)
    channel = Channel(config, 0, 8000.0)
    began = time.perf_counter()
    for start in range(0, PACKETS, BATCH):
        channel.transit_many(HOPS[start : start + BATCH])
    batched = PACKETS / (time.perf_counter() - began)
    return single, batched


def calibration_table() -> Table | str:
    from gcs.netsim.calibrate import CalibrationPlan, run_calibration
    from gcs.netsim.ns3 import IMPORT_TIMES, NetsimUnavailable, load_ns3

    try:
        load_ns3()
    except NetsimUnavailable as missing:
        return f"bench calibrate: {missing}"
    plan = CalibrationPlan()
    began = time.perf_counter()
    run = run_calibration(plan, 1, command="python -m bench calibrate")
    total = time.perf_counter() - began
    table = Table(
        title=f"gcs eval calibrate (default: {len(plan.rates_bps)} loads x {plan.runs} runs of "
        f"{plan.max_hops} UAVs) in {total:.1f} s; ns-3 import "
        f"{sum(IMPORT_TIMES.values()):.1f} s apart"
    )
    for column in ("bit/s per UAV", "simulated s per run", "wall s", "packets", "p50 1 hop ms",
                   "p50 10 hops ms", "loss 10 hops %"):  # fmt: skip
        table.add_column(column, justify="right")
    for level in run.table["levels"]:
        rows = level["hops"]
        median = run.table["quantiles"].index(0.5)
        rate = f"{level['rate_bps_per_node']:g}"
        table.add_row(
            rate,
            f"{level['run_duration_s']:g}",
            f"{run.wall_s[rate]:.2f}",
            str(level["packets_sent"]),
            f"{1e3 * rows[0]['delay_s'][median]:.3f}",
            f"{1e3 * rows[-1]['delay_s'][median]:.3f}",
            f"{100 * rows[-1]['loss_ratio']:.1f}",
        )
    return table


def main() -> None:
    console = Console(width=140)
    console.print(calibration_table())
    table = Table(
        title=f"medium draws: {PACKETS} packets over 1-12 hops, packets/s "
        f"(transit_many in batches of {BATCH})"
    )
    for column in ("model", "transit", "transit_many"):
        table.add_column(column, justify="right")
    shipped = load_calibration(DEFAULT_CALIBRATION)
    for name, config in (
        ("simple (2 ms +- 1 ms a hop)", RadioConfig(100.0, seed=1)),
        (
            "calibrated (shipped table)",
            RadioConfig(100.0, seed=1, model="calibrated", calibration=shipped),
        ),
    ):
        single, batched = draw_rates(config)
        table.add_row(name, f"{single:,.0f}", f"{batched:,.0f}")
    console.print(table)


if __name__ == "__main__":
    main()
