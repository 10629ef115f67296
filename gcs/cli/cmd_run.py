"""`gcs mission run FILE`: plan, connect (starting the simulated fleet), fly, land, summarise.

Registered under `gcs mission` (through `gcs.cli.cmd_mission.SUBCOMMANDS`). Exit statuses
(docs/cli.md): 0 completed, 1 aborted or a safety bound broken (or no valid path), 2 bad
input. With `--json` exactly one JSON object goes to stdout (the run JSON, also on exit 1) and
human text to stderr.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from contextlib import ExitStack
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from rich.console import Console

from gcs.errors import InputError
from gcs.mission import load_mission
from gcs.planning import plan_json, plan_within_limits

# The flight's modules (pymavlink, the drivers and the core, the MCAP recorder) are imported
# when `gcs mission run` runs, not when `gcs` starts: registering the command needs none of them.
if TYPE_CHECKING:
    from gcs.drivers.sim import SimVehicleSetup
    from gcs.recording.recording import FlightRecorder
    from gcs.transport.forward import Forwarder

#: Highest setpoint rate the scheduler streams (mission time), Hz.
MAX_SETPOINT_RATE_HZ = 50.0
#: Highest --speedup accepted.
MAX_SPEEDUP = 100.0
#: Longest --takeoff-lead (mission s): a take-off an hour before departure is no lead.
MAX_TAKEOFF_LEAD_S = 3600.0


def register(mission_commands: argparse._SubParsersAction) -> None:
    """Add `gcs mission run`."""
    from gcs.cli.cmd_mission import add_planning_arguments

    run = mission_commands.add_parser(
        "run",
        help="plan and fly a mission (starts the simulated fleet by default)",
        description=(
            "Plan and fly a mission: connect the fleet (backend sim starts its own vehicles), "
            "take off, fly the line formation, land on the arrival slots, print the summary. "
            "Exit 0 completed, 1 aborted or a safety bound broken, 2 bad input."
        ),
    )
    add_planning_arguments(run)
    run.add_argument(
        "--speedup",
        type=float,
        default=1.0,
        metavar="K",
        help="fly K times faster than real time (vehicles and mission clock), default 1",
    )
    run.add_argument("--log", type=Path, metavar="PATH", help="MCAP file to write (exact path)")
    run.add_argument("--force", action="store_true", help="overwrite an existing --log file")
    run.add_argument(
        "--json", action="store_true", help="print the run JSON on stdout (text goes to stderr)"
    )
    run.add_argument(
        "--foxglove",
        nargs="?",
        const=8765,
        type=int,
        metavar="PORT",
        help="also serve the recording live to Foxglove on 127.0.0.1:PORT (default 8765; "
        "0 picks a free port, printed at start)",
    )
    run.add_argument(
        "--out",
        action="append",
        metavar="URL",
        help="also forward every UAV's MAVLink to this pymavlink connection string, as "
        "MAVProxy's --out (QGroundControl: udpout:127.0.0.1:14550); what the tool sends goes "
        "to the UAV it names, unsigned (repeatable)",
    )
    run.add_argument(
        "--out-readonly",
        action="store_true",
        help="the --out tools watch only: nothing they send reaches a UAV",
    )
    run.add_argument(
        "--insecure",
        action="store_true",
        help="do not sign MAVLink (by default the simulated fleet, and any fleet with "
        "signing.key_file, is signed with MAVLink 2 signing): said loudly, and logged",
    )
    run.add_argument(
        "--foxglove-allow-origin",
        action="append",
        metavar="ORIGIN",
        help="with --foxglove: also let web pages of ORIGIN connect (e.g. "
        "https://app.foxglove.dev; repeat for several). Local and file origins, and clients "
        "that send none (the desktop app), always may; any other page is refused",
    )
    run.add_argument(
        "--no-lockstep",
        dest="lockstep",
        action="store_false",
        help="simulated fleet above speed-up 1: the vehicles and the radio medium run on the wall "
        "clock, as real vehicles would, instead of taking their time from the ground station",
    )
    run.add_argument(
        "--link-wait",
        type=float,
        default=10.0,
        metavar="S",
        help="after a link loss, without an operator: mission seconds to wait for it to come "
        "back before landing everyone (default 10)",
    )
    run.add_argument(
        "--takeoff-lead",
        type=float,
        metavar="S",
        help="mission seconds between a UAV's take-off and its departure (default: from the "
        "climb to the cruise altitude)",
    )
    run.add_argument(
        "--vehicles-per-process",
        type=int,
        default=None,
        metavar="N",
        help="sim backend: UAVs hosted by each `vehicles sim` process (default: all of them in "
        "one, a leader in its own: fewer processes leave more CPU to the ground station)",
    )
    run.add_argument("--no-live", action="store_true", help="no live view, even in a terminal")
    run.set_defaults(handler=run_command)


def default_log_path(name: str, now: datetime | None = None) -> Path:
    """`./logs/<name>-<UTC yyyymmddThhmmssZ>.mcap` (docs/cli.md)."""
    stamp = (now or datetime.now(UTC)).strftime("%Y%m%dT%H%M%SZ")
    return Path("logs") / f"{name}-{stamp}.mcap"


def resolve_log_path(args: argparse.Namespace, name: str) -> Path:
    """The log file to write; bad input (exit 2) if it exists without --force."""
    if args.log is None:
        path = default_log_path(name)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(
                None, "--log", f"a log file path: {path.parent}/ cannot be created here ({exc})"
            ) from None
    else:
        path = args.log
        if path.suffix.lower() != ".mcap":
            raise InputError(None, "--log", f"a file name ending in .mcap, got {path}")
        parent = path.parent if str(path.parent) else Path(".")
        if not parent.is_dir():
            raise InputError(None, "--log", f"a file in an existing directory, got {path}")
    if path.is_dir():
        raise InputError(None, "--log", f"a file path, got the directory {path}")
    if path.exists() and not args.force:
        raise InputError(None, "--log", f"a new file ({path} exists; add --force to overwrite)")
    return path


def check_arguments(args: argparse.Namespace) -> None:
    """Refuse bad flag values before anything starts (exit 2)."""
    if args.out_readonly and not args.out:
        raise InputError(None, "--out-readonly", "an --out URL to go with it")
    if not (math.isfinite(args.speedup) and 0 < args.speedup <= MAX_SPEEDUP):
        raise InputError(
            None, "--speedup", f"a number in (0, {MAX_SPEEDUP:g}], got {args.speedup:g}"
        )
    if not (math.isfinite(args.link_wait) and args.link_wait >= 0):
        raise InputError(None, "--link-wait", f"a number of seconds >= 0, got {args.link_wait:g}")
    if args.takeoff_lead is not None and not (
        math.isfinite(args.takeoff_lead) and 0 < args.takeoff_lead <= MAX_TAKEOFF_LEAD_S
    ):
        raise InputError(
            None,
            "--takeoff-lead",
            f"a number of seconds in (0, {MAX_TAKEOFF_LEAD_S:g}], got {args.takeoff_lead:g}",
        )
    if args.vehicles_per_process is not None and args.vehicles_per_process < 1:
        raise InputError(None, "--vehicles-per-process", "an integer >= 1")
    if args.foxglove is not None and not 0 <= args.foxglove < 65536:
        raise InputError(
            None, "--foxglove", f"a TCP port in 1..65535 (0: any free port), got {args.foxglove}"
        )


def run_command(args: argparse.Namespace) -> int:  # noqa: C901 (over 15 branches: to split)
    from gcs.drivers import BackendUnavailable, driver_class
    from gcs.drivers.base import DriverTiming, ExternalFleet
    from gcs.drivers.sim import SimFleet
    from gcs.flight.assembly import assemble
    from gcs.flight.clock import MissionClock
    from gcs.flight.core import RunOptions
    from gcs.flight.live import LiveLoop
    from gcs.recording.recording import FlightRecorder, LiveServerError
    from gcs.sim.medium_process import medium_setup
    from gcs.speed import OperatorSocket, socket_path_for
    from gcs.summary import EXIT_ABORTED, exit_status, run_json, summary_renderable
    from gcs.transport.forward import Forwarder
    from gcs.transport.link import Link
    from gcs.transport.signing import RunSigning

    check_arguments(args)
    mission = load_mission(args.file)
    rate = mission.sim.setpoint_rate_hz
    if rate > MAX_SETPOINT_RATE_HZ:
        raise InputError(
            mission.source,
            "sim.setpoint_rate_hz",
            f"at most {MAX_SETPOINT_RATE_HZ:g} Hz, got {rate:g}",
        )
    log_path = resolve_log_path(args, mission.name)  # refused before planning, if it is
    try:
        family = driver_class(mission.fleet.backend)
    except BackendUnavailable as error:
        raise InputError(
            mission.source, "fleet.backend", f"a backend this GCS can fly ({error})"
        ) from None
    from gcs.cli.cmd_mission import plan_with_args  # the planning options `run` shares

    plan = plan_with_args(mission, args)
    console = Console(stderr=True, highlight=False) if args.json else Console(highlight=False)
    if not plan.valid:
        if args.json:
            print(
                json.dumps(
                    {"completed": False, "fleet_size": 0, "reason": f"no valid path: {plan.reason}"}
                )
            )
        console.print(f"{mission.source}: no valid path: {plan.reason}")
        return EXIT_ABORTED
    options = RunOptions(
        speedup=args.speedup,
        setpoint_rate_hz=rate,
        link_wait_s=args.link_wait,
        takeoff_lead_s=args.takeoff_lead,
        autopilot_limits=(
            "apply"
            if mission.vehicle.apply_limits
            else "cap"
            if args.cap_speed or mission.speed.cap_to_safe
            else "refuse"
        ),
    )
    clock = MissionClock(args.speedup)
    formation = plan.formation
    stderr_tty = sys.stderr.isatty()
    simulated = mission.fleet.backend == "sim" and not (args.connect or mission.fleet.connections)
    with ExitStack() as stack:
        signing = RunSigning(mission, insecure=args.insecure, simulated=simulated)  # bad key: 2
        stack.callback(signing.close)
        level, notice = signing.notice()
        if level != "info":
            Console(stderr=True, highlight=False).print(f"[bold yellow]{notice}[/]")
        try:
            recorder = FlightRecorder(
                log_path,
                clock,
                force=args.force,
                serve_port=args.foxglove,
                allowed_origins=tuple(getattr(args, "foxglove_allow_origin", None) or ()),
            )
        except LiveServerError as error:
            raise InputError(None, "--foxglove", f"a free TCP port ({error})") from None
        except OSError as error:  # the folder exists but the system refuses the file
            raise InputError(
                None, "--log", f"a file we may create, got {log_path} ({error})"
            ) from None
        stack.callback(recorder.close)
        if recorder.server_port is not None:
            Console(stderr=True, highlight=False).print(
                f"Foxglove: live on ws://127.0.0.1:{recorder.server_port}"
            )
        recorder.describe(plan, plan_json(plan), time.monotonic())
        recorder.event(level, notice, time.monotonic(), name="signing")
        signing.record_to(recorder.event)

        forwarder = None  # the --out tools' outputs: opened before anything starts
        if args.out:
            try:
                forwarder = Forwarder(args.out, readonly=args.out_readonly)
            except OSError as error:
                raise InputError(
                    None, "--out", f"a MAVLink connection string we can open ({error})"
                ) from None
            stack.callback(forwarder.close)
        if simulated:
            leaders: dict[int, list[tuple[float, float]]] = {}
            for change in mission.speed.changes:
                if change.leader is not None:
                    leaders.setdefault(change.leader, []).append((change.at, change.speed))
            setup = sim_setup(mission, formation, args, leaders, log_path)
            setup.radio = medium_setup(mission)
            # the vehicles get the key; they exit once landed if this process dies (SIGKILL)
            orphan = f"--exit-when-orphaned={os.getpid()}"
            setup.extra_args = (*setup.extra_args, *signing.vehicle_args(), orphan)
            fleet = SimFleet(setup)
        else:
            fleet = ExternalFleet(list(args.connect or mission.fleet.connections))
        stack.callback(fleet.close)
        urls = fleet.start()

        operator = OperatorSocket(socket_path_for(log_path))
        stack.callback(operator.close)
        links = []
        for index, url in enumerate(urls):
            uav = index + 1
            try:
                link = Link(url, uav, capture=_capture(recorder, uav, forwarder))
            except OSError as error:  # a tcp: endpoint refusing, an address not ours...
                if args.connect:
                    where, key = None, "--connect"
                else:
                    where, key = mission.source, f"fleet.connections[{index}]"
                raise InputError(
                    where, key, f"a MAVLink endpoint that accepts a link, got {url} ({error})"
                ) from None
            stack.callback(link.close)
            signing.apply(link, uav)
            links.append(link)
        view = None
        if stderr_tty and not args.json and not args.no_live:
            from gcs.cli.liveview import LiveView

            view = LiveView(Console(stderr=True))
            stack.callback(view.close)
            options = RunOptions(**{**options.__dict__, "interactive": view.interactive})

        def replan(max_speed: float, max_acceleration: float):
            return plan_within_limits(
                plan,
                max_speed,
                max_acceleration,
                connections=tuple(args.connect) if args.connect else None,
                method=args.method,
            )

        timing = DriverTiming(speedup=args.speedup)
        # a full disk or an I/O error stops the file, never the flight: an event of the run
        run = assemble(
            plan, links, family, timing, clock, recorder, options, view=view, replan=replan
        )
        world = None
        if isinstance(fleet, SimFleet) and fleet.world is not None:
            from gcs.flight.lockstep import WorldSync

            world = WorldSync(fleet.world, fleet.world_slots())
        loop = LiveLoop(run, fleet=fleet, operator=operator, forwarder=forwarder, world=world)
        previous = signal.getsignal(signal.SIGINT)

        def on_sigint(signum, frame):
            run.interrupt()
            if run.interrupts >= 3:
                signal.signal(signal.SIGINT, previous)
                raise KeyboardInterrupt

        def on_sigterm(signum, frame):
            raise SystemExit(128 + signum)  # leave through the ExitStack: vehicles stopped

        previous_term = signal.signal(signal.SIGTERM, on_sigterm)
        stack.callback(signal.signal, signal.SIGTERM, previous_term)
        signal.signal(signal.SIGINT, on_sigint)
        stack.callback(signal.signal, signal.SIGINT, previous)
        result = loop.run()
        data = run_json(result, str(log_path), mission.safety_margin)
        data["signing"] = signing.summary()
        data["lockstep"] = world.summary(clock) if world is not None else {"enabled": False}
        data["recording"] = {"ok": recorder.error is None, "error": recorder.error}
        recorder.outcome(data)
        if result.limits_refused:  # before take-off: the mission, not the flight, was wrong
            refused = result.limits_refused[0]
            raise InputError(mission.source, refused.mission_key, refused.expected())

    if args.json:
        print(json.dumps(data, allow_nan=False))
    console.print(summary_renderable(result, str(log_path), mission.safety_margin))
    if recorder.error is not None:
        console.print(f"[bold red]the recording is incomplete: {recorder.error}[/]")
        return max(exit_status(result), EXIT_ABORTED)
    return exit_status(result)


def sim_setup(mission, formation, args, leaders, log_path: Path) -> SimVehicleSetup:
    """The simulated fleet of `mission`: homes on the parking slots at A, the mission's
    vehicle limits, wind and navigation noise, battery capacities, leaders and speedup."""
    from gcs.drivers.sim import SimVehicleSetup

    noise = mission.sim.noise
    direction = math.radians(noise.wind_direction_deg)
    return SimVehicleSetup(
        homes=np.asarray(formation.start_slots),
        origin=mission.origin,
        speedup=args.speedup,
        seed=mission.sim.seed,
        per_process=args.vehicles_per_process or len(formation.start_slots),
        max_speed=mission.vehicle.max_speed,
        max_acceleration=mission.vehicle.max_acceleration,
        wind_mps=(
            noise.wind_mean_mps * math.cos(direction),
            noise.wind_mean_mps * math.sin(direction),
        ),
        gust_mps=noise.wind_gust_mps,
        navigation_noise_m=noise.position_m,
        battery_mah=mission.sim.battery_capacities(len(formation.start_slots)),
        leaders=leaders,
        lockstep=getattr(args, "lockstep", True),
        log_dir=log_path.parent / (log_path.stem + "-vehicles")
        if getattr(args, "verbose", 0)
        else None,
    )


def _capture(recorder: FlightRecorder, uav: int, forwarder: Forwarder | None):
    """Every message of UAV `uav`'s link into the log; what the UAV sent also to the --out
    tools."""

    def capture(direction: str, raw: bytes, message, wall: float) -> None:
        recorder.mavlink(uav, direction, raw, message, wall)
        if forwarder is not None and direction == "rx":
            forwarder.from_uav(raw)

    return capture
