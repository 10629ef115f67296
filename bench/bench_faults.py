"""The faults of issue 32, flown again (`python -m bench faults`, about 12 minutes): the small
mission (examples/small.yaml, 4 UAVs, rho_c 5 m) with real `gcs` and `vehicles` processes
over loopback UDP, one fault per flight, on the wall clock (`--no-lockstep`, as with real
autopilots) unless said. Columns: the outcome (exit status, completed or the reason), the
largest tracking error, where the UAVs ended (landed, and how far from their goal slots at
most), and the state of the log. A last row flips one byte of a recording and asks
`gcs log info`.

A second table flies the same mission in the fast mode over a lossy network, every packet
each way lost with a probability (`Faults.link_loss`), one flight per seed: how many complete
within rho_c, the worst tracking error the ground station measured and the true one, and the
holds. A third cuts one UAV's link both ways for 2.5 s and 3.5 s at moments from take-off to
the speed changes (`Faults.link_cuts`): the cut UAV flies its last setpoint on alone."""

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

from tests.flying import (
    MISSION,
    Flight,
    children_running,
    environment,
    mission_file,
    udp_ports,
)

LOSSY_SEEDS = {0.3: 40, 0.4: 20}  # loss probability -> seeds flown
#: Link cuts flown by `link_cuts`: cut lengths (s), the UAVs cut, and the cut starts (mission
#: s: taking off, the start, joining, cruising, the speed changes at 20 s and 35 s).
CUT_LENGTHS = (2.5, 3.5)
CUT_UAVS = (1, 2, 3, 4)
CUT_STARTS = (-1.0, -0.6, -0.2, 0.2, 0.4, 0.6, 1.0, 2.0, 5.0, 19.6, 20.0, 20.4, 34.6, 35.0, 40.0)

FOLLOWING = "UAV 4: taking_off -> following"


def _stop(pid: int, seconds: float) -> None:
    os.kill(pid, signal.SIGSTOP)
    time.sleep(seconds)  # the fault itself
    os.kill(pid, signal.SIGCONT)


def _gcs_stopped(seconds: float):
    return lambda flight, folder: _stop(flight.pid, seconds)


def _vehicles_stopped(seconds: float):
    def fault(flight, folder):
        _stop(children_running(flight.pid, "vehicles sim")[-1], seconds)

    return fault


def _forged_land(flight, folder) -> None:
    """Unsigned LAND heartbeats, positions 200 m off and NaN from each UAV's system id, to
    every ground-station port (what an attacker on the host or the network sends)."""
    subprocess.run(
        [sys.executable, "-m", "tests.attacker", "--vehicles", "",
         "--gcs", ",".join(map(str, udp_ports(flight.pid))), "--rounds", "40",
         "--period", "0.05", "--sniff", str(folder / "f.mcap")],
        capture_output=True, env=environment(), timeout=60, check=True,
    )  # fmt: skip


#: (name, speed-up, extra flags, fault applied once every UAV follows, or None)
CASES = (
    ("the log on a full disk (/dev/full)", 2.0, ("--full-disk",), None),
    ("forged LAND heartbeats at the GCS ports (--insecure)", 2.0, ("--insecure",), _forged_land),
    ("gcs stopped 3 s, 2x", 2.0, (), _gcs_stopped(3.0)),
    ("gcs stopped 3 s, 1x", 1.0, (), _gcs_stopped(3.0)),
    ("gcs stopped 1 s, 1x", 1.0, (), _gcs_stopped(1.0)),
    ("a vehicle process stopped 2 s, 2x", 2.0, (), _vehicles_stopped(2.0)),
    ("a vehicle process stopped 6 s, 2x", 2.0, (), _vehicles_stopped(6.0)),
    ("a vehicle process stopped 6 s, 2x, --link-wait 30", 2.0, ("--link-wait", "30"),
     _vehicles_stopped(6.0)),
)  # fmt: skip


def fly(folder: Path, speedup: float, extra: tuple[str, ...], fault) -> dict:
    mission = mission_file(folder)
    log = folder / "f.mcap"
    log.unlink(missing_ok=True)
    if "--full-disk" in extra:
        log.symlink_to("/dev/full")
        extra = tuple(e for e in extra if e != "--full-disk")
    flight = Flight(
        ["-v", "mission", "run", str(mission), "--speedup", f"{speedup:g}", "--no-lockstep",
         "--vehicles-per-process", "4", "--json", "--force", "--log", str(log), *extra],
        folder,
    )  # fmt: skip
    try:
        if fault is not None:
            flight.wait_for(FOLLOWING, timeout=120)
            fault(flight, folder)
        code, out, err = flight.finish(timeout=600)
    finally:
        flight.kill()
    run = json.loads(out) if out.strip() else {}
    return {**run, "exit": code, "log_path": log}


