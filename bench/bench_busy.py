"""A busy machine: the paper's scenario (examples/table-ii.yaml, 9 simulated UAVs in one
process, with the radio medium) flown at 5x beside 0 to 3 CPU hogs (`python3 -c "while True:
pass"`), in lockstep (the default) and on the wall clock (`--no-lockstep`), and with the
vehicle process stopped (SIGSTOP) for 2 s of wall time 20 s into the flight: outcome, largest
tracking error, time the hold policy held the formation, mission time lockstep held the clock
back for the world, wall time. `python -m bench busy` (about 20 minutes)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

MISSION = Path(__file__).resolve().parents[1] / "examples" / "table-ii.yaml"
SPEEDUP = 5.0
#: (CPU hogs, lockstep, seconds the vehicle process is stopped)
CASES = (
    (0, True, 0.0), (1, True, 0.0), (2, True, 0.0), (3, True, 0.0),
    (2, False, 0.0), (3, False, 0.0), (2, True, 2.0), (2, False, 2.0),
)  # fmt: skip
STOP_AFTER_S = 20.0  # wall seconds after the start: cruising
HOG = "while True: pass"


def vehicle_processes(parent: int) -> list[int]:
    """The `vehicles sim` children of process `parent` (from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == parent and "vehicles sim" in command:
            found.append(int(entry.name))
    return found


def fly(hogs: int, lockstep: bool, stop_s: float, folder: Path) -> dict:
    """One flight beside `hogs` CPU hogs, its vehicle process stopped `stop_s` (wall) once;
    the run JSON plus its wall time."""
    busy = [subprocess.Popen([sys.executable, "-c", HOG]) for _ in range(hogs)]
    log = folder / f"busy-{hogs}-{int(lockstep)}.mcap"
    command = [
        sys.executable, "-m", "gcs", "mission", "run", str(MISSION),
        "--speedup", f"{SPEEDUP:g}", "--vehicles-per-process", "9",
        "--json", "--log", str(log), "--force",
    ]  # fmt: skip
    if not lockstep:
        command.append("--no-lockstep")
    try:
        began = time.monotonic()
        flight = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        if stop_s > 0:
            time.sleep(STOP_AFTER_S)  # the stimulus' timing, then the fault itself
            for pid in vehicle_processes(flight.pid):
                os.kill(pid, signal.SIGSTOP)
            time.sleep(stop_s)
            for pid in vehicle_processes(flight.pid):
                os.kill(pid, signal.SIGCONT)
        out, _ = flight.communicate(timeout=1200)
        wall = time.monotonic() - began
    finally:
        for hog in busy:
            hog.kill()
            hog.wait()
    run = json.loads(out) if out.strip() else {}
    return {**run, "exit": flight.returncode, "wall_s": wall}


def row(hogs: int, lockstep: bool, stop_s: float, run: dict) -> list[str]:
    holds = run.get("holds", [])
    held = sum(h["duration_s"] or 0.0 for h in holds)
    world = run.get("lockstep", {})
    outcome = "completed" if run.get("completed") else f"exit {run['exit']}: {run.get('reason')}"
    outcome = outcome.replace(" (the guarantees no longer hold)", "")
    error = run.get("max_tracking_error_m")
    return [
        str(hogs),
        "lockstep" if lockstep else "wall clock",
        f"{stop_s:g} s" if stop_s else "-",
        outcome,
        "n/a" if error is None else f"{error:.2f}",
        f"{len(holds)} / {held:.1f} s",
        f"{world.get('held_s', 0.0):.1f} s" if world.get("enabled") else "-",
        str(len(run.get("stalls", []))),
        f"{run['wall_s']:.0f} s",
    ]


def main(cases=CASES) -> None:
    table = Table(title=f"Table II at {SPEEDUP:g}x beside CPU hogs (rho_c 5 m)")
    for name in (
        "hogs", "clock", "vehicles stopped", "outcome", "max tracking (m)", "holds / held", "lockstep held",
        "stalls", "wall",
    ):  # fmt: skip
        table.add_column(name)
    with tempfile.TemporaryDirectory() as folder:
        for hogs, lockstep, stop_s in cases:
            run = fly(hogs, lockstep, stop_s, Path(folder))
            table.add_row(*row(hogs, lockstep, stop_s, run))
    Console(width=200).print(table)


if __name__ == "__main__":
    main()
