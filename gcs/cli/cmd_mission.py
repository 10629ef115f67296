"""`gcs mission check|plan`: validate and plan a mission file, print or write the plan.

`check` does everything `plan` does (so it refuses all that `plan` refuses) and writes nothing.
Other `gcs mission <command>` modules register through `SUBCOMMANDS`.
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.console import Console
from rich.table import Table

from gcs.cli.outputs import output_path, write_output
from gcs.errors import InputError, RowsRefused
from gcs.mission import MAX_FLEET_SIZE, Mission, load_mission
from gcs.planning import MissionPlan, mission_problem, plan_json, plan_mission
from planner.numbers import fmt_against, plural
from planner.search import SearchProgress
from planner.types import PathPlan

if TYPE_CHECKING:
    from planner.route import RoutePlan

#: Modules adding `gcs mission <command>`, each with `register(mission_subparsers)`.
SUBCOMMANDS: tuple[str, ...] = ("gcs.cli.cmd_run",)

#: File types `--plot` writes (matplotlib back ends).
PLOT_SUFFIXES = (".png", ".pdf", ".svg")

EXIT_OK, EXIT_NO_PATH = 0, 1


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `gcs mission` and its commands."""
    mission = subparsers.add_parser(
        "mission",
        help="check, plan and fly a mission file",
        description="Check, plan and fly a mission file (YAML, see docs/mission-file.md).",
    )
    commands = mission.add_subparsers(dest="mission_command", metavar="COMMAND", required=True)

    check = commands.add_parser(
        "check",
        help="validate and plan a mission, write nothing, print a summary",
        description="Validate and plan a mission; exit 0 ok, 1 no valid path, 2 bad input.",
    )
    add_planning_arguments(check)
    check.add_argument("--json", action="store_true", help="print the plan JSON on stdout")
    check.add_argument(
        "--near",
        type=float,
        metavar="R",
        help="when A (or B) or its parking row is refused, also name the nearest accepted "
        "start (or goal) point within R metres",
    )
    check.set_defaults(handler=check_command)

    plan = commands.add_parser(
        "plan",
        help="plan a mission: path, fleet size, duration, safe speed",
        description="Plan a mission; exit 0 ok, 1 no valid path, 2 bad input.",
    )
    add_planning_arguments(plan)
    plan.add_argument(
        "--json", action="store_true", help="print the plan JSON on stdout (text goes to stderr)"
    )
    plan.add_argument("--out", type=Path, metavar="PLAN.json", help="write the plan JSON here")
    plan.add_argument(
        "--plot", type=Path, metavar="PLAN.png", help="draw the map and the formation (png/pdf/svg)"
    )
    plan.set_defaults(handler=plan_command)

    for name in SUBCOMMANDS:
        importlib.import_module(name).register(commands)


def add_planning_arguments(parser: argparse.ArgumentParser) -> None:
    """FILE and the options every planning command shares (reused by `mission run`)."""
    parser.add_argument("file", type=Path, metavar="FILE", help="mission file (YAML)")
    parser.add_argument(
        "--cap-speed",
        action="store_true",
        help="cap speeds to the safe formation speed instead of refusing (speed.cap_to_safe)",
    )
    parser.add_argument(
        "--method",
        choices=("exact", "penalty"),
        default="exact",
        help="path search: exact directed-edge Dijkstra (default) or the paper's penalty loop",
    )
    parser.add_argument(
        "--connect",
        nargs="+",
        metavar="URL",
        help="MAVLink connection strings, one per UAV (overrides fleet.connections)",
    )
    parser.add_argument(
        "--time-limit",
        type=_seconds,
        default=DEFAULT_TIME_LIMIT_S,
        metavar="S",
        help=f"stop the path search after S seconds with the best valid path found so far "
        f"(exit 1; default {DEFAULT_TIME_LIMIT_S:g})",
    )
    parser.add_argument(
        "--gap",
        type=_percent,
        default=DEFAULT_GAP_PCT,
        metavar="PCT",
        help="stop certifying once the path is proven at most PCT percent longer than the "
        f"shortest valid path (default {DEFAULT_GAP_PCT:g}; 0 certifies exactly)",
    )


#: Default `--time-limit` of the path search, seconds.
DEFAULT_TIME_LIMIT_S = 60.0
#: Default `--gap`: the certification ends once the path is proven this close (percent).
DEFAULT_GAP_PCT = 0.01
#: Without a terminal, a long search prints one progress line this often (seconds).
PROGRESS_EVERY_S = 10.0


def _seconds(text: str) -> float:
    return _float_flag(text, lambda v: math.isfinite(v) and v > 0, "a positive number of seconds")


def _percent(text: str) -> float:
    return _float_flag(text, lambda v: 0.0 <= v < 100.0, "a percentage from 0 to below 100")


