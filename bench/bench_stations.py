"""Monitoring-station planning benchmark (`python -m bench stations`, issue 14).

On the 320-block city grid of `bench planner` (20 x 16 blocks of 40 m, 20 m streets, A in the
south-west intersection), 4, 8 and 16 points at street intersections drawn with a fixed seed:
the visiting order (exact up to 8 points, heuristic above), the route through them (one path
meeting definition 4 as a whole, `planner.route`) and the stations. Reported: the time of each
part (best of a few runs on freshly built obstacles), the route length against the straight
lines through the points in the same order, and the fleet size against its straight-line lower
bound (each gap between consecutive points, A included, needs ceil(gap / dS_r) UAVs).
"""

from __future__ import annotations

import time

import numpy as np
from rich.console import Console
from rich.table import Table

from planner.formation import radio_spacing
from planner.obstacles import Obstacles
from planner.route import RouteProblem, plan_route
from planner.scenarios import city_grid
from planner.stations import visit_order

POINT_COUNTS = (4, 8, 16)
SEED = 14
RUNS = 3


def grid_points(count: int, seed: int = SEED) -> tuple[np.ndarray, object]:
    """`count` distinct street intersections of the 20 x 16 grid (A's excluded)."""
    scenario = city_grid()
    pitch, street = 60.0, 20.0
    ix, iy = np.meshgrid(np.arange(21), np.arange(17), indexing="ij")
    crossings = street / 2.0 + pitch * np.column_stack([ix.ravel(), iy.ravel()])
    crossings = crossings[np.any(crossings != scenario.start, axis=1)]
    rng = np.random.default_rng(seed)
    return crossings[rng.choice(len(crossings), count, replace=False)], scenario


def measure(count: int) -> dict:
    points, scenario = grid_points(count)
    best_order = best_total = float("inf")
    plan = None
    for _ in range(RUNS):
        obstacles = Obstacles(polygons=scenario.obstacles.polygons)
        problem = RouteProblem(
            start=scenario.start,
            points=points,
            start_angle_deg=0.0,
            safety_margin=scenario.safety_margin,
            radio_range=scenario.radio_range,
            obstacles=obstacles,
        )
        began = time.perf_counter()
        visit_order(problem.start, points, "tsp")
        best_order = min(best_order, time.perf_counter() - began)
        began = time.perf_counter()
        plan = plan_route(problem)
        best_total = min(best_total, time.perf_counter() - began)
    visited = np.vstack([scenario.start, points[plan.order]])
    gaps = np.hypot(*np.diff(visited, axis=0).T)
    spacing = radio_spacing(scenario.safety_margin, scenario.radio_range)
    return {
        "points": count,
        "valid": plan.valid,
        "order_s": best_order,
        "total_s": best_total,
        "length": plan.length_m,
        "straight": float(gaps.sum()),
        "fleet": plan.fleet_size,
        "fleet_bound": int(np.sum(np.ceil(gaps / spacing - 1e-9))),
        "legs": len(plan.legs),
        "certified": plan.certified,
        "nodes": max(leg.node_count for leg in plan.legs),
        "edges": plan.path_plan().edges_examined,
    }


def main() -> None:
    table = Table(title="Monitoring stations on the 320-block city (order + route + stations)")
    for column in (
        "points",
        "order s",
        "order + route + stations s",
        "route m",
        "straight lines m",
        "UAVs",
        "straight-line bound",
        "legs certified",
        "nodes",
        "edges examined",
    ):
        table.add_column(column, justify="right")
    for count in POINT_COUNTS:
        row = measure(count)
        table.add_row(
            str(row["points"]),
            f"{row['order_s']:.4f}",
            f"{row['total_s']:.2f}",
            f"{row['length']:.1f}" if row["valid"] else "refused",
            f"{row['straight']:.1f}",
            str(row["fleet"]),
            str(row["fleet_bound"]),
            "yes" if row["certified"] else "no",
            f"{row['nodes']:,}",
            f"{row['edges']:,}",
        )
    Console(width=160).print(table)


if __name__ == "__main__":
    main()
