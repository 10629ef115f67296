"""`gcs sitl launch-plan FILE --autopilot ardupilot|px4`: print the commands that start one SITL
instance per UAV (home on its parking slot, its system id, its ports) and the matching
`fleet.connections` (see `gcs.sim.sitl`). Exit 0; 1 when the mission has no valid path; 2 on bad
input.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from gcs.mission import load_mission
from gcs.sim.sitl import AUTOPILOTS, NoValidPath, launch_plan, render

EXIT_OK, EXIT_NO_PATH = 0, 1


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `gcs sitl` and its commands."""
    sitl = subparsers.add_parser(
        "sitl",
        help="fly ArduPilot or PX4 SITL fleets",
        description="Helpers for flying a mission with ArduPilot or PX4 SITL instances.",
    )
    commands = sitl.add_subparsers(dest="sitl_command", metavar="COMMAND", required=True)
    plan = commands.add_parser(
        "launch-plan",
        help="print the commands that start one SITL instance per UAV, and fleet.connections",
        description=(
            "Print one command per UAV that starts an ArduPilot or PX4 SITL instance with its "
            "home on the UAV's parking slot, its system id and its ports, then the "
            "fleet.connections to paste into the mission. Exit 0; 1 no valid path; 2 bad input."
        ),
    )
    plan.add_argument("file", type=Path, metavar="FILE", help="mission file (YAML)")
    plan.add_argument("--autopilot", required=True, choices=AUTOPILOTS, help="which SITL to start")
    plan.add_argument(
        "--speedup",
        type=float,
        default=1.0,
        metavar="K",
        help="run the simulators K times faster than real time (fly with `--speedup K`)",
    )
    plan.set_defaults(handler=launch_plan_command)


def launch_plan_command(args: argparse.Namespace) -> int:
    mission = load_mission(args.file)
    try:
        plan = launch_plan(mission, args.autopilot, args.speedup)
    except NoValidPath as reason:
        print(f"{args.file}: no valid path: {reason}", file=sys.stderr)
        return EXIT_NO_PATH
    sys.stdout.write(render(plan))
    return EXIT_OK
