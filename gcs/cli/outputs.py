"""Where the commands write: files and folders the user names, refused on one line (exit 2)
before any work when the system will not take them."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path

from gcs.errors import InputError


def output_path(path: Path, flag: str, suffixes: tuple[str, ...]) -> Path:
    """Refuse, before planning, an output file path that cannot be written."""
    if path.suffix.lower() not in suffixes:
        raise InputError(None, flag, f"a file name ending in {' or '.join(suffixes)}, got {path}")
    if path.is_dir():
        raise InputError(None, flag, f"a file path, got the directory {path}")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(None, flag, f"a file in an existing directory, got {path}")
    return path


def output_folder(path: Path, flag: str) -> Path:
    """The output folder `path`, created if missing and proven writable (a file is made in it
    and removed), or one line naming `flag`."""
    if path.exists() and not path.is_dir():
        raise InputError(None, flag, f"a folder, got the file {path}")
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as error:
        raise InputError(None, flag, f"a folder we may write in, got {path} ({error})") from None
    return path


def write_output(path: Path, flag: str, write: Callable[[], object]) -> None:
    """Run `write` (which writes `path`); an error of the system is one line naming `flag`."""
    try:
        write()
    except OSError as exc:
        raise InputError(None, flag, f"a writable file, got {path} ({exc.strerror})") from None
