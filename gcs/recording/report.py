"""`gcs log report`: the paper's figures and a short summary from a recording, without flying.

Everything is recomputed from what the log holds (docs/design.md 5):
* the fleet samples the GCS's monitors checked (`/metrics` positions, every tick) go through
  the planner's guarantee checks (`planner.guarantees.check_positions`): smallest UAV-UAV and
  UAV-obstacle distance over time (the paper's figs. 8 and 9, D_min) and connectivity;
* each UAV's true track (`/uav<n>/state`) against its virtual target V_n(t) (eq. 27), rebuilt
  from the plan (`plan.json`), the speed changes actually flown (`/speed`) and, for a stations
  mission, its return home (`/return`): the tracking error per UAV, and the distance
  travelled against time next to the planned one (fig. 3);
* the map with the planned path and the flown tracks (fig. 7), drawn over `gcs.plot`'s map;
* reaction time of each UAV to each speed change, T_dv (fig. 10);
* packets received at the base stations over time, BS_con (figs. 12-13): the telemetry the
  ground station (wired to every base station) received from each UAV, plus the radio
  medium's counters (`/radio`) when the log has them.
Figures are PNG files in the output directory, with `summary.md` (human) and `summary.json`
(the numbers).
"""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import yaml  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from gcs import plot  # noqa: E402
from gcs.errors import InputError  # noqa: E402
from gcs.mission import Mission, parse_mission  # noqa: E402
from gcs.mission.footprints import SHAPEFILE_SIDES, footprint_file  # noqa: E402
from gcs.planning import MissionPlan  # noqa: E402
from gcs.recording.logreader import Recording  # noqa: E402
from planner.formation import ParkingRows  # noqa: E402
from planner.guarantees import check_positions  # noqa: E402
from planner.kinematics import LineFormation, SpeedProfile  # noqa: E402
from planner.obstacles import Obstacles  # noqa: E402
from planner.sight import Sight
from planner.types import PathPlan  # noqa: E402

#: The figures `write_report` draws (file name -> what it shows).
FIGURES = {
    "map.png": "map: planned path and flown tracks (fig. 7)",
    "distances.png": "smallest UAV-UAV and UAV-obstacle distance over time (figs. 8, 9)",
    "tracking.png": "tracking error |R_n - V_n| per UAV over time",
    "speed_reactions.png": "reaction time of each UAV to each speed change, T_dv (fig. 10)",
    "base_stations.png": "packets received at the base stations over time (figs. 12, 13)",
    "distance_travelled.png": "distance travelled per UAV against time (fig. 3)",
    "connectivity.png": "every UAV connected to a base station over time: by distance (the "
    "paper's disk) and by line of sight (every hop's chord clear of the obstacles)",
}
DPI = 110


@dataclass(frozen=True, eq=False)
class Track:
    """One UAV's recorded samples: mission time (T,), true position (T, 3), and the tracking
    error the GCS computed (T,) (NaN where it had none)."""

    times: np.ndarray
    positions: np.ndarray
    logged_error: np.ndarray


@dataclass(frozen=True, eq=False)
class Flight:
    """What a recording says about one flight, as arrays."""

    name: str
    fleet_size: int
    safety_margin: float
    radio_range: float
    plan: dict
    mission: Mission | None
    formation: LineFormation | None
    profile: SpeedProfile
    tracks: list[Track]
    sample_times: np.ndarray  # (S,) mission time of each fleet sample
    sample_positions: np.ndarray  # (S, N, 2), NaN = unknown
    requests: list[dict]
    acks: list[dict]
    telemetry_times: list[np.ndarray]  # per UAV: mission time of each message received
    radio: list[dict]
    run: dict | None  # the run JSON the GCS wrote (attachment), if it finished
    # reliefs (`/relief`): the samples' heights (S, N), NaN unless a relieved UAV flew above
    # the chain (the checks were 3-D), and the UAVs out of the fleet (S, N)
    reliefs: list[dict] = field(default_factory=list)
    sample_heights: np.ndarray | None = None
    sample_out: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class FlightMetrics:
    """The guarantee checks over the fleet samples and the tracking errors per UAV."""

    uav_uav_m: np.ndarray  # (S,) NaN when fewer than two UAVs were known
    uav_obstacle_m: np.ndarray  # (S,)
    connected: np.ndarray  # (S,) 1.0 / 0.0, NaN when not every UAV was known
    tracking_error_m: list[np.ndarray]  # per UAV, at its track's times
    #: (S,) as `connected`, every hop also in line of sight (`planner.sight`)
    los_connected: np.ndarray = field(default_factory=lambda: np.zeros(0))
    summary: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------- loading
