"""One run of a study: its mission built from the base mission, the map generator and its axis
values; planned, flown in the fast mode (and replayed in ns-3 with `network: ns3`); its row.

`execute_run(study, spec)` never raises: a run that fails (a refused combination, no valid
path, an exception anywhere) is a row with its `error`. It is a plain module-level function
of frozen values, so Ray ships it to its workers as is.

A row (one JSON object of the table):

* `id`, `index`, `label`: the run's stable id, its place in the study, its axis values as text;
* `params`: each axis and its value;
* `map`: the map flown: `name`, `obstacles` (count), `density` (obstacle area over the area of
  the map: the generator's, else the bounding box of the obstacles, A and B);
* `metrics`: each kept metric (`gcs.study.studyfile.METRICS`), null where it does not apply;
* `error`: null, or one line `Type: message` (then the metrics are all null);
* `meta`: what depends on the machine, not the parameters: wall seconds (`wall_s`, `plan_s`,
  `flight_s`, `ns3_s`), `host`, `pid` and for an error its `traceback`.
"""

from __future__ import annotations

import copy
import logging
import math
import os
import socket
import time
import traceback
from typing import Any

import numpy as np
import shapely
import yaml

from fleetline.errors import FleetlineError
from gcs.mission import Mission, parse_mission, parse_yaml
from gcs.study.studyfile import MapGenerator, RunSpec, Study

log = logging.getLogger(__name__)


class NoPath(FleetlineError, RuntimeError):
    """The planner found no valid path for the run's mission."""


def mission_data(base: dict, params: dict[str, Any]) -> dict:
    """The base mission's YAML data with the mission axes of `params` applied (a copy)."""
    data = copy.deepcopy(base)
    if "seed" in params:
        data["sim"] = {**(data.get("sim") or {}), "seed": params["seed"]}
    if "fleet_size" in params:
        data["fleet"] = {**(data.get("fleet") or {}), "size": params["fleet_size"]}
    for name in ("safety_margin", "radio_range"):
        if name in params:
            data[name] = params[name]
    if "radio" in params:
        data["radio"] = {**(data.get("radio") or {}), **params["radio"]}
    if "connectivity" in params:
        data["connectivity"] = {**(data.get("connectivity") or {}), "rule": params["connectivity"]}
    return data


def _map_data(data: dict, generator: MapGenerator, params: dict[str, Any]) -> tuple[str, tuple]:
    """Replace the obstacles (and for the generators A and B) of `data` in place; returns the
    map's name and its area (xmin, ymin, xmax, ymax) or () when the map has none."""
    from planner.scenarios import city_grid, paper_scenario, random_buildings

    seed = params.get("map_seed", generator.seed)
    size = params.get("map_size", generator.size)
    if generator.kind == "geojson":
        name = params["map_file"]
        data["obstacles"] = [{"geojson": str(generator.folder / name)}]
        return name, ()
    rho_c = float(data["safety_margin"])
    rho_r = float(data["radio_range"])
    if generator.kind == "table-ii":
        scenario = paper_scenario(seed)
    elif generator.kind == "random-buildings":
        scenario = random_buildings(
            size, seed, generator.area_m, generator.building_size_m, rho_c, rho_r
        )
    else:
        scenario = city_grid(size, size, generator.block_m, generator.street_m, rho_c, rho_r)
    data["start"] = {"x": float(scenario.start[0]), "y": float(scenario.start[1]), "theta_deg": 0}
    data["goal"] = {"x": float(scenario.goal[0]), "y": float(scenario.goal[1]), "theta_deg": 0}
    data["obstacles"] = [
        {"rectangle": {"center": [float(r[0]), float(r[1])], "size": [float(r[2]), float(r[3])],
                       "angle_deg": float(r[4])}}
        for r in scenario.rectangles
    ]  # fmt: skip
    return scenario.name, scenario.area


def build_mission(study: Study, spec: RunSpec) -> tuple[Mission, dict[str, Any]]:
    """The run's mission (before its speed schedule) and the description of its map."""
    from gcs.sim.eval import fixed_speed, led

    base = parse_yaml(study.base_text)
    params = spec.params
    data = mission_data(base, params)
    name, area = ("base", ())
    if study.map is not None:
        name, area = _map_data(data, study.map, params)
    text = yaml.safe_dump(data, sort_keys=False)
    mission = parse_mission(data, study.base, text)
    speed = params.get("speed")
    if params.get("leader") is not None:
        initial = mission.speed.initial if speed is None else speed
        mission = led(mission, params["leader"], initial, study.leader_requests)
    elif speed is not None:
        mission = fixed_speed(mission, speed)
    return mission, {"name": name, **_map_numbers(mission, area)}


def _map_numbers(mission: Mission, area: tuple) -> dict[str, Any]:
    geometries = mission.obstacles.geometries
    covered = float(shapely.union_all(geometries).area) if len(geometries) else 0.0
    if area:
        extent = (area[2] - area[0]) * (area[3] - area[1])
    else:
        points = [mission.start.xy] + ([mission.goal.xy] if mission.goal is not None else [])
        bounds = np.array([shapely.bounds(g) for g in geometries]).reshape(-1, 4)
        corners = np.concatenate([np.array(points), bounds[:, :2], bounds[:, 2:]])
        span = corners.max(axis=0) - corners.min(axis=0)
        extent = float(span[0] * span[1])
    return {
        "obstacles": int(len(geometries)),
        "density": covered / extent if extent > 0 else None,
    }