def _float_flag(text: str, accepted: Callable[[float], bool], expected: str) -> float:
    """A flag's number, or argparse's refusal naming what was `expected`."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not accepted(value):
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    return value


def plan_from_args(args: argparse.Namespace) -> MissionPlan:
    """Load and plan `args.file` with the shared planning options (`plan_with_args`)."""
    return plan_with_args(load_mission(args.file), args)


def plan_with_args(mission: Mission, args: argparse.Namespace) -> MissionPlan:
    """Plan `mission` with the shared planning options; a search that runs for more than a
    second shows its progress on stderr (a status line on a terminal, else a line every
    `PROGRESS_EVERY_S` seconds). The input is then accepted: held warnings are printed."""
    console = Console(stderr=True, highlight=False)
    status = None
    shown = [0.0]

    def on_progress(state: SearchProgress, elapsed: float) -> None:
        nonlocal status
        if elapsed < 1.0:
            return
        text = progress_text(state, elapsed)
        if console.is_terminal:
            if status is None:
                status = console.status(text)
                status.start()
            status.update(text)
        elif elapsed - shown[0] >= PROGRESS_EVERY_S:
            shown[0] = elapsed
            console.print(text, soft_wrap=True)

    try:
        plan = plan_mission(
            mission,
            cap_speed=args.cap_speed,
            connections=tuple(args.connect) if args.connect else None,
            method=args.method,
            time_limit_s=args.time_limit,
            gap_tolerance=args.gap / 100.0,
            on_progress=on_progress,
        )
    finally:
        if status is not None:
            status.stop()
    size = plan.formation.fleet_size if plan.valid and plan.formation is not None else 0
    if size > MAX_FLEET_SIZE:  # refused by `check` and `plan` too, not at take-off
        raise InputError(
            mission.source,
            "fleet.size",
            f"at most {MAX_FLEET_SIZE} UAVs (MAVLink system ids 1-{MAX_FLEET_SIZE}), "
            f"the plan needs {size}",
        )
    getattr(args, "release_warnings", lambda: None)()  # the input is accepted
    warning = plan.connectivity.warning() if plan.connectivity is not None else None
    if warning is not None:
        logging.getLogger("gcs.connectivity").warning("%s: %s", mission.source, warning)
    return plan


def progress_text(state: SearchProgress, elapsed: float) -> str:
    """One line of search progress: time, expansions, best path and lower bound."""
    best = "none yet" if math.isnan(state.best_length_m) else f"{state.best_length_m:,.1f} m"
    return (
        f"planning: {elapsed:.0f} s, {state.expansions:,} expansions, best valid path "
        f"{best}, lower bound {state.lower_bound_m:,.1f} m"
    )


def certification_text(pp: PathPlan, route: RoutePlan | None = None) -> str:
    """Whether the path is certified shortest under definition 4, else how far it may be
    (a stations route: whether each leg is, given the route before it)."""
    if pp.level == "route":
        legs = "every leg" if pp.certified else "not every leg"
        if route is not None and route.within_gap:
            legs = f"every leg within the --gap of {100 * pp.gap_tolerance:g} % or"
        gap = pp.length_m - pp.lower_bound_m
        return (
            f"{legs} certified shortest given the route before it (definition 4); "
            f"{gap:,.1f} m longer than the straight lines through the points"
        )
    if pp.certified:
        return "certified shortest (definition 4)"
    gap = pp.length_m - pp.lower_bound_m
    share = gap / pp.lower_bound_m if pp.lower_bound_m > 0 else math.inf
    why = "stopped at the time limit; " if pp.stopped else ""
    if not pp.stopped and pp.within_gap:
        why = f"within the --gap of {100 * pp.gap_tolerance:g} %: "
    return (
        f"not certified shortest: {why}at most {gap:.3g} m ({100 * share:.3g} %) longer than "
        f"the shortest (lower bound {fmt_against(pp.lower_bound_m, pp.length_m, 5)} m)"
    )


def check_command(args: argparse.Namespace) -> int:
    from planner.alternatives import suggest  # only when a refusal needs it

    near = getattr(args, "near", None)
    if near is not None and not (math.isfinite(near) and near > 0):
        raise InputError(None, "--near", f"a distance in metres > 0, got {near:g}")
    try:
        plan = plan_from_args(args)
    except InputError as refused:
        # A refused parking row (eqs. 14-15) or A/B in a margin: say what would be accepted,
        # on the same line (exit 2 stays one line on stderr and nothing on stdout, docs/cli.md).
        rows = isinstance(refused, RowsRefused)
        placed = refused.key_path in ("start", "goal") and near is not None
        if not (rows or placed) or refused.file != str(args.file):
            raise
        try:  # the mission again, without the A/B clearance test, to plan around it
            mission = load_mission(args.file, check_clearance=False)
        except InputError:
            raise refused from None
        problem = mission_problem(mission)
        found = suggest(problem, refused.fleet_size if rows else None, near)
        text = found.describe()
        if text is None:
            raise refused from None
        raise InputError(refused.file, refused.key_path, f"{refused.expected}; {text}") from None
    console = Console(stderr=args.json, highlight=False)
    if args.json:
        print(json.dumps(plan_json(plan), allow_nan=False))
    print_summary(console, plan)
    return EXIT_OK if plan.valid and not plan.path_plan.stopped else EXIT_NO_PATH


def plan_command(args: argparse.Namespace) -> int:
    out = output_path(args.out, "--out", (".json",)) if args.out else None
    plot = output_path(args.plot, "--plot", PLOT_SUFFIXES) if args.plot else None
    plan = plan_from_args(args)
    data = plan_json(plan)
    text = json.dumps(data, allow_nan=False)
    written = []
    if out is not None:
        write_output(out, "--out", lambda: out.write_text(json.dumps(data, indent=2) + "\n"))
        written.append(out)
    if plot is not None:
        from gcs.plot import save_plan_figure  # matplotlib only when asked

        write_output(plot, "--plot", lambda: save_plan_figure(plan, plot))
        written.append(plot)
    console = Console(stderr=args.json, highlight=False)
    if args.json:
        print(text)
    print_summary(console, plan, written)
    return EXIT_OK if plan.valid and not plan.path_plan.stopped else EXIT_NO_PATH


def print_summary(console: Console, plan: MissionPlan, written: list[Path] | None = None) -> None:
    """The human summary: path, length, fleet size, duration, safe speed, planning time."""
    mission = plan.mission
    pp = plan.path_plan
    if not plan.valid:
        console.print(f"{mission.source}: no valid path: {plan.reason}", soft_wrap=True)
        console.print(
            f"planning: {pp.node_count} nodes, {pp.edges_examined} edges examined, "
            f"{pp.iterations} iterations, {plan.planning_time_s * 1000:.1f} ms",
            soft_wrap=True,
        )
        for path in written or ():
            console.print(f"wrote {path}", soft_wrap=True)
        return
    table = Table(title=f"mission {mission.name} ({mission.source})", show_header=False)
    table.add_column("", style="bold")
    table.add_column("")
    table.add_row("path", _path_text(pp.path))
    table.add_row("length", f"{pp.length_m:.1f} m ({len(pp.path)} points)")
    if plan.route is None:
        table.add_row(
            "fleet size", f"{plural(pp.fleet_size, 'UAV')} (minimum {pp.min_fleet_size}, eq. 28)"
        )
        table.add_row("duration", f"{plan.duration_s:.1f} s")
    else:
        _station_rows(table, plan)
    capped = " (capped)" if plan.speed_capped else ""
    table.add_row(
        "speed",
        f"max {plan.speeds.max:.3g} m/s{capped}, safe {plan.safe_speed_mps:.3g} m/s "
        f"(a_max {mission.vehicle.max_acceleration:g} m/s², budget {plan.error_budget_m:.3g} m)",
    )
    over = plan.smoothing_error_m > plan.error_budget_m
    table.add_row(
        "smoothing error",
        f"{plan.smoothing_error_m:.3g} m over a {plan.smoothing_window_s:.3g} s window"
        + (f" [bold red](above the {plan.error_budget_m:.3g} m budget)[/]" if over else ""),
    )
    table.add_row(
        "planning",
        f"{plan.planning_time_s * 1000:.1f} ms, {pp.node_count} nodes, "
        f"{pp.edges_examined} edges examined, {pp.iterations} iterations, {pp.level} graph",
    )
    table.add_row("shortest", certification_text(pp, plan.route))
    for path in written or ():
        table.add_row("wrote", str(path))
    console.print(table)


def _station_rows(table: Table, plan: MissionPlan) -> None:
    """A stations mission: the points in visiting order with their holders, the fleet, the
    time every UAV is on its station, and when the fleet comes home."""
    mission, route = plan.mission, plan.route
    layout = route.layout
    visits = [
        f"{mission.stations[index].name} (UAV {uav}, {distance:.0f} m)"
        for index, uav, distance in zip(
            route.order.tolist(), layout.holders.tolist(), route.point_distance, strict=True
        )
    ]
    table.add_row("points", " -> ".join(visits))
    relays = int(layout.relays.sum())
    table.add_row(
        "fleet size",
        f"{plural(route.fleet_size, 'UAV')}: {plural(len(visits), 'point')} held, "
        f"{plural(relays, 'relay')} (minimum {layout.minimum})",
    )
    dwell = [point.dwell_s for point in mission.stations]
    if mission.return_at is not None:
        home = f"the fleet returns at t = {mission.return_at:g} s"
    elif min(dwell) > 0:
        home = f"the fleet returns {max(dwell):g} s later (dwell_s), or when asked (gcs return)"
    else:
        home = "the fleet returns when asked (gcs return)"
    table.add_row("on station", f"every UAV after {plan.duration_s:.1f} s; {home}")


def _path_text(path: Any, keep: int = 4) -> str:
    points = [f"({x:.1f}, {y:.1f})" for x, y in path]
    if len(points) > 2 * keep + 1:
        points = [*points[:keep], f"... {len(points) - 2 * keep} more ...", *points[-keep:]]
    return " -> ".join(points)
