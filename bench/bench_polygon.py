"""Large polygons (`python -m bench polygon`, about a minute): one finely drawn polygon
(`planner.scenarios.fine_polygon`) of 1,000 to 50,000 vertices. Columns: graph nodes, the
time to build them (best of 3; near-linear in the vertices since large polygons are queried
through their prepared geometry and edges, `Obstacles.LARGE_POLYGON`), and a plan stopped by
a time limit of `TIME_LIMIT_S`: its wall time and how far past the limit it stopped (the
search asks at every expansion; one batch of edges is not interrupted). Times also in units
of the machine's reference time R (`bench/machine.py`)."""

from __future__ import annotations

import time

from rich.console import Console
from rich.table import Table

from bench.machine import reference_seconds
from planner.graph import graph_nodes
from planner.scenarios import fine_polygon, scenario_problem
from planner.search import plan_path

VERTICES = (1_000, 10_000, 50_000)
TIME_LIMIT_S = 5.0


def node_seconds(vertices: int, runs: int = 3) -> tuple[int, float]:
    best, count = float("inf"), 0
    for _ in range(runs):
        problem = scenario_problem(fine_polygon(vertices))  # fresh obstacles: no cache
        began = time.perf_counter()
        count = len(graph_nodes(problem))
        best = min(best, time.perf_counter() - began)
    return count, best


def limited_plan_seconds(vertices: int) -> tuple[float, bool]:
    problem = scenario_problem(fine_polygon(vertices))
    began = time.perf_counter()
    plan = plan_path(problem, lambda _: time.perf_counter() - began >= TIME_LIMIT_S)
    return time.perf_counter() - began, plan.stopped


def main() -> None:
    unit = reference_seconds()
    table = Table(title=f"large polygons (R = {unit:.2f} s)")
    for column in ("vertices", "nodes", "node building s", "in R", "plan s", "stopped", "late s"):
        table.add_column(column, justify="right")
    for vertices in VERTICES:
        nodes, seconds = node_seconds(vertices)
        wall, stopped = limited_plan_seconds(vertices)
        table.add_row(
            f"{vertices:,}",
            f"{nodes:,}",
            f"{seconds:.3f}",
            f"{seconds / unit:.3f}",
            f"{wall:.1f}",
            "yes" if stopped else "no (done)",
            f"{max(wall - TIME_LIMIT_S, 0.0):.1f}" if stopped else "-",
        )
    Console().print(table)


if __name__ == "__main__":
    main()