def _finite(value: Any) -> Any:
    """JSON-safe: NaN and infinities become None, numpy scalars Python ones."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _ratio(counts: dict) -> float | None:
    return counts["received"] / counts["sent"] if counts["sent"] else None


def _flight_metrics(plan, flown, mission: Mission, speed, leader) -> dict[str, Any]:
    from gcs.sim.eval import EvalRun, run_metrics

    m = run_metrics(EvalRun("run", speed, leader, flown, 0.0), mission)
    pp = plan.path_plan
    return {
        "fleet_size": plan.fleet_size,
        "min_fleet_size": int(pp.min_fleet_size),
        "path_length_m": float(pp.length_m),
        "planned_duration_s": plan.duration_s,
        "safe_speed_mps": plan.safe_speed_mps,
        "graph_nodes": int(pp.node_count),
        "expansions": int(pp.expansions),
        "certified": bool(pp.certified),
        "completed": bool(m["completed"]),
        "duration_s": m["duration_s"],
        "min_uav_uav_m": m["min_uav_uav_m"],
        "min_uav_obstacle_m": m["min_uav_obstacle_m"],
        "max_tracking_error_m": m["max_tracking_error_m"],
        "connected_fraction": m["connected_fraction"],
        "los_connected_fraction": flown.run_json.get("los_connected_fraction"),
        "uav_delivery": _ratio(m["uav_data"]),
        "uav_dropped": m["uav_data"]["dropped"],
        "uav_delay_mean_ms": m["uav_data"]["delay_mean_ms"],
        "uav_max_hops": m["uav_data"]["max_hops"],
        "uav_longest_gap_s": m["uav_data"]["longest_gap_s"],
        "ground_delivery": m["ground_users"]["ratio"],
        "ground_dropped": m["ground_users"]["dropped"],
        "ground_delay_mean_ms": m["ground_users"]["delay_mean_ms"],
        "reaction_worst_s": m["reaction_worst_s"],
        "reaction_mean_s": m["reaction_mean_s"],
    }


def _ns3_metrics(study: Study, flown, mission: Mission, speed, leader) -> dict[str, Any]:
    from gcs.netsim.ns3 import NetOptions
    from gcs.netsim.paper import net_metrics, replay_in_ns3
    from gcs.sim.eval import EvalRun

    options = NetOptions(seed=max(1, mission.sim.seed), **dict(study.ns3))
    (replayed,) = replay_in_ns3([EvalRun("run", speed, leader, flown, 0.0)], mission, options)
    n = net_metrics(replayed, mission)
    chain = n["reactions"]["chain"]
    return {
        "ns3_uav_delivery": n["uav_data"]["ratio"],
        "ns3_uav_delay_mean_ms": n["uav_data"]["delay_mean_ms"],
        "ns3_uav_longest_gap_s": n["uav_data"]["longest_gap_s"],
        "ns3_ground_delivery": n["ground_users"]["ratio"],
        "ns3_reaction_worst_s": chain["worst_s"],
        "ns3_reaction_mean_s": chain["mean_s"],
    }


def execute_run(study: Study, spec: RunSpec) -> dict[str, Any]:
    """Fly one run of `study`; its row (see the module docstring). Never raises."""
    from gcs.planning import plan_mission
    from gcs.sim.fastsim import FastOptions, fly_fast

    began = time.perf_counter()
    meta: dict[str, Any] = {"host": socket.gethostname(), "pid": os.getpid()}
    row: dict[str, Any] = {
        "id": spec.id,
        "index": spec.index,
        "label": spec.label,
        "params": spec.params,
        "map": None,
        "metrics": {name: None for name in study.metrics},
        "error": None,
        "meta": meta,
    }
    try:
        mission, row["map"] = build_mission(study, spec)
        step = time.perf_counter()
        plan = plan_mission(mission, method=spec.params.get("planner", "exact"))
        meta["plan_s"] = time.perf_counter() - step
        if not plan.valid:
            raise NoPath(plan.reason or "no valid path")
        step = time.perf_counter()
        flown = fly_fast(plan, FastOptions())
        meta["flight_s"] = time.perf_counter() - step
        speed, leader = spec.params.get("speed"), spec.params.get("leader")
        values = _flight_metrics(plan, flown, mission, speed, leader)
        if spec.params.get("network") == "ns3":
            step = time.perf_counter()
            values |= _ns3_metrics(study, flown, mission, speed, leader)
            meta["ns3_s"] = time.perf_counter() - step
        row["metrics"] = {name: _finite(values.get(name)) for name in study.metrics}
    except Exception as error:  # noqa: BLE001 - a failed run is a row, never a lost study
        row["error"] = " ".join(f"{type(error).__name__}: {error}".split())
        meta["traceback"] = traceback.format_exc(limit=-3)
        log.info("run %s (%s) failed: %s", spec.id, spec.label, row["error"])
    meta["wall_s"] = time.perf_counter() - began
    return row


def failed_row(study: Study, spec: RunSpec, error: str) -> dict[str, Any]:
    """The row of a run that never returned its own (its worker died, say)."""
    return {
        "id": spec.id,
        "index": spec.index,
        "label": spec.label,
        "params": spec.params,
        "map": None,
        "metrics": {name: None for name in study.metrics},
        "error": " ".join(error.split()),
        "meta": {},
    }


__all__ = ["NoPath", "build_mission", "execute_run", "failed_row", "mission_data"]
