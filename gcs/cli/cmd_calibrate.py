"""`gcs eval calibrate [--out FILE] [--seed N] [--quick] [--json]`: measure per-hop delay and
loss in ns-3 for the live medium's `radio.model: calibrated` (docs/calibration.md).

Writes the table (`gcs.netsim.calibrate`, read by `medium.calibration`) to FILE, by default the
one the medium ships, `medium/calibration_ns3.json`, and prints it as a table (or as one JSON
object with `--json`, the table going to stderr).

Exit statuses: 0 written, 2 bad input (a bad flag, an --out that cannot be written, the ns3
extra missing).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from gcs.cli.ns3_flags import ns3_loaded
from gcs.errors import EXIT_BAD_INPUT, InputError

# ns-3, numpy and the calibration modules are imported when the command runs, not when `gcs`
# starts.


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `gcs eval calibrate` to the `gcs eval` commands."""
    calibrate = subparsers.add_parser(
        "calibrate",
        help="measure per-hop delay and loss in ns-3 for the medium's radio.model: calibrated",
        description="Fly static lines of UAVs in ns-3 (802.11b ad hoc, AODV; the ns3 extra), "
        "every UAV sending data to one base station, at several offered loads; write per load "
        "and hop count the packets sent, the loss ratio and the delay quantiles as JSON. The "
        "live medium draws from it with radio.model: calibrated. Exit 0 written, 2 bad input "
        "or the ns3 extra missing.",
    )
    calibrate.add_argument("--out", type=Path, default=None, metavar="FILE",
                           help="the table to write (default medium/calibration_ns3.json, the "
                           "one the medium ships)")  # fmt: skip
    calibrate.add_argument("--seed", type=int, default=1, metavar="N",
                           help="seeds ns-3 and the data sources' phases (default 1)")  # fmt: skip
    calibrate.add_argument("--quick", action="store_true",
                           help="1-3 hops, the paper's load, one 30 s run (seconds; for tests)")  # fmt: skip
    calibrate.add_argument("--json", action="store_true", help="print the table as one JSON object")
    calibrate.set_defaults(handler=calibrate_command)


def calibrate_command(args: argparse.Namespace) -> int:
    from gcs.cli.outputs import output_path
    from gcs.netsim.calibrate import QUICK_PLAN, CalibrationPlan, run_calibration, table_json
    from medium.calibration import DEFAULT_CALIBRATION, calibration_from_json

    if args.seed < 1:
        raise InputError(None, "--seed", f"an integer >= 1, got {args.seed}")
    out = output_path(
        args.out if args.out is not None else DEFAULT_CALIBRATION, "--out", (".json",)
    )
    _check_writable(out)
    plan = QUICK_PLAN if args.quick else CalibrationPlan()
    command = " ".join(["gcs eval calibrate", *(["--quick"] if args.quick else []),
                        f"--seed {args.seed}"])  # fmt: skip
    if not ns3_loaded():
        return EXIT_BAD_INPUT
    progress = Console(stderr=True, highlight=False)
    began = time.perf_counter()
    run = run_calibration(plan, args.seed, command=command, progress=progress.print)
    text = table_json(run.table)
    calibration_from_json(json.loads(text), str(out))  # what the medium will read (a check)
    _write_atomically(out, text)
    if args.json:
        print(json.dumps(run.table, allow_nan=False))
    console = Console(stderr=args.json, highlight=False)
    console.print(calibration_view(run.table))
    console.print(
        f"wrote {out} ({len(text.encode())} bytes); wall time: ns-3 import {run.import_s:.1f} s, "
        f"runs {sum(run.wall_s.values()):.1f} s, in all {time.perf_counter() - began:.1f} s"
    )
    return 0


def calibration_view(table: dict) -> Table:
    """The table as rich shows it: one row per load level and hop count (delays in ms)."""
    view = Table(
        title=f"per-hop delay and loss in ns-3 (seed {table['seed']}, "
        f"ns-3 {table['ns3']['version']})",
        caption=f"a line of {table['scenario']['uavs']} UAVs, each sending data at the rate "
        "shown; the delays of the delivered packets, ms",
    )
    names = [f"p{round(100 * q):02d}" for q in table["quantiles"]]
    shown = [k for k, name in enumerate(names) if name not in ("p00", "p25", "p75")]
    for name in ["bit/s/UAV", "hops", "sent", "loss %", *(names[k] for k in shown)]:
        view.add_column("max" if name == "p100" else name, justify="right")
    for level in table["levels"]:
        for index, row in enumerate(level["hops"]):
            delays = row["delay_s"]
            cells = ["-"] * len(shown) if delays is None else [_ms(delays[k]) for k in shown]
            view.add_row(
                f"{level['rate_bps_per_node']:g}" if index == 0 else "",
                str(row["hops"]),
                str(row["sent"]),
                f"{100 * row['loss_ratio']:.1f}",
                *cells,
                end_section=index == len(level["hops"]) - 1,
            )
    return view


def _ms(seconds: float) -> str:
    milliseconds = 1000.0 * seconds
    return f"{milliseconds:.3f}" if milliseconds < 100 else f"{milliseconds:.0f}"


def _check_writable(out: Path) -> None:
    """Refuse, before ns-3 runs, a folder that takes no file (one line naming --out)."""
    parent = out.parent if str(out.parent) else Path(".")
    try:
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as error:
        raise InputError(
            None, "--out", f"a file in a folder we may write in, got {out} ({error.strerror})"
        ) from None


def _write_atomically(out: Path, text: str) -> None:
    """Write `text` to `out` through a temporary file beside it (never a half-written table)."""
    parent = out.parent if str(out.parent) else Path(".")
    try:
        handle, temporary = tempfile.mkstemp(dir=parent, prefix=f".{out.name}.", suffix=".tmp")
        try:
            os.fchmod(handle, 0o644)  # (mkstemp's 0600 would follow the table)
            with os.fdopen(handle, "w", encoding="utf-8") as stream:
                stream.write(text)
            os.replace(temporary, out)
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise
    except OSError as error:
        raise InputError(None, "--out", f"a writable file, got {out} ({error.strerror})") from None
