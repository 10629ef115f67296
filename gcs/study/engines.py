"""Where a study's runs execute: in this process, one after the other, or as Ray tasks (the
`study` extra) on the local machine's cores or on a Ray cluster.

Both engines take the runs to fly and call `on_row(row)` in this process as each run
finishes, in the order they finish; the caller appends the row to the table at once.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from gcs.errors import InputError
from gcs.study.runs import execute_run, failed_row
from gcs.study.studyfile import RunSpec, Study

log = logging.getLogger(__name__)

#: The note (stderr) when Ray is missing and the study runs in this process instead.
RAY_MISSING = (
    "ray is not installed (pip install 'fleetline[study]'): running the study in this process"
)
ENGINES = ("auto", "ray", "process")

OnRow = Callable[[dict[str, Any]], None]


class Engine(Protocol):
    """Runs specs of a study; calls `on_row` in the caller's process as each finishes."""

    @property
    def description(self) -> str: ...

    def run(self, study: Study, specs: Sequence[RunSpec], on_row: OnRow) -> None: ...


@dataclass(frozen=True)
class InProcessEngine:
    """Every run in this process, in study order."""

    @property
    def description(self) -> str:
        return "in this process"

    def run(self, study: Study, specs: Sequence[RunSpec], on_row: OnRow) -> None:
        for spec in specs:
            on_row(execute_run(study, spec))


@dataclass(frozen=True)
class RayEngine:
    """Each run a Ray task (one CPU each).

    `address` None starts a local Ray instance of `workers` CPUs (all cores by default) and
    stops it when the study ends; an address (`auto`, `ray://host:10001`, `host:6379`)
    connects to a running cluster, where `workers`, if given, caps the tasks in flight. At
    most `in_flight` tasks (default four per worker) are submitted ahead of the finished ones,
    so a study of any size keeps a bounded queue."""

    address: str | None = None
    workers: int | None = None
    in_flight: int | None = None

    @property
    def description(self) -> str:
        where = f"the Ray cluster at {self.address}" if self.address else "local Ray"
        count = self.workers or (None if self.address else os.cpu_count())
        return f"{where}" + (f", {count} workers" if count else "")

    def run(self, study: Study, specs: Sequence[RunSpec], on_row: OnRow) -> None:
        import ray

        started = not ray.is_initialized()
        if started:
            local = self.address is None
            ray.init(
                address=self.address,
                num_cpus=(self.workers or os.cpu_count()) if local else None,
                include_dashboard=False if local else None,
                log_to_driver=False,
                logging_level=logging.ERROR,  # a failed run is a row; Ray's notices are noise
            )
        try:
            self._run(ray, study, specs, on_row)
        finally:
            if started:
                ray.shutdown()

    def _run(self, ray, study: Study, specs: Sequence[RunSpec], on_row: OnRow) -> None:
        task = ray.remote(num_cpus=1, max_retries=1)(execute_run)
        study_ref = ray.put(study)
        cpus = int(ray.cluster_resources().get("CPU", 1))
        limit = self.in_flight or 4 * max(1, min(cpus, self.workers or cpus))
        if self.address is not None and self.workers:
            limit = min(limit, self.workers)
        queue = iter(specs)
        pending: dict[Any, RunSpec] = {}

        def submit() -> None:
            spec = next(queue, None)
            if spec is not None:
                pending[task.remote(study_ref, spec)] = spec

        for _ in range(limit):
            submit()
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                spec = pending.pop(ref)
                try:
                    row = ray.get(ref)
                except Exception as error:  # noqa: BLE001 - the worker died: a row, not a crash
                    first = next((ln for ln in str(error).splitlines() if ln.strip()), "")
                    row = failed_row(study, spec, f"{type(error).__name__}: {first}")
                on_row(row)
                submit()


def ray_available() -> bool:
    """Whether Ray imports (the `study` extra)."""
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def choose_engine(name: str, address: str | None, workers: int | None) -> tuple[Engine, str | None]:
    """The engine for `--engine NAME --address A --workers N` and a note for stderr (None, or
    `RAY_MISSING` when `auto` falls back to this process). `InputError` when the flags ask for
    Ray and it is not installed, or for a bad combination."""
    if workers is not None and workers < 1:
        raise InputError(None, "--workers", f"an integer >= 1, got {workers}")
    if name not in ENGINES:
        raise InputError(None, "--engine", f"one of {', '.join(ENGINES)}, got {name!r}")
    if name == "process":
        if address is not None:
            raise InputError(None, "--address", "no --address with --engine process")
        return InProcessEngine(), None
    if ray_available():
        return RayEngine(address=address, workers=workers), None
    if address is not None or name == "ray":
        flag = "--address" if address is not None else "--engine"
        raise InputError(None, flag, "Ray installed (pip install 'fleetline[study]')")
    return InProcessEngine(), RAY_MISSING
