"""Connectivity by line of sight (`python -m bench sight`, under a minute): for each example,
the fleet eq. 28 needs, the share of the disk plan's flight connected by line of sight, the
rigid line-of-sight fleet on the shortest path (its chord reach), and the line-of-sight plan
(`connectivity.rule: line_of_sight`): the clearance its corners were planned with, its
spacing and fleet; the path length and duration of both plans, and the planning time of both (best of 3, in seconds and in units
of the machine's reference time R, `bench/machine.py`). Table II is planned with `fleet.size:
auto` here (its file flies the paper's 9 UAVs, too few for line of sight)."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import yaml
from rich.console import Console
from rich.table import Table

from bench.machine import reference_seconds
from gcs.mission import load_mission
from gcs.planning import plan_mission

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


def _planned(path: Path, runs: int = 3):
    mission = load_mission(path)
    best, plan = float("inf"), None
    for _ in range(runs):
        began = time.perf_counter()
        plan = plan_mission(mission, cap_speed=True)
        best = min(best, time.perf_counter() - began)
    return plan, best


def main() -> None:
    unit = reference_seconds()
    table = Table(title=f"line of sight (R = {unit:.2f} s)")
    for column in (
        "mission", "eq. 28", "disk: LOS share", "rigid fleet (reach m)", "corners m",
        "spacing m", "LOS fleet", "path disk / LOS m", "duration disk / LOS s",
        "planning disk / LOS s", "in R", "LOS / disk",
    ):  # fmt: skip
        table.add_column(column, justify="left" if column == "mission" else "right")
    with tempfile.TemporaryDirectory() as folder:
        for name in MISSIONS:
            disk, disk_s = _planned(_variant(EXAMPLES / name, Path(folder), "disk"))
            sight, sight_s = _planned(_variant(EXAMPLES / name, Path(folder), "line_of_sight"))
            c, w = disk.connectivity, sight.connectivity
            table.add_row(
                name,
                str(c.eq28_fleet_size),
                f"{100 * c.los_connected_fraction:.1f} %",
                f"{c.rigid_los_fleet_size} ({c.los_reach_m:g})",
                f"{w.corner_margin_m:g}",
                f"{w.spacing_m:g}",
                str(sight.fleet_size),
                f"{disk.path_plan.length_m:.0f} / {sight.path_plan.length_m:.0f}",
                f"{disk.duration_s:.0f} / {sight.duration_s:.0f}",
                f"{disk_s:.3f} / {sight_s:.3f}",
                f"{disk_s / unit:.3f} / {sight_s / unit:.3f}",
                f"{sight_s / disk_s:.2f}",
            )
    Console(width=200).print(table)


if __name__ == "__main__":
    main()