def load_flight(recording: Recording) -> Flight:
    """Arrays of one flight from a recording (refused, exit 2, without a plan)."""
    plan = recording.json_attachment("plan.json") or recording.first("/plan")
    if not plan or not plan.get("path"):
        raise InputError(recording.path, "", "a recording of `gcs mission run` (no plan in it)")
    epoch = recording.epoch_ns
    size = int(plan["fleet_size"])
    mission = _mission(recording)
    formation = _formation(plan, recording.first("/return"))
    requests = [m for _, m in recording.messages("/speed") if m.get("kind") == "request"]
    acks = [m for _, m in recording.messages("/speed") if m.get("kind") == "ack"]
    profile = SpeedProfile.constant(float(plan.get("initial_speed_mps") or plan["max_speed_mps"]))
    for request in requests:
        profile = profile.with_change(float(request["effective_s"]), float(request["speed"]))
    tracks = []
    for uav in range(1, size + 1):
        rows = [
            m
            for _, m in recording.messages(f"/uav{uav}/state")
            if m.get("t") is not None and (m.get("true_position") or m.get("position"))
        ]
        times = np.array([m["t"] for m in rows], float)
        xyz = np.array([m.get("true_position") or m["position"] for m in rows], float)
        logged = np.array([_num(m.get("tracking_error_m")) for m in rows], float)
        order = np.argsort(times, kind="stable")
        tracks.append(Track(times[order], xyz.reshape(-1, 3)[order], logged[order]))
    samples = [
        m
        for _, m in recording.messages("/metrics")
        if m.get("positions") and m.get("t") is not None
    ]
    sample_times = np.array([m["t"] for m in samples], float)
    sample_positions = np.full((len(samples), size, 2), np.nan)
    sample_heights = np.full((len(samples), size), np.nan)
    sample_out = np.zeros((len(samples), size), dtype=bool)
    for k, sample in enumerate(samples):
        for index, xy in enumerate(sample["positions"][:size]):
            if xy is not None:
                sample_positions[k, index] = xy[:2]
                if len(xy) > 2:
                    sample_heights[k, index] = xy[2]
        for uav in sample.get("out_of_fleet") or ():
            sample_out[k, uav - 1] = True
    if not samples:  # an older log: resample the true tracks on the metrics' times
        sample_times = np.array([m["t"] for _, m in recording.messages("/metrics")], float)
        sample_positions = _resample(tracks, sample_times)
    telemetry = []
    for uav in range(1, size + 1):
        data = recording.topics.get(f"/mavlink/{uav}/rx")
        times = np.array(data.times if data else [], float)
        telemetry.append(np.sort((times - epoch) / 1e9) if epoch is not None else times[:0])
    return Flight(
        name=recording.mission_name or plan.get("name") or recording.path.stem,
        fleet_size=size,
        safety_margin=float(plan["safety_margin_m"]),
        radio_range=float(plan["radio_range_m"]),
        plan=plan,
        mission=mission,
        formation=formation,
        profile=profile,
        tracks=tracks,
        sample_times=sample_times,
        sample_positions=sample_positions,
        requests=requests,
        acks=acks,
        telemetry_times=telemetry,
        radio=[m for _, m in recording.messages("/radio")],
        run=recording.json_attachment("run.json"),
        reliefs=[m for _, m in recording.messages("/relief")],
        sample_heights=sample_heights,
        sample_out=sample_out,
    )


def _num(value: Any) -> float:
    return float(value) if isinstance(value, int | float) else math.nan


def _resample(tracks: list[Track], times: np.ndarray) -> np.ndarray:
    out = np.full((len(times), len(tracks), 2), np.nan)
    for index, track in enumerate(tracks):
        if len(track.times) < 2:
            continue
        inside = (times >= track.times[0]) & (times <= track.times[-1])
        for axis in range(2):
            out[inside, index, axis] = np.interp(
                times[inside], track.times, track.positions[:, axis]
            )
    return out


