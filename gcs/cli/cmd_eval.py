"""`gcs eval paper [--out DIR]`: the paper's network evaluation in the fast mode (`gcs.sim.eval`).

Exit statuses (CONTRACTS.md): 0 every run completed with its fleet connected the whole
mission, 1 otherwise (the figures and the table are written either way), 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from gcs.errors import InputError

# The command's modules (matplotlib, the fast simulator) are imported when it runs, not when
# `gcs` starts: every other command would pay for them.


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `gcs eval paper`."""
    group = subparsers.add_parser(
        "eval",
        help="evaluations in the fast in-process mode",
        description="Evaluations flown in the fast in-process mode (same vehicles and radio "
        "medium as a networked run, lockstep, no sockets).",
    )
    commands = group.add_subparsers(dest="eval_command", metavar="COMMAND", required=True)
    paper = commands.add_parser(
        "paper",
        help="the paper's network evaluation (figs. 8-16 and a table next to its values)",
        description="Fly the paper's scenario at fixed speeds (2, 5, 10 m/s) and with a "
        "leader at UAV 1, 4, 6, 9 asking for speed changes; UAVs and ground users both send "
        "data. Writes fig08..fig16 PNGs, table.md and results.json to --out. Exit 0 every "
        "run completed and stayed connected, 1 otherwise, 2 bad input.",
    )
    paper.add_argument("--out", type=Path, default=Path("eval"), metavar="DIR",
                       help="output folder (default ./eval)")  # fmt: skip
    paper.add_argument("--mission", type=Path, default=None, metavar="FILE",
                       help="scenario (default examples/table-ii.yaml, the paper's Table II)")  # fmt: skip
    paper.add_argument("--speeds", default="2,5,10", metavar="V,...",
                       help="fixed formation speeds, m/s (default 2,5,10)")  # fmt: skip
    paper.add_argument("--leaders", default="1,4,6,9", metavar="N,...",
                       help="leader positions of the varying-speed runs (default 1,4,6,9)")  # fmt: skip
    paper.add_argument("--json", action="store_true", help="print results as one JSON object")
    paper.set_defaults(handler=paper_command)


def _numbers(flag: str, text: str, kind, positive: bool = True) -> tuple:
    try:
        values = tuple(kind(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise InputError(None, flag, f"comma-separated numbers, got {text!r}") from None
    if not all(math.isfinite(v) and (v > 0 or not positive) for v in values):
        raise InputError(None, flag, f"finite numbers > 0, got {text!r}")
    return values


def paper_command(args: argparse.Namespace) -> int:
    from gcs.cli.outputs import output_folder
    from gcs.mission import load_mission
    from gcs.sim.eval import DEFAULT_MISSION, EvalPlan, run_all, write_figures, write_results

    if args.mission is None:
        args.mission = DEFAULT_MISSION
    speeds = _numbers("--speeds", args.speeds, float)
    leaders = _numbers("--leaders", args.leaders, int)
    if not speeds and not leaders:
        raise InputError(None, "--speeds", "at least one speed or leader to fly")
    mission = load_mission(args.mission)  # bad file: exit 2 before anything flies
    output_folder(args.out, "--out")
    plan = EvalPlan(mission=args.mission, speeds=speeds, leaders=leaders)
    console = Console(stderr=args.json, highlight=False)
    began = time.perf_counter()
    progress = Console(stderr=True, highlight=False)
    runs = run_all(plan, progress=lambda label: progress.print(f"flying {label} ..."))
    files = write_figures(runs, args.out, mission)
    metrics, rows = write_results(runs, args.out, time.perf_counter() - began, plan)
    ok = all(m["completed"] and m["connected_fraction"] == 1.0 for m in metrics)
    if args.json:
        print(json.dumps({"ok": ok, "out": str(args.out), "runs": metrics}, allow_nan=False))
    table = Table(title=f"paper evaluation ({time.perf_counter() - began:.0f} s)")
    for name in ("quantity", "paper", "ours"):
        table.add_column(name)
    for quantity, paper, ours, _ in rows:
        table.add_row(quantity, paper, ours)
    console.print(table)
    console.print(f"{len(files)} figures, table.md and results.json in {args.out}")
    return 0 if ok else 1
