"""Launch plans for SITL fleets: one ArduPilot or PX4 SITL instance per UAV, each with its home
on its parking slot at A, its system id and its ports, following each autopilot's
multi-vehicle conventions; plus the matching `fleet.connections`.

Pure: it computes commands and text, it starts nothing (`gcs sitl launch-plan` prints them).

* ArduPilot (`Tools/autotest/sim_vehicle.py` in an ArduPilot checkout): instance i
  (`-I i`) serves SERIAL0 on TCP 5760+10i (the GCS connects there, so no MAVProxy is started
  on it) and SERIAL1/SERIAL2 on TCP 5762+10i / 5763+10i (for MAVProxy or QGroundControl to
  watch); the system id is set with `--sysid` (SYSID_THISMAV); the home with
  `--custom-location=lat,lon,alt,heading`.
* PX4 (`build/px4_sitl_default/bin/px4` in a PX4-Autopilot checkout built with
  `make px4_sitl`, SIH quad-X, airframe 10040): instance i (`-i i`) has system id i+1
  (MAV_SYS_ID), sends its offboard/API link towards UDP 14540+i (the GCS listens there) and its
  GCS link from UDP 18570+i towards 14550 (QGroundControl's port); the home is
  PX4_HOME_LAT/LON/ALT. Instances above 9 all share offboard port 14549, so a PX4 fleet has at
  most 10 UAVs here.
"""

from __future__ import annotations

import dataclasses
import math
import shlex
from dataclasses import dataclass

import numpy as np

from fleetline.errors import FleetlineError
from gcs.errors import InputError
from gcs.geodesy import enu_to_geodetic
from gcs.mission import Mission
from gcs.planning import MissionPlan, plan_mission

AUTOPILOTS = ("ardupilot", "px4")

#: ArduPilot SITL: TCP port of SERIAL0 of instance 0, and the per-instance step.
ARDUPILOT_SERIAL0_PORT = 5760
ARDUPILOT_SERIAL1_PORT = 5762
ARDUPILOT_PORT_STEP = 10
#: PX4 SITL: remote UDP port of the offboard/API link of instance 0, and of the GCS link.
PX4_OFFBOARD_PORT = 14540
PX4_GCS_LOCAL_PORT = 18570
QGC_PORT = 14550
#: PX4 SITL instances 10 and above all send their offboard link to 14549.
PX4_MAX_INSTANCES = 10
#: PX4 SIH quadrotor (airframe 10040) and its simulator model name.
PX4_AIRFRAME = 10040
PX4_MODEL = "sihsim_quadx"


class NoValidPath(FleetlineError):
    """The mission has no valid path: there is no fleet to launch."""


@dataclass(frozen=True)
class SitlVehicle:
    """One SITL instance: which UAV, where its home is, how to start it and reach it."""

    uav_id: int  # 1..N, formation order
    system_id: int
    instance: int  # the autopilot's instance number (0-based)
    latitude: float  # degrees
    longitude: float  # degrees
    altitude: float  # m AMSL (the mission origin's altitude: the slots are on the ground)
    heading_deg: float  # compass heading (clockwise from north) along the parking row
    command: str  # shell command line that starts the instance
    connection: str  # mavutil connection string for `fleet.connections`
    watch: str  # where MAVProxy / QGroundControl can follow this UAV at the same time


@dataclass(frozen=True)
class LaunchPlan:
    """The SITL fleet of one mission."""

    autopilot: str
    mission_name: str
    mission_file: str
    vehicles: tuple[SitlVehicle, ...]

    @property
    def connections(self) -> list[str]:
        """`fleet.connections`, in UAV order."""
        return [v.connection for v in self.vehicles]


def plan_for_launch(mission: Mission) -> MissionPlan:
    """Plan `mission` whatever its backend and connections say: the launch plan is what
    produces the connections (docs/mission-file.md: a SITL mission without them is refused)."""
    fleet = dataclasses.replace(mission.fleet, backend="sim", connections=())
    return plan_mission(dataclasses.replace(mission, fleet=fleet))


def slot_poses(plan: MissionPlan) -> np.ndarray:
    """(N, 4) latitude, longitude, altitude AMSL, compass heading of every parking slot at A.

    The heading points along the row towards A (e_0, the way each UAV first moves);
    mission angles are counter-clockwise from east, compass headings clockwise from north.
    """
    slots = np.asarray(plan.formation.start_slots, float)
    origin = plan.mission.origin
    count = len(slots)
    geodetic = enu_to_geodetic(slots[:, 0], slots[:, 1], np.zeros(count), origin).reshape(count, 3)
    east, north = np.asarray(plan.formation.rows.start_direction, float)
    heading = math.degrees(math.atan2(east, north)) % 360.0
    return np.column_stack([geodetic, np.full(count, heading)])


def ardupilot_vehicles(poses: np.ndarray, speedup: float = 1.0) -> tuple[SitlVehicle, ...]:
    """ArduCopter SITL instances 0..N-1 (see the module docstring)."""
    vehicles = []
    for index, (lat, lon, alt, heading) in enumerate(poses):
        uav = index + 1
        step = ARDUPILOT_PORT_STEP * index
        argv = [
            "Tools/autotest/sim_vehicle.py",
            "-v",
            "ArduCopter",
            "-I",
            str(index),
            "--sysid",
            str(uav),
            f"--custom-location={lat:.7f},{lon:.7f},{alt:.2f},{heading:.1f}",
            "--no-mavproxy",
            "--no-rebuild",
            f"--use-dir=fleetline-uav{uav}",
        ]
        if speedup != 1.0:
            argv += ["--speedup", f"{speedup:g}"]
        vehicles.append(
            SitlVehicle(
                uav_id=uav,
                system_id=uav,
                instance=index,
                latitude=float(lat),
                longitude=float(lon),
                altitude=float(alt),
                heading_deg=float(heading),
                command=shlex.join(argv),
                connection=f"tcp:127.0.0.1:{ARDUPILOT_SERIAL0_PORT + step}",
                watch=f"tcp:127.0.0.1:{ARDUPILOT_SERIAL1_PORT + step}",
            )
        )
    return tuple(vehicles)


