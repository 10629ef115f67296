"""`gcs log info|report|replay|netsim LOG`: summarise, figure, re-emit a recording, or replay its
flight in the ns-3 network simulator (docs/cli.md, docs/netsim.md).

Exit statuses: 0 done (a truncated recording is read up to its cut, and said so), 2 bad input
(not an MCAP file, not a recording of `gcs mission run`, a bad flag; for `netsim`, ns-3 not
installed).
"""

from __future__ import annotations

import argparse
import json
import math
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.console import Console
from rich.table import Table

from gcs.cli.ns3_flags import add_ns3_options, ns3_loaded, ns3_options
from gcs.cli.outputs import output_folder
from gcs.errors import EXIT_BAD_INPUT, InputError

if TYPE_CHECKING:  # the MCAP reader is imported when a command reads a log
    from gcs.recording.logreader import Recording

EXIT_OK = 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `gcs log` and its commands."""
    group = subparsers.add_parser(
        "log",
        help="summarise, figure or replay a flight recording (MCAP)",
        description="Summarise, figure or replay a flight recording (MCAP) of `gcs mission run`.",
    )
    commands = group.add_subparsers(dest="log_command", metavar="COMMAND", required=True)

    info = commands.add_parser(
        "info",
        help="duration, topics, message counts, UAVs, mission, outcome",
        description="Summarise a recording; a truncated one is read up to its cut. Exit 0, "
        "2 if it is not an MCAP file.",
    )
    info.add_argument("log", type=Path, metavar="LOG", help="MCAP file")
    info.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    info.set_defaults(handler=info_command)

    report = commands.add_parser(
        "report",
        help="the paper's figures (PNG) and a summary (Markdown, JSON) from a recording",
        description="Draw the map with planned and flown tracks, distances, tracking errors, "
        "reaction times, packets at base stations and distance travelled, recomputed from "
        "the recording; write summary.md and summary.json. Exit 0, 2 bad input.",
    )
    report.add_argument("log", type=Path, metavar="LOG", help="MCAP file")
    report.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    report.set_defaults(handler=report_command)

    replay = commands.add_parser(
        "replay",
        help="re-emit the recorded MAVLink to a ground-control program",
        description="Send the recorded MAVLink frames, byte for byte with their original "
        "timing divided by --rate, to a MAVLink connection string (e.g. "
        "udpout:127.0.0.1:14550 for QGroundControl or MAVProxy). Exit 0, 2 bad input.",
    )
    replay.add_argument("log", type=Path, metavar="LOG", help="MCAP file")
    replay.add_argument(
        "--to", required=True, metavar="URL", help="mavutil connection string to send to"
    )
    replay.add_argument(
        "--rate", type=float, default=1.0, metavar="X", help="X times real time (default 1)"
    )
    replay.add_argument(
        "--direction",
        choices=("rx", "tx", "both"),
        default="rx",
        help="rx: what the UAVs sent (default, shows the fleet); tx: what the GCS sent",
    )
    replay.add_argument(
        "--uav", type=int, action="append", metavar="N", help="only UAV N (repeatable)"
    )
    replay.set_defaults(handler=replay_command)

    netsim = commands.add_parser(
        "netsim",
        help="the flight's network in ns-3: delivery, T_BS, hops, gaps, T_dv (needs the ns3 extra)",
        description="Replay the recorded trajectories (10 Hz) in the ns-3 network simulator: "
        "802.11b ad hoc, AODV (or OLSR), 0.8 kbit/s of UDP from each UAV and ground user to "
        "its base station, each leader's speed request relayed UAV to UAV (the paper) and "
        "through the ground station. Prints a table per UAV; --out writes netsim.json and "
        "figures. Exit 0, 2 bad input or ns-3 not installed (docs/netsim.md).",
    )
    netsim.add_argument("log", type=Path, metavar="LOG", help="MCAP file")
    add_ns3_options(netsim)
    netsim.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="write netsim.json, t_bs.png and bs_con.png here")  # fmt: skip
    netsim.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    netsim.set_defaults(handler=netsim_command)


# --------------------------------------------------------------------------- info
def describe(recording: Recording) -> dict[str, Any]:
    """What `gcs log info --json` prints."""
    start, end = recording.start_ns, recording.end_ns
    mission_start = None if start is None else recording.mission_time(start)
    mission_end = None if end is None else recording.mission_time(end)
    return {
        "log": str(recording.path),
        "size_bytes": recording.size,
        "profile": recording.profile,
        "mission": recording.mission_name,
        "outcome": recording.outcome,
        "truncated": recording.truncated,
        "truncation": recording.truncation,
        "damaged": recording.damaged,
        "bytes_read": recording.bytes_read,
        "start_utc": None
        if start is None
        else datetime.fromtimestamp(start / 1e9, UTC).isoformat(timespec="milliseconds"),
        "duration_s": recording.duration_s,
        "mission_time_s": [mission_start, mission_end],
        "uavs": recording.uavs,
        "messages": recording.message_count,
        "topics": {
            topic: {
                "schema": data.schema_name,
                "encoding": data.message_encoding,
                "count": data.count,
            }
            for topic, data in sorted(recording.topics.items())
        },
        "attachments": {name: len(data) for name, data in recording.attachments.items()},
        "metadata": sorted(recording.metadata),
    }


def _outcome_text(outcome: dict | None) -> str:
    if outcome is None:
        return "unknown (no outcome record: the GCS did not finish this recording)"
    if outcome.get("completed"):
        return f"completed (exit {outcome.get('exit_status', 0)})"
    return f"not completed (exit {outcome.get('exit_status', 1)}): {outcome.get('reason')}"


def _seconds(value: float | None) -> str:
    return "?" if value is None or not math.isfinite(value) else f"{value:.1f} s"


def info_command(args: argparse.Namespace) -> int:
    from gcs.recording.logreader import read_recording

    recording = read_recording(args.log, keep=lambda topic: topic in ("/plan", "/metrics"))
    data = describe(recording)
    if args.json:
        print(json.dumps(data, allow_nan=False))
        return EXIT_OK
    console = Console(highlight=False)
    top = Table(title=f"{recording.path}", show_header=False)
    top.add_column("", style="bold")
    top.add_column("")
    top.add_row("mission", str(data["mission"] or "?"))
    top.add_row("outcome", _outcome_text(data["outcome"]))
    start, end = data["mission_time_s"]
    top.add_row(
        "duration",
        f"{data['duration_s']:.1f} s of log time"
        + (f" (mission time {_seconds(start)} to {_seconds(end)})" if start is not None else "")
        + (f", from {data['start_utc']}" if data["start_utc"] else ""),
    )
    top.add_row("UAVs", f"{len(data['uavs'])}: {', '.join(map(str, data['uavs'])) or '-'}")
    top.add_row("messages", f"{data['messages']} on {len(data['topics'])} topics")
    top.add_row(
        "attachments",
        ", ".join(f"{name} ({size} B)" for name, size in data["attachments"].items()) or "-",
    )
    if recording.damaged is not None:
        top.add_row("[bold red]damaged[/]", recording.damaged)
    if recording.truncated:
        top.add_row(
            "[bold red]truncated[/]",
            f"{recording.truncation}: the first {recording.bytes_read} of {recording.size} "
            "bytes were readable and are summarised here",
        )
    console.print(top)
    topics = Table(title="topics")
    for name in ("topic", "schema", "encoding", "messages"):
        topics.add_column(name, justify="right" if name == "messages" else "left")
    for topic, info in data["topics"].items():
        topics.add_row(topic, info["schema"], info["encoding"], str(info["count"]))
    console.print(topics)
    return EXIT_OK


# --------------------------------------------------------------------------- report
def report_command(args: argparse.Namespace) -> int:
    from gcs.recording.logreader import read_recording
    from gcs.recording.report import write_report

    out = output_folder(args.out, "--out")
    recording = read_recording(args.log, keep=lambda topic: not topic.startswith("/mavlink/"))
    report = write_report(recording, out)
    console = Console(highlight=False)
    summary = report.summary
    if recording.truncated:
        console.print(f"[bold red]{args.log}: truncated[/] ({recording.truncation})")
    console.print(
        f"{summary['mission']}: min UAV-UAV {_metres(summary['min_uav_uav_m'])}, "
        f"min UAV-obstacle {_metres(summary['min_uav_obstacle_m'])}, max tracking error "
        f"{_metres(summary['max_tracking_error_m'])}"
    )
    for path in report.files:
        console.print(f"wrote {path}")
    return EXIT_OK


def _metres(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2f} m"


# --------------------------------------------------------------------------- replay
def replay_command(args: argparse.Namespace) -> int:
    from gcs.recording.logreader import read_recording
    from gcs.recording.replay import ReplayError, open_output, recorded_frames, replay

    if not (math.isfinite(args.rate) and args.rate > 0):
        raise InputError(None, "--rate", f"a number > 0, got {args.rate:g}")
    directions = ("rx", "tx") if args.direction == "both" else (args.direction,)
    recording = read_recording(args.log, keep=lambda topic: topic.startswith("/mavlink/"))
    uavs = set(args.uav) if args.uav else None
    frames = recorded_frames(recording, directions, uavs)
    if not frames:
        which = "" if uavs is None else f" of UAV {', '.join(map(str, sorted(uavs)))}"
        raise InputError(
            args.log, "", f"recorded MAVLink ({'/'.join(directions)}{which}) to replay, found none"
        )
    connection = open_output(args.to)
    console = Console(stderr=True, highlight=False)
    span = (frames[-1].log_time_ns - frames[0].log_time_ns) / 1e9
    console.print(
        f"replaying {len(frames)} frames ({span:.1f} s recorded) to {args.to} at "
        f"{args.rate:g}x" + (" (truncated log)" if recording.truncated else "")
    )
    try:
        stats = replay(frames, connection, args.rate)
    except ReplayError as failure:
        raise InputError(
            None, "--to", f"a destination that takes MAVLink ({args.to}: {failure})"
        ) from None
    finally:
        connection.close()
    console.print(f"sent {stats.frames} frames, {stats.bytes} bytes in {stats.wall_s:.1f} s")
    return EXIT_OK


# --------------------------------------------------------------------------- netsim
def netsim_command(args: argparse.Namespace) -> int:
    from gcs.netsim.ns3 import (
        IMPORT_TIMES,
        run_network,
    )
    from gcs.netsim.scenario import scenario_from_recording

    options = ns3_options(args)
    out = output_folder(args.out, "--out") if args.out is not None else None
    scenario = scenario_from_recording(args.log)
    if not ns3_loaded():
        return EXIT_BAD_INPUT
    progress = Console(stderr=True, highlight=False)
    progress.print(
        f"{scenario.name}: {scenario.fleet_size} UAVs, {len(scenario.base_stations)} base "
        f"stations, {len(scenario.ground_users)} ground users, "
        f"{scenario.times[-1] - scenario.times[0]:.0f} s in ns-3 ({args.routing}, "
        f"{args.propagation}, seed {args.seed}) ..."
    )
    result = run_network(scenario, options)
    files = []
    if out is not None:
        from gcs.netsim.figures import write_outputs

        files = write_outputs(result, out)
    data = result.to_json()
    if args.json:
        print(json.dumps(data, allow_nan=False))
    console = Console(stderr=args.json, highlight=False)
    console.print(netsim_table(result))
    console.print(
        f"all packets: {data['packets_received']}/{data['packets_sent']} delivered; wall "
        f"time: ns-3 import {sum(IMPORT_TIMES.values()):.1f} s, build {result.build_s:.1f} s, "
        f"run {result.run_s:.1f} s"
    )
    for path in files:
        console.print(f"wrote {path}")
    return EXIT_OK


def netsim_table(result) -> Table:
    """The per-UAV table of `gcs log netsim`, then the ground users' delivery, T_BS and hops.
    T_dv: the slowest of the UAV's receptions of the leaders' requests, by the paper's chain
    and by the ground station's relay ("lost k": k requests never reached it)."""
    options = result.options
    table = Table(
        title=f"{result.scenario.name} in ns-3 ({options.routing}, {options.propagation}, "
        f"seed {options.seed})",
        caption="T_BS: to the base station; gap: longest without a delivery while flying; "
        "T_dv: slowest request, paper chain / ground station",
    )
    for name in ("node", "deliv %", "T_BS ms", "p95 ms", "hops", "max", "gap s",
                 "T_dv chain ms", "T_dv gcs ms"):  # fmt: skip
        table.add_column(name, justify="left" if name == "node" else "right")

    def worst(value: float | None, lost: int) -> str:
        if not result.scenario.requests:
            return "-"
        return f"lost {lost}" if lost else _ms(value)

    for row in result.per_uav():
        table.add_row(
            f"UAV {row['id']}",
            *_delivery_cells(row),
            "-" if row["longest_gap_s"] is None else f"{row['longest_gap_s']:.1f}",
            worst(row["t_dv_paper_worst_s"], row["t_dv_paper_lost"]),
            worst(row["t_dv_gcs_worst_s"], row["t_dv_gcs_lost"]),
        )
    for index in range(len(result.scenario.ground_users)):
        row = result.source_summary("user", index + 1)
        table.add_row(f"user {index + 1}", *_delivery_cells(row), "", "", "")
    return table


def _delivery_cells(row: dict) -> list[str]:
    ratio = row["delivery_ratio"]
    return [
        "-" if ratio is None else f"{100 * ratio:.1f}",
        _ms(row["t_bs_mean_s"]),
        _ms(row["t_bs_p95_s"]),
        "-" if row["hops_mean"] is None else f"{row['hops_mean']:.2f}",
        "-" if row["hops_max"] is None else str(row["hops_max"]),
    ]


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{1000 * value:.1f}"
