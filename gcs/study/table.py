"""The study's table: JSON lines, one row per run, appended and flushed as each run finishes.

An interrupted study leaves every finished row on disk (at worst a last line cut short, which
`read_rows` skips with a warning and `RowWriter` closes before appending), so the next
invocation resumes from `done_ids`. A run flown again (`--retry-failed`) appends a new row:
the last row of an id is the one that counts.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

#: The table's file name in the study's output folder.
TABLE = "runs.jsonl"


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of the table at `path` (none if it is missing), the last one of each id, in
    file order; lines that do not parse (a row cut short) are skipped with a warning."""
    if not path.exists():
        return []
    rows: dict[str, dict[str, Any]] = {}
    with path.open(encoding="utf-8") as lines:
        for number, line in enumerate(lines, 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                log.warning("%s: line %d is not a complete row (skipped)", path, number)
                continue
            if not isinstance(row, dict) or not isinstance(row.get("id"), str):
                log.warning("%s: line %d is not a row (skipped)", path, number)
                continue
            rows.pop(row["id"], None)
            rows[row["id"]] = row
    return list(rows.values())


def done_ids(rows: Iterable[dict[str, Any]], retry_failed: bool = False) -> set[str]:
    """Ids of the runs not to fly again: every row's, or with `retry_failed` the succeeded."""
    return {row["id"] for row in rows if not (retry_failed and row.get("error"))}


class RowWriter:
    """Appends rows to the table, one JSON line each, flushed (and synced) at once."""

    def __init__(self, path: Path, sync: bool = True) -> None:
        self.path = path
        self.sync = sync
        self._file = path.open("a+b")
        self._file.seek(0, os.SEEK_END)
        if self._file.tell():  # a row cut short by an interruption: end its line first
            self._file.seek(-1, os.SEEK_END)
            if self._file.read(1) != b"\n":
                self._file.write(b"\n")

    def append(self, row: dict[str, Any]) -> None:
        line = json.dumps(row, allow_nan=False, separators=(",", ":"), default=str)
        self._file.write(line.encode() + b"\n")
        self._file.flush()
        if self.sync:
            os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> RowWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
