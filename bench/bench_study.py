"""Studies on Ray (`python -m bench study`, issue 16; Ray from the `study` extra).

1. Runs per minute of the paper-like study (`examples/study.yaml`, a 12-run subset: two map
   seeds x two speeds x no leader, UAV 1, UAV 4) in this process, then on local Ray with 1
   and with 2 workers; each from an empty output folder, through the same code as `gcs eval
   study` (the table is written). Ray's start-up (`ray.init` of a local instance) is timed
   apart and counted in the Ray rows' wall time, as a user pays it.
2. Ray's overhead per task: the round trip of a trivial task (submit, run, get), one at a
   time and 1000 in flight, on the local instance of 2 workers.

Skipped (one line) without Ray.
"""

from __future__ import annotations

import logging
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from rich.console import Console
from rich.table import Table

from gcs.study.engines import InProcessEngine, RayEngine, ray_available
from gcs.study.studyfile import load_study
from gcs.study.table import RowWriter

REPO = Path(__file__).resolve().parents[1]
STUDY = REPO / "examples" / "study.yaml"
#: The subset flown: (axis, values) replacing the example's.
SUBSET = {"map_seed": (8, 25), "speed": (5.0, 10.0), "leader": (None, 1, 4)}


def _study():
    study = load_study(STUDY)
    axes = tuple((name, SUBSET.get(name, values)) for name, values in study.axes)
    return replace(study, axes=axes)


def _fly(engine, study) -> tuple[float, int]:
    """Wall seconds and failed runs of the whole study on `engine`, into a fresh table."""
    failed = 0
    with tempfile.TemporaryDirectory() as folder:
        with RowWriter(Path(folder) / "runs.jsonl") as writer:

            def on_row(row: dict) -> None:
                nonlocal failed
                writer.append(row)
                failed += bool(row["error"])

            began = time.perf_counter()
            engine.run(study, study.runs(), on_row)
            return time.perf_counter() - began, failed


def _ray_overhead() -> tuple[float, float, float]:
    """ray.init seconds, then µs per trivial task one at a time and with 1000 in flight."""
    import ray

    began = time.perf_counter()
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    init_s = time.perf_counter() - began
    try:

        @ray.remote
        def nothing(x):
            return x

        ray.get([nothing.remote(i) for i in range(20)])  # workers started and warm
        count = 300
        began = time.perf_counter()
        for i in range(count):
            ray.get(nothing.remote(i))
        serial = (time.perf_counter() - began) / count * 1e6
        count = 1000
        began = time.perf_counter()
        ray.get([nothing.remote(i) for i in range(count)])
        batched = (time.perf_counter() - began) / count * 1e6
    finally:
        ray.shutdown()
    return init_s, serial, batched


def main() -> None:
    console = Console()
    logging.getLogger("gcs.flight").setLevel(logging.ERROR)  # as `gcs eval study` without -v
    if not ray_available():
        console.print("bench study: skipped (ray is not installed: pip install 'fleetline[study]')")
        return
    import ray

    study = _study()
    count = len(study.runs())
    table = Table(title=f"study {study.name}, {count} runs (examples/study.yaml subset)")
    for column in ("engine", "wall (s)", "runs/min", "speed-up", "failed"):
        table.add_column(column, justify="right" if column != "engine" else "left")
    base = None
    for label, engine in (
        ("in this process", InProcessEngine()),
        ("local Ray, 1 worker", RayEngine(workers=1)),
        ("local Ray, 2 workers", RayEngine(workers=2)),
    ):
        wall, failed = _fly(engine, study)
        base = base or wall
        table.add_row(label, f"{wall:.1f}", f"{60 * count / wall:.1f}", f"{base / wall:.2f}x",
                      str(failed))  # fmt: skip
    console.print(table)
    init_s, serial, batched = _ray_overhead()
    overhead = Table(title=f"Ray {ray.__version__} overhead (local, 2 workers)")
    overhead.add_column("what")
    overhead.add_column("value", justify="right")
    overhead.add_row("ray.init of a local instance", f"{init_s:.2f} s")
    overhead.add_row("trivial task round trip, one at a time", f"{serial:.0f} µs")
    overhead.add_row("trivial task, 1000 in flight (per task)", f"{batched:.0f} µs")
    console.print(overhead)


if __name__ == "__main__":
    main()
