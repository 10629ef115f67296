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


#: Said by the fast tier's guard to a test that needs the `slow` mark.
NEEDS_SLOW = "starts a process or opens an IP socket: mark it @pytest.mark.slow (tests/conftest.py)"


@pytest.fixture(autouse=True)
def _fast_tier_guard(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """`make test-fast` (`-m "not slow"`) runs no process and opens no IP socket: a test that
    does so without the `slow` mark fails there, naming the mark it needs."""
    if "not slow" not in (request.config.option.markexpr or ""):
        return
    if request.node.get_closest_marker("slow") is not None:
        return
    import socket

    def no_process(self, *args, **kwargs):
        raise RuntimeError(f"{request.node.nodeid} {NEEDS_SLOW}")

    original = socket.socket.__init__

    def no_ip_socket(self, family=-1, *args, **kwargs):
        if family in (-1, socket.AF_INET, socket.AF_INET6):
            raise RuntimeError(f"{request.node.nodeid} {NEEDS_SLOW}")
        original(self, family, *args, **kwargs)

    monkeypatch.setattr(subprocess.Popen, "__init__", no_process)
    monkeypatch.setattr(socket.socket, "__init__", no_ip_socket)
