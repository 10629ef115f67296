"""Command line of the radio medium: ``python -m medium.cli --count N --base-port P
--vehicle-ports Q1,...,QN --stations "x,y;..." --range R ...``.

UAV k (0-based) is system `sysid-base + k`; the medium listens for its ground station on UDP
`base-port + k` and talks to the vehicle on `vehicle-ports[k]`. Reports (one JSON object per
`--report-period` simulated seconds, the last one at exit) go as UDP datagrams to `--report
udp:HOST:PORT`; `--trace FILE` writes one JSON line per datagram (tests, debugging).
`--model calibrated` draws each packet's delay and loss from the ns-3 table `--calibration
FILE` (default: the one shipped, `medium/calibration_ns3.json`) instead of `--hop-latency-ms`,
`--jitter-ms` and `--loss` (`medium.radio`), at the load its ground users offer. Bad input
is one line on stderr and exit status 2; SIGINT/SIGTERM stop it (exit 0), and so does the
end of the process that started it (it has nobody left to forward for).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import signal
import socket
import sys
from collections.abc import Sequence

from fleetline.errors import UsageError
from fleetwire.files import FOOTPRINT_BYTES, FileRefused, read_text_bounded
from fleetwire.worldclock import WorldClockError
from medium.calibration import DEFAULT_CALIBRATION, CalibrationTable, load_calibration
from medium.ground_users import DEFAULT_PACKET_BYTES, DEFAULT_RATE_BPS, GroundUser
from medium.medium import Medium, MediumConfig, MediumPortInUse, MediumUav
from medium.pathloss import ThroughBuildings
from medium.radio import MODELS, RadioConfig
from vehicles.cli import _home, _integer, _Parser, _positive, _world_clock
from vehicles.sim import DEFAULT_ORIGIN

PROG = "medium.cli"


def _ports(text: str) -> list[int]:
    try:
        ports = [int(part) for part in text.split(",")]
    except ValueError:
        raise UsageError(f"--vehicle-ports: expected comma-separated ports, got {text!r}") from None
    if not all(0 < p < 65536 for p in ports):
        raise UsageError(f"--vehicle-ports: expected ports in 1..65535, got {text!r}")
    return ports


def _range(text: str) -> float:
    if text.strip().lower() in ("inf", "infinite"):
        return math.inf
    return _positive("--range")(text)


def _xy(flag: str, text: str) -> list[tuple[float, float]]:
    points = []
    for part in filter(None, (p.strip() for p in text.split(";"))):
        try:
            x, y = (float(v) for v in part.split(","))
        except ValueError:
            raise UsageError(f"{flag}: expected 'x,y;x,y;...' in metres, got {part!r}") from None
        if not (math.isfinite(x) and math.isfinite(y)):
            raise UsageError(f"{flag}: expected finite coordinates, got {part!r}")
        points.append((x, y))
    return points


def _ground_users(text: str) -> list[GroundUser]:
    users = []
    for part in filter(None, (p.strip() for p in text.split(";"))):
        try:
            values = [float(v) for v in part.split(",")]
        except ValueError:
            values = []
        if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
            raise UsageError(f"--ground-users: expected 'x,y[,rate_bps];...', got {part!r}")
        rate = values[2] if len(values) == 3 else DEFAULT_RATE_BPS
        if rate <= 0:
            raise UsageError(f"--ground-users: expected a rate > 0 bit/s, got {part!r}")
        users.append(GroundUser(values[0], values[1], rate))
    return users


def _buildings(path: str | None, nlos_range_m: float = 0.0):
    """What blocks links: the obstacles of `--buildings` (`planner.sight.sight_json`'s file)
    with links through them up to `--nlos-range` kept (`medium.pathloss`), or None."""
    if path is None:
        return None
    from planner.sight import sight_from_json

    try:
        sight = sight_from_json(json.loads(read_text_bounded(path, FOOTPRINT_BYTES)))
        return ThroughBuildings(sight, nlos_range_m)
    except (OSError, UnicodeDecodeError, FileRefused, ValueError) as exc:
        raise UsageError(
            f"--buildings: expected a buildings file of the ground station: {path}: {exc}"
        ) from None


def _calibration(model: str, path: str | None) -> CalibrationTable | None:
    """The table of `--model calibrated` (`--calibration`, default the shipped one)."""
    if model != "calibrated":
        if path is not None:
            raise UsageError("--calibration: expected --model calibrated with it")
        return None
    try:
        return load_calibration(path if path is not None else DEFAULT_CALIBRATION)
    except ValueError as exc:
        raise UsageError(f"--calibration: expected a table of gcs eval calibrate ({exc})") from None


def _report_address(text: str) -> tuple[str, int]:
    host, _, port = text.removeprefix("udp:").rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UsageError(f"--report: expected udp:HOST:PORT, got {text!r}")
    return host, int(port)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Emulated multi-hop radio between a GCS and UAVs.")
    add = parser.add_argument
    add("--count", type=_integer("--count", 1, 254), required=True, help="number of UAVs")
    add("--base-port", type=_integer("--base-port", 1, 65535), required=True,
        help="the GCS reaches UAV k at base-port + k")  # fmt: skip
    add("--vehicle-ports", type=_ports, required=True, help="UDP port of each vehicle")
    add("--sysid-base", type=_integer("--sysid-base", 1, 254), default=1)
    add("--positions", required=True, help="start positions 'x,y;...' (local m)")
    add("--stations", required=True, help="base stations 'x,y;...' (local m)")
    add("--range", type=_range, required=True, help="radio range (m, or inf)")
    add("--hop-latency-ms", type=_positive("--hop-latency-ms", True), default=2.0)
    add("--jitter-ms", type=_positive("--jitter-ms", True), default=1.0)
    add("--loss", type=_positive("--loss", True), default=0.0, help="per-hop loss in [0, 1)")
    add("--seed", type=_integer("--seed", 0, 2**63 - 1), default=0)
    add("--model", choices=MODELS, default="simple",
        help="simple: the per-hop latency, jitter and loss; calibrated: the ns-3 table")  # fmt: skip
    add("--calibration", metavar="FILE",
        help="the table of --model calibrated (default: medium/calibration_ns3.json)")  # fmt: skip
    add("--buildings", metavar="FILE",
        help="links whose chord meets one of these obstacles are cut (JSON: polygons, walls)")  # fmt: skip
    add("--nlos-range", type=_positive("--nlos-range", True), default=0.0, metavar="M",
        help="with --buildings: links through them live up to M metres (3GPP UMi NLOS); 0: cut")  # fmt: skip
    add("--speedup", type=_positive("--speedup"), default=1.0)
    add("--home", type=_home, default=DEFAULT_ORIGIN, help="LAT,LON,ALT of local (0,0,0)")
    add("--ground-users", default="", help="'x,y[,rate_bps];...'")
    add("--packet-bytes", type=_integer("--packet-bytes", 1, 65535), default=DEFAULT_PACKET_BYTES)
    add("--report", type=_report_address, help="udp:HOST:PORT for the JSON reports")
    add("--report-period", type=_positive("--report-period"), default=1.0)
    add("--trace", help="write one JSON line per datagram to this file")
    add("--bind", default="127.0.0.1")
    add("--log-level", choices=("debug", "info", "warning", "error"), default="warning")
    add("--world-clock", type=_world_clock, metavar="PATH",
        help="lockstep: take the simulated time from this world clock file")  # fmt: skip
    add("--world-slot", type=_integer("--world-slot", 0, 4096), default=0, metavar="K")
    return parser


def config_from_args(args: argparse.Namespace) -> MediumConfig:
    count = args.count
    if len(args.vehicle_ports) != count:
        raise UsageError(f"--vehicle-ports: expected {count} ports, got {len(args.vehicle_ports)}")
    positions = _xy("--positions", args.positions)
    if len(positions) != count:
        raise UsageError(f"--positions: expected {count} positions, got {len(positions)}")
    stations = _xy("--stations", args.stations)
    if not stations:
        raise UsageError("--stations: expected at least one base station 'x,y'")
    if not args.loss < 1:
        raise UsageError(f"--loss: expected a probability in [0, 1), got {args.loss:g}")
    if args.base_port + count - 1 > 65535:
        raise UsageError("--base-port: base-port + count - 1 must be <= 65535")
    if args.sysid_base + count - 1 > 254:
        raise UsageError("--sysid-base: sysid-base + count - 1 must be <= 254")
    uavs = tuple(
        MediumUav(args.sysid_base + k, args.vehicle_ports[k], args.base_port + k, positions[k])
        for k in range(count)
    )
    return MediumConfig(
        radio=RadioConfig(
            range_m=args.range,
            hop_latency_s=args.hop_latency_ms / 1000.0,
            jitter_s=args.jitter_ms / 1000.0,
            loss=args.loss,
            seed=args.seed,
            model=args.model,
            calibration=_calibration(args.model, args.calibration),
            sight=_buildings(args.buildings, args.nlos_range),
        ),
        stations=tuple(stations),
        uavs=uavs,
        origin=args.home,
        speedup=args.speedup,
        host=args.bind,
        ground_users=tuple(_ground_users(args.ground_users)),
        packet_bytes=args.packet_bytes,
        report_period_s=args.report_period,
        world_clock=args.world_clock,
        world_slot=args.world_slot,
    )


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        config = config_from_args(args)
    except UsageError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    logging.basicConfig(
        level=args.log_level.upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s"
    )
    try:
        medium = Medium(config)
    except WorldClockError as exc:
        print(f"{PROG}: error: --world-clock: {exc}", file=sys.stderr)
        return 2
    except MediumPortInUse as exc:
        print(f"{PROG}: error: --base-port: {exc.strerror}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"{PROG}: error: --bind {args.bind}: cannot listen ({exc.strerror})", file=sys.stderr)
        return 2
    stop = False

    def request_stop(signum: int, frame: object) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)
    reporter = socket.socket(socket.AF_INET, socket.SOCK_DGRAM) if args.report else None
    trace_file = open(args.trace, "w") if args.trace else None  # noqa: SIM115

    def report(payload: dict) -> None:
        try:
            reporter.sendto(json.dumps(payload).encode(), args.report)
        except OSError as exc:  # nobody listening: reports are best effort
            logging.getLogger(PROG).debug("report not sent: %s", exc)

    def trace(record: dict) -> None:
        trace_file.write(json.dumps(record) + "\n")

    parent = os.getppid()  # the medium never outlives the ground station that started it
    try:
        medium.run(
            lambda: stop or os.getppid() != parent,
            report if reporter is not None else None,
            trace if trace_file is not None else None,
        )
    finally:
        medium.close()
        if reporter is not None:
            reporter.close()
        if trace_file is not None:
            trace_file.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
