"""ns-3 network evaluation benchmark (`python -m bench netsim`, issue 15; the `ns3` extra).

The paper's Table II mission (`examples/table-ii.yaml`: 9 UAVs, 2 base stations, 6 ground
users) flown once in the fast mode, then its network replayed in ns-3 (`gcs.netsim`): the
bindings' import and our C++'s compile (once per process) apart from building the scenario and
running it, for AODV and OLSR on the paper's disk, and for a log-distance channel. Reported
with the delivery, T_BS and the worst speed-request reaction times of both relays.

Then the whole paper evaluation (`gcs eval paper --network ns3`): its seven flights (2, 5,
10 m/s; leader UAV 1, 4, 6, 9 at 10 m/s) replayed in ns-3, one row each.
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
    console.print(paper_table(mission))


def paper_table(mission) -> Table:
    """Every flight of the paper evaluation replayed in ns-3: its mission time, ns-3's build
    and run time, delivery, T_BS, the longest gap and T_dv (worst, both relays)."""
    from gcs.netsim.ns3 import NetOptions
    from gcs.netsim.paper import net_metrics, replay_in_ns3
    from gcs.sim.eval import EvalPlan, run_all

    began = time.perf_counter()
    runs = run_all(EvalPlan(mission=EXAMPLE))
    flown = time.perf_counter() - began
    table = Table(
        title=f"gcs eval paper --network ns3 on Table II: {len(runs)} fast-mode flights in "
        f"{flown:.0f} s, then each in ns-3 (AODV, range, seed 1)"
    )
    for column in ("flight", "mission s", "build s", "run s", "UAV delivered %",
                   "T_BS mean ms", "longest gap s", "users delivered %",
                   "T_dv chain worst ms", "T_dv gcs worst ms"):  # fmt: skip
        table.add_column(column, justify="right")
    for replayed in replay_in_ns3(runs, mission, NetOptions()):
        m = net_metrics(replayed, mission)
        times = replayed.result.scenario.times
        chain, relay = m["reactions"]["chain"], m["reactions"]["gcs"]
        table.add_row(
            replayed.label,
            f"{times[-1] - times[0]:.0f}",
            f"{replayed.result.build_s:.2f}",
            f"{replayed.result.run_s:.2f}",
            f"{100 * m['uav_data']['ratio']:.1f}",
            f"{m['uav_data']['delay_mean_ms']:.2f}",
            f"{m['uav_data']['longest_gap_s']:.1f}",
            f"{100 * m['ground_users']['ratio']:.1f}",
            "-" if chain["worst_s"] is None else f"{1e3 * chain['worst_s']:.0f}",
            "-" if relay["worst_s"] is None else f"{1e3 * relay['worst_s']:.0f}",
        )
    return table


if __name__ == "__main__":
    main()
