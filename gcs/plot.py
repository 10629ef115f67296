"""The plan figure: the map (paper figs. 6-7) and distance travelled per UAV (fig. 3).

Left: candidate edges (faint), obstacles and their rho_c margins (mitre corners, square caps on
walls, as the graph nodes of docs/design.md 3.1 assume), parking rows and slots, base stations, A/B,
ground users and the chosen path. Right: the distance each UAV has travelled against time,
sampled from the line formation's virtual targets V_n(t) (eq. 27).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import shapely  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import PathPatch  # noqa: E402
from matplotlib.path import Path as MplPath  # noqa: E402

from gcs.planning import MissionPlan  # noqa: E402

#: Samples of the time axis on the right-hand plot.
TIME_SAMPLES = 1500


def plan_figure(plan: MissionPlan) -> Figure:
    """Build the figure (without pyplot: no global state, no GUI)."""
    fig = Figure(figsize=(14, 6.5), layout="constrained")
    left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.15, 1]})
    draw_map(left, plan)
    _draw_distance(right, plan)
    status = "valid" if plan.valid else f"no valid path: {plan.reason}"
    fig.suptitle(f"{plan.mission.name}: {status}")
    return fig


def save_plan_figure(plan: MissionPlan, path: str | Path, dpi: int = 120) -> None:
    """Draw the plan figure into `path` (format from its suffix)."""
    plan_figure(plan).savefig(path, dpi=dpi)


def _shape_patch(geom: shapely.Geometry, **style) -> PathPatch:
    """A shapely polygon (holes included) as a matplotlib patch."""
    parts = []
    for poly in getattr(geom, "geoms", [geom]):
        for ring in (poly.exterior, *poly.interiors):
            xy = np.asarray(ring.coords)
            codes = np.full(len(xy), MplPath.LINETO)
            codes[0], codes[-1] = MplPath.MOVETO, MplPath.CLOSEPOLY
            parts.append((xy, codes))
    vertices = np.concatenate([p[0] for p in parts])
    codes = np.concatenate([p[1] for p in parts])
    return PathPatch(MplPath(vertices, codes), **style)


def draw_map(ax, plan: MissionPlan) -> None:  # noqa: C901 (over 15 branches: to split)
    mission = plan.mission
    pp = plan.path_plan
    rho = mission.safety_margin
    obstacles = mission.obstacles
    geoms = obstacles.geometries
    extent = list(mission.base_station_points)

    edges = np.asarray(pp.candidate_edges if pp.candidate_edges is not None else [])
    if edges.size:
        edges = edges.reshape(-1, 2, 2)
        alpha = float(np.clip(2000 / len(edges), 0.04, 0.35))  # dense graphs stay readable
        ax.add_collection(LineCollection(edges, colors="0.5", linewidths=0.4, alpha=alpha))
    if len(geoms):
        margins = shapely.buffer(geoms, rho, join_style="mitre", cap_style="square")
        for margin in margins:
            ax.add_patch(
                _shape_patch(margin, facecolor="none", edgecolor="tab:red", lw=0.7, ls="--")
            )
        for poly in obstacles.polygons:
            ax.fill(*poly.T, color="0.35", zorder=2)
        if len(obstacles.walls):
            ax.add_collection(LineCollection(obstacles.walls, colors="0.2", linewidths=2, zorder=2))
        bounds = np.asarray(shapely.bounds(margins))
        extent += [bounds[:, :2].min(axis=0), bounds[:, 2:].max(axis=0)]

    rows = pp.rows
    if rows is not None:
        drawn = (rows.start_row,) if rows.open_goal else (rows.start_row, rows.goal_row)
        for index, row in enumerate(drawn):
            row = np.asarray(row)
            if mission.parking == "ray":  # draw a readable stub of the paper's rays
                direction = (row[1] - row[0]) / np.linalg.norm(row[1] - row[0])
                row = np.array([row[0], row[0] + direction * 0.15 * _span(extent)])
            label = "parking rows" if index == 0 else None
            ax.plot(*row.T, color="tab:blue", lw=1.2, alpha=0.6, zorder=3, label=label)
            extent += list(row)
    if plan.formation is not None:
        slots = plan.formation.start_slots
        if plan.route is None:
            slots = np.vstack([slots, plan.formation.goal_slots])
        ax.scatter(*slots.T, s=14, color="tab:blue", zorder=4, label="parking slots")
        extent += list(slots)
    if len(pp.path):
        path = np.asarray(pp.path)
        ax.plot(*path.T, color="tab:orange", lw=2.2, marker="o", ms=3, zorder=5, label="path")
        extent += list(path)
    stations = np.array([b.xy for b in mission.base_stations]).reshape(-1, 2)
    if len(stations):
        ax.scatter(*stations.T, marker="^", s=70, color="tab:green", zorder=6, label="base station")
        extent += list(stations)
    users = np.array([[u.x, u.y] for u in mission.ground_users]).reshape(-1, 2)
    if len(users):
        ax.scatter(*users.T, marker="s", s=25, color="tab:purple", zorder=6, label="ground user")
        extent += list(users)
    if plan.route is not None:
        _draw_stations(ax, plan)
    ends = mission.base_station_points[: 1 if mission.goal is None else 2]
    label = "A (base station)" if mission.goal is None else "A, B (base stations)"
    ax.scatter(*ends.T, marker="^", s=110, color="tab:green", edgecolor="k", zorder=7,
               label=label)  # fmt: skip
    for name, (x, y) in zip(mission.base_station_names, ends.tolist(), strict=False):
        ax.annotate(name, (x, y), xytext=(6, 6), textcoords="offset points",
                    fontsize=12, weight="bold", zorder=8)  # fmt: skip

    pts = np.array(extent, float).reshape(-1, 2)
    low, high = pts.min(axis=0), pts.max(axis=0)
    pad = 0.05 * max(high - low) + 2 * rho
    ax.set_xlim(low[0] - pad, high[0] + pad)
    ax.set_ylim(low[1] - pad, high[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    what = f"path of {pp.length_m:.0f} m" if plan.valid else "no valid path"
    ax.set_title(f"map: {what}, margins rho_c = {rho:g} m (dashed)")
    ax.legend(loc="best", fontsize=8)


def _draw_stations(ax, plan: MissionPlan) -> None:
    """A stations mission: each point with its name and holder, the UAVs' stations."""
    mission, route = plan.mission, plan.route
    points = np.array([p.xy for p in mission.stations]).reshape(-1, 2)
    ax.scatter(*points.T, marker="*", s=160, color="gold", edgecolor="k", zorder=7,
               label="monitoring points")  # fmt: skip
    holder = {}
    if route.layout is not None:
        holder = dict(zip(route.order.tolist(), route.layout.holders.tolist(), strict=True))
    for index, point in enumerate(mission.stations):
        text = point.name + (f" (UAV {holder[index]})" if index in holder else "")
        ax.annotate(text, (point.x, point.y), xytext=(6, -12), textcoords="offset points",
                    fontsize=9, zorder=8)  # fmt: skip
    if plan.formation is not None:
        relays = plan.formation.station_slots
        ax.scatter(*relays.T, marker="x", s=30, color="tab:blue", zorder=6,
                   label="UAV stations")  # fmt: skip


