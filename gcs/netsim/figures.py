"""The figures of `gcs log netsim --out DIR`: T_BS and BS_con over mission time (PNG)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from gcs.netsim.ns3 import NetResult  # noqa: E402

#: The files `write_outputs` writes (name -> what it holds).
OUTPUTS = {
    "netsim.json": "NetResult.to_json(): scenario, options, summaries, every packet",
    "t_bs.png": "T_BS: delay of each delivered packet against the time it was sent",
    "bs_con.png": "BS_con: packets received per base station per second",
}
DPI = 110


def _colours(count: int):
    return matplotlib.colormaps["viridis"](np.linspace(0, 0.9, max(count, 1)))


def t_bs_figure(result: NetResult) -> Figure:
    """T_BS of every delivered packet (log scale) against its send time, one colour per UAV,
    ground users in grey; lost packets as ticks at the bottom."""
    fig = Figure(figsize=(10, 5.5), layout="constrained")
    ax = fig.subplots()
    delivered = result.delivered
    delay_ms = 1000.0 * result.delay_s
    size = result.scenario.fleet_size
    users = (result.source_kind == "user") & delivered
    if users.any():
        ax.scatter(result.sent_s[users], delay_ms[users], s=4, color="0.6", label="ground users")
    for index, colour in enumerate(_colours(size)):
        mask = (result.source_kind == "uav") & (result.source_id == index + 1) & delivered
        if mask.any():
            ax.scatter(result.sent_s[mask], delay_ms[mask], s=5, color=colour,
                       label=f"UAV {index + 1}")  # fmt: skip
    lost = ~delivered
    if lost.any():
        ax.plot(result.sent_s[lost], np.zeros(int(lost.sum())), "|", color="tab:red", ms=8,
                transform=ax.get_xaxis_transform(), label="lost")  # fmt: skip
    if delivered.any():
        ax.set_yscale("log")
    else:
        ax.text(0.5, 0.5, "no packet delivered", ha="center", va="center",
                transform=ax.transAxes)  # fmt: skip
    summary = result.delay_summary()
    title = "T_BS per packet (ns-3)"
    if summary["mean_s"] is not None:
        title += (
            f": mean {1000 * summary['mean_s']:.1f} ms, p95 {1000 * summary['p95_s']:.1f} ms, "
            f"max {1000 * summary['max_s']:.0f} ms"
        )
    ax.set_title(title)
    ax.set_xlabel("mission time the packet was sent (s)")
    ax.set_ylabel("T_BS (ms)")
    ax.grid(alpha=0.3, which="both")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="upper right", ncols=2 if size > 6 else 1, markerscale=2)
    return fig


def bs_con_figure(result: NetResult) -> Figure:
    """BS_con: packets received per second at each base station, 1 s bins."""
    fig = Figure(figsize=(10, 5), layout="constrained")
    ax = fig.subplots()
    starts, counts = result.bs_con()
    names = ["BS 1 (A)"] + [f"BS {k + 1}" for k in range(1, counts.shape[1])]
    for s, colour in enumerate(_colours(counts.shape[1])):
        ax.step(starts, counts[:, s], where="post", color=colour, lw=1.0, label=names[s])
    ax.step(starts, counts.sum(axis=1), where="post", color="0.3", lw=0.8, ls=":", label="all")
    sources = result.scenario.fleet_size + len(result.scenario.ground_users)
    offered = sources / result.scenario.packet_interval_s
    ax.axhline(offered, color="tab:red", ls="--", lw=0.8, label=f"offered ({offered:g}/s)")
    ax.set_title("BS_con: packets received per base station per second (ns-3)")
    ax.set_xlabel("mission time (s)")
    ax.set_ylabel("packets / s")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    return fig


def write_outputs(result: NetResult, out_dir: Path) -> list[Path]:
    """netsim.json and the figures into `out_dir`; the paths written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    files = []
    path = out_dir / "netsim.json"
    path.write_text(json.dumps(result.to_json(), allow_nan=False) + "\n")
    files.append(path)
    for name, figure in (("t_bs.png", t_bs_figure(result)), ("bs_con.png", bs_con_figure(result))):
        figure.savefig(out_dir / name, dpi=DPI)
        files.append(out_dir / name)
    return files
