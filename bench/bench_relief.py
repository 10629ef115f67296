"""Relief benchmark (`python -m bench relief`, issue 14): planning one UAV's relief.

`examples/stations.yaml` (4 points over the city-blocks district, radio range 150 m) flown by
11 UAVs where 9 would do: every UAV in turn is relieved from the hold (`planner.relief`: the
new stations, the motions, the sampled check of the whole manoeuvre). Reported per UAV: the
planning time (best of a few runs), accepted or why not, how many UAVs close the gap, when
the climb ends, the gap is closed and the UAV stands above its landing slot (seconds from the
request), and the closest two UAVs came in the check (3-D, virtual positions; 2 rho_c = 8 m).
Then one fast-mode flight (`gcs.sim.fastsim`) with UAV 6 relieved: wall time and its figures.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from gcs.mission import load_mission
from gcs.planning import plan_json, plan_mission
from gcs.sim.fastsim import FastOptions, Faults, fly_fast
from planner.relief import ReliefRefused, plan_relief

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "stations.yaml"
FLEET_SIZE = 11
RUNS = 3
FLOWN_UAV = 6


def planned():
    mission = load_mission(EXAMPLE)
    return plan_mission(replace(mission, fleet=replace(mission.fleet, size=FLEET_SIZE)))


def main() -> None:
    plan = planned()
    formation, route = plan.formation, plan.route
    base = np.array(plan.mission.base_station_points)
    speed, acceleration = plan.speeds.initial, 0.5 * plan.mission.vehicle.max_acceleration
    table = Table(title=f"Relief of one UAV: examples/stations.yaml, {FLEET_SIZE} UAVs (9 needed)")
    for column in ("UAV", "plan ms", "outcome", "moving", "climbed s", "closed s", "home s",
                   "closest m"):  # fmt: skip
        table.add_column(column, justify="right")
    for uav in range(1, formation.fleet_size + 1):
        best, outcome = float("inf"), None
        for _ in range(RUNS):
            began = time.perf_counter()
            try:
                outcome = plan_relief(
                    formation, formation.stations, route.point_distance, uav, 0.0, speed,
                    acceleration, base, climb_speed=2.5,
                )  # fmt: skip
            except ReliefRefused as refused:
                outcome = refused
            best = min(best, time.perf_counter() - began)
        if isinstance(outcome, ReliefRefused):
            reason = "refused: gap at its fewest" if "cannot leave" in str(outcome) else "refused"
            table.add_row(str(uav), f"{best * 1e3:.1f}", reason, "", "", "", "", "")
            continue
        table.add_row(
            str(uav),
            f"{best * 1e3:.1f}",
            "accepted",
            str(len(outcome.moves)),
            f"{outcome.climbed_s:.1f}",
            f"{outcome.closed_s:.1f}",
            f"{outcome.home_s:.1f}",
            f"{outcome.min_separation_m:.2f}",
        )
    console = Console(width=140)
    console.print(table)
    on_station = float(plan_json(plan)["stations"]["on_station_s"])
    began = time.perf_counter()
    run = fly_fast(
        plan, FastOptions(faults=Faults(operator_reliefs=((on_station + 5.0, FLOWN_UAV),)))
    )
    wall = time.perf_counter() - began
    data = run.run_json
    (relief,) = data["stations"]["relieved"]
    console.print(
        f"fast-mode flight with UAV {FLOWN_UAV} relieved: {wall:.1f} s wall for "
        f"{data['duration_s']:.0f} s of mission, completed {data['completed']}, min UAV-UAV "
        f"{data['min_uav_uav_m']:.2f} m, max tracking error {data['max_tracking_error_m']:.2f} m, "
        f"connected {100 * data['connected_fraction']:.1f} %, UAV {FLOWN_UAV} landed "
        f"{relief['landed_s'] - relief['asked_s']:.0f} s after the request"
    )


if __name__ == "__main__":
    main()
