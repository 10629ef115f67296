"""ns-3 network evaluation benchmark (`python -m bench netsim`, issue 15; the `ns3` extra).

The paper's Table II mission (`examples/table-ii.yaml`: 9 UAVs, 2 base stations, 6 ground
users) flown once in the fast mode, then its network replayed in ns-3 (`gcs.netsim`): the
bindings' import and our C++'s compile (once per process) apart from building the scenario and
running it, for AODV and OLSR on the paper's disk, and for a log-distance channel. Reported
with the delivery, T_BS and the worst speed-request reaction times of both relays.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.sim.fastsim import FastOptions, fly_fast

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "table-ii.yaml"
CASES = (("aodv", "range"), ("olsr", "range"), ("aodv", "logdistance"))


def main() -> None:
    from gcs.netsim.ns3 import (
        IMPORT_TIMES,
        NetOptions,
        NetsimUnavailable,
        load_ns3,
        run_network,
    )
    from gcs.netsim.scenario import scenario_from_fast_run

    console = Console(width=140)
    try:
        load_ns3()
    except NetsimUnavailable as missing:
        console.print(f"bench netsim: {missing}")
        return
    mission = load_mission(EXAMPLE)
    began = time.perf_counter()
    run = fly_fast(plan_mission(mission), FastOptions())
    flown = time.perf_counter() - began
    scenario = scenario_from_fast_run(run, mission)
    table = Table(
        title=f"ns-3 on Table II ({scenario.fleet_size} UAVs, {len(scenario.ground_users)} ground "
        f"users, {scenario.times[-1] - scenario.times[0]:.0f} s of mission); import "
        f"{IMPORT_TIMES.get('bindings_s', 0):.1f} s + compile {IMPORT_TIMES.get('compile_s', 0):.2f} s"
        f" once, fast-mode flight {flown:.1f} s"
    )
    for column in ("routing", "channel", "build s", "run s", "packets", "delivered %",
                   "T_BS mean ms", "T_BS p95 ms", "T_dv paper worst s", "T_dv gcs worst s"):  # fmt: skip
        table.add_column(column, justify="right")
    for routing, propagation in CASES:
        result = run_network(scenario, NetOptions(routing=routing, propagation=propagation))
        delay = result.delay_summary()
        delivered = result.delivered
        paper, relay = result.t_dv("paper"), result.t_dv("gcs")
        table.add_row(
            routing,
            propagation,
            f"{result.build_s:.2f}",
            f"{result.run_s:.2f}",
            str(len(delivered)),
            f"{100 * delivered.mean():.1f}",
            f"{1e3 * (delay['mean_s'] or np.nan):.2f}",
            f"{1e3 * (delay['p95_s'] or np.nan):.2f}",
            f"{np.nanmax(paper) if np.isfinite(paper).any() else float('nan'):.3f}",
            f"{np.nanmax(relay) if np.isfinite(relay).any() else float('nan'):.3f}",
        )
    console.print(table)


if __name__ == "__main__":
    main()