def _mission(recording: Recording) -> Mission | None:
    """The mission, validated again from the attached file (its GeoJSON files too)."""
    text = recording.attachments.get("mission.yaml")
    if text is None:
        return None
    try:
        data = yaml.safe_load(text.decode())
        with tempfile.TemporaryDirectory(prefix="fleetline-report-") as folder:
            source = Path(folder) / "mission.yaml"
            for index, item in enumerate(data.get("obstacles") or []):
                name = footprint_file(item)
                if name is None or f"geojson/{name}" not in recording.attachments:
                    continue
                # written under a new stem, its suffix kept (it decides the format), with a
                # shapefile's side files beside it
                stem = Path(folder) / f"obstacles-{index}"
                suffix = "".join(Path(name).suffixes)
                local = Path(f"{stem}{suffix}")
                local.write_bytes(recording.attachments[f"geojson/{name}"])
                base = name[: -len(".shp")] if name.lower().endswith(".shp") else None
                for side in SHAPEFILE_SIDES if base is not None else ():
                    if f"geojson/{base}{side}" in recording.attachments:
                        Path(f"{stem}{side}").write_bytes(
                            recording.attachments[f"geojson/{base}{side}"]
                        )
                if isinstance(item["geojson"], dict):
                    item["geojson"]["file"] = str(local)  # absolute: read from here
                else:
                    item["geojson"] = str(local)
            return parse_mission(data, source, text.decode())
    except (InputError, yaml.YAMLError, AttributeError, UnicodeDecodeError):
        return None


def _formation(plan: dict, returned: dict | None = None) -> LineFormation | None:
    """The line formation of the plan JSON (path, fleet size, parking rows). A stations
    mission's (no row at B, `stations.uav_stations_m`) is capped on its stations, and flies
    home from the distance of the recording's `/return` record (`returned`) when it has one."""
    try:
        path = np.array(plan["path"], float)
        start_row = np.array(plan["parking_rows"]["A"], float)
        e0 = start_row[0] - start_row[1]
        stations = None
        if plan.get("stations"):
            stations = np.array(plan["stations"]["uav_stations_m"], float)
            goal_row = np.array([path[-1], path[-1]])  # open: no row beyond the last point
            ek = path[-1] - path[-2]  # (never flown: every UAV stops on the route)
        else:
            goal_row = np.array(plan["parking_rows"]["B"], float)
            ek = goal_row[1] - goal_row[0]
        rows = ParkingRows(
            start_row=start_row,
            goal_row=goal_row,
            start_direction=e0 / np.hypot(*e0),
            goal_direction=ek / np.hypot(*ek),
            open_goal=stations is not None,
        )
        formation = LineFormation(
            path=path,
            fleet_size=int(plan["fleet_size"]),
            safety_margin=float(plan["safety_margin_m"]),
            radio_range=float(plan["radio_range_m"]),
            rows=rows,
            stations=stations,
            spacing=(plan.get("connectivity") or {}).get("spacing_m"),
            warp=(plan.get("connectivity") or {}).get("warp_m"),
        )
        if stations is not None and returned is not None:
            formation = formation.with_return(float(returned["distance"]))
        return formation
    except (KeyError, ValueError, IndexError, TypeError):
        return None


# --------------------------------------------------------------------------- metrics
def _base_stations(flight: Flight) -> np.ndarray:
    mission = flight.mission
    if mission is not None:
        return mission.base_station_points
    path = np.array(flight.plan["path"], float)
    return path[[0, -1]]


