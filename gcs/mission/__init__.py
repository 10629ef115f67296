"""Mission file (YAML, version 1, docs/mission-file.md) -> a validated, frozen `Mission`:
the model (`gcs.mission.model`), the parser (`gcs.mission.parser`) and the footprint files
it reads (`gcs.mission.footprints`).

Everything docs/mission-file.md lists as refused is refused here with `InputError` (file, 0-based
key path, what is expected, on one line), except the checks that need the planned path's fleet
size (fixed size below the minimum of eq. 28, leader outside 1..N, connection count, length
of a `sim.battery_mah` list, parking rows vs obstacles and each other, eqs. 14-15):
`gcs.planning` makes those, naming the key too.

Types: numbers must be YAML numbers (a boolean is not a number, a string is never converted;
`1e3` is read as a number, as YAML 1.2 does); integers must be integers. Unknown keys and
duplicate keys are refused.

Defaults (every key not listed as required is optional):

* `name`: the file name without its extension.
* `origin`: `{lat: -35.363262, lon: 149.165237, alt: 584.0}`, the default home of ArduPilot's
  SITL (CMAC, Canberra), so a SITL fleet started with its defaults shares the frame.
* `start.theta_deg`, `goal.theta_deg`: 0 (rows aligned with A->B).
* `parking`: `segment` (rows as long as the fleet needs; `ray` is the paper's infinite rays).
* `speed.initial`: `speed.max`; `speed.changes`: none; `speed.cap_to_safe`: false (a
  `speed.max` above the safe formation speed is refused instead of capped, docs/design.md 3.5).
  A change's `leader` is a 1-based UAV number; `at` is the effective mission time, or for a
  leader's request the time the leader sends it.
* `fleet`: `{size: auto, backend: sim, connections: []}`.
* `vehicle`: `{max_speed: 15, max_acceleration: 6, radius: 0.5}`; `vehicle.tracking_allowance`
  (m): the part of the safety margin reserved for tracking error and navigation noise, default
  30 % of `safety_margin`; the rest is the smoothing error budget used for the safe speed.
* `base_stations`, `obstacles`, `ground_users`: none. `ground_users[i].rate_bps`: 800.
* `sim`: `{setpoint_rate_hz: 10, seed: 1}`, `sim.noise`: `{wind_mean_mps: 0,
  wind_direction_deg: 0, wind_gust_mps: 0.5, wind_time_s: 5, position_m: 0.1}` (mean wind,
  direction it blows towards (counter-clockwise from east), standard deviation and
  correlation time of the gusts, standard deviation of the navigation error on the reported
  position). `sim.battery_mah`: unset (the simulated airframe's 8000 mAh); a number > 0 for
  every UAV, or a list with one per UAV.
* `radio`: `{enabled: true, hop_latency_ms: 2, jitter_ms: 1, loss: 0}`.
* `signing.key_file`: unset (the signing layer picks its default); paths are relative to the
  mission file.
* `stations` (monitoring stations, use case 1: the fleet leaves A, a UAV holds each point,
  then the fleet flies home): none. With `stations`, `goal` is optional (`Mission.goal` is
  None without it; given, B is one more base station, not a route point).
  `stations.order`: `tsp` (`given`: the order written); `stations.points[i].name`: `P<i+1>`;
  `stations.points[i].dwell_s`: 0 (with one on every point and no `return`, the fleet
  flies home once the longest has passed). A point is `x`/`y` (m) or `lat`/`lon`
  (WGS84 degrees, through `origin` at `origin.alt`, within `MAX_FOOTPRINT_DISTANCE_M`).
  Each point keeps safety_margin from every obstacle, 2 x safety_margin from every other
  point and 2 sqrt 2 x safety_margin from A (the parking row).
  `stations.relieve_below_pct` (a number in (0, 100)): unset, no UAV is relieved for its
  battery; set, a UAV on station whose SYS_STATUS battery_remaining falls below it is relieved
  (it flies home alone, the others close the gap).
* `return.at` (only with `stations`): unset, the fleet flies home on the operator's command.

Obstacles: `rectangle` (center, size, angle_deg) and `polygon` are solid polygons, `segment` a
wall, `geojson` a footprint file (relative to the mission file; `FILE` or `{file, strict, crs,
height_key, bbox}`) read by `gcs.mission.footprints`: Polygon and MultiPolygon features become solid
polygons (holes ignored: a courtyard is not flyable), LineString and MultiLineString features
walls; what was skipped, repaired, dropped or left out below the flight is in
`Mission.footprints` and one warning line per file (logger `gcs.mission.footprints`).
"""

from gcs.mission.footprints import MAX_FOOTPRINT_DISTANCE_M
from gcs.mission.model import (
    BACKENDS,
    BUILDING_MODELS,
    CONNECTIVITY_RULES,
    DEFAULT_ORIGIN,
    DEFAULT_TRACKING_FRACTION,
    MAX_FLEET_SIZE,
    MAX_METRES,
    MAX_SEED,
    PARKING,
    RADIO_MODELS,
    STATION_ORDERS,
    VERSION,
    Fleet,
    GroundUser,
    Mission,
    Point,
    Pose,
    Radio,
    ScheduledChange,
    Signing,
    Sim,
    SimNoise,
    SpeedSchedule,
    Station,
    Vehicle,
)
from gcs.mission.parser import (
    MissionParser,
    describe_value,
    load_mission,
    parse_mission,
    parse_yaml,
    read_yaml,
)

__all__ = [
    "BACKENDS",
    "BUILDING_MODELS",
    "CONNECTIVITY_RULES",
    "DEFAULT_ORIGIN",
    "DEFAULT_TRACKING_FRACTION",
    "Fleet",
    "GroundUser",
    "MAX_FLEET_SIZE",
    "MAX_FOOTPRINT_DISTANCE_M",
    "MAX_METRES",
    "MAX_SEED",
    "Mission",
    "MissionParser",
    "PARKING",
    "Point",
    "Pose",
    "RADIO_MODELS",
    "Radio",
    "STATION_ORDERS",
    "ScheduledChange",
    "Signing",
    "Sim",
    "SimNoise",
    "SpeedSchedule",
    "Station",
    "VERSION",
    "Vehicle",
    "describe_value",
    "load_mission",
    "parse_mission",
    "parse_yaml",
    "read_yaml",
]
