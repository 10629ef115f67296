"""Connectivity by line of sight (`python -m bench sight`, about two minutes): for each example,
the fleet eq. 28 needs, the share of the disk plan's flight connected by line of sight, the
rigid line-of-sight fleet on the shortest path (its chord reach) and the elastic one, and the
line-of-sight plan (`connectivity.rule: line_of_sight`): the clearance its corners were
planned with, its spacing (rigid or elastic, dS) and fleet; the path length and duration of both plans, and the planning time of both (best of 3, in seconds and in units
of the machine's reference time R, `bench/machine.py`). Table II is planned with `fleet.size:
auto` here. Then the small mission and city-blocks, each plan flown in the fast mode through a
medium that knows the buildings (`radio.buildings`: 3gpp-umi and cut): the share connected."""

from __future__ import annotations

import os
import re
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from rich.console import Console
from rich.table import Table

from bench.machine import reference_seconds
from gcs.errors import InputError
from gcs.mission import load_mission
from gcs.planning import plan_mission
from planner.formation import radio_spacing
from planner.sight import Sight

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
MISSIONS = ("small.yaml", "table-ii.yaml", "city-blocks.yaml", "helsinki-centre.yaml")


def _variant(source: Path, folder: Path, rule: str) -> Path:
    data = yaml.safe_load(source.read_text())
    data["connectivity"] = {"rule": rule}
    data.setdefault("fleet", {})["size"] = "auto"
    path = folder / f"{rule}-{source.name}"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    for footprints in source.parent.glob("*.geojson"):
        (folder / footprints.name).write_bytes(footprints.read_bytes())
    return path


def chain_estimate(formation, sight: Sight, limit: float, step: float = 2.0) -> int:
    """The fewest hops of a chain along the formation's path from A to B, each a clear chord
    (margin 0) at most `limit` long between path points `step` apart: what an elastic
    formation (or relays) would need at the instant its chain spans the whole path, dynamics
    ignored (the greedy-chain estimate of docs/design.md 10, made exact on the samples by a shortest
    path). Comparable to eq. 28's ceil(length / spacing)."""
    points = formation.path
    arcs = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])
    grid = np.append(np.arange(0.0, arcs[-1], step), arcs[-1])
    samples = np.column_stack([np.interp(grid, arcs, points[:, k]) for k in (0, 1)])
    count, gaps = len(samples), int(np.ceil(limit / step)) + 1
    hops = np.full(count, np.inf)
    hops[0] = 0.0
    for j in range(1, count):
        i = np.arange(max(0, j - gaps), j)
        ends = np.repeat(samples[j][None], len(i), axis=0)
        ok = (np.hypot(*(ends - samples[i]).T) <= limit) & sight.clear(samples[i], ends)
        if ok.any():
            hops[j] = hops[i[ok]].min() + 1
    return int(hops[-1]) if np.isfinite(hops[-1]) else -1


def _planned(path: Path, runs: int = 3):
    mission = load_mission(path)
    best, plan = float("inf"), None
    for _ in range(runs):
        began = time.perf_counter()
        plan = plan_mission(mission, cap_speed=True)
        best = min(best, time.perf_counter() - began)
    return plan, best


#: City maps of `bench maps` (FLEETLINE_BENCH_MAPS=OUT, written by `bench.city_maps`) whose
#: routes are under 2 km: planned under both rules as well, best of one.
CITY_ROUTES = (
    "mumbai-960m-1", "vienna-1.5km-1", "vienna-1.5km-2", "betshemesh-1.1km-1",
    "betshemesh-2km-1", "betshemesh-2km-2", "betshemesh-2km-3", "betshemesh-2km-4",
    "betshemesh-2km-heights", "terraced-1.3km",
)  # fmt: skip


def _sources() -> list[tuple[Path, int]]:
    """The missions planned: the examples (best of 3), then the city maps if written."""
    sources = [(EXAMPLES / name, 3) for name in MISSIONS]
    for folder in filter(None, os.environ.get("FLEETLINE_BENCH_MAPS", "").split(":")):
        routes = (Path(folder) / f"{name}.yaml" for name in CITY_ROUTES)
        sources += [(route, 1) for route in routes if route.exists()]
    return sources