def flight_metrics(flight: Flight) -> FlightMetrics:
    """Guarantee checks on every fleet sample and tracking errors on every track sample.

    As the GCS's monitors do: distances over the UAVs known at a sample (at least one), the
    connectivity only at samples where every UAV is known. Since a relief: the UAVs out of the
    fleet are left out, the samples with heights are checked in 3-D, and the tracking errors
    are the ground station's own (its V_n flew the relief's motions and the formation of the
    UAVs left; the plan's formation is rebuilt only up to the first relief)."""
    positions = flight.sample_positions
    count, size = positions.shape[:2]
    pair = np.full(count, np.nan)
    obstacle = np.full(count, np.nan)
    connected = np.full(count, np.nan)
    los_connected = np.full(count, np.nan)
    obstacles = flight.mission.obstacles if flight.mission is not None else Obstacles()
    sight = Sight(obstacles)
    stations = _base_stations(flight)
    out = flight.sample_out if flight.sample_out is not None else np.zeros((count, size), bool)
    heights = flight.sample_heights
    lane = np.zeros(count, bool) if heights is None else np.isfinite(heights).any(axis=1)
    known = np.isfinite(positions).all(axis=2) & ~out  # (S, N)
    keys = np.column_stack([known, out, lane])
    masks, groups = np.unique(keys, axis=0, return_inverse=True)
    for g, key in enumerate(masks):
        mask, left, above = key[:size], key[size : 2 * size], key[-1]
        if not mask.any():
            continue
        rows = np.flatnonzero(groups.reshape(-1) == g)
        checked = check_positions(
            positions[rows][:, mask],
            obstacles,
            stations,
            flight.radio_range,
            np.nan_to_num(heights[rows][:, mask]) if above else None,
        )
        pair[rows] = np.where(np.isfinite(checked.min_uav_uav_m), checked.min_uav_uav_m, np.nan)
        obstacle[rows] = np.where(
            np.isfinite(checked.min_uav_obstacle_m), checked.min_uav_obstacle_m, np.nan
        )
        if (mask | left).all():
            connected[rows] = checked.connected.astype(float)
            by_sight = check_positions(
                positions[rows][:, mask],
                Obstacles(),
                stations,
                flight.radio_range,
                np.nan_to_num(heights[rows][:, mask]) if above else None,
                sight=sight,
            )
            los_connected[rows] = by_sight.connected.astype(float)
    relieved_from = min((float(r["t"]) for r in flight.reliefs), default=math.inf)
    errors = []
    for index, track in enumerate(flight.tracks):
        if flight.formation is None or not len(track.times):
            errors.append(track.logged_error)
            continue
        virtual = flight.formation.positions(flight.profile.distance(track.times))[:, index]
        error = np.hypot(*(track.positions[:, :2] - virtual).T)
        errors.append(np.where(track.times < relieved_from, error, track.logged_error))
    metrics = FlightMetrics(pair, obstacle, connected, errors, los_connected=los_connected)
    metrics.summary.update(_summary(flight, metrics))
    return metrics


def _finite_min(values: np.ndarray) -> float | None:
    values = values[np.isfinite(values)]
    return float(values.min()) if values.size else None


def _finite_max(values: np.ndarray) -> float | None:
    values = values[np.isfinite(values)]
    return float(values.max()) if values.size else None


def _summary(flight: Flight, metrics: FlightMetrics) -> dict[str, Any]:
    rho = flight.safety_margin
    per_uav = [_finite_max(e) for e in metrics.tracking_error_m]
    worst = [e for e in per_uav if e is not None]
    full = metrics.connected[np.isfinite(metrics.connected)]
    sighted = metrics.los_connected[np.isfinite(metrics.los_connected)]
    changes = []
    for request in flight.requests:
        reactions = {
            str(a["uav"]): a["reaction_s"]
            for a in flight.acks
            if a.get("seq") == request["seq"] and "reaction_s" in a
        }
        changes.append(
            {
                "seq": request["seq"],
                "source": request.get("source"),
                "speed": request["speed"],
                "requested_s": request.get("t"),
                "effective_s": request["effective_s"],
                "reaction_s": reactions,
            }
        )
    takeoff = [float(t.times[0]) for t in flight.tracks if len(t.times)]
    return {
        "mission": flight.name,
        "fleet_size": flight.fleet_size,
        "safety_margin_m": rho,
        "radio_range_m": flight.radio_range,
        "samples": int(len(flight.sample_times)),
        "min_uav_uav_m": _finite_min(metrics.uav_uav_m),
        "min_uav_obstacle_m": _finite_min(metrics.uav_obstacle_m),
        "connected_fraction": float(full.mean()) if full.size else None,
        "los_connected_fraction": float(sighted.mean()) if sighted.size else None,
        "max_tracking_error_m": max(worst) if worst else None,
        "tracking_error_m": per_uav,
        "distance_travelled_m": [
            float(np.sum(np.hypot(*np.diff(t.positions[:, :2], axis=0).T)))
            if len(t.times) > 1
            else 0.0
            for t in flight.tracks
        ],  # fmt: skip
        "first_sample_s": min(takeoff) if takeoff else None,
        "speed_changes": changes,
        "telemetry_received": [int(len(t)) for t in flight.telemetry_times],
        "radio": flight.radio[-1] if flight.radio else None,
        "recorded_outcome": None
        if flight.run is None
        else {
            k: flight.run.get(k)
            for k in (
                "completed",
                "reason",
                "duration_s",
                "min_uav_uav_m",
                "min_uav_obstacle_m",
                "max_tracking_error_m",
                "connected_fraction",
            )
        },
    }


