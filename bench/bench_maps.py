"""City maps end to end (`make bench` / `python -m bench maps`): `gcs mission check --json`
as a user runs it, one process per map, timed from outside (wall) with its peak memory.

Maps: the examples in `examples/` (the Helsinki centre is real OpenStreetMap data) and every
`*.yaml` in the folders named by `FLEETLINE_BENCH_MAPS` (colon-separated), for maps whose
data may not be redistributed (BENCHMARKS.md names the public sources used).

Columns: wall and planner seconds, graph nodes, node pairs examined, expansions, the graph
the path came from, whether it is certified shortest (definition 4), its length and the
proven lower bound, and the peak resident memory of the process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ("helsinki-centre.yaml", "city-blocks.yaml", "table-ii.yaml", "small.yaml")
#: A trivial map, for the start-up time (written to a temporary folder).
TRIVIAL = """version: 1
name: trivial
origin: {lat: 45.764, lon: 4.8357, alt: 170.0}
start: {x: 0, y: 0, theta_deg: 0}
goal: {x: 300, y: 100, theta_deg: 0}
safety_margin: 5
radio_range: 120
altitude: 20
speed: {max: 5}
fleet: {size: auto, backend: sim}
vehicle: {max_speed: 12, max_acceleration: 8, radius: 0.5}
"""


def run_check(mission: Path, time_limit: float = 60.0) -> tuple[dict | None, float, float, int]:
    """(plan JSON or None, wall seconds, peak RSS MB, exit status) of one check."""
    command = [sys.executable, "-m", "gcs", "mission", "check", str(mission), "--json"]
    command += ["--time-limit", f"{time_limit:g}"]
    began = time.perf_counter()
    child = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, cwd=ROOT, text=True
    )
    out = child.stdout.read()
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - began
    child.returncode = os.waitstatus_to_exitcode(status)
    try:
        plan = json.loads(out)
    except json.JSONDecodeError:
        plan = None
    return plan, wall, usage.ru_maxrss / 1024.0, child.returncode


def _certified(plan: dict) -> str:
    """yes (proven shortest), within --gap (proven within the gap tolerance), stopped (the
    time limit), or no."""
    if plan.get("certified"):
        return "yes"
    if plan.get("stopped"):
        return "stopped"
    gap, tolerance = plan.get("gap_m"), plan.get("gap_tolerance") or 0.0
    if gap is not None and gap <= tolerance * plan["length_m"]:
        return "within --gap"
    return "no"


def missions(tmp: Path) -> list[Path]:
    found = [ROOT / "examples" / name for name in EXAMPLES]
    trivial = tmp / "trivial.yaml"
    trivial.write_text(TRIVIAL)
    found.insert(0, trivial)
    for folder in filter(None, os.environ.get("FLEETLINE_BENCH_MAPS", "").split(":")):
        found += sorted(Path(folder).glob("*.yaml"))
    return found


def main() -> None:
    import tempfile

    table = Table(title="city maps: gcs mission check, one process each (wall = what a user waits)")
    columns = ["map", "wall s", "planner s", "nodes", "examined", "expansions", "graph"]
    columns += ["certified", "length m", "lower bound m", "peak MB", "exit"]
    for column in columns:
        table.add_column(column, justify="left" if column in ("map", "graph") else "right")
    with tempfile.TemporaryDirectory() as tmp:
        for mission in missions(Path(tmp)):
            plan, wall, peak, status = run_check(mission)
            if plan is None:
                table.add_row(mission.name, f"{wall:.2f}", *["-"] * 8, f"{peak:.0f}", str(status))
                continue
            length = plan["length_m"]
            bound = plan.get("lower_bound_m")
            table.add_row(
                mission.name,
                f"{wall:.2f}",
                f"{plan['planning_time_s']:.2f}",
                f"{plan['node_count']:,}",
                f"{plan['edges_examined']:,}",
                f"{plan['expansions']:,}",
                plan.get("graph") or "-",
                _certified(plan),
                f"{length:.1f}" if length is not None else "no path",
                f"{bound:.1f}" if bound is not None else "-",
                f"{peak:.0f}",
                str(status),
            )
    console = Console()
    console.width = max(console.width, 170)
    console.print(table)


if __name__ == "__main__":
    main()