def row(name: str, run: dict) -> list[str]:
    outcome = "completed" if run.get("completed") else str(run.get("reason"))
    error = run.get("max_tracking_error_m")
    uavs = run.get("per_uav", [])
    landed = sum(u["phase"] == "landed" for u in uavs)
    off = max((u["landing_error_m"] or 0.0 for u in uavs), default=float("nan"))
    recording = run.get("recording", {})
    if recording.get("ok", True):
        log = "complete"
    else:
        log = f"stopped: {recording.get('error', '')[:40]}"
    return [
        name,
        str(run["exit"]),
        outcome[:70],
        "n/a" if error is None else f"{error:.2f}",
        f"{landed}/{len(uavs)} landed, {off:.2f} m from slots",
        log,
    ]


def flipped_byte(recording: Path) -> list[str]:
    data = bytearray(recording.read_bytes())
    data[len(data) // 2] ^= 0xFF
    damaged = recording.with_name("flipped.mcap")
    damaged.write_bytes(bytes(data))
    info = subprocess.run(
        [sys.executable, "-m", "gcs", "log", "info", str(damaged), "--json"],
        capture_output=True, text=True, env=environment(), timeout=60,
    )  # fmt: skip
    report = json.loads(info.stdout) if info.stdout.strip() else {}
    said = f"damaged: {report.get('damaged')}" if report else info.stderr.strip()[:60]
    return ["one byte flipped in a recording", str(info.returncode), said, "-", "-", "-"]


def lossy(seeds: dict[float, int] = LOSSY_SEEDS) -> Table:
    """The fast mode over a lossy network (see the module docstring)."""
    import numpy as np

    from gcs.mission import load_mission
    from gcs.planning import plan_mission
    from gcs.sim.fastsim import FastOptions, Faults, fly_fast

    plan = plan_mission(load_mission(MISSION))
    rho_c = plan.mission.safety_margin
    table = Table(title="the small mission over a lossy network (fast mode, one flight per seed)")
    for name in ("loss each way", "flights", "completed within rho_c", "worst measured m",
                 "worst true m", "true >= rho_c", "flights that held", "holds"):  # fmt: skip
        table.add_column(name)
    for loss, count in seeds.items():
        measured, true, held, holds, ok = [], [], 0, 0, 0
        for seed in range(count):
            run = fly_fast(plan, FastOptions(faults=Faults(link_loss=loss, link_loss_seed=seed)))
            result = run.run_json
            worst = float(np.nanmax(run.tracking_error_m))
            measured.append(result["max_tracking_error_m"])
            true.append(worst)
            held += bool(result["holds"])
            holds += len(result["holds"])
            ok += bool(result["completed"]) and worst < rho_c
        table.add_row(
            f"{loss:.0%}", str(count), str(ok), f"{max(measured):.2f}", f"{max(true):.2f}",
            str(sum(t >= rho_c for t in true)), str(held), str(holds),
        )  # fmt: skip
    return table


def link_cuts(
    lengths: tuple[float, ...] = CUT_LENGTHS,
    uavs: tuple[int, ...] = CUT_UAVS,
    starts: tuple[float, ...] = CUT_STARTS,
) -> Table:
    """The fast mode with one UAV's link cut both ways (`Faults.link_cuts`), one flight per
    (length, UAV, start): the cut UAV flies its last setpoint on alone, then brakes."""
    import numpy as np

    from gcs.mission import load_mission
    from gcs.planning import plan_mission
    from gcs.sim.fastsim import FastOptions, Faults, fly_fast

    plan = plan_mission(load_mission(MISSION))
    rho_c = plan.mission.safety_margin
    table = Table(title="the small mission with one UAV's link cut (fast mode)")
    for name in ("cut", "flights", "within rho_c", "worst true m", "mean worst m",
                 "flights that held", "link lost"):  # fmt: skip
        table.add_column(name)
    for length in lengths:
        worst, held, lost = [], 0, 0
        for uav in uavs:
            for start in starts:
                cut = Faults(link_cuts=((uav, start, start + length),))
                run = fly_fast(plan, FastOptions(faults=cut))
                worst.append(float(np.nanmax(run.tracking_error_m)))
                kinds = {event["kind"] for event in run.run_json["events"]}
                held += "hold" in kinds
                lost += "link_lost" in kinds
        table.add_row(
            f"{length:g} s", str(len(worst)), str(sum(w < rho_c for w in worst)),
            f"{max(worst):.2f}", f"{float(np.mean(worst)):.2f}", str(held), str(lost),
        )  # fmt: skip
    return table


def main(cases=CASES) -> None:
    table = Table(title="faults on the small mission (rho_c 5 m)")
    for name in ("fault", "exit", "outcome", "max tracking m", "UAVs", "log"):
        table.add_column(name)
    with tempfile.TemporaryDirectory() as folder:
        kept = None
        for name, speedup, extra, fault in cases:
            run = fly(Path(folder), speedup, extra, fault)
            table.add_row(*row(name, run))
            if run.get("recording", {}).get("ok", True) and run["log_path"].is_file():
                kept = run["log_path"].rename(Path(folder) / "kept.mcap")
        if kept is not None:
            table.add_row(*flipped_byte(kept))
    Console(width=220).print(table)
    Console(width=220).print(lossy())
    Console(width=220).print(link_cuts())


if __name__ == "__main__":
    main()
