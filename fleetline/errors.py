"""The root of fleetline's own errors, with the exit status a command ends with.

Every command line (`gcs`, `vehicles`, the radio medium) catches `FleetlineError`, prints
`str(error)` on one line to stderr and exits with `error.exit_status`: `EXIT_BAD_INPUT` (2)
for bad input (a mission file, a flag, a key file, a port in use), `EXIT_FAILED` (1) for a
request refused or a run that could not be done (docs/cli.md). Each package's errors subclass
it, keeping the built-in base callers catch (`ValueError`, `OSError`, ...).
"""

from __future__ import annotations

#: A command that could not do what was asked (a refusal, no path, a missing answer).
EXIT_FAILED = 1
#: Bad input: a mission file, a flag, a file the command reads (docs/cli.md).
EXIT_BAD_INPUT = 2


class FleetlineError(Exception):
    """Root of fleetline's own errors; `exit_status` is what a command exits with."""

    exit_status: int = EXIT_FAILED


class UsageError(FleetlineError):
    """A bad command line (argparse's complaint, or a flag's value), on one line."""

    exit_status = EXIT_BAD_INPUT
