"""The mission file parser: YAML -> `Mission`, every refusal one `InputError`
(docs/mission-file.md; the package docstring lists the defaults).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import shapely
import yaml

from fleetwire.files import MISSION_BYTES, FileRefused, check_nesting, read_bounded
from gcs.errors import InputError, join_key
from gcs.geodesy import Origin, geodetic_to_enu
from gcs.mission.footprints import (
    MAX_FOOTPRINT_DISTANCE_M,  # also re-exported
    FootprintError,
    FootprintOptions,
    FootprintReport,
    Footprints,
    read_footprints,
)
from gcs.mission.footprints import log as footprint_log
from gcs.mission.model import (
    _NAME,
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
from medium.pathloss import FREQUENCY_RANGE_GHZ
from planner.formation import DISTANCE_TOLERANCE, min_radio_range
from planner.numbers import fmt_against
from planner.obstacles import Obstacles


def load_mission(path: str | Path, *, check_clearance: bool = True) -> Mission:
    """Read and validate a mission file; raise `InputError` on anything docs/mission-file.md
    refuses. `check_clearance=False` skips only the test that A and B keep safety_margin from every
    obstacle (to suggest where they could go instead)."""
    path = Path(path)
    text, data = read_yaml(path, "a mission file")
    return parse_mission(data, path, text, check_clearance=check_clearance)


def read_yaml(path: Path, what: str) -> tuple[str, Any]:
    """The text of the YAML file `path` (`what` it should be, for a directory's refusal) and
    its data, duplicate keys refused; `InputError` naming the file on anything unreadable."""
    try:
        text = read_bounded(path, MISSION_BYTES).decode("utf-8")
    except FileRefused as exc:
        raise InputError(path, "", f"{what}: {exc}") from None
    except UnicodeDecodeError:
        raise InputError(path, "", "a UTF-8 YAML text file") from None
    except OSError as exc:
        raise InputError(path, "", f"a readable file ({exc.strerror or exc})") from None
    try:
        data = parse_yaml(text)
    except FileRefused as exc:
        raise InputError(path, "", f"YAML {exc}") from None
    except _DuplicateKey as exc:
        raise InputError(path, exc.key, f"each key once (duplicate at line {exc.line})") from None
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        at = f" at line {where.line + 1}, column {where.column + 1}" if where else ""
        problem = getattr(exc, "problem", None) or "syntax error"
        raise InputError(path, "", f"valid YAML ({problem}{at})") from None
    return text, data


def parse_yaml(text: str) -> Any:
    """YAML text as data, the way mission files are read: safe, duplicate keys refused
    (`_DuplicateKey`), YAML 1.2 floats such as 1e3, nesting bounded (`FileRefused`: libyaml
    crashes the process on text nested tens of thousands of levels deep)."""
    check_nesting(text, yaml=True)
    return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass


def parse_mission(
    data: Any, source: Path, text: str = "", *, check_clearance: bool = True
) -> Mission:
    """Validate already-parsed YAML `data` read from `source` (for paths and messages)."""
    return MissionParser(Path(source), check_clearance).mission(data, text)


# --- YAML loading --------------------------------------------------------------------------


class _DuplicateKey(yaml.YAMLError):
    def __init__(self, key: Any, line: int) -> None:
        super().__init__(f"duplicate key {key!r}")
        self.key = str(key)
        self.line = line


#: libyaml's parser when PyYAML was built with it (about 5x faster on big maps), else PyYAML's
#: own; both safe, with the same marks (line numbers) and constructors.
_SafeLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _Loader(_SafeLoader):
    """Safe YAML loader that refuses duplicate keys and reads YAML 1.2 floats such as 1e3."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=deep)
            try:
                duplicate = key in seen
                seen.add(key)
            except TypeError:  # unhashable key: let the base class refuse it
                continue
            if duplicate:
                raise _DuplicateKey(key, key_node.start_mark.line + 1)
        return super().construct_mapping(node, deep=deep)


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


# --- validation ----------------------------------------------------------------------------


def describe_value(value: Any) -> str:
    """How a refused value is shown: its YAML spelling and kind (the study file's refusals too)."""
    if isinstance(value, bool):
        return f"{str(value).lower()} (a boolean)"
    if value is None:
        return "nothing (null)"
    if isinstance(value, str):
        shown = value if len(value) <= 40 else value[:37] + "..."
        return f"{shown!r} (a string)"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, float):
        return f"{value:g}"
    return repr(value)


def _fmt(x: float, against: float | None = None) -> str:
    """A number in a message: 6 significant digits, or more until it no longer reads as
    `against`, the limit it is compared with (format the limit with `against=` the value too)."""
    return f"{x:.6g}" if against is None else fmt_against(x, against, 6)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