# --------------------------------------------------------------------------- figures
def _colours(count: int):
    return matplotlib.colormaps["viridis"](np.linspace(0, 0.9, max(count, 1)))


def _legend(ax, **style) -> None:
    """A legend, when something is labelled."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(**style)


def _no_data(ax, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")


def map_figure(flight: Flight) -> Figure:
    """Fig. 7: the mission map (obstacles, margins, rows, path: `gcs.plot`) and flown tracks."""
    fig = Figure(figsize=(8.5, 7.5), layout="constrained")
    ax = fig.subplots()
    view = _plan_view(flight)
    if view is not None:
        plot.draw_map(ax, view)
    else:
        path = np.array(flight.plan["path"], float)
        ax.plot(*path.T, color="tab:orange", lw=2.2, marker="o", ms=3, label="path")
        ax.set_aspect("equal")
    for index, (track, colour) in enumerate(
        zip(flight.tracks, _colours(len(flight.tracks)), strict=True)
    ):
        if len(track.times):
            ax.plot(*track.positions[:, :2].T, color=colour, lw=1.0, alpha=0.9,
                    label="flown tracks" if index == 0 else None, zorder=6)  # fmt: skip
    _legend(ax, loc="best", fontsize=8)
    ax.set_title(f"{flight.name}: planned path and flown tracks ({flight.fleet_size} UAVs)")
    return fig


def _plan_view(flight: Flight) -> MissionPlan | None:
    """A `MissionPlan` rebuilt from the recording (no re-planning), for `gcs.plot`'s map."""
    mission, formation, plan = flight.mission, flight.formation, flight.plan
    if mission is None or formation is None:
        return None
    path_plan = PathPlan(
        valid=True,
        reason=None,
        path=np.array(plan["path"], float),
        length_m=float(plan["length_m"]),
        fleet_size=int(plan["fleet_size"]),
        min_fleet_size=int(plan.get("min_fleet_size") or plan["fleet_size"]),
        rows=formation.rows,
        iterations=int(plan.get("iterations") or 0),
        expansions=int(plan.get("expansions") or 0),
        node_count=int(plan.get("node_count") or 0),
        edges_examined=int(plan.get("edges_examined") or 0),
        candidate_edges=np.zeros((0, 2, 2)),
    )
    return MissionPlan(
        mission=mission,
        path_plan=path_plan,
        formation=formation,
        speeds=mission.speed,
        profile=flight.profile,
        safe_speed_mps=plan.get("safe_speed_mps"),
        speed_capped=bool(plan.get("speed_capped")),
        duration_s=plan.get("duration_s"),
        error_budget_m=float(plan.get("error_budget_m") or mission.error_budget),
        smoothing_window_s=plan.get("smoothing_window_s"),
        smoothing_error_m=plan.get("smoothing_error_m"),
        planning_time_s=float(plan.get("planning_time_s") or 0.0),
    )


