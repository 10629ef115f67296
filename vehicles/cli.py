"""Command line of the simulated vehicles: ``vehicles sim --count N --base-port P ...``.

Bad input (a flag, a value, a port in use) is one line on stderr and exit status 2.
SIGINT and SIGTERM stop the simulation cleanly (exit 0): with a vehicle in the air, the first
one makes every flying vehicle LAND and the process exits once all are disarmed (a stop never
drops a UAV from the sky); a second one stops at once.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import signal
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from fleetline.errors import UsageError
from fleetwire.geodesy import Origin
from fleetwire.messages import GCS_SYSTEM_ID
from fleetwire.worldclock import WorldClockError, check_world_clock
from vehicles.autopilot import AutopilotConfig, FailsafeConfig
from vehicles.dynamics import Airframe, Disturbances, DynamicsConfig
from vehicles.fleet_speed import LeaderRequest
from vehicles.link import PortInUseError
from vehicles.orphan import OrphanExit
from vehicles.signing import KeyFileError, read_key_file
from vehicles.sim import DEFAULT_ORIGIN, SimConfig, Simulation, VehicleSpec
from vehicles.telemetry import TelemetryRates

PROG = "vehicles"
DEFAULT_SPACING_M = 5.0


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse prints usage too)
        raise UsageError(message)


def _positive(flag: str, allow_zero: bool = False):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise UsageError(f"{flag}: expected a number, got {text!r}") from None
        if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
            expected = ">= 0" if allow_zero else "> 0"
            raise UsageError(f"{flag}: expected a finite number {expected}, got {text!r}")
        return value

    return parse


def _integer(flag: str, low: int, high: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise UsageError(f"{flag}: expected an integer, got {text!r}") from None
        if not low <= value <= high:
            raise UsageError(f"{flag}: expected an integer in [{low}, {high}], got {value}")
        return value

    return parse


def _floats(flag: str, text: str, sizes: tuple[int, ...]) -> list[float]:
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        raise UsageError(
            f"{flag}: expected {' or '.join(map(str, sizes))} comma-separated numbers, got {text!r}"
        ) from None
    if len(values) not in sizes or not all(math.isfinite(v) for v in values):
        raise UsageError(
            f"{flag}: expected {' or '.join(map(str, sizes))} comma-separated finite numbers, got {text!r}"
        )
    return values


def _home(text: str) -> Origin:
    lat, lon, alt = _floats("--home", text, (3,))
    if abs(lat) > 90 or abs(lon) > 180:
        raise UsageError(
            f"--home: expected LAT,LON,ALT with |LAT| <= 90 and |LON| <= 180, got {text!r}"
        )
    return Origin(lat, lon, alt)


def _wind(text: str) -> tuple[float, float, float]:
    values = _floats("--wind", text, (2, 3))
    return (values[0], values[1], values[2] if len(values) == 3 else 0.0)


def _out(text: str) -> tuple[str, int]:
    address = text.removeprefix("udpout:")
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UsageError(
            f"--out: expected udpout:HOST:PORT (e.g. udpout:127.0.0.1:14550), got {text!r}"
        )
    return host, int(port)


def _leader_requests(text: str) -> tuple[LeaderRequest, ...]:
    requests = []
    for item in filter(None, (part.strip() for part in text.split(","))):
        when, _, speed = item.partition(":")
        try:
            request = LeaderRequest(float(when), float(speed))
        except ValueError:
            raise UsageError(
                f"--leader-requests: expected T:V,... (mission time s : speed m/s), got {item!r}"
            ) from None
        if not (math.isfinite(request.mission_time_s) and math.isfinite(request.speed_mps)):
            raise UsageError(f"--leader-requests: expected finite numbers, got {item!r}")
        if request.mission_time_s < 0 or request.speed_mps < 0:
            raise UsageError(f"--leader-requests: expected T >= 0 and V >= 0, got {item!r}")
        requests.append(request)
    if not requests:
        raise UsageError(
            f"--leader-requests: expected T:V,... (mission time s : speed m/s), got {text!r}"
        )
    return tuple(requests)


def _position_list(source: str, items: list) -> list[tuple[float, float, float]]:
    positions = []
    for k, item in enumerate(items):
        values = item if isinstance(item, list) else None
        if (
            values is None
            or len(values) not in (2, 3)
            or not all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                for v in values
            )
        ):
            raise UsageError(
                f"{source}[{k}]: expected [x, y] or [x, y, z] in metres (local ENU), got {item!r}"
            )
        positions.append(
            (float(values[0]), float(values[1]), float(values[2]) if len(values) == 3 else 0.0)
        )
    return positions


def _positions(text: str) -> list[tuple[float, float, float]]:
    items = []
    for k, part in enumerate(p.strip() for p in text.split(";")):
        try:
            items.append([float(v) for v in part.split(",")])
        except ValueError:
            raise UsageError(
                f"--positions[{k}]: expected x,y or x,y,z in metres, got {part!r}"
            ) from None
    return _position_list("--positions", items)


def _positions_file(path: str) -> list[tuple[float, float, float]]:
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise UsageError(
            f"{path}: expected a readable JSON file ({exc.__class__.__name__})"
        ) from None
    if not isinstance(data, list):
        raise UsageError(f"{path}: expected a JSON list of [x, y] or [x, y, z] positions")
    return _position_list(path, data)


def _battery_mah(text: str) -> tuple[float, ...]:
    """`MAH` or `MAH,MAH,...` (one per vehicle, checked against --count later)."""
    try:
        values = tuple(float(part) for part in text.split(","))
    except ValueError:
        values = ()
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise UsageError(
            f"--battery-mah: expected a number > 0 or comma-separated numbers > 0 (mAh, one "
            f"per vehicle), got {text!r}"
        )
    return values


def _signing_key(path: str) -> bytes:
    try:
        return read_key_file(path)
    except KeyFileError as exc:
        raise UsageError(f"--signing-key-file: {exc}") from None


def _world_clock(path: str) -> Path:
    try:
        return check_world_clock(path)
    except WorldClockError as exc:
        raise UsageError(f"--world-clock: {exc}") from None


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Simulated MAVLink vehicles (ArduCopter-compatible).")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    sim = commands.add_parser("sim", help="run N simulated vehicles, one UDP port each")
    add = sim.add_argument
    add(
        "--count",
        type=_integer("--count", 1, 10000),
        default=1,
        help="number of vehicles (default 1)",
    )
    add(
        "--base-port",
        type=_integer("--base-port", 1, 65535),
        required=True,
        help="vehicle k listens on base-port + k",
    )
    add(
        "--sysid-base",
        type=_integer("--sysid-base", 1, 254),
        default=1,
        help="vehicle k is system sysid-base + k",
    )
    add(
        "--speedup",
        type=_positive("--speedup"),
        default=1.0,
        help="simulated clock / wall clock (default 1)",
    )
    add(
        "--out",
        type=_out,
        default=None,
        help="also send to udpout:HOST:PORT (e.g. QGroundControl's 14550)",
    )
    add("--bind", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    add(
        "--seed",
        type=_integer("--seed", 0, 2**63 - 1),
        default=0,
        help="seed of wind and navigation noise",
    )
    add(
        "--home",
        type=_home,
        default=DEFAULT_ORIGIN,
        help="LAT,LON,ALT of local (0,0,0) (default 45.764,4.8357,170)",
    )
    where = sim.add_mutually_exclusive_group()
    where.add_argument(
        "--positions",
        type=_positions,
        help="start positions 'x,y[,z];x,y[,z];...' (ENU m from --home)",
    )
    where.add_argument(
        "--positions-file",
        type=_positions_file,
        help="JSON list of [x, y] or [x, y, z] start positions",
    )
    add(
        "--leader-requests",
        type=_leader_requests,
        default=(),
        help="T:V,... send speed V to the GCS at mission time T",
    )
    add(
        "--leader-sysid",
        type=_integer("--leader-sysid", 1, 255),
        help="the vehicle acting as leader (default: the first)",
    )
    add(
        "--telemetry-hz",
        type=_positive("--telemetry-hz", True),
        default=10.0,
        help="position and attitude rate (10)",
    )
    add(
        "--truth-hz",
        type=_positive("--truth-hz", True),
        help="SIM_STATE (true state) rate (default: telemetry rate)",
    )
    add(
        "--status-hz",
        type=_positive("--status-hz", True),
        default=1.0,
        help="SYS_STATUS, BATTERY_STATUS, ... rate (1)",
    )
    add(
        "--setpoint-timeout",
        type=_positive("--setpoint-timeout"),
        default=1.0,
        help="GUID_TIMEOUT: velocity/acceleration targets stop after this (s, 1; ArduCopter 3)",
    )
    add(
        "--gcs-timeout",
        type=_positive("--gcs-timeout"),
        default=5.0,
        help="no GCS heartbeat this long: hold (s, 5)",
    )
    add(
        "--gcs-hold",
        type=_positive("--gcs-hold", True),
        default=5.0,
        help="then hold this long before landing (s, 5)",
    )
    add(
        "--gcs-sysid",
        type=_integer("--gcs-sysid", 1, 255),
        default=GCS_SYSTEM_ID,
        help=f"system id of the GCS ({GCS_SYSTEM_ID})",
    )
    add(
        "--timeout-floor",
        type=_positive("--timeout-floor", True),
        default=0.25,
        help="wall-clock floor of timeouts (s)",
    )
    add(
        "--boot-time",
        type=_positive("--boot-time", True),
        default=1.0,
        help="seconds before arming is possible (1)",
    )
    add(
        "--disarm-delay",
        type=_positive("--disarm-delay", True),
        default=10.0,
        help="landed and armed: disarm after (s)",
    )
    add(
        "--max-speed",
        type=_positive("--max-speed"),
        default=15.0,
        help="horizontal speed limit m/s (15)",
    )
    add(
        "--max-acceleration",
        type=_positive("--max-acceleration"),
        default=6.0,
        help="horizontal m/s^2 (6)",
    )
    add(
        "--max-climb", type=_positive("--max-climb"), default=2.5, help="climb rate limit m/s (2.5)"
    )
    add(
        "--max-descent",
        type=_positive("--max-descent"),
        default=1.5,
        help="descent rate limit m/s (1.5)",
    )
    add("--wind", type=_wind, default=(0.0, 0.0, 0.0), help="mean wind E,N[,U] m/s (0,0)")
    add(
        "--gust",
        type=_positive("--gust", True),
        default=1.0,
        help="gust standard deviation m/s per axis (1)",
    )
    add(
        "--nav-noise",
        type=_positive("--nav-noise", True),
        default=0.2,
        help="navigation noise std dev m (0.2)",
    )
    add("--no-noise", action="store_true", help="no gusts and no navigation noise")
    add(
        "--battery-mah",
        type=_battery_mah,
        metavar="MAH[,MAH...]",
        help="battery capacity mAh, for every vehicle or one per vehicle (8000)",
    )
    add(
        "--rate-hz",
        type=_positive("--rate-hz"),
        default=100.0,
        help="dynamics rate in simulated Hz (100)",
    )
    add("--log-level", choices=("debug", "info", "warning", "error"), default="warning")
    add(
        "--signing-key-file",
        type=_signing_key,
        dest="signing_key",
        metavar="PATH",
        help="MAVLink 2 signing: owner-only file whose first line is the passphrase (key = its "
        "SHA-256, as MAVProxy's `signing setup`); without it SETUP_SIGNING sets a key while "
        "disarmed",
    )
    add(
        "--world-clock",
        type=_world_clock,
        metavar="PATH",
        help="lockstep: take the simulated time from this world clock file (written by the "
        "ground station that started this process; fleetwire.worldclock)",
    )
    add(
        "--world-slot",
        type=_integer("--world-slot", 0, 4096),
        default=0,
        metavar="K",
        help="this process's slot in the world clock file (0)",
    )
    add(
        "--exit-when-orphaned",
        nargs="?",
        const=0,
        type=_integer("--exit-when-orphaned", 0, 2**22),
        metavar="PID",
        help="exit once the parent process (PID, default: the one at start) is gone and every "
        "vehicle is disarmed on the ground",
    )
    return parser


def config_from_args(args: argparse.Namespace) -> SimConfig:
    count = args.count
    positions = args.positions or args.positions_file
    if positions is None:
        positions = [(k * DEFAULT_SPACING_M, 0.0, 0.0) for k in range(count)]
    elif len(positions) != count:
        raise UsageError(
            f"--positions: expected {count} positions (one per vehicle), got {len(positions)}"
        )
    if args.base_port + count - 1 > 65535:
        raise UsageError(
            f"--base-port: base-port + count - 1 must be <= 65535, got {args.base_port + count - 1}"
        )
    if args.sysid_base + count - 1 > 254:
        raise UsageError(
            f"--sysid-base: sysid-base + count - 1 must be <= 254, got {args.sysid_base + count - 1}"
        )
    sysids = range(args.sysid_base, args.sysid_base + count)
    leader = args.leader_sysid if args.leader_sysid is not None else args.sysid_base
    if args.leader_requests and leader not in sysids:
        raise UsageError(
            f"--leader-sysid: expected one of this process's system ids {sysids[0]}..{sysids[-1]}, got {leader}"
        )
    if args.gcs_sysid in sysids:
        raise UsageError(
            f"--gcs-sysid: must differ from the vehicles' system ids, got {args.gcs_sysid}"
        )
    batteries: tuple[float | None, ...] = (None,) * count
    if args.battery_mah is not None:
        if len(args.battery_mah) not in (1, count):
            raise UsageError(
                f"--battery-mah: expected 1 or {count} numbers (one per vehicle), "
                f"got {len(args.battery_mah)}"
            )
        batteries = args.battery_mah * (count if len(args.battery_mah) == 1 else 1)
    disturbances = Disturbances(
        wind_mean_mps=args.wind,
        gust_sigma_mps=args.gust,
        gust_sigma_vertical_mps=0.3 * args.gust,
        navigation_sigma_m=args.nav_noise,
        navigation_sigma_vertical_m=1.5 * args.nav_noise,
    )
    if args.no_noise:
        disturbances = disturbances.scaled(0.0)
    airframe = Airframe(
        max_speed_mps=args.max_speed,
        max_acceleration_mps2=args.max_acceleration,
        max_climb_mps=args.max_climb,
        max_descent_mps=args.max_descent,
    )
    telemetry = TelemetryRates(
        position_hz=args.telemetry_hz,
        attitude_hz=args.telemetry_hz,
        truth_hz=args.telemetry_hz if args.truth_hz is None else args.truth_hz,
        status_hz=args.status_hz,
    )
    failsafe = FailsafeConfig(
        setpoint_timeout_s=args.setpoint_timeout,
        gcs_timeout_s=args.gcs_timeout,
        gcs_hold_s=args.gcs_hold,
        wall_floor_s=args.timeout_floor,
        gcs_system=args.gcs_sysid,
    )
    autopilot = replace(
        AutopilotConfig(),
        failsafe=failsafe,
        telemetry=telemetry,
        # WPNAV_SPEED: ArduCopter's GUIDED controller is bounded by it, as ours by the airframe
        waypoint_speed_mps=args.max_speed,
        boot_time_s=args.boot_time,
        disarm_delay_s=args.disarm_delay,
        takeoff_speed_mps=min(2.5, args.max_climb),
        land_speed_high_mps=min(1.5, args.max_descent),
        land_speed_mps=min(0.5, args.max_descent),
    )
    vehicles = tuple(
        VehicleSpec(sysid, args.base_port + k, positions[k], batteries[k])
        for k, sysid in enumerate(sysids)
    )
    return SimConfig(
        vehicles=vehicles,
        host=args.bind,
        out=args.out,
        speedup=args.speedup,
        seed=args.seed,
        origin=args.home,
        dynamics=DynamicsConfig(
            step_s=1.0 / args.rate_hz, airframe=airframe, disturbances=disturbances
        ),
        autopilot=autopilot,
        leader_sysid=leader if args.leader_requests else None,
        leader_requests=args.leader_requests,
        signing_key=args.signing_key,
        world_clock=args.world_clock,
        world_slot=args.world_slot,
    )


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        config = config_from_args(args)
    except UsageError as exc:
        print(f"{PROG} sim: error: {exc}", file=sys.stderr)
        return 2
    logging.basicConfig(
        level=args.log_level.upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s"
    )
    try:
        simulation = Simulation(config)
    except WorldClockError as exc:
        print(f"{PROG} sim: error: --world-clock: {exc}", file=sys.stderr)
        return 2
    except PortInUseError as exc:
        print(f"{PROG} sim: error: --base-port: {exc.strerror}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(
            f"{PROG} sim: error: --bind {args.bind}: cannot listen ({exc.strerror})",
            file=sys.stderr,
        )
        return 2
    stops = 0  # SIGINT/SIGTERM received: the first lands what flies, the second stops now

    def request_stop(signum: int, frame: object) -> None:
        nonlocal stops
        stops += 1

    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)
    first, last = config.vehicles[0], config.vehicles[-1]
    print(
        f"{PROG}: {len(config.vehicles)} vehicle(s), sysid {first.sysid}-{last.sysid}, "
        f"udp {config.host}:{first.port}-{last.port}, speedup {config.speedup:g}",
        file=sys.stderr,
        flush=True,
    )
    try:
        orphan = None
        if args.exit_when_orphaned is not None:
            orphan = OrphanExit(simulation.autopilots, args.exit_when_orphaned or None)

        def should_stop() -> bool:
            asked = stops >= 2 or (stops == 1 and simulation.land_before_stopping())
            done = asked or (orphan is not None and orphan())
            if orphan is not None and orphan.orphaned:
                simulation.leave_world()  # no ground station to wait for: failsafes on
            return done

        stats = simulation.run(should_stop)
    finally:
        simulation.close()
    print(
        f"{PROG}: stopped after {stats.sim_s:.1f} s simulated in {stats.wall_s:.1f} s"
        + (f" (clock slipped {stats.slipped_sim_s:.2f} s)" if stats.slipped_sim_s else ""),
        file=sys.stderr,
    )
    return 0
