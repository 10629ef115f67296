"""Bad-input errors: one line naming the file, the key (or flag) and what is expected.

Every refusal of a mission file or of a command-line value raises `InputError`; the CLI
prints `str(error)` on one line to stderr and exits with status 2 (docs/cli.md).
"""

from __future__ import annotations

from pathlib import Path

from fleetline.errors import EXIT_BAD_INPUT, FleetlineError

__all__ = ["EXIT_BAD_INPUT", "InputError", "RowsRefused", "join_key"]


class InputError(FleetlineError):
    """A refused input: `FILE: KEY.PATH: expected ...` on one line.

    `file` may be None (a command-line flag), `key_path` may be empty (the whole file).
    Key paths use 0-based indexes, e.g. `obstacles[3].rectangle.size`.
    """

    exit_status = EXIT_BAD_INPUT

    def __init__(self, file: str | Path | None, key_path: str, expected: str) -> None:
        self.file = None if file is None else str(file)
        self.key_path = key_path
        self.expected = " ".join(str(expected).split())  # never more than one line
        super().__init__(self.message)

    @property
    def message(self) -> str:
        parts = [" ".join(p.split()) for p in (self.file, self.key_path) if p]
        return ": ".join([*parts, f"expected {self.expected}"])

    def __str__(self) -> str:
        return self.message


class RowsRefused(InputError):
    """A parking row refused (eqs. 14-15) for rows sized for `fleet_size` UAVs."""

    def __init__(self, file: str | Path | None, key_path: str, expected: str, fleet_size: int):
        super().__init__(file, key_path, expected)
        self.fleet_size = fleet_size


def join_key(parent: str, key: str | int) -> str:
    """Extend a key path: `join_key("obstacles", 3)` -> `obstacles[3]`, then `.rectangle`."""
    if isinstance(key, int):
        return f"{parent}[{key}]"
    return f"{parent}.{key}" if parent else str(key)
