"""Study file (YAML, version 1, docs/study.md) -> a validated, frozen `Study`, and its axes
expanded into `RunSpec`s.

A study is a base mission, optionally with its map replaced by a generator, and axes: every
combination of the axes' values is one run. Each run has a stable id, a hash of its
parameters and of everything else that decides its result (the base mission's text, the map
generator, the leader's requests, the ns-3 options and the kept metrics), so an interrupted
study resumes exactly where it stopped, and a changed study never reuses a stale row.

Bad input raises `gcs.errors.InputError` naming the study file, the key and what is expected
(the base mission's own refusals name the base mission file), in the style of `gcs.mission`.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gcs.errors import InputError, join_key
from gcs.mission import (
    CONNECTIVITY_RULES,
    MissionParser,
    describe_value,
    load_mission,
    parse_mission,
    parse_yaml,
    read_yaml,
)
from planner.scenarios import LEADER_REQUESTS
from planner.types import METHODS

#: The only study file version this code reads.
VERSION = 1
GENERATORS = ("table-ii", "random-buildings", "city-grid", "geojson")
NETWORKS = ("medium", "ns3")
#: What each axis sets, in the order the docs list them.
AXES = {
    "seed": "sim.seed of the mission (the simulator's wind and noise)",
    "map_seed": "the map generator's seed (table-ii, random-buildings)",
    "map_size": "buildings (random-buildings) or blocks per side (city-grid)",
    "map_file": "one GeoJSON file of the geojson generator's folder (all of them by default)",
    "speed": "a fixed formation speed, m/s (the base mission's schedule when absent)",
    "leader": "null: no leader; N: UAV N asks for leader_requests at `speed`",
    "fleet_size": "auto or a number of UAVs",
    "safety_margin": "rho_c, m",
    "radio_range": "rho_R, m",
    "radio": "a mapping merged into the mission's radio section",
    "connectivity": "the mission's connectivity.rule: disk or line_of_sight",
    "network": "medium (the fast mode's radio only) or ns3 (the flight also replayed in ns-3)",
    "planner": "the path search method: exact or penalty",
}
#: The metrics a row can keep (`metrics:`), with what they are.
METRICS = {
    # the plan
    "fleet_size": "UAVs flown (eq. 28, or fleet.size)",
    "min_fleet_size": "the smallest fleet the planned path allows",
    "path_length_m": "length of the planned path, m",
    "planned_duration_s": "the plan's mission duration, s",
    "safe_speed_mps": "the safe formation speed at the path's bends, m/s",
    "graph_nodes": "nodes of the planner's graph",
    "expansions": "states the path search took off its queues",
    "certified": "the path length is proven minimal",
    # the flight (fast mode, our radio medium)
    "completed": "every UAV landed at B",
    "duration_s": "first take-off to last landing, s",
    "min_uav_uav_m": "smallest UAV-UAV distance, m",
    "min_uav_obstacle_m": "smallest UAV-obstacle distance, m",
    "max_tracking_error_m": "largest distance of a UAV from its set point, m",
    "los_connected_fraction": "share of the ground station's samples with every UAV connected "
    "by line of sight",
    "connected_fraction": "fraction of samples with every UAV connected to a base station",
    "uav_delivery": "UAV data packets received at a base station / sent",
    "uav_dropped": "UAV data packets dropped",
    "uav_delay_mean_ms": "mean delay of the UAV data to a base station (T_BS), ms",
    "uav_max_hops": "most hops of a UAV data packet",
    "uav_longest_gap_s": "longest stretch without UAV data received (a flat BS_con), s",
    "ground_delivery": "ground-user packets received / sent",
    "ground_dropped": "ground-user packets dropped",
    "ground_delay_mean_ms": "mean delay of the ground users' packets, ms",
    "reaction_worst_s": "worst T_dv of the leader's requests, s",
    "reaction_mean_s": "mean T_dv of the leader's requests, s",
    # the flight replayed in ns-3 (network: ns3; null otherwise)
    "ns3_uav_delivery": "ns-3: UAV data delivered / sent",
    "ns3_uav_delay_mean_ms": "ns-3: mean UAV data delay, ms",
    "ns3_uav_longest_gap_s": "ns-3: longest handover gap of a UAV, s",
    "ns3_ground_delivery": "ns-3: ground-user packets delivered / sent",
    "ns3_reaction_worst_s": "ns-3: worst T_dv by the paper's UAV-to-UAV chain, s",
    "ns3_reaction_mean_s": "ns-3: mean T_dv by the paper's chain, s",
}
#: Keys of the `ns3:` section (`gcs.netsim.ns3.NetOptions`) and their choices.
NS3_KEYS = {"propagation": ("range", "logdistance"), "routing": ("aodv", "olsr")}


@dataclass(frozen=True)
class MapGenerator:
    """How each run's map is made (None in `Study.map`: the base mission's own obstacles).

    `seed` and `size` are the values when the study has no `map_seed` / `map_size` axis."""

    kind: str
    seed: int = 8
    size: int = 50
    area_m: float = 2000.0
    building_size_m: tuple[float, float] = (20.0, 90.0)
    block_m: float = 40.0
    street_m: float = 20.0
    folder: Path | None = None
    files: tuple[str, ...] = ()  # geojson: the folder's *.geojson, sorted


@dataclass(frozen=True)
class RunSpec:
    """One run: its stable id, its index in the study and the value of each axis."""

    id: str
    index: int
    params: dict[str, Any] = field(hash=False)

    @property
    def label(self) -> str:
        return " ".join(f"{k}={_short(v)}" for k, v in self.params.items()) or "base"


@dataclass(frozen=True)
class Study:
    """A validated study file; `axes` in file order, each with its values."""

    source: Path
    text: str
    name: str
    base: Path
    base_text: str
    map: MapGenerator | None
    axes: tuple[tuple[str, tuple[Any, ...]], ...]
    leader_requests: tuple[tuple[float, float], ...]
    metrics: tuple[str, ...]
    ns3: tuple[tuple[str, str], ...] = ()

    @property
    def axis_names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.axes)

    @property
    def digest(self) -> str:
        """Hash of what decides a run's result besides its parameters."""
        context = {
            "base": self.base_text,
            "map": None if self.map is None else _canonical_map(self.map),
            "leader_requests": self.leader_requests,
            "metrics": self.metrics,
            "ns3": self.ns3,
        }
        return hashlib.sha256(_canonical(context).encode()).hexdigest()

    def runs(self) -> tuple[RunSpec, ...]:
        """Every combination of the axes, in file order (the last axis varies fastest)."""
        digest = self.digest
        names = self.axis_names
        out = []
        for index, values in enumerate(itertools.product(*(v for _, v in self.axes))):
            params = dict(zip(names, values, strict=True))
            key = _canonical({"study": digest, "params": params})
            out.append(RunSpec(hashlib.sha256(key.encode()).hexdigest()[:16], index, params))
        return tuple(out)

    def summary(self) -> dict[str, Any]:
        """What `DIR/study.json` records for the report: the axes, the metrics, the run ids."""
        return {
            "name": self.name,
            "source": str(self.source),
            "base": str(self.base),
            "map": None if self.map is None else _canonical_map(self.map),
            "axes": {name: list(values) for name, values in self.axes},
            "metrics": list(self.metrics),
            "runs": [spec.id for spec in self.runs()],
        }


