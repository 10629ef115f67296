"""`gcs eval paper --network ns3`: the paper's evaluation flights replayed in ns-3.

Each flight of `gcs.sim.eval.run_all` (the fast mode: our vehicles, our radio medium) is
replayed packet by packet in ns-3 (`gcs.netsim.ns3.run_network`: 802.11b, AODV, the paper's
traffic) on its true trajectories. This module reduces each `NetResult` to the numbers of the
paper's table (`net_metrics`, the ns-3 column of `gcs.sim.eval.comparison`) and draws the
paper's network figures (10-16) from ns-3's packets, into `ns3/` next to the medium's.

The paper's speed-change relay (the leader's request forwarded UAV to UAV) is what ns-3's
"chain" measures; fleetline flies requests through the ground station ("gcs"): both T_dv are
reported. A leader is not its own follower: its cell is left out, as in `reaction_times`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gcs.mission import Mission
from gcs.netsim.ns3 import IMPORT_TIMES, NetOptions, NetResult, run_network
from gcs.netsim.scenario import scenario_from_fast_run
from gcs.sim.eval import (
    GROUND,
    UAV_DATA,
    EvalRun,
    PacketSeries,
    Reactions,
    fig_reactions,
    network_figures,
    packet_counts,
    save_figures,
)

#: ns-3's packet kinds for the eval's (`medium.radio_stats.KINDS` indices).
_SOURCE_KIND = {UAV_DATA: "uav", GROUND: "user"}


@dataclass(frozen=True, eq=False)
class NetEvalRun:
    """One evaluation flight replayed in ns-3: the flight's label, leader and speed (as
    `EvalRun`'s) and what ns-3 measured."""

    label: str
    speed: float | None
    leader: int | None
    result: NetResult


def replay_in_ns3(
    runs: list[EvalRun],
    mission: Mission,
    options: NetOptions,
    progress: Callable[[str], None] | None = None,
) -> list[NetEvalRun]:
    """Every flight of `runs` (of `mission`) in ns-3 with `options`; `progress(label)` before
    each. `NetsimUnavailable` without the ns3 extra (`run_network` loads ns-3 before its first
    run)."""
    replayed = []
    for run in runs:
        if progress is not None:
            progress(run.label)
        scenario = scenario_from_fast_run(run.run, mission)
        result = run_network(scenario, options)
        replayed.append(NetEvalRun(run.label, run.speed, run.leader, result))
    return replayed


def summary(replayed: list[NetEvalRun], mission: Mission, wall_s: float) -> dict[str, Any]:
    """`results.json` "ns3": the options, wall times and each run's `net_metrics`."""
    return {
        "options": asdict(replayed[0].result.options) if replayed else None,
        "ns3": replayed[0].result.extra if replayed else {},
        "wall_s": {
            "total": wall_s,
            "import": sum(IMPORT_TIMES.values()),
            "build": sum(r.result.build_s for r in replayed),
            "run": sum(r.result.run_s for r in replayed),
        },
        "runs": {r.label: net_metrics(r, mission) for r in replayed},
    }


def net_metrics(replayed: NetEvalRun, mission: Mission) -> dict[str, Any]:
    """The numbers of one replayed flight the table reports: UAV data (delivery, T_BS, hops,
    the longest handover gap of any UAV), ground users (all, and those beyond every base
    station's range) and T_dv by the paper's chain and through the ground station."""
    result = replayed.result
    uav = result.source_kind == "uav"
    delivered = result.delivered
    delays = result.delay_s[uav & delivered]
    gaps = result.handover_gaps()
    users = result.source_kind == "user"
    far = users & np.isin(result.source_id, _users_beyond_stations(mission))
    return {
        "label": replayed.label,
        "uav_data": {
            **packet_counts(delivered[uav]),
            "delay_mean_ms": _ms(np.mean(delays)) if delays.size else None,
            "delay_p95_ms": _ms(np.percentile(delays, 95)) if delays.size else None,
            "max_hops": int(result.hops[uav & delivered].max()) if delays.size else None,
            "longest_gap_s": float(np.nanmax(gaps)) if np.isfinite(gaps).any() else None,
        },
        "ground_users": packet_counts(delivered[users]),
        "ground_users_beyond_stations": packet_counts(delivered[far]),
        "reactions": {
            "chain": _reaction_summary(result, "paper"),
            "gcs": _reaction_summary(result, "gcs"),
        },
        "wall_s": {"build": result.build_s, "run": result.run_s},
    }