def _span(extent: list) -> float:
    pts = np.array(extent, float).reshape(-1, 2)
    return float(max(pts.max(axis=0) - pts.min(axis=0)).max()) or 100.0


def _draw_distance(ax, plan: MissionPlan) -> None:
    ax.set_xlabel("mission time (s)")
    ax.set_ylabel("distance travelled (m)")
    if plan.formation is None or plan.duration_s is None:
        ax.set_title("distance travelled per UAV: no plan")
        ax.text(0.5, 0.5, "no valid path", ha="center", va="center", transform=ax.transAxes)
        return
    duration = plan.duration_s
    times = np.linspace(0.0, duration * 1.02, TIME_SAMPLES)
    positions = np.asarray(plan.formation.positions(plan.profile.distance(times)))  # (T, N, 2)
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=-1)
    travelled = np.vstack([np.zeros((1, positions.shape[1])), np.cumsum(steps, axis=0)])
    fleet = travelled.shape[1]
    colours = matplotlib.colormaps["viridis"](np.linspace(0, 0.9, fleet))
    for n in range(fleet):
        ax.plot(times, travelled[:, n], color=colours[n], lw=1.3, label=f"UAV {n + 1}")
    for change in plan.speeds.changes:
        ax.axvline(change.at, color="0.5", lw=0.8, ls=":")
        who = f" (UAV {change.leader})" if change.leader else ""
        ax.annotate(f"{change.speed:g} m/s{who}", (change.at, 0), xytext=(3, 3),
                    textcoords="offset points", fontsize=8, color="0.3")  # fmt: skip
    ax.axvline(duration, color="k", lw=0.8, ls="--")
    ax.set_title(f"distance travelled per UAV (N = {fleet}, T = {duration:.0f} s)")
    ax.legend(loc="upper left", fontsize=7, ncols=2 if fleet > 8 else 1)
    ax.grid(alpha=0.3)
