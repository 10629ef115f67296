"""Shared test helpers: repository paths and the `gcs` command, in-process or as a process."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
MISSIONS = REPO / "tests" / "missions"


@dataclass(frozen=True)
class Result:
    """Exit status and captured output of one `gcs` invocation."""

    returncode: int
    stdout: str
    stderr: str

    def __iter__(self):
        """`code, out, err = gcs_main(...)` unpacks like a tuple."""
        return iter((self.returncode, self.stdout, self.stderr))


@pytest.fixture
def gcs_main(capsys: pytest.CaptureFixture[str]) -> Callable[..., Result]:
    """Run `gcs ARGS...` in this process (fast); returns its exit status and output."""
    from gcs.cli import main

    def run(*args: str | Path) -> Result:
        capsys.readouterr()
        code = main([str(a) for a in args])
        out, err = capsys.readouterr()
        return Result(code, out, err)

    return run


@pytest.fixture
def gcs_process() -> Callable[..., Result]:
    """Run `gcs ARGS...` as a real subprocess (`python -m gcs`, the console script's code)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))

    def run(*args: str | Path, cwd: Path | None = None, timeout: float = 120) -> Result:
        done = subprocess.run(
            [sys.executable, "-m", "gcs", *map(str, args)],
            capture_output=True,
            text=True,
            cwd=cwd or REPO,
            env=env,
            timeout=timeout,
        )
        return Result(done.returncode, done.stdout, done.stderr)

    return run