def px4_vehicles(poses: np.ndarray, speedup: float = 1.0) -> tuple[SitlVehicle, ...]:
    """PX4 SITL (SIH) instances 0..N-1 (see the module docstring)."""
    if len(poses) > PX4_MAX_INSTANCES:
        raise InputError(
            None,
            "--autopilot px4",
            f"at most {PX4_MAX_INSTANCES} UAVs (PX4 SITL sends the offboard link of every "
            f"instance above 9 to UDP 14549), got {len(poses)}",
        )
    vehicles = []
    for index, (lat, lon, alt, heading) in enumerate(poses):
        uav = index + 1
        directory = f"build/px4_sitl_default/instance_{index}"
        env = [
            f"PX4_SYS_AUTOSTART={PX4_AIRFRAME}",
            f"PX4_SIM_MODEL={PX4_MODEL}",
            f"PX4_HOME_LAT={lat:.7f}",
            f"PX4_HOME_LON={lon:.7f}",
            f"PX4_HOME_ALT={alt:.2f}",
        ]
        if speedup != 1.0:
            env.append(f"PX4_SIM_SPEED_FACTOR={speedup:g}")
        run = shlex.join([*env, "../bin/px4", "-i", str(index), "-d", "../etc"])
        command = f"(mkdir -p {directory} && cd {directory} && {run} > out.log 2> err.log &)"
        vehicles.append(
            SitlVehicle(
                uav_id=uav,
                system_id=uav,  # PX4 sets MAV_SYS_ID to instance + 1
                instance=index,
                latitude=float(lat),
                longitude=float(lon),
                altitude=float(alt),
                heading_deg=float(heading),
                command=command,
                connection=f"udpin:127.0.0.1:{PX4_OFFBOARD_PORT + index}",
                watch=f"udp:127.0.0.1:{QGC_PORT} (from {PX4_GCS_LOCAL_PORT + index})",
            )
        )
    return tuple(vehicles)


def launch_plan(mission: Mission, autopilot: str, speedup: float = 1.0) -> LaunchPlan:
    """The SITL fleet that flies `mission`: one instance per UAV, homes on the slots at A.

    Raises `InputError` (exit 2) for an autopilot it does not know or too many PX4 UAVs, and
    `NoValidPath` when the mission has no valid path (no fleet size, no slots).
    """
    if autopilot not in AUTOPILOTS:
        raise InputError(None, "--autopilot", f"one of {', '.join(AUTOPILOTS)}, got {autopilot}")
    if not (math.isfinite(speedup) and speedup > 0):
        raise InputError(None, "--speedup", f"a finite number > 0, got {speedup:g}")
    plan = plan_for_launch(mission)
    if not plan.valid or plan.formation is None:
        raise NoValidPath(plan.reason or "no valid path")
    poses = slot_poses(plan)
    build = ardupilot_vehicles if autopilot == "ardupilot" else px4_vehicles
    return LaunchPlan(autopilot, mission.name, str(mission.source), build(poses, speedup))


def render(plan: LaunchPlan) -> str:
    """The launch plan as a shell-friendly text: commands, then the `fleet` YAML to paste."""
    count = len(plan.vehicles)
    lines = [f"# {plan.mission_name}: {count} UAVs on {plan.autopilot} SITL"]
    if plan.autopilot == "ardupilot":
        lines += [
            "# From your ArduPilot checkout, build once: ./waf configure --board sitl && "
            "./waf copter",
            "# then start each instance (one terminal each, or append ' &'):",
        ]
    else:
        lines += [
            "# From your PX4-Autopilot checkout, build once: make px4_sitl",
            "# then start each instance (in the background, logs in its instance directory):",
        ]
    for v in plan.vehicles:
        lines.append(
            f"# UAV {v.uav_id}: system id {v.system_id}, home {v.latitude:.7f}, "
            f"{v.longitude:.7f}, {v.altitude:.2f} m, heading {v.heading_deg:.1f} deg"
        )
        lines.append(v.command)
    lines += [
        "",
        f"# Watch the fleet at the same time (MAVProxy / QGroundControl on UDP {QGC_PORT}):",
    ]
    if plan.autopilot == "ardupilot":
        for v in plan.vehicles:
            lines.append(
                shlex.join(
                    [
                        "mavproxy.py",
                        f"--master={v.watch}",
                        f"--out=udp:127.0.0.1:{QGC_PORT}",
                        "--daemon",
                    ]  # fmt: skip
                )
            )
    else:
        lines.append(
            f"# PX4 sends every instance's GCS link to UDP {QGC_PORT}: open QGroundControl,"
        )
        lines.append(f"# or: mavproxy.py --master=udpin:127.0.0.1:{QGC_PORT}")
    lines += [
        "",
        f"# Paste into {plan.mission_file} (or pass each with --connect):",
        "fleet:",
        f"  size: {count}",
        f"  backend: {plan.autopilot}",
        "  connections:",
        *(f"    - {c}" for c in plan.connections),
    ]
    return "\n".join(lines) + "\n"
