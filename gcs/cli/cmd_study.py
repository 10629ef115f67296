"""`gcs eval study STUDY.yaml --out DIR` and `gcs eval study-report DIR` (docs/study.md).

`study` flies every combination of the study file's axes (fast mode, and ns-3 for `network:
ns3`) as Ray tasks (the `study` extra; local Ray on all cores by default, `--address` for a
cluster) or, without Ray, in this process with a one-line note. Each finished run is one row
appended to DIR/runs.jsonl; a second invocation flies only the runs missing from it.

Exit statuses: `study`: 0 every run of the study succeeded, 1 some failed (their rows carry
the error), 2 bad input (the study file, its base mission or a flag; `--address` or `--engine
ray` without Ray; `network: ns3` without the ns3 extra). `study-report`: 0 written, 2 DIR is
not a study's output folder.
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
import sys
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from gcs.errors import EXIT_BAD_INPUT, InputError

# Ray, matplotlib and the fast simulator are imported when a command runs, not when `gcs`
# starts.

#: The study's files in its output folder.
STUDY_COPY, STUDY_JSON, REPORT_DIR = "study.yaml", "study.json", "report"


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `gcs eval study` and `gcs eval study-report`."""
    study = subparsers.add_parser(
        "study",
        help="fly every combination of a study file's axes (Ray when installed)",
        description="Fly every combination of the axes of STUDY (seeds, speeds, leaders, "
        "fleet size, rho_c, rho_R, radio, network, planner, maps) in the fast mode, as Ray "
        "tasks (local Ray on all cores; --address for a cluster) or in this process without "
        "Ray. One row per run is appended to DIR/runs.jsonl as it finishes; running again "
        "flies only the missing runs. Exit 0 every run succeeded, 1 some failed (their rows "
        "carry the error), 2 bad input.",
    )
    study.add_argument("study", type=Path, metavar="STUDY.yaml", help="the study file")
    study.add_argument("--out", type=Path, required=True, metavar="DIR",
                       help="output folder: the table runs.jsonl, a copy of the study")  # fmt: skip
    study.add_argument("--engine", choices=("auto", "ray", "process"), default="auto",
                       help="auto: Ray when installed, else this process (default); ray; "
                       "process: one run after the other in this process")  # fmt: skip
    study.add_argument("--address", default=None, metavar="ADDR",
                       help="a running Ray cluster (ray.init address: auto, ray://HOST:10001)")  # fmt: skip
    study.add_argument("--workers", type=int, default=None, metavar="N",
                       help="local Ray: CPUs (default all cores); cluster: most runs at once")  # fmt: skip
    study.add_argument("--retry-failed", action="store_true",
                       help="fly again the runs whose row has an error")  # fmt: skip
    study.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    study.set_defaults(handler=study_command)

    report = subparsers.add_parser(
        "study-report",
        help="tables and figures of a study, per axis, with confidence intervals",
        description="Read DIR (the --out of gcs eval study) and write, per axis of the "
        "study, each metric's mean and 95 % confidence interval at each value (report.md, "
        "report.json) and figures (axis_<name>.png, density.png) to DIR/report or --out. "
        "Exit 0 written, 2 DIR is not a study's output folder.",
    )
    report.add_argument("dir", type=Path, metavar="DIR", help="the study's output folder")
    report.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="where to write (default DIR/report)")  # fmt: skip
    report.add_argument("--json", action="store_true", help="print the report as one JSON object")
    report.set_defaults(handler=report_command)


