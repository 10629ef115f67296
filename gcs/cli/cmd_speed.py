"""`gcs speed V [--at T]`: ask the running mission for a speed change, over its local socket.

The running `gcs mission run` listens on a Unix socket next to its log, `<log>.sock` (owner-only
permissions). Without `--socket` or `--log`, the newest socket under `./logs/` is used.
Exit statuses (CONTRACTS.md): 0 accepted (prints the sequence number and the effective time),
1 refused by the mission or no mission running, 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

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
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--socket", type=Path, metavar="PATH", help="the mission's socket")
    where.add_argument("--log", type=Path, metavar="LOG", help="the running mission's --log file")
    parser.add_argument("--json", action="store_true", help="print the mission's answer as JSON")
    parser.set_defaults(handler=speed_command)


def _number(text: str, flag: str, minimum: float | None = None) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or (minimum is not None and value < minimum):
        bound = f" >= {minimum:g}" if minimum is not None else ""
        raise InputError(None, flag, f"a finite number{bound}, got {text!r}")
    return value


def speed_command(args: argparse.Namespace) -> int:
    from gcs.speed import find_running_sockets, send_operator_request, socket_path_for

    speed = _number(args.speed, "V", 0.0)
    at = None if args.at is None else _number(args.at, "--at")
    if args.socket is not None:
        candidates = [args.socket]
    elif args.log is not None:
        candidates = [socket_path_for(args.log)]
    else:
        candidates = find_running_sockets(Path("logs"))
    if not candidates:
        print(
            "gcs speed: no running mission (no socket under ./logs; use --socket or --log)",
            file=sys.stderr,
        )
        return EXIT_REFUSED
    errors = []
    for path in candidates:
        try:
            answer = send_operator_request(path, speed, at)
        except (OSError, ValueError) as error:
            errors.append(f"{path}: {error}")
            continue
        if args.json:
            print(json.dumps(answer))
        if answer.get("ok"):
            print(
                f"speed change {answer['seq']}: {answer['speed']:g} m/s at mission time "
                f"{answer['effective_s']:.2f} s",
                file=sys.stderr if args.json else sys.stdout,
            )
            return EXIT_OK
        print(f"gcs speed: refused: {answer.get('reason')}", file=sys.stderr)
        return EXIT_REFUSED
    print(f"gcs speed: no running mission answered ({'; '.join(errors)})", file=sys.stderr)
    return EXIT_REFUSED