def distances_figure(flight: Flight, metrics: FlightMetrics) -> Figure:
    """Figs. 8-9: smallest UAV-UAV and UAV-obstacle distance against mission time."""
    fig = Figure(figsize=(10, 7), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    rho = flight.safety_margin
    t = flight.sample_times
    for ax, values, bound, label, title in (
        (top, metrics.uav_uav_m, 2 * rho, "2 rho_c", "smallest UAV-UAV distance (fig. 8)"),
        (bottom, metrics.uav_obstacle_m, rho, "rho_c", "smallest UAV-obstacle distance (fig. 9)"),
    ):
        if np.isfinite(values).any():
            ax.plot(t, values, color="tab:blue", lw=1.0)
            ax.axhline(bound, color="tab:red", ls="--", lw=0.9, label=f"{label} = {bound:g} m")
            low = _finite_min(values)
            ax.set_title(f"{title}: min {low:.2f} m")
            _legend(ax, loc="upper right", fontsize=8)
            ax.set_yscale("log")
        else:
            _no_data(ax, "no fleet samples")
            ax.set_title(title)
        ax.set_ylabel("distance (m)")
        ax.grid(alpha=0.3, which="both")
    bottom.set_xlabel("mission time (s)")
    return fig


def connectivity_figure(flight: Flight, metrics: FlightMetrics) -> Figure:
    """Whether every UAV reached a base station, against mission time, under both rules."""
    fig = Figure(figsize=(10, 4), layout="constrained")
    ax = fig.subplots()
    t = flight.sample_times
    if np.isfinite(metrics.connected).any():
        for values, offset, colour, label in (
            (metrics.connected, 0.02, "tab:blue", "by distance (disk)"),
            (metrics.los_connected, -0.02, "tab:orange", "by line of sight"),
        ):
            known = np.isfinite(values)
            share = 100 * float(values[known].mean())
            ax.step(t[known], values[known] + offset, where="post", color=colour, lw=1.2,
                    label=f"{label}: {share:.1f} % of samples")  # fmt: skip
        ax.set_yticks([0, 1], ["cut off", "connected"])
        ax.set_ylim(-0.3, 1.3)
        _legend(ax, loc="lower right", fontsize=8)
    else:
        _no_data(ax, "no fleet samples with every UAV known")
    ax.set_title("every UAV connected to a base station")
    ax.set_xlabel("mission time (s)")
    ax.grid(alpha=0.3)
    return fig


def tracking_figure(flight: Flight, metrics: FlightMetrics) -> Figure:
    """Tracking error |R_n(t) - V_n(t)| per UAV, against rho_c."""
    fig = Figure(figsize=(10, 5), layout="constrained")
    ax = fig.subplots()
    for index, (track, errors, colour) in enumerate(
        zip(flight.tracks, metrics.tracking_error_m, _colours(len(flight.tracks)), strict=True)
    ):
        if len(track.times):
            ax.plot(track.times, errors, color=colour, lw=0.9, label=f"UAV {index + 1}")
    ax.axhline(flight.safety_margin, color="tab:red", ls="--", lw=0.9,
               label=f"rho_c = {flight.safety_margin:g} m")  # fmt: skip
    worst = metrics.summary.get("max_tracking_error_m")
    what = "no samples" if worst is None else f"max {worst:.2f} m"
    ax.set_title(f"tracking error per UAV |R_n - V_n|: {what}")
    ax.set_xlabel("mission time (s)")
    ax.set_ylabel("tracking error (m)")
    _legend(ax, loc="upper right", fontsize=7, ncols=2 if flight.fleet_size > 8 else 1)
    ax.grid(alpha=0.3)
    return fig


def reactions_figure(flight: Flight, metrics: FlightMetrics) -> Figure:
    """Fig. 10: reaction time T_dv of each UAV to each speed change (request to receipt)."""
    fig = Figure(figsize=(10, 5), layout="constrained")
    ax = fig.subplots()
    changes = metrics.summary["speed_changes"]
    size = flight.fleet_size
    if not changes:
        _no_data(ax, "no speed change in this flight")
    width = 0.8 / max(len(changes), 1)
    uavs = np.arange(1, size + 1)
    for k, change in enumerate(changes):
        values = [change["reaction_s"].get(str(u), np.nan) for u in uavs]
        ax.bar(uavs - 0.4 + width * (k + 0.5), values, width,
               label=f"#{change['seq']}: {change['speed']:g} m/s ({change['source']})")  # fmt: skip
    ax.set_xticks(uavs)
    ax.set_xlabel("UAV")
    ax.set_ylabel("reaction time T_dv (s)")
    ax.set_title("reaction time to each speed change (fig. 10)")
    if changes:
        _legend(ax, fontsize=8)
    ax.grid(alpha=0.3, axis="y")
    return fig


def base_stations_figure(flight: Flight) -> Figure:
    """Figs. 12-13: packets received at the base stations over time: the telemetry of each UAV
    (a flat stretch = that UAV was cut off), and the radio medium's counters if recorded."""
    radio = [r for r in flight.radio if isinstance(r.get("t"), int | float)]
    fig = Figure(figsize=(10, 7 if radio else 5), layout="constrained")
    axes = fig.subplots(2 if radio else 1, 1, sharex=True, squeeze=False)[:, 0]
    ax = axes[0]
    for index, (times, colour) in enumerate(
        zip(flight.telemetry_times, _colours(flight.fleet_size), strict=True)
    ):
        if len(times):
            ax.step(times, np.arange(1, len(times) + 1), where="post", color=colour, lw=1.0,
                    label=f"UAV {index + 1}")  # fmt: skip
    if not any(len(t) for t in flight.telemetry_times):
        _no_data(ax, "no telemetry recorded")
    ax.set_ylabel("messages received")
    ax.set_title("telemetry received at the base stations per UAV (BS_con)")
    _legend(ax, loc="upper left", fontsize=7, ncols=2 if flight.fleet_size > 8 else 1)
    ax.grid(alpha=0.3)
    if radio:
        ax = axes[1]
        t = np.array([r["t"] for r in radio], float)
        for key, label in (("packets", "UAV data"), ("ground_users", "ground users")):
            counters = [r.get(key) or {} for r in radio]
            for what, style in (("received", "-"), ("dropped", ":")):
                values = np.array([_num(c.get(what)) for c in counters])
                if np.isfinite(values).any():
                    ax.plot(t, values, ls=style, lw=1.1, label=f"{label} {what}")
        ax.set_ylabel("packets")
        ax.set_title("radio medium: packets received and dropped (S_r-d)")
        _legend(ax, fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("mission time (s)")
    return fig


def distance_figure(flight: Flight) -> Figure:
    """Fig. 3: distance travelled by each UAV against time (flown: solid; V_n(t): dashed)."""
    fig = Figure(figsize=(10, 5.5), layout="constrained")
    ax = fig.subplots()
    colours = _colours(flight.fleet_size)
    ends = [t.times[-1] for t in flight.tracks if len(t.times)]
    if flight.formation is not None and ends:
        times = np.linspace(0.0, max(ends), 1500)
        virtual = np.asarray(flight.formation.positions(flight.profile.distance(times)))
        steps = np.linalg.norm(np.diff(virtual, axis=0), axis=-1)
        planned = np.vstack([np.zeros((1, virtual.shape[1])), np.cumsum(steps, axis=0)])
        for index in range(flight.fleet_size):
            ax.plot(times, planned[:, index], color=colours[index], lw=0.8, ls="--")
    for index, track in enumerate(flight.tracks):
        if len(track.times) > 1:
            steps = np.hypot(*np.diff(track.positions[:, :2], axis=0).T)
            travelled = np.concatenate([[0.0], np.cumsum(steps)])
            ax.plot(track.times, travelled, color=colours[index], lw=1.3, label=f"UAV {index + 1}")
    for request in flight.requests:
        ax.axvline(request["effective_s"], color="0.5", lw=0.8, ls=":")
    ax.set_xlabel("mission time (s)")
    ax.set_ylabel("distance travelled (m)")
    ax.set_title("distance travelled per UAV: flown (solid), virtual target V_n (dashed)")
    _legend(ax, loc="upper left", fontsize=7, ncols=2 if flight.fleet_size > 8 else 1)
    ax.grid(alpha=0.3)
    return fig


# --------------------------------------------------------------------------- the report
@dataclass(frozen=True)
class Report:
    """What `write_report` wrote."""

    files: tuple[Path, ...]
    summary: dict[str, Any]


def write_report(recording: Recording, out_dir: Path) -> Report:
    """Every figure of `FIGURES`, `summary.md` and `summary.json` into `out_dir`."""
    flight = load_flight(recording)
    metrics = flight_metrics(flight)
    out_dir.mkdir(parents=True, exist_ok=True)
    figures = {
        "map.png": map_figure(flight),
        "distances.png": distances_figure(flight, metrics),
        "tracking.png": tracking_figure(flight, metrics),
        "speed_reactions.png": reactions_figure(flight, metrics),
        "base_stations.png": base_stations_figure(flight),
        "distance_travelled.png": distance_figure(flight),
        "connectivity.png": connectivity_figure(flight, metrics),
    }
    files = []
    for name, figure in figures.items():
        figure.savefig(out_dir / name, dpi=DPI)
        files.append(out_dir / name)
    summary = {
        **metrics.summary,
        "log": str(recording.path),
        "truncated": recording.truncated,
        "outcome": recording.outcome,
        "figures": list(figures),
    }
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
    (out_dir / "summary.md").write_text(summary_markdown(summary))
    files += [out_dir / "summary.json", out_dir / "summary.md"]
    return Report(tuple(files), summary)


def _m(value: float | None, digits: int = 2) -> str:
    return "n/a" if value is None else f"{value:.{digits}f} m"


def summary_markdown(summary: dict[str, Any]) -> str:
    """The human summary (Markdown)."""
    rho = summary["safety_margin_m"]
    outcome = summary.get("outcome")
    if outcome is None:
        ended = "unknown: the recording has no outcome (the GCS did not finish it)"
    elif outcome.get("completed"):
        ended = "completed"
    else:
        ended = f"not completed: {outcome.get('reason')}"
    lines = [
        f"# Flight report: {summary['mission']}",
        "",
        f"- log: `{summary['log']}`" + (" (truncated)" if summary["truncated"] else ""),
        f"- outcome: {ended}",
        f"- fleet: {summary['fleet_size']} UAVs, safety margin rho_c = {rho:g} m, "
        f"radio range rho_R = {summary['radio_range_m']:g} m",
        "",
        "Recomputed from the log with the planner's guarantee checks "
        f"({summary['samples']} fleet samples):",
        "",
        "| metric | value | design bound |",
        "|---|---|---|",
        f"| smallest UAV-UAV distance | {_m(summary['min_uav_uav_m'])} | > 0 "
        f"(2 rho_c = {2 * rho:g} m for the virtual targets) |",
        f"| smallest UAV-obstacle distance | {_m(summary['min_uav_obstacle_m'])} | > 0 "
        f"(rho_c = {rho:g} m for the virtual targets) |",
        f"| largest tracking error | {_m(summary['max_tracking_error_m'])} | < rho_c = {rho:g} m |",
        "| connected samples | "
        + (
            "n/a"
            if summary["connected_fraction"] is None
            else f"{100 * summary['connected_fraction']:.1f} %"
        )
        + " | 100 % |",
        "| connected by line of sight | "
        + (
            "n/a"
            if summary["los_connected_fraction"] is None
            else f"{100 * summary['los_connected_fraction']:.1f} %"
        )
        + " | 100 % with `connectivity.rule: line_of_sight` |",
        "",
        "| UAV | max tracking error | distance travelled | telemetry received |",
        "|---|---|---|---|",
    ]
    for index, (error, travelled, received) in enumerate(
        zip(
            summary["tracking_error_m"],
            summary["distance_travelled_m"],
            summary["telemetry_received"],
            strict=True,
        )
    ):
        lines.append(f"| {index + 1} | {_m(error)} | {travelled:.0f} m | {received} |")
    if summary["speed_changes"]:
        lines += [
            "",
            "| speed change | speed | effective at | slowest reaction T_dv |",
            "|---|---|---|---|",
        ]
        for change in summary["speed_changes"]:
            reactions = list(change["reaction_s"].values())
            slowest = f"{max(reactions):.3f} s" if reactions else "no ack"
            lines.append(
                f"| #{change['seq']} ({change['source']}) | {change['speed']:g} m/s | "
                f"{change['effective_s']:.2f} s | {slowest} |"
            )
    lines += ["", "Figures:", ""]
    for name in summary["figures"]:
        lines.append(f"- [{name}]({name}): {FIGURES[name]}")
    return "\n".join(lines) + "\n"