class MissionParser:
    """Walks the YAML tree with key paths; every refusal raises `InputError`. Its primitive
    readers (mapping, sequence, number, integer, choice, ...) serve the other YAML inputs too
    (`gcs.study.studyfile`)."""

    document = "mission"  # what the file is, in the refusal of a file that is not a mapping

    def __init__(self, source: Path, check_clearance: bool = True) -> None:
        self.source = source
        self.check_clearance = check_clearance

    def fail(self, path: str, expected: str) -> InputError:
        return InputError(self.source, path, expected)

    # primitive readers

    def mapping(
        self, value: Any, path: str, allowed: tuple[str, ...], required: tuple[str, ...] = ()
    ) -> dict:
        if not isinstance(value, dict):
            keys = ", ".join(allowed)
            what = (
                f"the {self.document} as a mapping of keys" if not path else f"a mapping ({keys})"
            )
            raise self.fail(path, f"{what}, got {describe_value(value)}")
        for key in value:
            if not isinstance(key, str) or key not in allowed:
                raise self.fail(
                    join_key(path, str(key)), f"a known key: one of {', '.join(allowed)}"
                )
        for key in required:
            if key not in value:
                raise self.fail(join_key(path, key), "this required key")
        return value

    def sequence(self, value: Any, path: str, what: str) -> list:
        if not isinstance(value, list):
            raise self.fail(path, f"a list of {what}, got {describe_value(value)}")
        return value

    def number(
        self,
        value: Any,
        path: str,
        *,
        low: float | None = None,
        high: float | None = None,
        low_open: bool = False,
        high_open: bool = False,
        unit: str = "",
    ) -> float:
        """A finite YAML number within [low, high] (open ends where asked)."""
        suffix = f" ({unit})" if unit else ""

        def want(got: float | None = None) -> str:  # each bound told apart from `got`
            if low == 0 and low_open and high is None:
                return f"a finite number > 0{suffix}"
            if low == 0 and not low_open and high is None:
                return f"a finite number >= 0{suffix}"
            if low is not None and high is not None:
                lo, hi = "(" if low_open else "[", ")" if high_open else "]"
                return f"a number in {lo}{_fmt(low, got)}, {_fmt(high, got)}{hi}{suffix}"
            return f"a finite number{suffix}"

        if not _is_number(value) or not math.isfinite(value):
            raise self.fail(path, f"{want()}, got {describe_value(value)}")
        value = float(value)
        if unit == "m" and abs(value) > MAX_METRES:  # a local frame, a radio, a building
            raise self.fail(path, f"at most {MAX_METRES:,.0f} m in magnitude, got {value:g}")
        if low is not None and (value < low or (low_open and value <= low)):
            raise self.fail(path, f"{want(value)}, got {_fmt(value, low)}")
        if high is not None and (value > high or (high_open and value >= high)):
            raise self.fail(path, f"{want(value)}, got {_fmt(value, high)}")
        return value

    def positive(self, value: Any, path: str, unit: str = "") -> float:
        return self.number(value, path, low=0.0, low_open=True, unit=unit)

    def nonnegative(self, value: Any, path: str, unit: str = "") -> float:
        return self.number(value, path, low=0.0, unit=unit)

    def integer(self, value: Any, path: str, low: int | None = None) -> int:
        want = "an integer" if low is None else f"an integer >= {low}"
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.fail(path, f"{want}, got {describe_value(value)}")
        if low is not None and value < low:
            raise self.fail(path, f"{want}, got {value}")
        return value

    def boolean(self, value: Any, path: str) -> bool:
        if not isinstance(value, bool):
            raise self.fail(path, f"true or false, got {describe_value(value)}")
        return value

    def string(self, value: Any, path: str, what: str = "a non-empty string") -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.fail(path, f"{what}, got {describe_value(value)}")
        return value

    def choice(self, value: Any, path: str, options: tuple[str, ...]) -> str:
        if not isinstance(value, str) or value not in options:
            raise self.fail(path, f"one of {', '.join(options)}, got {describe_value(value)}")
        return value

    def point(self, value: Any, path: str) -> np.ndarray:
        if not isinstance(value, list) or len(value) != 2:
            raise self.fail(path, f"a point [x, y] in metres, got {describe_value(value)}")
        return np.array([self.number(v, join_key(path, i), unit="m") for i, v in enumerate(value)])

    # sections

    def mission(self, data: Any, text: str) -> Mission:
        root = self.mapping(
            data,
            "",
            (
                "version", "name", "origin", "start", "goal", "safety_margin", "radio_range",
                "altitude", "parking", "speed", "fleet", "vehicle", "base_stations",
                "obstacles", "ground_users", "sim", "radio", "signing", "stations", "return",
                "connectivity",
            ),
            tuple(
                key
                for key in ("version", "start", "goal", "safety_margin", "radio_range",
                            "altitude", "speed")
                # a stations mission needs no B (it ends where it began)
                if not (key == "goal" and isinstance(data, dict) and "stations" in data)
            ),
        )  # fmt: skip
        version = root["version"]
        if not isinstance(version, int) or isinstance(version, bool) or version != VERSION:
            raise self.fail("version", f"{VERSION}, got {describe_value(version)}")
        name = self.name(root.get("name"))
        origin = self.origin(root["origin"]) if "origin" in root else DEFAULT_ORIGIN
        start = self.pose(root["start"], "start")
        goal = self.pose(root["goal"], "goal") if "goal" in root else None
        safety_margin = self.positive(root["safety_margin"], "safety_margin", "m")
        radio_range = self.positive(root["radio_range"], "radio_range", "m")
        needed = min_radio_range(safety_margin)
        if radio_range < needed - DISTANCE_TOLERANCE:
            raise self.fail(
                "radio_range",
                f"at least 2(1+sqrt 2) x safety_margin = {_fmt(needed, radio_range)} m "
                f"(eq. 9), got {_fmt(radio_range, needed)}",
            )
        altitude = self.positive(root["altitude"], "altitude", "m")
        parking = self.choice(root.get("parking", "segment"), "parking", PARKING)
        connectivity = self.mapping(root.get("connectivity", {}), "connectivity", ("rule",))
        rule = self.choice(
            connectivity.get("rule", "disk"), "connectivity.rule", CONNECTIVITY_RULES
        )
        vehicle = self.vehicle(root.get("vehicle", {}), safety_margin)
        speed = self.speed(root["speed"], vehicle)
        fleet = self.fleet(root.get("fleet", {}))
        base_stations = tuple(
            Point(*self.xy_mapping(item, join_key("base_stations", i)))
            for i, item in enumerate(
                self.sequence(root.get("base_stations", []), "base_stations", "{x, y}")
            )
        )
        obstacles, keys = self.obstacles(
            root.get("obstacles", []), origin, height_limit=altitude - safety_margin
        )
        ground_users = self.ground_users(root.get("ground_users", []))
        sim = self.sim(root.get("sim", {}))
        radio = self.radio(root.get("radio", {}))
        signing = self.signing(root.get("signing", {}))
        stations: tuple[Station, ...] = ()
        order = STATION_ORDERS[0]
        relieve_below_pct = None
        if "stations" in root:
            stations, order, relieve_below_pct = self.stations(root["stations"], origin)
        return_at = None
        if "return" in root:
            if "stations" not in root:
                raise self.fail(
                    "return", "this key only with stations (it brings the fleet home from them)"
                )
            return_at = self.return_at(root["return"])
        if goal is not None and np.linalg.norm(goal.xy - start.xy) <= DISTANCE_TOLERANCE:
            raise self.fail("goal", f"a point different from start, got ({goal.x:g}, {goal.y:g})")
        for key, pose in (("start", start), ("goal", goal)):
            if self.check_clearance and pose is not None:
                self.clear_of_obstacles(key, pose, obstacles, keys, safety_margin)
        self.stations_apart(stations, start, obstacles, keys, safety_margin)
        for report in self.footprint_reports:  # once the mission is accepted: one line each
            if report.noteworthy:
                footprint_log.warning("%s", report.line())
        return Mission(
            source=self.source,
            text=text,
            version=version,
            name=name,
            origin=origin,
            start=start,
            goal=goal,
            safety_margin=safety_margin,
            radio_range=radio_range,
            altitude=altitude,
            parking=parking,
            speed=speed,
            fleet=fleet,
            vehicle=vehicle,
            base_stations=base_stations,
            obstacles=obstacles,
            obstacle_keys=keys,
            ground_users=ground_users,
            sim=sim,
            radio=radio,
            signing=signing,
            footprints=tuple(self.footprint_reports),
            stations=stations,
            station_order=order,
            return_at=return_at,
            relieve_below_pct=relieve_below_pct,
            connectivity_rule=rule,
        )

    def name(self, value: Any) -> str:
        if value is None:
            stem = re.sub(r"[^A-Za-z0-9._-]", "-", self.source.stem).lstrip("._-")
            return stem or "mission"
        text = self.string(value, "name")
        if not _NAME.match(text):
            raise self.fail(
                "name", f"letters, digits, '.', '_' or '-' (it names log files), got {text!r}"
            )
        return text

    def origin(self, value: Any) -> Origin:
        m = self.mapping(value, "origin", ("lat", "lon", "alt"), ("lat", "lon"))
        lat = self.number(m["lat"], "origin.lat", low=-90.0, high=90.0, unit="degrees")
        lon = self.number(m["lon"], "origin.lon", low=-180.0, high=180.0, unit="degrees")
        alt = self.number(m.get("alt", 0.0), "origin.alt", unit="m")
        return Origin(lat=lat, lon=lon, alt=alt)

    def pose(self, value: Any, path: str) -> Pose:
        m = self.mapping(value, path, ("x", "y", "theta_deg"), ("x", "y"))
        return Pose(
            x=self.number(m["x"], join_key(path, "x"), unit="m"),
            y=self.number(m["y"], join_key(path, "y"), unit="m"),
            theta_deg=self.number(m.get("theta_deg", 0.0), join_key(path, "theta_deg")),
        )

    def xy_mapping(self, value: Any, path: str) -> tuple[float, float]:
        m = self.mapping(value, path, ("x", "y"), ("x", "y"))
        return (
            self.number(m["x"], join_key(path, "x"), unit="m"),
            self.number(m["y"], join_key(path, "y"), unit="m"),
        )

    def stations(self, value: Any, origin: Origin) -> tuple[tuple[Station, ...], str, float | None]:
        """`stations: {order, points, relieve_below_pct}` -> the points (local frame), the
        order and the battery threshold (None: unset)."""
        m = self.mapping(value, "stations", ("order", "points", "relieve_below_pct"), ("points",))
        order = self.choice(m.get("order", STATION_ORDERS[0]), "stations.order", STATION_ORDERS)
        relieve_below_pct = None
        if "relieve_below_pct" in m:
            relieve_below_pct = self.number(
                m["relieve_below_pct"],
                "stations.relieve_below_pct",
                low=0.0,
                high=100.0,
                low_open=True,
                high_open=True,
                unit="% battery remaining",
            )
        what = "points {name, x, y, dwell_s} or {name, lat, lon, dwell_s}"
        items = self.sequence(m["points"], "stations.points", what)
        if not items:
            raise self.fail("stations.points", f"a non-empty list of {what}, got an empty list")
        out: list[Station] = []
        named: dict[str, int] = {}
        for i, item in enumerate(items):
            station = self.station(item, join_key("stations.points", i), i, origin)
            if station.name in named:
                j = named[station.name]
                given = isinstance(item, dict) and "name" in item
                key = join_key(join_key("stations.points", i), "name")
                shown = f"{station.name!r}" if given else f"the default {station.name!r}"
                raise self.fail(
                    key,
                    f"a name no other point has ({shown} is already stations.points[{j}]'s)",
                )
            named[station.name] = i
            out.append(station)
        return tuple(out), order, relieve_below_pct

    def station(self, value: Any, path: str, index: int, origin: Origin) -> Station:
        """One `stations.points[i]`: exactly one of x/y or lat/lon, a name, dwell_s."""
        m = self.mapping(value, path, ("name", "x", "y", "lat", "lon", "dwell_s"))
        name = f"P{index + 1}"
        if "name" in m:
            name = self.string(m["name"], join_key(path, "name"))
        local = any(k in m for k in ("x", "y"))
        geodetic = any(k in m for k in ("lat", "lon"))
        if local == geodetic:
            got = "both" if local else "neither"
            raise self.fail(path, f"exactly one of x/y (m) or lat/lon (degrees), got {got}")
        if local:
            for key in ("x", "y"):
                if key not in m:
                    raise self.fail(join_key(path, key), "this required key (with x/y)")
            x = self.number(m["x"], join_key(path, "x"), unit="m")
            y = self.number(m["y"], join_key(path, "y"), unit="m")
        else:
            for key in ("lat", "lon"):
                if key not in m:
                    raise self.fail(join_key(path, key), "this required key (with lat/lon)")
            lat = self.number(m["lat"], join_key(path, "lat"), low=-90.0, high=90.0, unit="degrees")
            lon = self.number(
                m["lon"], join_key(path, "lon"), low=-180.0, high=180.0, unit="degrees"
            )
            enu = geodetic_to_enu(lat, lon, origin.alt, origin)
            away = float(np.linalg.norm(enu))  # straight line, so the far side of the Earth too
            if away > MAX_FOOTPRINT_DISTANCE_M:
                raise self.fail(
                    path,
                    f"a point within {MAX_FOOTPRINT_DISTANCE_M / 1000:g} km of origin "
                    f"(lat {lat:g}, lon {lon:g} is {away / 1000:.0f} km away: is origin right?)",
                )
            x, y = float(enu[0]), float(enu[1])
        dwell = self.nonnegative(m.get("dwell_s", 0.0), join_key(path, "dwell_s"), "s")
        return Station(name=name, x=x, y=y, dwell_s=dwell)

    def return_at(self, value: Any) -> float:
        m = self.mapping(value, "return", ("at",), ("at",))
        return self.positive(m["at"], "return.at", "s, mission time")

    def stations_apart(
        self,
        stations: tuple[Station, ...],
        start: Pose,
        obstacles: Obstacles,
        keys: tuple[str, ...],
        safety_margin: float,
    ) -> None:
        """Each station: safety_margin from every obstacle (as A and B), 2 x safety_margin
        from every other station (two UAVs hold them), 2 sqrt 2 x safety_margin from A (a UAV
        holds it apart from the parking row, whose slots are that far apart)."""
        if not stations:
            return
        xy = np.array([s.xy for s in stations], float)
        paths = [join_key("stations.points", i) for i in range(len(stations))]
        for path, station in zip(paths, stations, strict=True):
            self.clear_of_obstacles(path, station, obstacles, keys, safety_margin)
        from_a = 2.0 * math.sqrt(2.0) * safety_margin
        to_a = np.hypot(*(xy - start.xy).T)
        near_a = np.flatnonzero(to_a < from_a - DISTANCE_TOLERANCE)
        if len(near_a):
            i = int(near_a[0])
            d = float(to_a[i])
            raise self.fail(
                paths[i],
                f"a point at least 2 sqrt 2 x safety_margin = {_fmt(from_a, d)} m from start "
                f"(A, where the fleet parks); {stations[i].name} is {_fmt(d, from_a)} m from it",
            )
        apart = 2.0 * safety_margin
        gaps = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        gaps[np.triu_indices(len(xy))] = np.inf  # each pair once: the later point (j > i)
        for j in range(1, len(xy)):
            i = int(np.argmin(gaps[j]))
            if gaps[j, i] < apart - DISTANCE_TOLERANCE:
                d = float(gaps[j, i])
                raise self.fail(
                    paths[j],
                    f"a point at least 2 x safety_margin = {_fmt(apart, d)} m from every other "
                    f"point; {stations[j].name} is {_fmt(d, apart)} m from {stations[i].name} "
                    f"({paths[i]})",
                )

    def vehicle(self, value: Any, safety_margin: float) -> Vehicle:
        keys = ("max_speed", "max_acceleration", "radius", "tracking_allowance", "apply_limits")
        m = self.mapping(value, "vehicle", keys)
        d = Vehicle()
        radius = self.positive(m.get("radius", d.radius), "vehicle.radius", "m")
        if radius >= safety_margin:
            raise self.fail(
                "vehicle.radius",
                f"less than safety_margin ({_fmt(safety_margin, radius)} m), "
                f"got {_fmt(radius, safety_margin)}",
            )
        default_allowance = DEFAULT_TRACKING_FRACTION * safety_margin
        allowance = self.number(
            m.get("tracking_allowance", default_allowance),
            "vehicle.tracking_allowance",
            low=0.0,
            high=safety_margin,
            high_open=True,
            unit="m (below safety_margin)",
        )
        return Vehicle(
            max_speed=self.positive(m.get("max_speed", d.max_speed), "vehicle.max_speed", "m/s"),
            max_acceleration=self.positive(
                m.get("max_acceleration", d.max_acceleration), "vehicle.max_acceleration", "m/s^2"
            ),
            radius=radius,
            tracking_allowance=allowance,
            apply_limits=self.boolean(m.get("apply_limits", False), "vehicle.apply_limits"),
        )

    def speed(self, value: Any, vehicle: Vehicle) -> SpeedSchedule:
        m = self.mapping(value, "speed", ("max", "initial", "changes", "cap_to_safe"), ("max",))
        vmax = self.positive(m["max"], "speed.max", "m/s")
        if vmax > vehicle.max_speed:
            raise self.fail(
                "speed.max",
                f"at most vehicle.max_speed ({_fmt(vehicle.max_speed, vmax)} m/s), "
                f"got {_fmt(vmax, vehicle.max_speed)}",
            )
        initial = vmax
        if "initial" in m:
            initial = self.nonnegative(m["initial"], "speed.initial", "m/s")
            if initial > vmax:
                raise self.fail(
                    "speed.initial",
                    f"at most speed.max ({_fmt(vmax, initial)} m/s), got {_fmt(initial, vmax)}",
                )
        changes = []
        items = self.sequence(m.get("changes", []), "speed.changes", "{at, speed[, leader]}")
        for i, item in enumerate(items):
            path = join_key("speed.changes", i)
            c = self.mapping(item, path, ("at", "speed", "leader"), ("at", "speed"))
            at = self.nonnegative(c["at"], join_key(path, "at"), "s")
            if changes and at <= changes[-1].at:
                raise self.fail(
                    join_key(path, "at"),
                    f"a time after speed.changes[{i - 1}].at ({_fmt(changes[-1].at, at)} s): "
                    f"times strictly increasing, got {_fmt(at, changes[-1].at)}",
                )
            speed = self.number(
                c["speed"],
                join_key(path, "speed"),
                low=0.0,
                high=vmax,
                unit="m/s, at most speed.max",
            )
            leader = None
            if "leader" in c:
                leader = self.integer(c["leader"], join_key(path, "leader"), low=1)
            changes.append(ScheduledChange(at=at, speed=speed, leader=leader))
        last_path = f"speed.changes[{len(changes) - 1}].speed" if changes else "speed.initial"
        last = changes[-1].speed if changes else initial
        if last <= 0:
            raise self.fail(last_path, "a last speed > 0 (the mission would never end), got 0")
        cap = self.boolean(m.get("cap_to_safe", False), "speed.cap_to_safe")
        return SpeedSchedule(max=vmax, initial=initial, changes=tuple(changes), cap_to_safe=cap)

    def fleet(self, value: Any) -> Fleet:
        m = self.mapping(value, "fleet", ("size", "backend", "connections"))
        size_value = m.get("size", "auto")
        size = None
        if size_value != "auto":
            if not isinstance(size_value, int) or isinstance(size_value, bool) or size_value < 1:
                raise self.fail(
                    "fleet.size", f"auto or an integer >= 1, got {describe_value(size_value)}"
                )
            if size_value > MAX_FLEET_SIZE:
                raise self.fail(
                    "fleet.size",
                    f"at most {MAX_FLEET_SIZE} UAVs (MAVLink system ids 1-{MAX_FLEET_SIZE}), "
                    f"got {size_value}",
                )
            size = size_value
        backend = self.choice(m.get("backend", "sim"), "fleet.backend", BACKENDS)
        items = self.sequence(m.get("connections", []), "fleet.connections", "connection strings")
        connections = tuple(
            self.string(c, join_key("fleet.connections", i), "a MAVLink connection string")
            for i, c in enumerate(items)
        )
        return Fleet(size=size, backend=backend, connections=connections)

    def ground_users(self, value: Any) -> tuple[GroundUser, ...]:
        out = []
        for i, item in enumerate(self.sequence(value, "ground_users", "{x, y[, rate_bps]}")):
            path = join_key("ground_users", i)
            m = self.mapping(item, path, ("x", "y", "rate_bps"), ("x", "y"))
            out.append(
                GroundUser(
                    x=self.number(m["x"], join_key(path, "x"), unit="m"),
                    y=self.number(m["y"], join_key(path, "y"), unit="m"),
                    rate_bps=self.positive(
                        m.get("rate_bps", 800.0), join_key(path, "rate_bps"), "bit/s"
                    ),
                )
            )
        return tuple(out)

    def sim(self, value: Any) -> Sim:
        m = self.mapping(value, "sim", ("setpoint_rate_hz", "seed", "noise", "battery_mah"))
        d = Sim()
        rate = self.positive(
            m.get("setpoint_rate_hz", d.setpoint_rate_hz), "sim.setpoint_rate_hz", "Hz"
        )
        seed = self.integer(m.get("seed", d.seed), "sim.seed", low=0)
        if seed > MAX_SEED:
            raise self.fail("sim.seed", f"an integer in [0, {MAX_SEED}], got {seed}")
        keys = ("wind_mean_mps", "wind_direction_deg", "wind_gust_mps", "wind_time_s", "position_m")
        n = self.mapping(m.get("noise", {}), "sim.noise", keys)
        dn = SimNoise()
        noise = SimNoise(
            wind_mean_mps=self.nonnegative(
                n.get("wind_mean_mps", dn.wind_mean_mps), "sim.noise.wind_mean_mps", "m/s"
            ),
            wind_direction_deg=self.number(
                n.get("wind_direction_deg", dn.wind_direction_deg), "sim.noise.wind_direction_deg"
            ),
            wind_gust_mps=self.nonnegative(
                n.get("wind_gust_mps", dn.wind_gust_mps), "sim.noise.wind_gust_mps", "m/s"
            ),
            wind_time_s=self.positive(
                n.get("wind_time_s", dn.wind_time_s), "sim.noise.wind_time_s", "s"
            ),
            position_m=self.nonnegative(
                n.get("position_m", dn.position_m), "sim.noise.position_m", "m"
            ),
        )
        battery = self.battery_mah(m["battery_mah"]) if "battery_mah" in m else None
        return Sim(setpoint_rate_hz=rate, seed=seed, noise=noise, battery_mah=battery)

    def battery_mah(self, value: Any) -> float | tuple[float, ...]:
        """`sim.battery_mah`: a number > 0, or a non-empty list of them (one per UAV)."""
        if isinstance(value, list):
            if not value:
                raise self.fail(
                    "sim.battery_mah", "a number > 0 (mAh) or one per UAV, got an empty list"
                )
            return tuple(
                self.positive(v, join_key("sim.battery_mah", i), "mAh") for i, v in enumerate(value)
            )
        if not _is_number(value):
            raise self.fail(
                "sim.battery_mah",
                f"a number > 0 (mAh) or a list with one per UAV, got {describe_value(value)}",
            )
        return self.positive(value, "sim.battery_mah", "mAh")

    def radio(self, value: Any) -> Radio:
        m = self.mapping(
            value,
            "radio",
            (
                "enabled",
                "hop_latency_ms",
                "jitter_ms",
                "loss",
                "model",
                "calibration",
                "buildings",
                "frequency_ghz",
            ),  # fmt: skip
        )
        d = Radio()
        model = self.choice(m.get("model", d.model), "radio.model", RADIO_MODELS)
        return Radio(
            enabled=self.boolean(m.get("enabled", d.enabled), "radio.enabled"),
            hop_latency_ms=self.nonnegative(
                m.get("hop_latency_ms", d.hop_latency_ms), "radio.hop_latency_ms", "ms"
            ),
            jitter_ms=self.nonnegative(m.get("jitter_ms", d.jitter_ms), "radio.jitter_ms", "ms"),
            loss=self.number(
                m.get("loss", d.loss), "radio.loss", low=0.0, high=1.0, high_open=True
            ),
            model=model,
            calibration=self.calibration(m["calibration"], model) if "calibration" in m else None,
            buildings=self.buildings(m.get("buildings", False)),
            frequency_ghz=self.number(
                m.get("frequency_ghz", d.frequency_ghz),
                "radio.frequency_ghz",
                low=FREQUENCY_RANGE_GHZ[0],
                high=FREQUENCY_RANGE_GHZ[1],
                unit="GHz",
            ),  # fmt: skip
        )

    def buildings(self, value: Any) -> str | None:
        """`radio.buildings`: false, true (3gpp-umi) or a model of `BUILDING_MODELS`."""
        if value is False:
            return None
        if value is True:
            return BUILDING_MODELS[0]
        if isinstance(value, str) and value in BUILDING_MODELS:
            return value
        raise self.fail(
            "radio.buildings",
            f"true, false or one of {', '.join(BUILDING_MODELS)}, got {describe_value(value)}",
        )

    def calibration(self, value: Any, model: str) -> Path:
        """`radio.calibration`: a table of `gcs eval calibrate`, relative to the mission file,
        read now (a bad one is refused here, not when the medium starts)."""
        from medium.calibration import load_calibration

        name = self.string(value, "radio.calibration", "a calibration file path")
        if model != "calibrated":
            raise self.fail("radio.calibration", "radio.model: calibrated with it")
        path = (self.source.parent / name).resolve()
        try:
            load_calibration(path)
        except ValueError as error:
            raise self.fail(
                "radio.calibration", f"a calibration table of gcs eval calibrate ({error})"
            ) from None
        return path

    def signing(self, value: Any) -> Signing:
        m = self.mapping(value, "signing", ("key_file",))
        if "key_file" not in m:
            return Signing()
        key = self.string(m["key_file"], "signing.key_file", "a file path")
        return Signing(key_file=(self.source.parent / key).resolve())

    # obstacles

    def obstacles(
        self, value: Any, origin: Origin, height_limit: float | None = None
    ) -> tuple[Obstacles, tuple[str, ...]]:
        """The obstacle list -> Obstacles and their key paths; footprint files' reports go to
        `self.footprint_reports`. `height_limit` = altitude - safety_margin (heights rule)."""
        self.footprint_reports: list[FootprintReport] = []
        polygons: list[np.ndarray] = []
        polygon_keys: list[str] = []
        walls: list[np.ndarray] = []
        wall_keys: list[str] = []
        kinds = ("rectangle", "polygon", "segment", "geojson")
        items = self.sequence(
            value, "obstacles", "obstacles (rectangle, polygon, segment, geojson)"
        )
        for i, item in enumerate(items):
            path = join_key("obstacles", i)
            m = self.mapping(item, path, kinds)
            if len(m) != 1:
                raise self.fail(path, f"exactly one of {', '.join(kinds)}, got {len(m)} keys")
            (kind, spec), sub = next(iter(m.items())), join_key(path, next(iter(m)))
            if kind == "rectangle":
                polygons.append(self.rectangle(spec, sub))
                polygon_keys.append(sub)
            elif kind == "polygon":
                polygons.append(self.polygon(spec, sub))
                polygon_keys.append(sub)
            elif kind == "segment":
                walls.append(self.segment(spec, sub))
                wall_keys.append(sub)
            else:
                found = self.geojson(spec, sub, origin, height_limit)
                polygons.extend(p for _, p in found.polygons)
                polygon_keys.extend(f"{sub}.{label}" for label, _ in found.polygons)
                walls.extend(w for _, w in found.walls)
                wall_keys.extend(f"{sub}.{label}" for label, _ in found.walls)
                self.footprint_reports.append(found.report)
        obstacles = Obstacles(
            polygons=tuple(polygons),
            walls=np.array(walls, float).reshape(-1, 2, 2),
        )
        return obstacles, tuple(polygon_keys + wall_keys)

    def rectangle(self, value: Any, path: str) -> np.ndarray:
        m = self.mapping(value, path, ("center", "size", "angle_deg"), ("center", "size"))
        center = self.point(m["center"], join_key(path, "center"))
        size_path = join_key(path, "size")
        size = m["size"]
        if not isinstance(size, list) or len(size) != 2:
            raise self.fail(size_path, f"[width, height] in metres, got {describe_value(size)}")
        size = np.array([self.positive(s, join_key(size_path, k), "m") for k, s in enumerate(size)])
        angle = math.radians(self.number(m.get("angle_deg", 0.0), join_key(path, "angle_deg")))
        half = 0.5 * size
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
        rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
        return center + corners @ rot.T

    def polygon(self, value: Any, path: str) -> np.ndarray:
        if not isinstance(value, list) or len(value) < 3:
            raise self.fail(
                path, f"a list of at least 3 points [x, y], got {describe_value(value)}"
            )
        ring = np.array([self.point(p, join_key(path, k)) for k, p in enumerate(value)])
        if np.allclose(ring[0], ring[-1]) and len(ring) > 3:
            ring = ring[:-1]  # an explicitly closed ring
        shape = shapely.Polygon(ring)
        if not shape.is_valid or shape.area <= DISTANCE_TOLERANCE:
            raise self.fail(path, "a simple polygon (no self-intersection, non-zero area)")
        return ring

    def segment(self, value: Any, path: str) -> np.ndarray:
        if not isinstance(value, list) or len(value) != 2:
            raise self.fail(path, f"two points [[x, y], [x, y]], got {describe_value(value)}")
        ends = np.array([self.point(p, join_key(path, k)) for k, p in enumerate(value)])
        if np.linalg.norm(ends[1] - ends[0]) <= DISTANCE_TOLERANCE:
            raise self.fail(path, "two distinct end points")
        return ends

    def geojson(
        self, value: Any, path: str, origin: Origin, height_limit: float | None = None
    ) -> Footprints:
        """A footprint file item (`FILE` or `{file, strict, crs, height_key, bbox}`) ->
        `gcs.mission.footprints.Footprints` (labelled local rings and walls, and the report)."""
        if isinstance(value, dict):
            keys = ("file", "strict", "crs", "height_key", "bbox")
            m = self.mapping(value, path, keys, ("file",))
            options = FootprintOptions(
                file=self.string(
                    m["file"],
                    join_key(path, "file"),
                    "a footprint file path (relative to the mission file)",
                ),
                strict=self.boolean(m.get("strict", False), join_key(path, "strict")),
                crs=(
                    self.string(m["crs"], join_key(path, "crs"), "a CRS such as EPSG:3857")
                    if "crs" in m
                    else None
                ),
                height_key=(
                    self.string(m["height_key"], join_key(path, "height_key"), "a property name")
                    if "height_key" in m
                    else None
                ),
                bbox=self.bbox(m["bbox"], join_key(path, "bbox")) if "bbox" in m else None,
            )
        else:
            options = FootprintOptions(
                file=self.string(
                    value,
                    path,
                    "a GeoJSON file path (relative to the mission file) or "
                    "{file, strict, crs, height_key, bbox}",
                )
            )
        try:
            return read_footprints(
                self.source.parent / options.file,
                options,
                origin,
                key=path,
                height_limit=height_limit,
            )
        except FootprintError as exc:
            raise self.fail(join_key(path, exc.key) if exc.key else path, exc.expected) from None

    def bbox(self, value: Any, path: str) -> tuple[float, float, float, float]:
        """[west, south, east, north] in degrees, west < east, south < north."""
        want = "[west, south, east, north] in degrees"
        if not isinstance(value, list) or len(value) != 4:
            raise self.fail(path, f"{want}, got {describe_value(value)}")
        west, south, east, north = (
            self.number(v, join_key(path, i), low=-lim, high=lim, unit="degrees")
            for i, (v, lim) in enumerate(zip(value, (180.0, 90.0, 180.0, 90.0), strict=True))
        )
        if not (west < east and south < north):
            raise self.fail(path, f"{want} with west < east and south < north")
        return (west, south, east, north)

    def clear_of_obstacles(
        self,
        key: str,
        pose: Pose | Station,
        obstacles: Obstacles,
        keys: tuple[str, ...],
        safety_margin: float,
    ) -> None:
        """A and B (and each station) must lie outside every obstacle and its safety margin
        (docs/design.md 3.2)."""
        if len(obstacles) == 0:
            return
        point = shapely.Point(pose.x, pose.y)
        hits = obstacles.tree.query(
            point, predicate="dwithin", distance=safety_margin - DISTANCE_TOLERANCE
        )
        if len(hits):
            geoms = obstacles.geometries[hits]
            dist = shapely.distance(geoms, point)
            worst = int(hits[int(np.argmin(dist))])
            inside = float(dist.min()) == 0.0
            nearest = float(dist.min())
            got = "inside it" if inside else f"{_fmt(nearest, safety_margin)} m from it"
            raise self.fail(
                key,
                f"a point at least safety_margin ({_fmt(safety_margin, nearest)} m) from every "
                f"obstacle; it is {got}: {keys[worst]}",
            )
