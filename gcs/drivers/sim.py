"""The simulated backend: `vehicles sim` processes and their (ArduCopter-like) driver.

`SimFleet` starts one `vehicles sim` process per UAV (or one process hosting every UAV with
`per_process > 1`), each UAV on its own free loopback UDP port, homed on its parking slot, with
the run's speedup; it always stops them (`close`, also on exceptions and Ctrl-C) and reports a
process that died. `SimDriver` speaks to one simulated UAV: ArduCopter mode numbers, mode
changes by `MAV_CMD_DO_SET_MODE` (acknowledged), `MAV_CMD_NAV_TAKEOFF` to a relative altitude,
acceleration feed-forward, and speed changes whose effective time and sequence number the
vehicle honours.
"""

from __future__ import annotations

import logging
import shutil
import signal
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fleetwire.messages import MISSION_TIME_NAME, SETPOINT_EXTRAPOLATION_S, encode_mission_time
from fleetwire.modes import COPTER_MODE, COPTER_MODE_NAME
from fleetwire.worldclock import WorldClockMaster
from gcs.drivers.base import CommandSpec, Driver, Fleet, FleetProblem, FlightMode
from gcs.geodesy import Origin
from gcs.sim.children import start_child
from gcs.sim.medium_process import MediumProcess, MediumSetup
from gcs.transport.link import mavutil
from vehicles.ports import free_udp_ports

log = logging.getLogger(__name__)
mavlink = mavutil.mavlink

#: ArduCopter custom modes the simulated vehicles implement (see tests/sitl/README.md).
COPTER_MODES = {
    FlightMode.GUIDED: COPTER_MODE["GUIDED"],
    FlightMode.HOLD: COPTER_MODE["LOITER"],
    FlightMode.LAND: COPTER_MODE["LAND"],
}
_MODE_OF_NUMBER = {number: mode for mode, number in COPTER_MODES.items()}
#: Wall seconds a vehicle process may take to land its UAVs and exit when the fleet is closed.
LANDING_GRACE_S = 60.0


class SimDriver(Driver):
    """Driver of one `vehicles sim` UAV (ArduCopter-compatible MAVLink)."""

    family = "sim"
    connect_timeout_s = 30.0
    connect_wall_floor_s = 20.0  # a Python process starting on a busy 2-core machine
    initialise_timeout_s = 30.0
    #: Streams the ground station never reads are turned off: decoding them is CPU that a
    #: busy machine does not have (they are a third of what the vehicles send).
    stream_rates_hz = {
        mavlink.MAVLINK_MSG_ID_ATTITUDE: 0.0,
        mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.0,
    }

    def mode_command(self, mode: FlightMode) -> CommandSpec:
        return CommandSpec(
            mavlink.MAV_CMD_DO_SET_MODE,
            (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, COPTER_MODES[mode], 0, 0, 0, 0, 0),
            label=f"mode {mode.value}",
        )

    def current_mode(self) -> FlightMode | None:
        return _MODE_OF_NUMBER.get(self.telemetry.custom_mode)

    def describe_mode(self) -> str:
        number = self.telemetry.custom_mode
        return COPTER_MODE_NAME.get(number, str(number))

    def takeoff_command(self, relative_altitude: float) -> CommandSpec | None:
        return CommandSpec(
            mavlink.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, relative_altitude), label="takeoff"
        )

    def on_heartbeat_sent(self, now: float) -> None:
        """The vehicles' mission clock: NAMED_VALUE_INT "MSN_TIME" = mission time in ms at
        sending (vehicles/fleet_speed.py); a leader sends its requests on that clock."""
        self.on_mission_clock_changed(now)

    def on_mission_clock_changed(self, now: float) -> None:
        mission_time = self.mission_clock(now)
        if mission_time is None:
            return
        msg = self.link.mav.named_value_int_encode(
            self.time_boot_ms(now), MISSION_TIME_NAME, encode_mission_time(mission_time)
        )
        self.link.send(msg, now)

    @property
    def accepts_acceleration_feedforward(self) -> bool:
        return True

    @property
    def setpoint_horizon_s(self) -> float:
        return SETPOINT_EXTRAPOLATION_S

    @property
    def honours_speed_change_time(self) -> bool:
        return True

    @property
    def home_tolerance_m(self) -> float:
        return 0.5


