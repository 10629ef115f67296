"""`gcs speed V [--at T]`: ask the running mission for a speed change, over its local socket.

The running `gcs mission run` listens on a Unix socket next to its log, `<log>.sock` (owner-only
permissions). Without `--socket` or `--log`, the newest socket under `./logs/` is used.
Exit statuses (docs/cli.md): 0 accepted (prints the sequence number and the effective time),
1 refused by the mission or no mission running, 2 bad input. `add_mission_arguments`, `ask`,
`number` and `positive_int` are shared with `gcs return` and `gcs relieve`
(`gcs.cli.cmd_return`, `gcs.cli.cmd_relieve`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable

from gcs.errors import InputError

EXIT_OK, EXIT_REFUSED = 0, 1


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `gcs speed`."""
    parser = subparsers.add_parser(
        "speed",
        help="ask the running mission for a speed change",
        description=(
            "Ask the running mission (gcs mission run) for a formation speed change; it takes "
            "effect for every UAV at the same mission time. Exit 0 accepted, 1 refused, 2 bad input."
        ),
    )
    parser.add_argument("speed", type=str, metavar="V", help="new formation speed, m/s (0 stops)")
    parser.add_argument(
        "--at", type=str, metavar="T", help="effective mission time, s (default: the earliest)"
    )
    add_mission_arguments(parser)
    parser.set_defaults(handler=speed_command)


def add_mission_arguments(parser: argparse.ArgumentParser) -> None:
    """`--socket PATH | --log LOG` (which running mission) and `--json`."""
    from pathlib import Path

    where = parser.add_mutually_exclusive_group()
    where.add_argument("--socket", type=Path, metavar="PATH", help="the mission's socket")
    where.add_argument("--log", type=Path, metavar="LOG", help="the running mission's --log file")
    parser.add_argument("--json", action="store_true", help="print the mission's answer as JSON")


def number(text: str, flag: str, minimum: float | None = None) -> float:
    """A finite number (`minimum` or more) from a flag's text; bad input names `flag`."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or (minimum is not None and value < minimum):
        bound = f" >= {minimum:g}" if minimum is not None else ""
        raise InputError(None, flag, f"a finite number{bound}, got {text!r}")
    return value


def positive_int(text: str, flag: str) -> int:
    """A positive integer (e.g. a UAV id) from an argument's text; bad input names `flag`."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise InputError(None, flag, f"a positive integer, got {text!r}")
    return value


def ask(
    args: argparse.Namespace, request: dict, command: str, accepted: Callable[[dict], str]
) -> int:
    """Send `request` to the running mission (`--socket`, `--log` or the newest under
    ./logs), print its answer (`--json`: as JSON on stdout; `accepted(answer)` on success, the
    reason of a refusal on stderr), return the exit status."""
    from gcs.speed import NoMissionAnswered, ask_running_mission

    try:
        answer = ask_running_mission(request, socket_path=args.socket, log_path=args.log)
    except NoMissionAnswered as error:
        print(f"gcs {command}: {error}", file=sys.stderr)
        return EXIT_REFUSED
    if args.json:
        print(json.dumps(answer))
    if answer.get("ok"):
        print(accepted(answer), file=sys.stderr if args.json else sys.stdout)
        return EXIT_OK
    print(f"gcs {command}: refused: {answer.get('reason')}", file=sys.stderr)
    return EXIT_REFUSED


def speed_command(args: argparse.Namespace) -> int:
    speed = number(args.speed, "V", 0.0)
    at = None if args.at is None else number(args.at, "--at")
    request = {"speed": speed} if at is None else {"speed": speed, "at": at}

    def accepted(answer: dict) -> str:
        return (
            f"speed change {answer['seq']}: {answer['speed']:g} m/s at mission time "
            f"{answer['effective_s']:.2f} s"
        )

    return ask(args, request, "speed", accepted)
