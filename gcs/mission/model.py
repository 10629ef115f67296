"""The mission model: the frozen value types a mission file becomes, and the vocabularies
its keys take (docs/mission-file.md). `gcs.mission.parser` builds them."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gcs.geodesy import Origin
from gcs.mission.footprints import (
    FootprintReport,
)
from planner.obstacles import Obstacles

#: The only mission file version this code reads.
VERSION = 1
#: ArduPilot SITL's default home, the documented default origin.
DEFAULT_ORIGIN = Origin(lat=-35.363262, lon=149.165237, alt=584.0)
#: Fraction of the safety margin reserved for tracking error and noise by default.
DEFAULT_TRACKING_FRACTION = 0.3
#: Footprints further than this from the origin are refused (a wrong origin, most likely):
#: `gcs.mission.footprints.MAX_FOOTPRINT_DISTANCE_M`, imported above.
BACKENDS = ("sim", "ardupilot", "px4")
PARKING = ("segment", "ray")
#: `connectivity.rule`: the paper's disk (within radio_range), or also a chord clear of the
#: buildings (line of sight, docs/line-of-sight.md).
CONNECTIVITY_RULES = ("disk", "line_of_sight")
#: `radio.buildings`: links through buildings follow 3GPP TR 38.901 UMi-Street Canyon's NLOS
#: path loss (`true` means this one), or are all cut (the bound the planner's line-of-sight
#: rule assumes); docs/line-of-sight.md.
BUILDING_MODELS = ("3gpp-umi", "cut")
#: `stations.order`: `tsp` (the planner picks the shortest tour) or `given` (as written).
STATION_ORDERS = ("tsp", "given")
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*\Z")


#: Largest magnitude of a length in metres (coordinates, margins, ranges): 1,000 km, well past
#: any local frame a fleet flies in; beyond it floats lose the centimetre.
MAX_METRES = 1e6
#: UAVs one ground station can fly: MAVLink system ids 1-254 (255 is the ground station's,
#: `fleetwire.messages.GCS_SYSTEM_ID`; fleetwire is not imported here: planning stays light).
MAX_FLEET_SIZE = 254
#: Largest `sim.seed`: the vehicles' and the medium's seeds are 63-bit.
MAX_SEED = 2**63 - 1


@dataclass(frozen=True)
class Pose:
    """A (departure or arrival) point and the angle of its parking row vs A->B, degrees."""

    x: float
    y: float
    theta_deg: float = 0.0

    @property
    def xy(self) -> np.ndarray:
        return np.array([self.x, self.y])


@dataclass(frozen=True)
class Point:
    """A point of the local frame (a base station), metres."""

    x: float
    y: float

    @property
    def xy(self) -> np.ndarray:
        return np.array([self.x, self.y])


@dataclass(frozen=True)
class Station:
    """A monitoring station (use case 1): a point a UAV holds, metres in the local frame.

    `dwell_s` is how long the point should be held (informative, seconds, default 0)."""

    name: str
    x: float
    y: float
    dwell_s: float = 0.0

    @property
    def xy(self) -> np.ndarray:
        return np.array([self.x, self.y])


@dataclass(frozen=True)
class ScheduledChange:
    """A speed change of the mission file's schedule: effective time `at` (s), new speed (m/s),
    optional leader.

    With a `leader` (1-based UAV number) `at` is when that UAV sends the request.
    """

    at: float
    speed: float
    leader: int | None = None


@dataclass(frozen=True)
class SpeedSchedule:
    """v_max, v(0) and the scheduled changes (eq. 6, sec. III-B)."""

    max: float
    initial: float
    changes: tuple[ScheduledChange, ...] = ()
    cap_to_safe: bool = False


@dataclass(frozen=True)
class Fleet:
    """Fleet size (None = `auto`, the minimum of eq. 28), backend and MAVLink connections."""

    size: int | None = None
    backend: str = "sim"
    connections: tuple[str, ...] = ()


@dataclass(frozen=True)
class Vehicle:
    """What the GCS assumes of each airframe (and the simulator simulates)."""

    max_speed: float = 15.0
    max_acceleration: float = 6.0
    radius: float = 0.5
    tracking_allowance: float = 0.0  # metres; resolved from the safety margin when absent
    #: Set each autopilot's own limits (its parameters) to max_speed / max_acceleration for
    #: the flight when they are lower, and put them back after landing.
    apply_limits: bool = False


@dataclass(frozen=True)
class GroundUser:
    """A data source on the ground (x, y in metres, rate in bit/s)."""

    x: float
    y: float
    rate_bps: float = 800.0


@dataclass(frozen=True)
class SimNoise:
    """Wind and navigation noise of the simulated vehicles (see the module docstring)."""

    wind_mean_mps: float = 0.0
    wind_direction_deg: float = 0.0
    wind_gust_mps: float = 0.5
    wind_time_s: float = 5.0
    position_m: float = 0.1


@dataclass(frozen=True)
class Sim:
    """Simulated backend: setpoint rate, random seed, noise, battery capacity (mAh: one for
    every UAV, one per UAV, or None for the simulated airframe's)."""

    setpoint_rate_hz: float = 10.0
    seed: int = 1
    noise: SimNoise = field(default_factory=SimNoise)
    battery_mah: float | tuple[float, ...] | None = None

    def battery_capacities(self, count: int) -> tuple[float, ...] | None:
        """`battery_mah` for `count` UAVs, one number each (None: the airframe's);
        ValueError if it is a list of another length."""
        if self.battery_mah is None:
            return None
        if isinstance(self.battery_mah, tuple):
            if len(self.battery_mah) != count:
                raise ValueError(
                    f"sim.battery_mah has {len(self.battery_mah)} numbers for {count} UAVs"
                )
            return self.battery_mah
        return (self.battery_mah,) * count


#: `radio.model`: the medium's per-hop latency, jitter and loss, or draws from a table
#: measured in ns-3 (`medium.radio`, docs/calibration.md).
RADIO_MODELS = ("simple", "calibrated")


@dataclass(frozen=True)
class Radio:
    """Emulated radio medium of the sim backend (range is the mission's `radio_range`).
    `model` "calibrated" draws each packet's delay and loss from `calibration` (absolute,
    resolved from the mission file; None: the table the medium ships)."""

    enabled: bool = True
    hop_latency_ms: float = 2.0
    jitter_ms: float = 1.0
    loss: float = 0.0
    model: str = "simple"
    calibration: Path | None = None
    #: links whose chord meets an obstacle: None, as if there were none (the paper's disk);
    #: a model of `BUILDING_MODELS` (docs/line-of-sight.md)
    buildings: str | None = None
    #: carrier frequency (GHz) of the path-loss model of `buildings`
    frequency_ghz: float = 2.4


@dataclass(frozen=True)
class Signing:
    """MAVLink 2 signing: key file (absolute, resolved from the mission file), or None."""

    key_file: Path | None = None


@dataclass(frozen=True, eq=False)
class Mission:
    """A validated mission. `obstacle_keys[i]` is the key path of `obstacles.geometries[i]`.

    `goal` is None only in a stations mission without `goal` (`stations` non-empty)."""

    source: Path
    text: str
    version: int
    name: str
    origin: Origin
    start: Pose
    goal: Pose | None
    safety_margin: float
    radio_range: float
    altitude: float
    parking: str
    speed: SpeedSchedule
    fleet: Fleet
    vehicle: Vehicle
    base_stations: tuple[Point, ...]
    obstacles: Obstacles
    obstacle_keys: tuple[str, ...]
    ground_users: tuple[GroundUser, ...]
    sim: Sim
    radio: Radio
    signing: Signing
    #: One report per footprint file (`obstacles[i].geojson`), in obstacle order.
    footprints: tuple[FootprintReport, ...] = ()
    #: Monitoring stations (use case 1), in the order written; empty for an A->B mission.
    stations: tuple[Station, ...] = ()
    #: `stations.order`: `tsp` or `given`.
    station_order: str = "tsp"
    #: `return.at`: mission time (s) at which the fleet flies home; None = on command.
    return_at: float | None = None
    #: `stations.relieve_below_pct`: a UAV on station whose battery (%) is below it is
    #: relieved; None = never for its battery.
    relieve_below_pct: float | None = None
    #: `connectivity.rule`: `disk` or `line_of_sight` (CONNECTIVITY_RULES).
    connectivity_rule: str = "disk"

    @property
    def base_station_points(self) -> np.ndarray:
        """(k, 2) float: A, then B when the mission has one, then every `base_stations` point."""
        points = [self.start.xy]
        if self.goal is not None:
            points.append(self.goal.xy)
        points.extend(b.xy for b in self.base_stations)
        return np.array(points, float).reshape(-1, 2)

    @property
    def base_station_names(self) -> tuple[str, ...]:
        """Names of `base_station_points`: A, B (when the mission has one), BS1, BS2, ..."""
        ends = ("A",) if self.goal is None else ("A", "B")
        return ends + tuple(f"BS{k + 1}" for k in range(len(self.base_stations)))

    @property
    def error_budget(self) -> float:
        """Smoothing error allowed at bends: rho_c minus the tracking allowance
        (docs/design.md 3.5)."""
        return self.safety_margin - self.vehicle.tracking_allowance
