"""How fast this machine is today: one fixed, seeded workload of the kinds planning spends
its time on (numpy over millions of pairs, GEOS distance tests through an STRtree and a
prepared union), timed best of 3. The same machine runs 10-30 % faster or slower from day to
day, so every `python -m bench` run prints this figure first, and BENCHMARKS.md gives it
beside the tables of each day: divide two tables' times by their days' figures to compare
them."""

from __future__ import annotations

import time

import numpy as np
import shapely


def reference_seconds(runs: int = 3) -> float:
    """Best wall time over `runs` of the reference workload (about 1 s on the project's
    2-core box)."""
    rng = np.random.default_rng(2026)
    corners = rng.uniform(0.0, 2000.0, (3000, 2))
    sides = rng.uniform(4.0, 20.0, (3000, 1))
    squares = shapely.box(*corners.T, *(corners + sides).T)
    starts = rng.uniform(0.0, 2000.0, (60_000, 2))
    ends = starts + rng.normal(0.0, 80.0, (60_000, 2))
    lines = shapely.linestrings(np.stack([starts, ends], axis=1))
    points = rng.uniform(0.0, 2000.0, (4_000_000, 2))
    best = float("inf")
    for _ in range(runs):
        began = time.perf_counter()
        tree = shapely.STRtree(squares)
        tree.query(lines, predicate="dwithin", distance=5.0)
        union = shapely.union_all(squares)
        shapely.prepare(union)
        shapely.dwithin(union, lines, 5.0)
        angle = np.arctan2(points[:, 1] - 1000.0, points[:, 0] - 1000.0)
        np.argsort(angle + np.hypot(points[:, 0], points[:, 1]))
        best = min(best, time.perf_counter() - began)
    return best


def main() -> None:
    print(
        f"machine: reference workload {reference_seconds():.3f} s (best of 3; see bench/machine.py)"
    )


if __name__ == "__main__":
    main()