def _users_beyond_stations(mission: Mission) -> np.ndarray:
    """1-based ids of the ground users no base station hears (they need the fleet)."""
    stations = mission.base_station_points
    users = np.array([(u.x, u.y) for u in mission.ground_users]).reshape(-1, 2)
    to_station = np.hypot(*(users[:, None, :] - stations[None, :, :]).transpose(2, 0, 1))
    return np.flatnonzero(to_station.min(axis=1, initial=np.inf) > mission.radio_range) + 1


def _ms(seconds: float) -> float:
    return 1000.0 * float(seconds)


def _followers(result: NetResult) -> np.ndarray:
    """(R, N) True where UAV n is a follower of request r (not its leader)."""
    size = result.scenario.fleet_size
    leaders = np.array([r.leader for r in result.scenario.requests], dtype=int).reshape(-1, 1)
    return np.arange(1, size + 1)[None, :] != leaders


def _reaction_summary(result: NetResult, relay: str) -> dict[str, Any]:
    """Worst and mean T_dv (s) over every request and follower; how many never arrived."""
    t_dv = result.t_dv(relay)
    if not t_dv.size:
        return {"worst_s": None, "mean_s": None, "lost": 0}
    values = t_dv[_followers(result)]
    arrived = values[np.isfinite(values)]
    return {
        "worst_s": float(arrived.max()) if arrived.size else None,
        "mean_s": float(arrived.mean()) if arrived.size else None,
        "lost": int(np.isnan(values).sum()),
    }


# --------------------------------------------------------------------------- figures
def packet_series(replayed: NetEvalRun, kind: int) -> PacketSeries:
    """ns-3's packets of one kind (UAV data or ground users), in send order."""
    result = replayed.result
    mask = result.source_kind == _SOURCE_KIND[kind]
    order = np.argsort(result.sent_s[mask], kind="stable")
    sent = result.sent_s[mask][order]
    delays = result.delay_s[mask][order]
    return PacketSeries(replayed.label, sent, delays, result.hops[mask][order])


def reactions(replayed: NetEvalRun, relay: str = "paper") -> Reactions:
    """T_dv of each UAV to each of the leader's requests, by `relay` ("paper": the chain)."""
    result = replayed.result
    t_dv = result.t_dv(relay)
    followers = _followers(result)
    requests = []
    for r, request in enumerate(result.scenario.requests):
        requests.append(
            {
                "requested_s": request.t,
                "t_dv_s": {
                    uav + 1: float(t_dv[r, uav])
                    for uav in range(result.scenario.fleet_size)
                    if followers[r, uav] and np.isfinite(t_dv[r, uav])
                },
            }
        )
    return Reactions(f"{replayed.label}, {relay} relay", result.scenario.fleet_size, requests)


def write_figures(replayed: list[NetEvalRun], out: Path) -> list[Path]:
    """Figs. 10-16 from ns-3's packets into `out` (the paper's chain for figs. 10 and 14,
    as the paper relays; the ground station's relay in `fig14_reaction_time_leaders_gcs.png`)."""
    figures = network_figures(replayed, packet_series, reactions, network=" (ns-3)")
    leaders = [r for r in replayed if r.leader is not None]
    if leaders:
        figures["fig14_reaction_time_leaders_gcs.png"] = fig_reactions(
            [reactions(r, "gcs") for r in leaders],
            "Fig. 14, relayed through the ground station (ns-3)",
        )
    return save_figures(figures, out)
