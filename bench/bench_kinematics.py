"""Kinematics and guarantee checks: how fast V_n(t), the smoothed reference and the checks run."""

from __future__ import annotations

import time

import numpy as np
from rich.console import Console
from rich.table import Table

from planner.formation import min_fleet_size, parking_rows
from planner.guarantees import check_positions
from planner.kinematics import (
    LineFormation,
    SpeedProfile,
    recommended_window,
    safe_speed,
    smoothed_reference,
    smoothing_error_bound,
)
from planner.obstacles import Obstacles

SAFETY_MARGIN = 5.0
RADIO_RANGE = 220.0


def staircase(bends: int, seed: int = 0) -> np.ndarray:
    """A path of `bends` alternating 90-degree turns (a city crossing), segments 40-120 m."""
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(40.0, 120.0, bends + 1)
    axes = np.tile([[1.0, 0.0], [0.0, 1.0]], ((bends + 2) // 2, 1))[: bends + 1]
    return np.vstack([[0.0, 0.0], np.cumsum(lengths[:, None] * axes, axis=0)])


def formation_for(path: np.ndarray, fleet_size: int) -> LineFormation:
    rows = parking_rows(path[0], path[-1], 0.0, 0.0, fleet_size, SAFETY_MARGIN)
    return LineFormation(path, fleet_size, SAFETY_MARGIN, RADIO_RANGE, rows)


def best_of(run, repeat: int = 3) -> float:
    """Smallest wall time of `repeat` runs, seconds."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best


def bench_fleet(table: Table, fleet_size: int, bends: int, profile: SpeedProfile) -> None:
    """Rows of `table` for one fleet on a staircase path with `bends` 90-degree bends."""
    path = staircase(bends)
    length = float(np.sum(np.hypot(*np.diff(path, axis=0).T)))
    fleet_size = max(fleet_size, min_fleet_size(length, SAFETY_MARGIN, RADIO_RANGE))
    formation = formation_for(path, fleet_size)
    times = np.linspace(0.0, formation.duration(profile), 10_000)
    one = times[len(times) // 2 : len(times) // 2 + 1]
    window = recommended_window(10.0, 5.0, formation)
    positions = formation.positions(profile.distance(times[::10]))
    corners = path[1:-1] + 30.0
    obstacles = Obstacles(
        polygons=tuple(corner + [[0, 0], [20, 0], [20, 20], [0, 20]] for corner in corners)
    )
    stations = np.array([path[0], path[-1]])
    sampled = [
        ("V_n(t), batch", times, lambda: formation.positions(profile.distance(times))),
        ("V_n(t), one tick", one, lambda: formation.positions(profile.distance(one))),
        (
            "smoothed reference, batch",
            times,
            lambda: smoothed_reference(formation, profile, times, window),
        ),
        (
            "smoothed reference, one tick",
            one,
            lambda: smoothed_reference(formation, profile, one, window),
        ),
        (
            "check_positions",
            positions,
            lambda: check_positions(positions, obstacles, stations, RADIO_RANGE),
        ),
    ]
    for name, samples, run in sampled:
        seconds = best_of(run)
        rate = len(samples) * fleet_size / seconds
        table.add_row(
            name,
            str(fleet_size),
            str(len(path)),
            str(len(samples)),
            f"{seconds * 1e3:.2f} ms",
            f"{rate:,.0f} UAV-samples/s",
        )
    for name, run in (
        ("safe_speed", lambda: safe_speed(formation, 5.0, 2.5)),
        ("recommended_window", lambda: recommended_window(10.0, 5.0, formation)),
        ("smoothing_error_bound", lambda: smoothing_error_bound(formation, profile, window)),
    ):
        seconds = best_of(run)
        table.add_row(name, str(fleet_size), str(len(path)), "-", f"{seconds * 1e3:.2f} ms", "-")


def main() -> None:
    profile = SpeedProfile.from_changes(10.0, [(60.0, 0.0), (75.0, 5.0), (200.0, 10.0)])
    table = Table(title="planner.kinematics / planner.guarantees (best of 3)")
    for column in ("case", "N", "K", "samples", "time", "rate"):
        table.add_column(column, justify="left" if column == "case" else "right")
    for fleet_size, bends in ((9, 10), (100, 60)):
        bench_fleet(table, fleet_size, bends, profile)
    Console(width=120).print(table)


if __name__ == "__main__":
    main()
