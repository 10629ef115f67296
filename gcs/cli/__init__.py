"""`gcs`: the ground-control station's command line (argparse).

Each command group lives in its own module `gcs/cli/cmd_<group>.py` exposing
`register(subparsers)`: it adds its parser(s) and sets `handler=func` on each leaf, where
`func(args) -> int` returns the exit status. Adding a group is one line in `GROUPS`.
Every group is imported at start-up (to build the parser), so a group module imports at its
top only what planning needs anyway (the mission, the planner, rich); the flight stack
(pymavlink, drivers, core), MCAP and matplotlib are imported inside the handlers that use
them (tests/gcs/test_startup.py checks `gcs mission plan` imports none of them).

Exit statuses (docs/cli.md): 0 success, 1 the command ran and failed (no valid path, mission
aborted...), 2 bad input. Bad input (`InputError`, argparse usage errors) is one line on
stderr, never a traceback; so is every other `fleetline.errors.FleetlineError` that ends a
command, with its own exit status.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys

from fleetline.errors import FleetlineError, UsageError

#: Command-group modules, each with `register(subparsers)`. Add a group here.
GROUPS: tuple[str, ...] = (
    "gcs.cli.cmd_mission",
    "gcs.cli.cmd_speed",
    "gcs.cli.cmd_return",
    "gcs.cli.cmd_relieve",
    "gcs.cli.cmd_log",
    "gcs.cli.cmd_sitl",
    "gcs.cli.cmd_eval",
)


class ArgumentParser(argparse.ArgumentParser):
    """argparse that raises `UsageError` (one line) instead of printing usage and exiting."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(f"{self.prog}: {message} (see {self.prog} --help)")


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="gcs",
        description="Connectivity-aware ground control for a fleet of UAVs.",
    )
    parser.add_argument(
        "-v", "--verbose", action="count", default=0, help="more log output (-vv: debug)"
    )
    groups = parser.add_subparsers(dest="group", metavar="COMMAND", required=True)
    for name in GROUPS:
        importlib.import_module(name).register(groups)
    return parser


#: Loggers whose warnings wait until the input is accepted: a refusal (exit 2) stays one line.
DEFERRED_LOGGERS = ("gcs.mission.footprints",)


class _Deferred(logging.Handler):
    """Holds the warnings of `DEFERRED_LOGGERS` until `print_held()`: a command calls it (as
    `args.release_warnings()`) once its input is accepted; `main` calls it when a command
    returns, and drops them on a refusal."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)

    def print_held(self) -> None:
        records, self.records = self.records, []
        for record in records:
            logging.getLogger().handle(record)


def main(argv: list[str] | None = None) -> int:
    """Parse `argv`, run the chosen command, return its exit status."""
    parser = build_parser()
    deferred = _Deferred()
    held = [logging.getLogger(name) for name in DEFERRED_LOGGERS]
    for logger in held:
        logger.addHandler(deferred)
        logger.propagate = False
    try:
        args = parser.parse_args(argv)
        level = (logging.WARNING, logging.INFO, logging.DEBUG)[min(args.verbose, 2)]
        logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
        args.release_warnings = deferred.print_held
        status = int(args.handler(args))
        deferred.print_held()
        return status
    except FleetlineError as exc:  # bad input (2) or a refusal (1): one line, no traceback
        print(exc, file=sys.stderr)
        return exc.exit_status
    except KeyboardInterrupt:
        print("gcs: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # stdout closed early (e.g. `gcs ... | head`): silence the flush at exit too.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1
    finally:
        for logger in held:
            logger.removeHandler(deferred)
            logger.propagate = True
