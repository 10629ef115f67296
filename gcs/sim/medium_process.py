"""The ground station's side of the emulated radio medium (sim backend, `radio.enabled`).

`medium_setup(mission)` says what the medium needs from the mission (base stations A, B and
the extra ones, radio range, the `radio:` section with its model, ground users, seed);
`MediumProcess` starts
`python -m medium.cli` between the GCS and the vehicle processes, always stops it,
and collects its periodic reports (JSON datagrams on a loopback UDP socket: never blocking,
whoever reads them or not). The last report is the run JSON's `radio` object (docs/outputs.md).
"""

from __future__ import annotations

import json
import logging
import signal
import socket
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gcs.sim.children import start_child
from medium.pathloss import ThroughBuildings, nlos_range_m
from planner.sight import Sight, sight_json

log = logging.getLogger(__name__)

#: The run JSON's `radio` keys (docs/outputs.md), plus our extras.
MAX_REPORT_BYTES = 65535
MAX_REPORTS_PER_POLL = 100


@dataclass(frozen=True)
class MediumSetup:
    """The medium of one run."""

    stations: tuple[tuple[float, float], ...]
    range_m: float
    hop_latency_ms: float = 2.0
    jitter_ms: float = 1.0
    loss: float = 0.0
    seed: int = 0
    ground_users: tuple[tuple[float, float, float], ...] = ()  # x, y, rate bit/s
    report_period_s: float = 0.5  # simulated
    model: str = "simple"  # or "calibrated": draws from an ns-3 table (medium.radio)
    calibration: Path | None = None  # the table of "calibrated" (None: the medium's own)
    #: `radio.buildings`: what blocks a link (`planner.sight.sight_json`), None: nothing
    buildings: dict | None = None
    #: links through buildings live up to this long (`medium.pathloss`; 0: all cut)
    nlos_range_m: float = 0.0


def medium_setup(mission) -> MediumSetup | None:
    """The medium of `mission` (None when `radio.enabled` is false)."""
    radio = mission.radio
    if not radio.enabled:
        return None
    stations = mission.base_station_points
    return MediumSetup(
        stations=tuple((float(x), float(y)) for x, y in stations),
        range_m=float(mission.radio_range),
        hop_latency_ms=radio.hop_latency_ms,
        jitter_ms=radio.jitter_ms,
        loss=radio.loss,
        seed=mission.sim.seed,
        ground_users=tuple((u.x, u.y, u.rate_bps) for u in mission.ground_users),
        model=radio.model,
        calibration=radio.calibration,
        buildings=sight_json(mission.obstacles) if radio.buildings else None,
        nlos_range_m=nlos_range(mission),
    )


def nlos_range(mission) -> float:
    """How long a link through buildings may be under the mission's `radio.buildings` model
    (`medium.pathloss`, at the mission's altitude): 0 when every one is cut."""
    radio = mission.radio
    if radio.buildings != "3gpp-umi":
        return 0.0
    return nlos_range_m(mission.radio_range, radio.frequency_ghz, mission.altitude)


def buildings_sight(mission):
    """What the radio of `mission` is blocked by (`medium.radio.LineOfSight`), None: nothing."""
    if not mission.radio.buildings:
        return None
    return ThroughBuildings(Sight(mission.obstacles), nlos_range(mission))


def model_args(setup: MediumSetup) -> list[str]:
    """The medium's flags of the radio model: none for the simple one (its defaults)."""
    if setup.model == "simple":
        return []
    args = ["--model", setup.model]
    if setup.calibration is not None:
        args += ["--calibration", str(setup.calibration)]
    return args


def _points(points) -> str:
    return ";".join(",".join(f"{v:.4f}" for v in point) for point in points)


class MediumProcess:
    """The medium between the GCS and the vehicles: UAV k is reached at `port(k)`."""

    host = "127.0.0.1"

    def __init__(
        self,
        setup: MediumSetup,
        *,
        listen_port: int,
        vehicle_ports: list[int],
        starts: np.ndarray,
        sysid_base: int,
        speedup: float,
        origin,
        extra_args: tuple[str, ...] = (),
        stderr_path: Path | None = None,
    ) -> None:
        self.listen_port = listen_port
        self._reports = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._reports.bind((self.host, 0))
        self._reports.setblocking(False)
        report_port = self._reports.getsockname()[1]
        self._buildings = None
        if setup.buildings is not None:  # the obstacles, for the medium to read
            self._buildings = tempfile.NamedTemporaryFile(  # noqa: SIM115 (closed in close())
                "w", prefix="fleetline-buildings-", suffix=".json", delete=False
            )
            json.dump(setup.buildings, self._buildings)
            self._buildings.close()
            extra_args = ("--buildings", self._buildings.name, *extra_args)
            if setup.nlos_range_m > 0:
                extra_args = ("--nlos-range", f"{setup.nlos_range_m:.6g}", *extra_args)
        cmd = [
            sys.executable, "-m", "medium.cli",
            "--count", str(len(vehicle_ports)),
            "--base-port", str(listen_port),
            "--vehicle-ports", ",".join(map(str, vehicle_ports)),
            "--sysid-base", str(sysid_base),
            f"--positions={_points(np.asarray(starts)[:, :2])}",
            f"--stations={_points(setup.stations)}",
            "--range", f"{setup.range_m!r}",
            "--hop-latency-ms", f"{setup.hop_latency_ms!r}",
            "--jitter-ms", f"{setup.jitter_ms!r}",
            "--loss", f"{setup.loss!r}",
            "--seed", str(setup.seed),
            "--speedup", f"{speedup!r}",
            f"--home={origin.lat:.9f},{origin.lon:.9f},{origin.alt:.3f}",
            f"--ground-users={_points(setup.ground_users)}",
            "--report", f"udp:{self.host}:{report_port}",
            "--report-period", f"{setup.report_period_s!r}",
            *model_args(setup),
            *extra_args,
        ]  # fmt: skip
        self.command = cmd
        log.info("starting %s", " ".join(cmd))
        stderr = open(stderr_path, "wb") if stderr_path else subprocess.DEVNULL  # noqa: SIM115
        try:
            self.process = start_child(cmd, root=Path(__file__).resolve().parents[2], stderr=stderr)
        except OSError:
            self._reports.close()
            if self._buildings is not None:
                Path(self._buildings.name).unlink(missing_ok=True)
            raise
        finally:
            if stderr is not subprocess.DEVNULL:
                stderr.close()
        self.last_report: dict | None = None

    def port(self, k: int) -> int:
        return self.listen_port + k

    def reports(self) -> list[dict]:
        """The reports that arrived since the last call (oldest first)."""
        out = []
        for _ in range(MAX_REPORTS_PER_POLL):
            try:
                data = self._reports.recv(MAX_REPORT_BYTES)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                log.debug("medium report: %s", exc)
                break
            try:
                report = json.loads(data)
            except ValueError:
                continue
            if isinstance(report, dict):
                out.append(report)
        if out:
            self.last_report = out[-1]
        return out

    def exit_code(self) -> int | None:
        return self.process.poll()

    def close(self) -> None:
        """Stop the process (SIGTERM, then SIGKILL), keep its last report."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(timeout=3.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=3.0)
        self.reports()
        self._reports.close()
        if self._buildings is not None:
            Path(self._buildings.name).unlink(missing_ok=True)