def _ns3_missing(study) -> str | None:
    """The ns3 extra's one-line message when a run needs ns-3 and it is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    networks = dict(study.axes).get("network", ())
    if "ns3" not in networks:
        return None
    try:
        version("ns3")
    except PackageNotFoundError:
        from gcs.netsim.ns3 import MISSING_EXTRA

        return MISSING_EXTRA
    return None


class _QuietFlights:
    """Hold the flights' own warnings (gcs.flight.core: a UAV near an obstacle...) during a
    study unless -v: hundreds of runs would bury the progress bar; each row has the minima."""

    def __init__(self, verbose: int) -> None:
        self.logger = logging.getLogger("gcs.flight")
        self.verbose = verbose
        self.level = self.logger.level

    def __enter__(self) -> None:
        if not self.verbose:
            self.logger.setLevel(logging.ERROR)

    def __exit__(self, *exc) -> None:
        self.logger.setLevel(self.level)


def study_command(args: argparse.Namespace) -> int:
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from gcs.cli.outputs import output_folder
    from gcs.study.engines import choose_engine
    from gcs.study.studyfile import load_study
    from gcs.study.table import TABLE, RowWriter, done_ids, read_rows

    study = load_study(args.study)
    engine, note = choose_engine(args.engine, args.address, args.workers)
    missing = _ns3_missing(study)
    if missing is not None:
        print(missing, file=sys.stderr)
        return EXIT_BAD_INPUT
    out = output_folder(args.out, "--out")
    args.release_warnings()
    console = Console(stderr=True, highlight=False)
    if note:
        print(note, file=sys.stderr)  # one plain line (rich would wrap it and eat "[study]")
    if args.study.resolve() != (out / STUDY_COPY).resolve():
        shutil.copyfile(args.study, out / STUDY_COPY)
    summary = study.summary()
    (out / STUDY_JSON).write_text(json.dumps(summary, indent=1, default=str))
    table = out / TABLE
    specs = study.runs()
    ids = set(summary["runs"])
    before = [r for r in read_rows(table) if r["id"] in ids]
    done = done_ids(before, args.retry_failed)
    todo = [spec for spec in specs if spec.id not in done]
    failed_before = sum(1 for r in before if r.get("error") and r["id"] in done)
    began = time.perf_counter()
    failures = 0
    progress = Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("runs, {task.fields[failed]} failed"),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
        console=console,
        transient=False,
    )
    with progress, _QuietFlights(args.verbose), RowWriter(table) as writer:
        bar = progress.add_task(
            study.name, total=len(specs), completed=len(specs) - len(todo), failed=failed_before
        )

        def on_row(row: dict) -> None:
            nonlocal failures
            writer.append(row)
            failures += bool(row.get("error"))
            progress.update(bar, advance=1, failed=failed_before + failures)

        engine.run(study, todo, on_row)
    wall = time.perf_counter() - began
    rows = [r for r in read_rows(table) if r["id"] in ids]
    failed = sum(1 for r in rows if r.get("error"))
    result = {
        "ok": failed == 0 and len(rows) == len(specs),
        "out": str(out),
        "table": str(table),
        "engine": engine.description,
        "runs": len(specs),
        "done_before": len(specs) - len(todo),
        "flown": len(todo),
        "failed": failed,
        "wall_s": wall,
        "runs_per_minute": 60.0 * len(todo) / wall if todo and wall > 0 else None,
    }
    if args.json:
        print(json.dumps(result, allow_nan=False))
    view = Table(title=f"study {study.name}")
    view.add_column("runs")
    view.add_column("done before")
    view.add_column("flown now")
    view.add_column("failed")
    view.add_column("wall")
    view.add_row(str(len(specs)), str(result["done_before"]), str(len(todo)), str(failed),
                 f"{wall:.1f} s ({engine.description})")  # fmt: skip
    Console(stderr=args.json, highlight=False).print(view)
    if failed:
        console.print(f"{failed} runs failed: their rows in {table} have the error", markup=False)
    return 0 if result["ok"] else 1


def report_command(args: argparse.Namespace) -> int:
    from gcs.cli.outputs import output_folder
    from gcs.study.report import write_report
    from gcs.study.table import TABLE, read_rows

    folder: Path = args.dir
    if not (folder / STUDY_JSON).is_file():
        raise InputError(
            None, "DIR", f"the output folder of gcs eval study (with {STUDY_JSON}), got {folder}"
        )
    try:
        summary = json.loads((folder / STUDY_JSON).read_text())
        if not isinstance(summary, dict) or not {"axes", "metrics", "runs"} <= set(summary):
            raise ValueError("keys")
    except ValueError:
        raise InputError(folder / STUDY_JSON, "", "the study.json gcs eval study writes") from None
    out = output_folder(args.out if args.out is not None else folder / REPORT_DIR, "--out")
    report = write_report(summary, read_rows(folder / TABLE), out)
    console = Console(stderr=args.json, highlight=False)
    if args.json:
        print(json.dumps({"out": str(out), "files": [str(f) for f in report.files],
                          "rows": report.runs, "failed": report.failed,
                          "ignored": report.ignored}))  # fmt: skip
    console.print(
        f"study {summary.get('name')}: {report.runs} of {len(summary['runs'])} runs, "
        f"{report.failed} failed; {len(report.files)} files in {out}",
        markup=False,
    )
    if report.ignored:
        console.print(f"{report.ignored} rows of the table belong to another study (ignored)")
    return 0
