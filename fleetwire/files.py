"""Reading a file a user names, for every process of the project (the ground station's
mission and footprint files, the medium's calibration table): a regular file, of bounded size,
with bounded nesting, before any parser sees it.

A device (`/dev/zero`, `/dev/urandom`) would be read until memory runs out and a FIFO would
block forever: both are refused from `stat`, before the file is opened. A parser given text
nested tens of thousands of levels deep overflows (libyaml's C loader crashes the process,
Python's JSON parser raises RecursionError): `nesting_depth` measures the flow nesting of the
text first, vectorised, so that it is refused with one line.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

import numpy as np

from fleetline.errors import EXIT_BAD_INPUT, FleetlineError

#: A mission file (YAML): the largest real ones are a few hundred kB.
MISSION_BYTES = 16 * 2**20
#: A footprint file (GeoJSON): city extracts run to tens of MB.
FOOTPRINT_BYTES = 512 * 2**20
#: A calibration table (JSON written by `gcs eval calibrate`): kB.
CALIBRATION_BYTES = 16 * 2**20
#: Brackets nested deeper than this in a YAML or JSON file are refused (a GeoJSON polygon needs
#: 6 levels, a mission file fewer).
MAX_NESTING = 64

#: A YAML line indented (spaces, tabs and "- " sequence marks before its content) deeper than
#: this is refused: block nesting can be no deeper than twice that.
MAX_INDENT = 128
_LINE_START = re.compile(r"^([ \t]*(?:-[ \t]+)*)", re.MULTILINE)

_OPEN = np.frombuffer(b"[{", dtype=np.uint8)
_CLOSE = np.frombuffer(b"]}", dtype=np.uint8)


class FileRefused(FleetlineError, ValueError):
    """The file is not what may be read; the message says what was expected and what it is."""

    exit_status = EXIT_BAD_INPUT


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _size(count: int) -> str:
    return f"{count / 2**20:.1f} MB" if count >= 2**20 else f"{count} bytes"


def read_bounded(path: str | Path, max_bytes: int) -> bytes:
    """The bytes of regular file `path`, at most `max_bytes` of them; `FileRefused` for
    anything else (`OSError` when it cannot be read at all)."""
    path = Path(path)
    mode = os.stat(path).st_mode
    if not stat.S_ISREG(mode):
        raise FileRefused(f"a regular file, got {_kind(mode)}")
    with open(path, "rb") as file:
        data = file.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise FileRefused(f"a file of at most {_size(max_bytes)}, got a larger one")
    return data


def nesting_depth(text: str | bytes) -> int:
    """The deepest nesting of `[` and `{` in `text` (brackets inside strings counted too: an
    upper bound, which is what a guard needs)."""
    data = text.encode("utf-8", "replace") if isinstance(text, str) else text
    codes = np.frombuffer(data, dtype=np.uint8)
    if codes.size == 0:
        return 0
    steps = np.isin(codes, _OPEN).astype(np.int32) - np.isin(codes, _CLOSE).astype(np.int32)
    return int(max(np.cumsum(steps).max(), 0))


def yaml_indent(text: str) -> int:
    """The deepest indentation of a YAML text's lines, "- " sequence marks included (each
    block level is indented further, or opens with a mark, than the one around it)."""
    return max((len(match.group(1)) for match in _LINE_START.finditer(text)), default=0)


def check_nesting(text: str, yaml: bool = False) -> None:
    """`FileRefused` for text nested deeper than a parser can take: brackets deeper than
    `MAX_NESTING`; for YAML also lines indented deeper than `MAX_INDENT`."""
    depth = nesting_depth(text)
    if depth > MAX_NESTING:
        raise FileRefused(f"brackets nested at most {MAX_NESTING} deep, got {depth}")
    if yaml and (indent := yaml_indent(text)) > MAX_INDENT:
        raise FileRefused(f"lines indented at most {MAX_INDENT} columns deep, got {indent}")


def read_text_bounded(path: str | Path, max_bytes: int, *, yaml: bool = False) -> str:
    """`read_bounded` decoded as UTF-8 (`UnicodeDecodeError` otherwise) and `check_nesting`ed
    (`FileRefused`)."""
    text = read_bounded(path, max_bytes).decode("utf-8")
    check_nesting(text, yaml)
    return text