def main() -> None:
    unit = reference_seconds()
    table = Table(title=f"line of sight (R = {unit:.2f} s)")
    for column in (
        "mission", "eq. 28", "disk: LOS share", "shortest path: rigid (reach m) / elastic",
        "corners m", "spacing", "LOS fleet", "chain: shortest / LOS path", "path disk / LOS m", "duration disk / LOS s",
        "planning disk / LOS s", "in R", "LOS / disk",
    ):  # fmt: skip
        table.add_column(column, justify="left" if column == "mission" else "right")
    with tempfile.TemporaryDirectory() as folder:
        for source, runs in _sources():
            name = source.name
            disk, disk_s = _planned(_variant(source, Path(folder), "disk"), runs)
            c = disk.connectivity
            try:
                sight, sight_s = _planned(_variant(source, Path(folder), "line_of_sight"), runs)
            except InputError as refused:
                table.add_row(
                    name, str(c.eq28_fleet_size), f"{100 * c.los_connected_fraction:.1f} %",
                    f"{c.rigid_los_fleet_size} ({c.los_reach_m:g}) / {c.elastic_los_fleet_size}",
                    "", "", _refusal(str(refused)), "", f"{disk.path_plan.length_m:.0f} / -",
                    f"{disk.duration_s:.0f} / -", f"{disk_s:.3f} / -", f"{disk_s / unit:.3f} / -",
                    "",
                )  # fmt: skip
                continue
            w = sight.connectivity
            limit = radio_spacing(disk.mission.safety_margin, disk.mission.radio_range)
            table.add_row(
                name,
                str(c.eq28_fleet_size),
                f"{100 * c.los_connected_fraction:.1f} %",
                f"{c.rigid_los_fleet_size} ({c.los_reach_m:g}) / {c.elastic_los_fleet_size}",
                f"{w.corner_margin_m:g}",
                f"{w.spacing} {w.spacing_m:g} m",
                str(sight.fleet_size),
                " / ".join(
                    str(chain_estimate(p.formation, Sight(p.mission.obstacles), limit))
                    for p in (disk, sight)
                ),
                f"{disk.path_plan.length_m:.0f} / {sight.path_plan.length_m:.0f}",
                f"{disk.duration_s:.0f} / {sight.duration_s:.0f}",
                f"{disk_s:.3f} / {sight_s:.3f}",
                f"{disk_s / unit:.3f} / {sight_s / unit:.3f}",
                f"{sight_s / disk_s:.2f}",
            )
    Console(width=200).print(table)
    Console(width=200).print(_flights())


def _refusal(message: str) -> str:
    """A line-of-sight refusal in a few words: the fleet it needed and what stopped it."""
    match = re.search(r"it needs (\d+) UAVs", message)
    why = "parking row" if "parking row" in message else "chords"
    return f"refused ({match.group(1)} UAVs: {why})" if match else f"refused ({why})"


#: The missions flown through a radio that knows buildings (fast mode), and the models.
FLOWN = ("small.yaml", "city-blocks.yaml")
BUILDING_MODELS = ("3gpp-umi", "cut")


def _flights() -> Table:
    """Each mission's disk plan and line-of-sight plan flown in the fast mode through a medium
    that knows the buildings, under each model: the share of the medium's samples connected,
    the outcome."""
    from dataclasses import replace

    from gcs.sim.fastsim import FastOptions, fly_fast

    table = Table(title="flown through buildings (fast mode)")
    for column in (
        "mission", "model", "plan", "UAVs", "connected", "by line of sight", "duration s",
        "worst tracking m", "outcome",
    ):  # fmt: skip
        table.add_column(column, justify="left" if column in ("mission", "outcome") else "right")
    with tempfile.TemporaryDirectory() as folder:
        for name in FLOWN:
            for model in BUILDING_MODELS:
                for rule in ("disk", "line_of_sight"):
                    mission = load_mission(_variant(EXAMPLES / name, Path(folder), rule))
                    radio = replace(mission.radio, enabled=True, buildings=model)
                    plan = plan_mission(replace(mission, radio=radio), cap_speed=True)
                    run = fly_fast(plan, FastOptions()).run_json
                    table.add_row(
                        name, model, rule, str(run["fleet_size"]),
                        f"{100 * run['radio']['connected_fraction']:.1f} %",
                        f"{100 * run['los_connected_fraction']:.1f} %",
                        f"{run['duration_s']:.0f}", f"{run['max_tracking_error_m']:.2f}",
                        "completed" if run["completed"] else str(run["reason"])[:60],
                    )  # fmt: skip
    return table


if __name__ == "__main__":
    main()