@dataclass
class SimVehicleSetup:
    """How to start the simulated UAVs (what `SimFleet` passes to `vehicles sim`)."""

    homes: np.ndarray  # (N, 2) local x, y of each UAV's start (its parking slot at A)
    origin: Origin  # the mission's origin: the vehicles' local frame is the mission's
    speedup: float = 1.0
    seed: int = 1
    sysid_base: int = 1
    per_process: int = 1  # UAVs per `vehicles sim` process
    max_speed: float | None = None
    max_acceleration: float | None = None
    wind_mps: tuple[float, float] = (0.0, 0.0)  # mean wind east, north
    gust_mps: float | None = None
    navigation_noise_m: float | None = None
    battery_mah: tuple[float, ...] | None = None  # one capacity per UAV (None: the airframe's)
    leaders: dict[int, list[tuple[float, float]]] = field(default_factory=dict)
    extra_args: tuple[str, ...] = ()
    log_dir: Path | None = None  # where each process's stderr goes (None: discarded)
    #: links through the radio medium (gcs.sim.medium_process); None: direct
    radio: MediumSetup | None = None
    #: lockstep: the vehicles and the medium take their time from the ground station's mission
    #: clock (fleetwire.worldclock) when the speed-up is above 1; False: the wall clock
    lockstep: bool = True

    @property
    def in_lockstep(self) -> bool:
        return self.lockstep and self.speedup > 1

    def groups(self) -> list[list[int]]:
        """UAV indexes (0-based) per process: runs of consecutive UAVs (a process numbers its
        vehicles' system ids consecutively), at most `per_process` long; a leader (one per
        process) always gets a process of its own."""
        leaders = {uav - 1 for uav in self.leaders}
        groups: list[list[int]] = []
        for k in range(len(self.homes)):
            alone = k in leaders
            if (
                alone
                or not groups
                or len(groups[-1]) >= self.per_process
                or groups[-1][0] in leaders
            ):
                groups.append([k])
            else:
                groups[-1].append(k)
        return groups


