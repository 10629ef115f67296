"""`gcs relieve N`: ask the running stations mission to send UAV N home alone.

Over the same socket as `gcs speed` (`<log>.sock`; without `--socket` or `--log`, the newest
under `./logs/`). UAV N climbs above the chain, flies home above the route and lands on a
start-row slot, while the UAVs left close the gap. Exit statuses (docs/cli.md): 0 accepted
(prints the effective time and the landing slot), 1 refused or no mission running, 2 bad input.
"""

from __future__ import annotations

import argparse

from gcs.cli.cmd_speed import add_mission_arguments, ask, positive_int


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `gcs relieve`."""
    parser = subparsers.add_parser(
        "relieve",
        help="ask the running stations mission to send one UAV home",
        description=(
            "Ask the running stations mission (gcs mission run) to relieve UAV N: it flies home "
            "above the chain and lands while the others close the gap. Exit 0 accepted, "
            "1 refused or no mission, 2 bad input."
        ),
    )
    parser.add_argument("uav", type=str, metavar="N", help="the UAV to relieve (its id, 1..)")
    add_mission_arguments(parser)
    parser.set_defaults(handler=relieve_command)


def relieve_command(args: argparse.Namespace) -> int:
    request = {"command": "relieve", "uav": positive_int(args.uav, "N")}

    def accepted(answer: dict) -> str:
        x, y = answer["landing_xy"]
        return (
            f"UAV {answer['uav']} relieved at mission time {answer['effective_s']:.2f} s: it "
            f"flies home above the chain and lands at ({x:.1f}, {y:.1f})"
        )

    return ask(args, request, "relieve", accepted)
