"""`gcs eval paper [--out DIR] [--network ns3]`: the paper's network evaluation in the fast mode
(`gcs.sim.eval`), its flights optionally replayed in ns-3 as well (`gcs.netsim.paper`).

Exit statuses (docs/cli.md): 0 every run completed with its fleet connected the whole
mission, 1 otherwise (the figures and the table are written either way), 2 bad input (or
`--network ns3` without the ns3 extra).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from gcs.cli.ns3_flags import add_ns3_options, ns3_loaded, ns3_options
from gcs.errors import EXIT_BAD_INPUT, InputError

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
        "data. Writes fig08..fig16 PNGs, table.md and results.json to --out. With --network "
        "ns3 every flight is also replayed in ns-3 (802.11b, AODV; the ns3 extra): an ns-3 "
        "column in the table, figs. 10-16 from ns-3 in DIR/ns3. Exit 0 every run completed "
        "and stayed connected, 1 otherwise, 2 bad input or ns-3 not installed.",
    )
    paper.add_argument("--out", type=Path, default=Path("eval"), metavar="DIR",
                       help="output folder (default ./eval)")  # fmt: skip
    paper.add_argument("--mission", type=Path, default=None, metavar="FILE",
                       help="scenario (default examples/table-ii.yaml, the paper's Table II)")  # fmt: skip
    paper.add_argument("--speeds", default="2,5,10", metavar="V,...",
                       help="fixed formation speeds, m/s (default 2,5,10)")  # fmt: skip
    paper.add_argument("--leaders", default="1,4,6,9", metavar="N,...",
                       help="leader positions of the varying-speed runs (default 1,4,6,9)")  # fmt: skip
    paper.add_argument("--network", choices=("medium", "ns3"), default="medium",
                       help="medium: our radio medium only (default); ns3: also replay every "
                       "flight in ns-3 (docs/netsim.md)")  # fmt: skip
    add_ns3_options(paper)
    paper.add_argument("--buildings", action=argparse.BooleanOptionalAction, default=True,
                       help="also fly the paper's formation and the line-of-sight one through a "
                       "radio that knows buildings (3GPP TR 38.901; default on)")  # fmt: skip
    paper.add_argument("--json", action="store_true", help="print results as one JSON object")
    paper.set_defaults(handler=paper_command)
    from gcs.cli import cmd_calibrate  # `gcs eval calibrate`: the live medium from ns-3

    cmd_calibrate.register(commands)
    from gcs.cli import cmd_study  # `gcs eval study` and `gcs eval study-report`

    cmd_study.register(commands)


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
    from gcs.sim.eval import (
        DEFAULT_MISSION,
        EvalPlan,
        buildings_runs,
        run_all,
        with_buildings,
        write_figures,
        write_results,
    )

    if args.mission is None:
        args.mission = DEFAULT_MISSION
    speeds = _numbers("--speeds", args.speeds, float)
    leaders = _numbers("--leaders", args.leaders, int)
    if not speeds and not leaders:
        raise InputError(None, "--speeds", "at least one speed or leader to fly")
    mission = load_mission(args.mission)  # bad file: exit 2 before anything flies
    if leaders:
        from gcs.planning import plan_mission

        planned = plan_mission(mission)
        size = planned.formation.fleet_size if planned.valid else None
        beyond = [n for n in leaders if size is not None and n > size]
        if beyond:
            raise InputError(
                None,
                "--leaders",
                f"UAV numbers in 1..{size} (the mission's fleet), got {beyond[0]}",
            )
    options = ns3_options(args) if args.network == "ns3" else None
    if options is not None:
        if not ns3_loaded():  # before anything flies: a missing extra is one line, exit 2
            return EXIT_BAD_INPUT
    output_folder(args.out, "--out")
    plan = EvalPlan(mission=args.mission, speeds=speeds, leaders=leaders)
    console = Console(stderr=args.json, highlight=False)
    began = time.perf_counter()
    progress = Console(stderr=True, highlight=False)
    runs = run_all(plan, progress=lambda label: progress.print(f"flying {label} ..."))
    through = []
    if args.buildings and len(mission.obstacles):
        through = buildings_runs(plan, progress=lambda label: progress.print(f"flying {label} ..."))
    files = write_figures(runs, args.out, mission)
    network = None
    if options is not None:
        from gcs.netsim import paper as ns3_paper

        replay_began = time.perf_counter()
        replayed = ns3_paper.replay_in_ns3(
            runs, mission, options, lambda label: progress.print(f"ns-3: {label} ...")
        )
        files += ns3_paper.write_figures(replayed, args.out / "ns3")
        network = ns3_paper.summary(replayed, mission, time.perf_counter() - replay_began)
        if through:  # the runs through buildings, with the same footprints in ns-3
            walled = ns3_paper.replay_in_ns3(
                through, with_buildings(mission), options,
                lambda label: progress.print(f"ns-3: {label} ..."),
            )  # fmt: skip
            network["runs"] |= ns3_paper.summary(walled, mission, 0.0)["runs"]
    metrics, rows = write_results(
        runs, args.out, time.perf_counter() - began, plan, network, through
    )
    ok = all(m["completed"] and m["connected_fraction"] == 1.0 for m in metrics)
    if args.json:
        print(json.dumps({"ok": ok, "out": str(args.out), "runs": metrics}, allow_nan=False))
    table = Table(title=f"paper evaluation ({time.perf_counter() - began:.0f} s)")
    columns = ("quantity", "paper", "ours", "ns-3") if network else ("quantity", "paper", "ours")
    for name in columns:
        table.add_column(name)
    for quantity, paper, ours, ns3, _ in rows:
        table.add_row(quantity, paper, ours, *((ns3,) if network else ()))
    console.print(table)
    if network is not None:
        wall = network["wall_s"]
        console.print(
            f"ns-3: import {wall['import']:.1f} s, build {wall['build']:.1f} s, run "
            f"{wall['run']:.1f} s for {len(runs)} flights"
        )
    console.print(f"{len(files)} figures, table.md and results.json in {args.out}")
    return 0 if ok else 1