class SimFleet(Fleet):
    """Starts and always stops the `vehicles sim` processes of a run."""

    host = "127.0.0.1"

    def __init__(self, setup: SimVehicleSetup) -> None:
        self.setup = setup
        #: the world clock the processes follow (lockstep), slot k = process k, the medium last
        self.world: WorldClockMaster | None = None
        self._world_dir: Path | None = None
        self.processes: list[subprocess.Popen] = []
        self.groups: list[tuple[int, ...]] = []  # UAV ids (1-based) of each process
        self.ports: dict[int, int] = {}  # UAV id -> UDP port
        self._reported: set[int] = set()
        self.medium: MediumProcess | None = None

    def start(self) -> list[str]:
        groups = self.setup.groups()
        if self.setup.in_lockstep:
            self._world_dir = Path(tempfile.mkdtemp(prefix="fleetline-world-"))  # owner-only
            slots = len(groups) + (self.setup.radio is not None)
            self.world = WorldClockMaster(self._world_dir / "clock", slots, self.setup.speedup)
        for group in groups:
            port = free_udp_ports(len(group), self.host)
            for i, k in enumerate(group):
                self.ports[k + 1] = port + i
            self.processes.append(self._spawn(group, port))
            self.groups.append(tuple(k + 1 for k in group))
        if self.setup.radio is not None:  # every link goes through the radio medium
            self.medium = self._start_medium()
            return [f"udpout:{self.host}:{self.medium.port(k)}" for k in range(len(self.ports))]
        return [f"udpout:{self.host}:{self.ports[uav]}" for uav in sorted(self.ports)]

    def _start_medium(self) -> MediumProcess:
        s = self.setup
        return MediumProcess(
            s.radio,
            listen_port=free_udp_ports(len(self.ports), self.host),
            vehicle_ports=[self.ports[uav] for uav in sorted(self.ports)],
            starts=s.homes,
            sysid_base=s.sysid_base,
            speedup=s.speedup,
            origin=s.origin,
            extra_args=self._world_args(len(self.processes)),
            stderr_path=s.log_dir / "medium.log" if s.log_dir is not None else None,
        )

    def _world_args(self, slot: int) -> tuple[str, ...]:
        """The command-line flags of a process following the world clock in `slot`."""
        if self.world is None:
            return ()
        return ("--world-clock", str(self.world.path), "--world-slot", str(slot))

    def world_slots(self) -> list[str]:
        """Who follows the world clock, by slot: each vehicle process, then the medium."""
        names = [f"vehicle process of UAV {', '.join(map(str, uavs))}" for uavs in self.groups]
        return names + (["radio medium"] if self.setup.radio is not None else [])

    def radio_reports(self) -> list[dict]:
        """The radio medium's reports since the last call (none without a medium)."""
        return self.medium.reports() if self.medium is not None else []

    def vehicle_command(self, group: list[int], port: int) -> list[str]:
        """The `vehicles sim` command line for UAVs `group` (0-based, consecutive ports)."""
        s = self.setup
        origin = s.origin
        positions = ";".join(f"{s.homes[k][0]:.4f},{s.homes[k][1]:.4f}" for k in group)
        cmd = [
            sys.executable,
            "-m",
            "vehicles",
            "sim",
            "--count",
            str(len(group)),
            "--base-port",
            str(port),
            "--sysid-base",
            str(s.sysid_base + group[0]),
            "--speedup",
            f"{s.speedup:g}",
            "--seed",
            str(s.seed),
            # FLAG=VALUE: a value starting with "-" (a negative coordinate) is not an option
            f"--home={origin.lat:.9f},{origin.lon:.9f},{origin.alt:.3f}",
            f"--positions={positions}",
        ]
        if s.max_speed is not None:
            cmd += ["--max-speed", f"{s.max_speed:g}"]
        if s.max_acceleration is not None:
            cmd += ["--max-acceleration", f"{s.max_acceleration:g}"]
        if any(s.wind_mps):
            cmd += [f"--wind={s.wind_mps[0]:g},{s.wind_mps[1]:g}"]
        if s.gust_mps is not None:
            cmd += ["--gust", f"{s.gust_mps:g}"]
        if s.navigation_noise_m is not None:
            cmd += ["--nav-noise", f"{s.navigation_noise_m:g}"]
        if s.battery_mah is not None:
            cmd += ["--battery-mah", ",".join(f"{s.battery_mah[k]:g}" for k in group)]
        if len(group) == 1 and group[0] + 1 in s.leaders:
            requests = ",".join(f"{at:g}:{speed:g}" for at, speed in s.leaders[group[0] + 1])
            cmd += ["--leader-requests", requests, "--leader-sysid", str(s.sysid_base + group[0])]
        slot = len(self.processes)  # the process about to start
        return cmd + list(s.extra_args) + list(self._world_args(slot))

    def poll(self) -> list[FleetProblem]:
        problems = []
        for index, process in enumerate(self.processes):
            code = process.poll()
            if code is not None and index not in self._reported:
                self._reported.add(index)
                if self.world is not None:
                    self.world.release(index)  # nobody waits for a process that exited
                uavs = self.groups[index]
                who = ", ".join(map(str, uavs))
                text = f"vehicle process of UAV {who} (pid {process.pid}) exited with {code}"
                problems.append(FleetProblem(text, uavs))
        code = self.medium.exit_code() if self.medium is not None else None
        if code is not None and -1 not in self._reported:
            self._reported.add(-1)
            if self.world is not None:
                self.world.release(len(self.processes))
            text = f"radio medium (pid {self.medium.process.pid}) exited with {code}"
            problems.append(FleetProblem(text, tuple(sorted(self.ports))))
        return problems

    def close(self) -> None:
        """SIGTERM every process, then SIGKILL what is still alive after a grace period. A
        vehicle process asked to stop while one of its UAVs flies lands it first (`vehicles
        sim`: the first SIGTERM lands, the process exits once every vehicle is disarmed): the
        grace period is long enough for a landing."""
        if self.medium is not None:
            self.medium.close()
        for process in self.processes:
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
        for process in self.processes:
            try:
                process.wait(timeout=LANDING_GRACE_S)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(timeout=3.0)
        for process in self.processes:
            if process.stderr is not None and not process.stderr.closed:
                process.stderr.close()
        if self.world is not None:
            self.world.close()
            self.world = None
        if self._world_dir is not None:
            shutil.rmtree(self._world_dir, ignore_errors=True)
            self._world_dir = None

    def _spawn(self, group: list[int], port: int) -> subprocess.Popen:
        cmd = self.vehicle_command(group, port)
        log.info("starting %s", " ".join(cmd))
        stderr = subprocess.DEVNULL
        if self.setup.log_dir is not None:
            self.setup.log_dir.mkdir(parents=True, exist_ok=True)
            stderr = open(self.setup.log_dir / f"vehicles-{group[0] + 1}.log", "wb")  # noqa: SIM115
        try:
            return start_child(cmd, root=Path(__file__).resolve().parents[2], stderr=stderr)
        finally:
            if stderr is not subprocess.DEVNULL:
                stderr.close()
