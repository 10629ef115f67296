"""`gcs return [--at T]`: ask the running stations mission to fly its fleet home.

Over the same socket as `gcs speed` (`<log>.sock`; without `--socket` or `--log`, the newest
under `./logs/`). The mission stops the formation at the effective time (the earliest a
speed change may have, or `--at` if later), then every UAV flies its way out backwards to its
start slot and lands there. Exit statuses (docs/cli.md): 0 accepted (prints the effective
time), 1 refused (no stations, already returning, the fleet landing) or no mission running,
2 bad input.
"""

from __future__ import annotations

import argparse

from gcs.cli.cmd_speed import add_mission_arguments, ask, number


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `gcs return`."""
    parser = subparsers.add_parser(
        "return",
        help="ask the running stations mission to fly its fleet home",
        description=(
            "Ask the running stations mission (gcs mission run) to bring its fleet home: every "
            "UAV flies its way out backwards to its start slot and lands there. Exit 0 accepted, "
            "1 refused or no mission, 2 bad input."
        ),
    )
    parser.add_argument(
        "--at",
        type=str,
        metavar="T",
        help="mission time the return starts, s (default, or if sooner: the earliest)",
    )
    add_mission_arguments(parser)
    parser.set_defaults(handler=return_command)


def return_command(args: argparse.Namespace) -> int:
    request: dict = {"command": "return"}
    if args.at is not None:
        request["at"] = number(args.at, "--at")

    def accepted(answer: dict) -> str:
        return (
            f"return home at mission time {answer['effective_s']:.2f} s "
            f"(formation distance {answer['distance']:.1f} m)"
        )

    return ask(args, request, "return", accepted)