def _canonical(value: Any) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=str)


def _canonical_map(generator: MapGenerator) -> dict[str, Any]:
    return {
        "generator": generator.kind,
        "seed": generator.seed,
        "size": generator.size,
        "area_m": generator.area_m,
        "building_size_m": list(generator.building_size_m),
        "block_m": generator.block_m,
        "street_m": generator.street_m,
        "folder": None if generator.folder is None else str(generator.folder),
        "files": list(generator.files),
    }


def _short(value: Any) -> str:
    if isinstance(value, dict):
        return "{" + ",".join(f"{k}:{v}" for k, v in value.items()) + "}"
    if isinstance(value, float):
        return f"{value:g}"
    return "none" if value is None else str(value)


# --------------------------------------------------------------------------- loading
def load_study(path: str | Path) -> Study:
    """Read and validate a study file (and its base mission); `InputError` on bad input."""
    path = Path(path)
    text, data = read_yaml(path, "a study file")
    return _StudyParser(path).study(data, text)


class _StudyParser(MissionParser):
    """Walks the study file with key paths (the mission file's readers); every refusal raises
    `InputError`."""

    document = "study"

    def __init__(self, source: Path) -> None:
        super().__init__(source)

    # sections

    def study(self, data: Any, text: str) -> Study:
        root = self.mapping(
            data,
            "",
            ("version", "name", "base", "map", "axes", "leader_requests", "metrics", "ns3"),
            ("version", "base", "axes"),
        )
        if root["version"] != VERSION or isinstance(root["version"], bool):
            raise self.fail("version", f"{VERSION}, got {describe_value(root['version'])}")
        name = root.get("name", self.source.stem)
        if not isinstance(name, str) or not name.strip():
            raise self.fail("name", f"a non-empty string, got {describe_value(name)}")
        base = self.base(root["base"])
        base_mission = load_mission(base)  # its own refusals name the base mission file
        generator = self.map(root["map"]) if "map" in root else None
        requests = self.requests(root.get("leader_requests"))
        metrics = self.metrics(root.get("metrics"))
        ns3 = self.ns3(root.get("ns3", {}))
        axes = self.axes(root["axes"], generator)
        study = Study(
            source=self.source.resolve(),
            text=text,
            name=name,
            base=base,
            base_text=base_mission.text,
            map=generator,
            axes=axes,
            leader_requests=requests,
            metrics=metrics,
            ns3=ns3,
        )
        self.check_overrides(study)
        return study

    def base(self, value: Any) -> Path:
        if not isinstance(value, str) or not value.strip():
            raise self.fail("base", f"a mission file path, got {describe_value(value)}")
        path = (self.source.parent / value).resolve()
        if not path.is_file():
            raise self.fail(
                "base", f"an existing mission file (relative to the study), got {value}"
            )
        return path

    def map(self, value: Any) -> MapGenerator:
        m = self.mapping(
            value,
            "map",
            ("generator", "seed", "buildings", "area_m", "building_size_m", "blocks", "block_m",
             "street_m", "folder"),
            ("generator",),
        )  # fmt: skip
        kind = self.choice(m["generator"], "map.generator", GENERATORS)
        fits = {
            "seed": ("table-ii", "random-buildings"),
            "buildings": ("random-buildings",),
            "area_m": ("random-buildings",),
            "building_size_m": ("random-buildings",),
            "blocks": ("city-grid",),
            "block_m": ("city-grid",),
            "street_m": ("city-grid",),
            "folder": ("geojson",),
        }
        for key in m:
            if key != "generator" and kind not in fits[key]:
                raise self.fail(
                    f"map.{key}",
                    f"no such key with generator {kind} (it is for {', '.join(fits[key])})",
                )
        d = MapGenerator(kind)
        size = m.get("buildings", m.get("blocks", 8 if kind == "city-grid" else d.size))
        generator = MapGenerator(
            kind=kind,
            seed=self.integer(m.get("seed", d.seed), "map.seed", 0),
            size=self.integer(size, "map.buildings" if "buildings" in m else "map.blocks", 1),
            area_m=self.positive(m.get("area_m", d.area_m), "map.area_m", "m"),
            building_size_m=self.size_range(m.get("building_size_m", list(d.building_size_m))),
            block_m=self.positive(m.get("block_m", d.block_m), "map.block_m", "m"),
            street_m=self.positive(m.get("street_m", d.street_m), "map.street_m", "m"),
        )
        if kind == "geojson":
            if "folder" not in m:
                raise self.fail("map.folder", "this required key with generator geojson")
            folder = m["folder"]
            if not isinstance(folder, str) or not folder.strip():
                raise self.fail("map.folder", f"a folder path, got {describe_value(folder)}")
            path = (self.source.parent / folder).resolve()
            files = tuple(sorted(p.name for p in path.glob("*.geojson"))) if path.is_dir() else ()
            if not files:
                raise self.fail("map.folder", f"a folder of .geojson files, got {folder}")
            generator = MapGenerator(kind, folder=path, files=files)
        return generator

    def size_range(self, value: Any) -> tuple[float, float]:
        key = "map.building_size_m"
        if not isinstance(value, list) or len(value) != 2:
            raise self.fail(key, f"[smallest, largest] in metres, got {describe_value(value)}")
        low, high = (self.positive(v, join_key(key, i), "m") for i, v in enumerate(value))
        if low > high:
            raise self.fail(key, f"smallest <= largest, got [{low:g}, {high:g}]")
        return low, high

    def requests(self, value: Any) -> tuple[tuple[float, float], ...]:
        if value is None:
            return LEADER_REQUESTS
        key = "leader_requests"
        if not isinstance(value, list) or not value:
            raise self.fail(
                key, f"a non-empty list of [time s, speed m/s], got {describe_value(value)}"
            )
        out = []
        for i, item in enumerate(value):
            if not isinstance(item, list) or len(item) != 2:
                raise self.fail(
                    join_key(key, i), f"[time s, speed m/s], got {describe_value(item)}"
                )
            out.append(
                (
                    self.positive(item[0], join_key(join_key(key, i), 0), "s"),
                    self.positive(item[1], join_key(join_key(key, i), 1), "m/s"),
                )
            )
        return tuple(out)

    def metrics(self, value: Any) -> tuple[str, ...]:
        if value is None:
            return tuple(METRICS)
        if not isinstance(value, list) or not value:
            raise self.fail(
                "metrics", f"a non-empty list of metric names, got {describe_value(value)}"
            )
        for i, name in enumerate(value):
            if name not in METRICS:
                raise self.fail(
                    join_key("metrics", i),
                    f"one of {', '.join(METRICS)}, got {describe_value(name)}",
                )
        if len(set(value)) != len(value):
            raise self.fail("metrics", "each metric once")
        return tuple(value)

    def ns3(self, value: Any) -> tuple[tuple[str, str], ...]:
        m = self.mapping(value, "ns3", tuple(NS3_KEYS))
        return tuple((k, self.choice(m[k], f"ns3.{k}", NS3_KEYS[k])) for k in NS3_KEYS if k in m)

    def axes(self, value: Any, generator: MapGenerator | None) -> tuple[tuple[str, tuple], ...]:
        m = self.mapping(value, "axes", tuple(AXES))
        kind = None if generator is None else generator.kind
        needs = {
            "map_seed": ("table-ii", "random-buildings"),
            "map_size": ("random-buildings", "city-grid"),
            "map_file": ("geojson",),
        }
        out = []
        for name, values in m.items():
            key = f"axes.{name}"
            if name in needs and kind not in needs[name]:
                raise self.fail(key, f"a map generator {' or '.join(needs[name])} (map.generator)")
            if not isinstance(values, list) or not values:
                raise self.fail(key, f"a non-empty list of values, got {describe_value(values)}")
            parsed = tuple(
                self.axis_value(name, v, join_key(key, i), generator) for i, v in enumerate(values)
            )
            seen = [_canonical(v) for v in parsed]
            if len(set(seen)) != len(seen):
                raise self.fail(key, "each value once")
            out.append((name, parsed))
        if kind == "geojson" and "map_file" not in m:
            out.append(("map_file", generator.files))
        return tuple(out)

    def axis_value(self, name: str, value: Any, key: str, generator: MapGenerator | None) -> Any:
        if name in ("seed", "map_seed"):
            return self.integer(value, key, 0)
        if name == "map_size":
            return self.integer(value, key, 1)
        if name == "map_file":
            if value not in generator.files:
                raise self.fail(
                    key, f"a .geojson file of {generator.folder}, got {describe_value(value)}"
                )
            return value
        if name in ("speed", "safety_margin", "radio_range"):
            return self.positive(value, key, "m/s" if name == "speed" else "m")
        if name == "leader":
            return None if value is None or value == "none" else self.integer(value, key, 1)
        if name == "fleet_size":
            return "auto" if value == "auto" else self.integer(value, key, 1)
        if name == "radio":
            if not isinstance(value, dict) or not value:
                raise self.fail(key, f"a mapping of radio keys, got {describe_value(value)}")
            return dict(value)
        if name == "network":
            return self.choice(value, key, NETWORKS)
        if name == "connectivity":
            return self.choice(value, key, CONNECTIVITY_RULES)
        return self.choice(value, key, METHODS)  # planner

    def check_overrides(self, study: Study) -> None:
        """Each value of a mission axis alone on the base mission must be a valid mission (a
        combination may still be refused: that run's row then carries the refusal)."""
        from gcs.study.runs import mission_data

        base = parse_yaml(study.base_text)
        for name, values in study.axes:
            if name not in ("safety_margin", "radio_range", "radio", "fleet_size", "connectivity"):
                continue
            for i, value in enumerate(values):
                data = mission_data(base, {name: value})
                try:
                    parse_mission(data, study.base, check_clearance=False)
                except InputError as error:
                    raise self.fail(
                        f"axes.{name}[{i}]",
                        f"a value the base mission accepts ({error.key_path}: expected "
                        f"{error.expected})",
                    ) from None
