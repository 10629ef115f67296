"""`gcs eval paper`: the paper's network evaluation (sec. V-VI, figs. 8-16), in the fast mode.

The paper's scenario (Table II, `examples/table-ii.yaml`: 9 UAVs, rho_c 5 m, rho_R 220 m, six
ground users, 0.8 kbps of data per source) is flown by `gcs.sim.fastsim`:

* at a fixed formation speed of 2, 5 and 10 m/s (figs. 13, 16; D_min "very similar to figs.
  8-9"), and
* at 10 m/s with a leader asking for speed changes (10 -> 5 -> 10 -> 2 -> 10 m/s), the leader
  being UAV 1, 4, 6 or 9 (figs. 8-12 for UAV 1, figs. 14-15 for all four).

Every run carries both of the paper's traffic sources at once (UAVs sending data to a base
station, sec. VI-A, and ground users, sec. VI-B): the medium has no contention, so one source
never changes what the other sees, and one flight per configuration serves both.

Outputs in the chosen directory: `fig08_*.png` ... `fig16_*.png`, `table.md` (our figures next
to the paper's, docs/design.md 6) and `results.json` (every number of the table and of each run).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from gcs.mission import Mission, ScheduledChange, SpeedSchedule, load_mission  # noqa: E402
from gcs.planning import plan_mission  # noqa: E402
from gcs.sim.fastsim import FastOptions, FastRun, fly_fast  # noqa: E402
from medium.radio_stats import KINDS  # noqa: E402
from planner.scenarios import LEADER_REQUESTS  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
DEFAULT_MISSION = REPO / "examples" / "table-ii.yaml"
DPI = 110
UAV_DATA, GROUND = KINDS.index("uav_data"), KINDS.index("ground")

#: What the paper reports (sec. VI; docs/design.md 6 on its ground-user counts that do not add up).
PAPER = {
    "min_uav_uav_parked_m": 15.0,
    "worst_reaction_s": 0.58,
    "duration_2mps_s": 1800.0,
    "ground_users": {
        2.0: {"sent": 5250, "received": 3211, "dropped": 1666, "ratio": 0.6116},
        5.0: {"sent": 2028, "received": 1276, "dropped": 602, "ratio": 0.621},
        10.0: {"sent": 930, "received": None, "dropped": 243, "ratio": 0.627},
    },
}


@dataclass(frozen=True)
class EvalPlan:
    """Which runs: fixed speeds, leader positions and the nominal speed of the leader runs."""

    mission: Path = DEFAULT_MISSION
    speeds: tuple[float, ...] = (2.0, 5.0, 10.0)
    leaders: tuple[int, ...] = (1, 4, 6, 9)
    leader_speed: float = 10.0
    leader_requests: tuple[tuple[float, float], ...] = LEADER_REQUESTS


@dataclass(frozen=True, eq=False)
class EvalRun:
    """One configuration flown: its label, what varied, and the fast run."""

    label: str
    speed: float | None
    leader: int | None
    run: FastRun
    wall_s: float


def fixed_speed(mission: Mission, speed: float) -> Mission:
    """`mission` flown at `speed` from start to end (no speed changes)."""
    return replace(mission, speed=SpeedSchedule(max=speed, initial=speed))


def led(mission: Mission, leader: int, speed: float, requests) -> Mission:
    """`mission` at `speed` with UAV `leader` asking for each (time, speed) of `requests`."""
    top = max([speed, *(v for _, v in requests)])
    changes = tuple(ScheduledChange(at, v, leader) for at, v in requests)
    return replace(mission, speed=SpeedSchedule(max=top, initial=speed, changes=changes))


def run_all(plan: EvalPlan, progress=None) -> list[EvalRun]:
    """Fly every configuration of `plan` (`progress(label)` is called before each)."""
    base = load_mission(plan.mission)
    configurations: list[tuple[str, float | None, int | None, Mission]] = [
        (f"{v:g} m/s", v, None, fixed_speed(base, v)) for v in plan.speeds
    ]
    size = plan_mission(base).fleet_size
    configurations += [
        (f"leader UAV {n}", None, n, led(base, n, plan.leader_speed, plan.leader_requests))
        for n in plan.leaders
        if n <= size
    ]
    runs = []
    for label, speed, leader, mission in configurations:
        if progress is not None:
            progress(label)
        began = time.perf_counter()
        flown = fly_fast(plan_mission(mission), FastOptions())
        runs.append(EvalRun(label, speed, leader, flown, time.perf_counter() - began))
    return runs


#: The runs through a radio that knows buildings (`radio.buildings: 3gpp-umi`): (label, the
#: mission's `connectivity.rule`): the paper's formation as the file flies it, and ours.
BUILDING_RUNS = (
    ("buildings: the paper's formation", "disk"),
    ("buildings: line-of-sight formation", "line_of_sight"),
)


def with_buildings(mission: Mission) -> Mission:
    """`mission` through a radio that knows its buildings (`radio.buildings: 3gpp-umi`)."""
    return replace(mission, radio=replace(mission.radio, enabled=True, buildings="3gpp-umi"))


def buildings_runs(plan: EvalPlan, progress=None) -> list[EvalRun]:
    """The scenario at `plan.leader_speed` through a radio whose links through buildings
    follow 3GPP TR 38.901 (`medium.pathloss`): planned under the paper's disk rule (its fleet
    as the file says) and under `connectivity.rule: line_of_sight` (the fleet it needs)."""
    base = with_buildings(load_mission(plan.mission))
    runs = []
    for label, rule in BUILDING_RUNS:
        mission = replace(fixed_speed(base, plan.leader_speed), connectivity_rule=rule)
        if rule == "line_of_sight":
            mission = replace(mission, fleet=replace(mission.fleet, size=None))
        if progress is not None:
            progress(label)
        began = time.perf_counter()
        flown = fly_fast(plan_mission(mission, cap_speed=True), FastOptions())
        runs.append(EvalRun(label, plan.leader_speed, None, flown, time.perf_counter() - began))
    return runs


@dataclass(frozen=True, eq=False)
class PacketSeries:
    """One run's packets of one kind, in send order: the figures' input, whichever network
    carried them (the fast mode's medium here, ns-3 in `gcs.netsim.paper`)."""

    label: str
    times: np.ndarray  # mission s each was sent
    delays: np.ndarray  # s to a base station, NaN: dropped
    hops: np.ndarray


@dataclass(frozen=True)
class Reactions:
    """One leader run's T_dv per request and UAV (`reaction_times` rows), for figs. 10, 14."""

    label: str
    fleet_size: int
    requests: list[dict]


# --------------------------------------------------------------------------- metrics
def _packets(run: FastRun, kind: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(send times, delays s (NaN: dropped), hops) of one kind of packet, in time order."""
    p = run.packets
    mask = p["kind"] == kind
    order = np.argsort(p["time_s"][mask], kind="stable")
    return p["time_s"][mask][order], p["delay_s"][mask][order], p["hops"][mask][order]


def packet_series(run: EvalRun, kind: int) -> PacketSeries:
    return PacketSeries(run.label, *_packets(run.run, kind))


def leader_reactions(run: EvalRun) -> Reactions:
    """The leader's requests of `run` and each UAV's T_dv."""
    requests = [r for r in reaction_times(run.run) if r["source"].startswith("leader:")]
    return Reactions(run.label, run.run.run_json["fleet_size"], requests)


def reaction_times(run: FastRun) -> list[dict]:
    """Per speed change: when it was asked, by whom, and T_dv per UAV (s): from the leader's
    request (or the ground station's, for a scheduled change) to that UAV's receipt; a leader
    is not its own follower (the paper's fig. 10 has the non-leader UAVs)."""
    out = []
    for change in run.speed_changes:
        start = change["leader_sent_s"]
        if start is None:
            start = change["requested_s"]
        source = change["source"]
        leader = int(source.split(":")[1]) if source.startswith("leader:") else None
        out.append(
            {
                "seq": change["seq"],
                "source": source,
                "requested_s": start,
                "speed": change["speed"],
                "t_dv_s": {
                    int(u): r - start for u, r in change["received_s"].items() if int(u) != leader
                },
            }
        )
    return out


def longest_gap_s(times: np.ndarray, received: np.ndarray, start: float, end: float) -> float:
    """Longest stretch of [start, end] without a packet received (a flat BS_con)."""
    got = np.sort(times[received & (times >= start) & (times <= end)])
    edges = np.concatenate([[start], got, [end]])
    return float(np.diff(edges).max()) if len(edges) > 1 else end - start


def airborne_min_distance(run: FastRun, above_m: float = 1.0) -> np.ndarray:
    """(T,) smallest horizontal distance between two UAVs in the air (NaN: fewer than two)."""
    xy, up = run.positions[..., :2], run.positions[..., 2] > above_m
    gap = xy[:, :, None, :] - xy[:, None, :, :]
    distance = np.hypot(gap[..., 0], gap[..., 1])
    pair = up[:, :, None] & up[:, None, :]
    count = distance.shape[1]
    pair[:, np.arange(count), np.arange(count)] = False
    smallest = np.where(pair, distance, np.inf).min(axis=(1, 2), initial=np.inf)
    return np.where(np.isfinite(smallest), smallest, np.nan)


def packet_counts(received: np.ndarray) -> dict[str, Any]:
    """Sent, received, dropped and their ratio, of packets `received` (bool)."""
    return {
        "sent": int(len(received)),
        "received": int(received.sum()),
        "dropped": int((~received).sum()),
        "ratio": float(received.mean()) if len(received) else None,
    }


def run_metrics(run: EvalRun, mission: Mission) -> dict[str, Any]:
    """The numbers of one run that the table and `results.json` report."""
    flown = run.run
    data = flown.run_json
    start = float(np.nanmin(flown.takeoff_s))
    end = float(np.nanmax(flown.landed_s)) if np.isfinite(flown.landed_s).any() else start
    times, delays, hops = _packets(flown, UAV_DATA)
    received = np.isfinite(delays)
    g_times, g_delays, _ = _packets(flown, GROUND)
    g_received = np.isfinite(g_delays)
    p = flown.packets
    users = p["node"][p["kind"] == GROUND][
        np.argsort(p["time_s"][p["kind"] == GROUND], kind="stable")
    ]
    stations = mission.base_station_points
    user_xy = np.array([(u.x, u.y) for u in mission.ground_users]).reshape(-1, 2)
    to_station = np.hypot(*(user_xy[:, None, :] - stations[None, :, :]).transpose(2, 0, 1))
    needs_fleet = np.flatnonzero(to_station.min(axis=1) > mission.radio_range)
    far = np.isin(users, needs_fleet)
    airborne = airborne_min_distance(flown)
    reactions = reaction_times(flown)
    leader_reactions = [r for r in reactions if r["source"].startswith("leader:")]
    worst = max((max(r["t_dv_s"].values()) for r in leader_reactions if r["t_dv_s"]), default=None)
    mean = (
        float(np.mean([v for r in leader_reactions for v in r["t_dv_s"].values()]))
        if leader_reactions
        else None
    )
    parked = flown.checks.min_uav_uav_m[flown.times < 0]
    return {
        "label": run.label,
        "speed_mps": run.speed,
        "leader": run.leader,
        "completed": data["completed"],
        "fleet_size": data["fleet_size"],
        "duration_s": data["duration_s"],
        "min_uav_uav_m": data["min_uav_uav_m"],
        "min_uav_uav_parked_m": float(parked.min()) if parked.size else None,
        "min_airborne_uav_uav_m": float(np.nanmin(airborne))
        if np.isfinite(airborne).any()
        else None,
        "max_airborne_uav_uav_m": float(np.nanmax(airborne))
        if np.isfinite(airborne).any()
        else None,
        "min_uav_obstacle_m": data["min_uav_obstacle_m"],
        "max_tracking_error_m": data["max_tracking_error_m"],
        "connected_fraction": data["radio"]["connected_fraction"],
        "los_connected_fraction": data["los_connected_fraction"],
        "reason": data.get("reason"),
        "uav_data": {
            "sent": int(len(times)),
            "received": int(received.sum()),
            "dropped": int((~received).sum()),
            "delay_mean_ms": float(np.nanmean(delays) * 1000) if received.any() else None,
            "max_hops": int(hops.max()) if len(hops) else None,
            "longest_gap_s": longest_gap_s(times, received, start, end),
        },
        "ground_users": {
            **packet_counts(g_received),
            "delay_mean_ms": float(np.nanmean(g_delays) * 1000) if g_received.any() else None,
        },
        "ground_users_beyond_stations": {
            **packet_counts(g_received[far]),
            "users": [int(u) + 1 for u in needs_fleet],
        },
        "reaction_worst_s": worst,
        "reaction_mean_s": mean,
        "wall_s": run.wall_s,
    }


# --------------------------------------------------------------------------- figures
def _colours(count: int):
    from matplotlib import colormaps

    return [colormaps["viridis"](x) for x in np.linspace(0.0, 0.9, max(count, 1))]


def _figure(width: float = 10, height: float = 5, rows: int = 1, cols: int = 1):
    fig = Figure(figsize=(width, height), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False)
    return fig, axes


def fig_min_distance(run: EvalRun, which: str, rho_c: float, rho_r: float) -> Figure:
    """Figs. 8-9: smallest UAV-UAV (or UAV-obstacle) distance over time."""
    fig, axes = _figure()
    ax = axes[0, 0]
    flown = run.run
    if which == "uav":
        ax.plot(flown.times, flown.checks.min_uav_uav_m, lw=1.0, label="min UAV-UAV (all)")
        ax.plot(flown.times, airborne_min_distance(flown), lw=1.0, label="min UAV-UAV in the air")
        ax.axhline(2 * math.sqrt(2) * rho_c, color="C2", ls="--", lw=0.8, label="dS_c = 2√2 rho_c")
        ax.axhline(rho_r, color="C3", ls=":", lw=0.8, label="rho_R")
        ax.set_title(f"Fig. 8: minimum UAV-UAV distance ({run.label})")
    else:
        ax.plot(flown.times, flown.checks.min_uav_obstacle_m, lw=1.0, label="min UAV-obstacle")
        ax.axhline(rho_c, color="C3", ls="--", lw=0.8, label="rho_c")
        ax.set_title(f"Fig. 9: minimum UAV-obstacle distance ({run.label})")
    ax.set_xlabel("mission time (s)")
    ax.set_ylabel("distance (m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def fig_reactions(runs: list[Reactions], title: str) -> Figure:
    """Figs. 10 and 14: each UAV's reaction time T_dv to each leader request."""
    fig, axes = _figure(10, 3.2 * len(runs) if len(runs) > 1 else 5, rows=len(runs))
    for ax, run in zip(axes[:, 0], runs, strict=True):
        reactions, size = run.requests, run.fleet_size
        colours = _colours(len(reactions))
        width = 0.8 / max(len(reactions), 1)
        for i, reaction in enumerate(reactions):
            uavs = np.arange(1, size + 1)
            values = [_ms_value(reaction["t_dv_s"].get(int(u))) for u in uavs]
            speed = reaction.get("speed")
            ax.bar(
                uavs + (i - (len(reactions) - 1) / 2) * width,
                values,
                width=width,
                color=colours[i],
                label=f"t={reaction['requested_s']:.0f} s"
                + (f" -> {speed:g} m/s" if speed is not None else ""),
            )
        ax.set_xticks(np.arange(1, size + 1))
        ax.set_ylabel("T_dv (ms)")
        ax.set_title(f"{run.label}: reaction time to the leader's requests")
        ax.grid(alpha=0.3, axis="y")
        ax.legend(fontsize=7, ncols=2)
    axes[-1, 0].set_xlabel("UAV")
    fig.suptitle(title)
    return fig


def _ms_value(seconds: float | None) -> float:
    """Milliseconds for a bar (NaN, no bar, for a UAV the request never reached)."""
    return np.nan if seconds is None else 1000.0 * seconds


def fig_delay(series: PacketSeries, network: str = "") -> Figure:
    """Fig. 11: delay of the UAVs' data packets to a base station (T_BS), and their hops."""
    fig, axes = _figure()
    ax = axes[0, 0]
    times, delays, hops = series.times, series.delays, series.hops
    ok = np.isfinite(delays)
    ax.scatter(times[ok], delays[ok] * 1000, s=2, alpha=0.3, label="each packet")
    if ok.any():
        bins = np.arange(np.floor(times.min()), times.max() + 10, 10.0)
        index = np.digitize(times[ok], bins)
        centres = [(bins[i - 1] + 5) for i in np.unique(index)]
        means = [delays[ok][index == i].mean() * 1000 for i in np.unique(index)]
        ax.plot(centres, means, color="C1", lw=1.5, label="mean per 10 s")
        twin = ax.twinx()
        hop_means = [hops[ok][index == i].mean() for i in np.unique(index)]
        twin.plot(centres, hop_means, color="C2", lw=1.0, ls="--", label="mean hops")
        twin.set_ylabel("hops")
        twin.legend(loc="upper right", fontsize=8)
    ax.set_xlabel("mission time (s)")
    ax.set_ylabel("delay to a base station (ms)")
    ax.set_title(
        f"Fig. 11: data packet delay to reach a base station, T_BS ({series.label}){network}"
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    return fig


def fig_packets(runs: list[PacketSeries], title: str, dropped: bool) -> Figure:
    """Figs. 12-13 (UAV data) and 15-16 (ground users): packets received at the base
    stations (and dropped) over time, cumulative."""
    fig, axes = _figure()
    ax = axes[0, 0]
    colours = _colours(len(runs))
    for colour, run in zip(colours, runs, strict=True):
        got = np.isfinite(run.delays)
        ax.step(run.times, np.cumsum(got), where="post", color=colour, lw=1.3,
                label=f"{run.label} received")  # fmt: skip
        if dropped:
            ax.step(run.times, np.cumsum(~got), where="post", color=colour, lw=1.0, ls=":",
                    label=f"{run.label} dropped")  # fmt: skip
    ax.set_xlabel("mission time (s)")
    ax.set_ylabel("packets (cumulative)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncols=2)
    return fig


def write_figures(runs: list[EvalRun], out: Path, mission: Mission) -> list[Path]:
    """The figures corresponding to the paper's figs. 8-16."""
    rho_c, rho_r = mission.safety_margin, mission.radio_range
    main = main_run(runs)
    figures = {
        "fig08_min_uav_uav.png": fig_min_distance(main, "uav", rho_c, rho_r),
        "fig09_min_uav_obstacle.png": fig_min_distance(main, "obstacle", rho_c, rho_r),
    }
    figures |= network_figures(
        runs, lambda run, kind: packet_series(run, kind), leader_reactions, network=""
    )
    return save_figures(figures, out)


def main_run(runs: list):
    """The run of figs. 8-12: the first leader run (UAV 1's, by default), else the fastest."""
    leaders = [r for r in runs if r.leader is not None]
    return leaders[0] if leaders else [r for r in runs if r.leader is None][-1]


def network_figures(runs: list, series, reactions, network: str) -> dict[str, Figure]:
    """Figs. 10-16, the network's: `series(run, kind)` -> `PacketSeries`, `reactions(run)` ->
    `Reactions` (of a leader run); `network` is appended to the titles (" (ns-3)")."""
    fixed = [r for r in runs if r.leader is None]
    leaders = [r for r in runs if r.leader is not None]
    main = main_run(runs)
    figures = {
        "fig11_delay_to_bs.png": fig_delay(series(main, UAV_DATA), network),
        "fig12_packets_at_bs.png": fig_packets(
            [series(main, UAV_DATA)],
            f"Fig. 12: UAV data packets received at the base stations ({main.label}){network}",
            dropped=True,
        ),  # fmt: skip
    }
    if leaders:
        figures["fig10_reaction_time.png"] = fig_reactions(
            [reactions(main)],
            f"Fig. 10: reaction time to speed change requests ({main.label}){network}",
        )
        figures["fig14_reaction_time_leaders.png"] = fig_reactions(
            [reactions(r) for r in leaders],
            f"Fig. 14: reaction time to speed change requests per leader position{network}",
        )
        figures["fig15_ground_users_leaders.png"] = fig_packets(
            [series(r, GROUND) for r in leaders],
            f"Fig. 15: ground-user packets received and dropped, per leader{network}",
            dropped=True,
        )  # fmt: skip
    if fixed:
        figures["fig13_packets_at_bs_speeds.png"] = fig_packets(
            [series(r, UAV_DATA) for r in fixed],
            f"Fig. 13: UAV data packets received at the base stations, fixed speeds{network}",
            dropped=False,
        )  # fmt: skip
        figures["fig16_ground_users_speeds.png"] = fig_packets(
            [series(r, GROUND) for r in fixed],
            f"Fig. 16: ground-user packets received and dropped, fixed speeds{network}",
            dropped=True,
        )  # fmt: skip
    return figures


def save_figures(figures: dict[str, Figure], out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, figure in sorted(figures.items()):
        figure.savefig(out / name, dpi=DPI)
        written.append(out / name)
    return written


# --------------------------------------------------------------------------- table
def _fmt(value, digits: int = 2, unit: str = "") -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value:.{digits}f}{unit}"


def _ms(seconds: float | None) -> str:
    return _fmt(None if seconds is None else seconds * 1000, 1)


def comparison(
    metrics: list[dict],
    network: dict[str, dict] | None = None,
    buildings: list[dict] | None = None,
) -> list[tuple[str, str, str, str, str]]:
    """Rows (quantity, paper, ours, ns-3, note) of the table next to the paper (docs/design.md 6).
    `network`: run label -> `gcs.netsim.paper.net_metrics` of that flight replayed in ns-3
    (the ns-3 cells are empty without it); `buildings`: the metrics of `buildings_runs`."""
    by_label = {m["label"]: m for m in metrics}
    net = network or {}
    rows: list[tuple[str, str, str, str, str]] = []
    parked = [m["min_uav_uav_parked_m"] for m in metrics if m["min_uav_uav_parked_m"]]
    rows.append(
        (
            "min UAV-UAV distance while parked",
            "about 15 m (dS_c)",
            _fmt(min(parked), 2, " m") if parked else "n/a",
            "",
            "dS_c = 2√2 rho_c (14.14 m for rho_c = 5 m), less the tracking error",
        )
    )
    rows.append(
        (
            "min UAV-UAV distance, all runs",
            "> 0 (no collision)",
            _fmt(min(m["min_uav_uav_m"] for m in metrics), 2, " m"),
            "",
            "",
        )
    )
    airborne = [m["max_airborne_uav_uav_m"] for m in metrics if m["max_airborne_uav_uav_m"]]
    rows.append(
        (
            "largest min distance between airborne UAVs",
            "below 200 m < rho_R",
            _fmt(max(airborne), 1, " m") if airborne else "n/a",
            "",
            "in flight the line is spaced dS_r = rho_R - 2 rho_c apart",
        )
    )
    rows.append(
        (
            "min UAV-obstacle distance, all runs",
            "> 0 (no collision)",
            _fmt(min(m["min_uav_obstacle_m"] for m in metrics), 2, " m"),
            "",
            "the plan passes corners at rho_c by design; below it: tracking error",
        )
    )
    for m in (m for m in metrics if m["leader"] is not None):
        paper = (
            "0.58 s worst (UAV 9, leader UAV 1)"
            if m["leader"] == 1
            else "lower mean with the leader mid-fleet"
        )
        rows.append(
            (
                f"T_dv, leader UAV {m['leader']}: worst / mean",
                paper,
                f"{_ms(m['reaction_worst_s'])} / {_ms(m['reaction_mean_s'])} ms",
                _net_reactions(net.get(m["label"])),
                "leader -> base station -> ground station -> each UAV, 2 ± 1 ms per hop"
                + ("; ns-3: the paper's UAV-to-UAV chain, then our relay" if net else ""),
            )
        )
    for m in metrics:
        n = net.get(m["label"])
        rows.append(
            (
                f"connectivity ({m['label']})",
                "always connected (one handover gap near 365 s)",
                f"{_fmt(100 * m['connected_fraction'], 1)} % of samples, longest gap "
                f"{_fmt(m['uav_data']['longest_gap_s'], 2)} s, "
                f"{m['uav_data']['dropped']} UAV packets dropped",
                ""
                if n is None
                else f"{_fmt(_percent(n['uav_data']['ratio']), 1)} % delivered, longest gap "
                f"{_fmt(n['uav_data']['longest_gap_s'], 1)} s, "
                f"{n['uav_data']['dropped']} dropped",
                "BS_con: UAV data received at the base stations",
            )
        )
    for speed, paper in PAPER["ground_users"].items():
        m = by_label.get(f"{speed:g} m/s")
        if m is None:
            continue
        g = m["ground_users"]
        n = net.get(m["label"])
        paper_text = (
            f"{100 * paper['ratio']:.1f} % ({paper['received'] or '?'}/{paper['sent']}, "
            f"{paper['dropped']} dropped)"
        )
        rows.append(
            (
                f"ground-user success ratio, {speed:g} m/s",
                paper_text,
                f"{_fmt(100 * g['ratio'], 1)} % ({g['received']}/{g['sent']}, "
                f"{g['dropped']} dropped)",
                "" if n is None else _net_counts(n["ground_users"]),
                "S_r-d; the paper's own counts do not add up (docs/design.md 6): compare ratios",
            )
        )
        far = m["ground_users_beyond_stations"]
        if far["sent"]:
            rows.append(
                (
                    f"... users beyond every base station's range, {speed:g} m/s",
                    "",
                    f"{_fmt(100 * far['ratio'], 1)} % ({far['received']}/{far['sent']}, "
                    f"users {', '.join(map(str, far['users']))})",
                    "" if n is None else _net_counts(n["ground_users_beyond_stations"]),
                    "the others are within rho_R of A or B and never drop",
                )
            )
    m = by_label.get("2 m/s")
    if m is not None:
        rows.append(
            (
                "mission duration at 2 m/s",
                "1800 s",
                _fmt(m["duration_s"], 0, " s"),
                "",
                "first take-off to last landing; the paper's path and fleet spacing differ",
            )
        )
    for m in buildings or ():
        n = net.get(m["label"])
        rows.append(
            (
                f"connectivity through buildings, {m['label'].split(': ', 1)[1]}",
                "not studied (links through walls)",
                f"{m['fleet_size']} UAVs: {_fmt(100 * m['connected_fraction'], 1)} % of samples, "
                f"{_fmt(100 * m['los_connected_fraction'], 1)} % by line of sight, "
                f"{m['uav_data']['dropped']} UAV packets dropped, "
                + ("completed" if m["completed"] else f"not completed ({m['reason']})"),
                ""
                if n is None
                else f"{_fmt(_percent(n['uav_data']['ratio']), 1)} % delivered, "
                f"{n['uav_data']['dropped']} dropped",
                "radio.buildings: 3gpp-umi (3GPP TR 38.901 UMi-Street Canyon, docs/line-of-sight.md)"
                + ("; ns-3: our footprint loss in front of its range model" if n else ""),
            )
        )
    delays = [m["uav_data"]["delay_mean_ms"] for m in metrics if m["uav_data"]["delay_mean_ms"]]
    net_delays = [n["uav_data"]["delay_mean_ms"] for n in net.values()]
    net_delays = [d for d in net_delays if d is not None]
    rows.append(
        (
            "T_BS, mean data delay to a base station",
            "hat-shaped over time, similar at every speed",
            f"{_fmt(min(delays), 2)}-{_fmt(max(delays), 2)} ms over the runs",
            f"{_fmt(min(net_delays), 2)}-{_fmt(max(net_delays), 2)} ms over the runs"
            if net_delays
            else "",
            "hops x (2 ± 1 ms); no MAC contention or routing discovery"
            + ("; ns-3: 802.11b MAC, AODV route discovery" if net else ""),
        )
    )
    return rows


def _percent(ratio: float | None) -> float | None:
    return None if ratio is None else 100.0 * ratio


def _net_counts(counts: dict) -> str:
    return (
        f"{_fmt(_percent(counts['ratio']), 1)} % ({counts['received']}/{counts['sent']}, "
        f"{counts['dropped']} dropped)"
    )


def _net_reactions(n: dict | None) -> str:
    """The ns-3 cell of a T_dv row: worst / mean by the paper's chain, then our relay."""
    if n is None:
        return ""
    cells = []
    for relay, name in (("chain", "chain"), ("gcs", "gcs")):
        r = n["reactions"][relay]
        text = f"{name} {_ms(r['worst_s'])} / {_ms(r['mean_s'])} ms"
        if r["lost"]:
            text += f" ({r['lost']} never arrived)"
        cells.append(text)
    return "; ".join(cells)


def table_markdown(rows) -> str:
    """The table; the ns-3 column only when some row has an ns-3 cell."""
    with_network = any(row[3] for row in rows)
    if with_network:
        lines = ["| quantity | paper | ours | ns-3 | note |", "|---|---|---|---|---|"]
        lines += [f"| {q} | {p} | {o} | {n} | {note} |" for q, p, o, n, note in rows]
    else:
        lines = ["| quantity | paper | ours | note |", "|---|---|---|---|"]
        lines += [f"| {q} | {p} | {o} | {note} |" for q, p, o, _, note in rows]
    return "\n".join(lines) + "\n"


def write_results(
    runs: list[EvalRun],
    out: Path,
    wall_s: float,
    plan: EvalPlan,
    network: dict | None = None,
    buildings: list[EvalRun] | None = None,
) -> tuple[list[dict], list[tuple[str, str, str, str, str]]]:
    """`table.md` and `results.json` in `out`; returns the per-run metrics and the rows.
    `network`: the ns-3 replay (`gcs.netsim.paper.replay_in_ns3`'s summary: "options",
    "wall_s" and "runs", label -> metrics), written as `results.json` "ns3" and as the table's
    ns-3 column; `buildings`: `buildings_runs`, written as `results.json` "buildings"."""
    mission = load_mission(plan.mission)
    metrics = [run_metrics(run, mission) for run in runs]
    through = [run_metrics(run, mission) for run in buildings or ()]
    rows = comparison(metrics, None if network is None else network["runs"], through)
    columns = ("quantity", "paper", "ours", "ns3", "note")
    out.mkdir(parents=True, exist_ok=True)
    (out / "table.md").write_text(table_markdown(rows))
    results = {
        "mission": str(plan.mission),
        "wall_s": wall_s,
        "leader_requests": plan.leader_requests,
        "runs": metrics,
        "reactions": {run.label: reaction_times(run.run) for run in runs},
        "table": [
            {k: v for k, v in zip(columns, row, strict=True) if k != "ns3" or network}
            for row in rows
        ],
    }
    if buildings:
        results["buildings"] = through
    if network is not None:
        results["ns3"] = network
    (out / "results.json").write_text(json.dumps(results, indent=1, allow_nan=False))
    return metrics, rows
