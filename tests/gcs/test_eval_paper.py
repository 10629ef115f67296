"""`gcs eval paper`, reduced to a short mission (tests/missions/core.yaml) (one fixed speed, one leader): it flies in
the fast mode, writes the figures of the paper's figs. 8-16, a table next to the paper's
values and the numbers; bad input is one line and exit status 2."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
MISSIONS = Path(__file__).resolve().parents[1] / "missions"  # core.yaml: a short flight
FIGURES = [
    "fig08_min_uav_uav.png",
    "fig09_min_uav_obstacle.png",
    "fig10_reaction_time.png",
    "fig11_delay_to_bs.png",
    "fig12_packets_at_bs.png",
    "fig13_packets_at_bs_speeds.png",
    "fig14_reaction_time_leaders.png",
    "fig15_ground_users_leaders.png",
    "fig16_ground_users_speeds.png",
]


def test_a_reduced_paper_evaluation_writes_figures_table_and_numbers(gcs_main, tmp_path):
    out = tmp_path / "eval"
    args = ["eval", "paper", "--mission", MISSIONS / "core.yaml", "--speeds", "8",
            "--leaders", "2", "--out", out, "--json"]  # fmt: skip
    result = gcs_main(*args)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["ok"] is True
    for name in FIGURES:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    results = json.loads((out / "results.json").read_text())
    labels = [run["label"] for run in results["runs"]]
    assert labels == ["8 m/s", "leader UAV 2"]
    for run in results["runs"]:
        assert run["completed"] and run["connected_fraction"] == 1.0
        assert run["uav_data"]["dropped"] == 0 and run["uav_data"]["received"] > 0
        assert run["ground_users"]["sent"] == (
            run["ground_users"]["received"] + run["ground_users"]["dropped"]
        )
    led = results["runs"][1]
    # relayed as soon as the ground station reads it (a few hops and the fast mode's 20 ms
    # step), not at its next 10 Hz tick (82 ms when it waited)
    assert 0 < led["reaction_mean_s"] <= led["reaction_worst_s"] < 0.05
    reactions = results["reactions"]["leader UAV 2"]
    assert all("2" not in r["t_dv_s"] for r in reactions)  # the leader is not its follower
    table = (out / "table.md").read_text()
    assert table.startswith("| quantity | paper | ours | note |")
    assert "T_dv, leader UAV 2" in table and "connectivity (8 m/s)" in table
    # the paper's formation and ours, through a radio that knows buildings (3GPP UMi)
    paper, ours = results["buildings"]
    assert ours["label"] == "buildings: line-of-sight formation"
    assert ours["completed"] and ours["connected_fraction"] == 1.0
    assert ours["los_connected_fraction"] == 1.0 and ours["uav_data"]["dropped"] == 0
    assert paper["connected_fraction"] < 1.0  # a UAV behind the block, 50-60 m through it
    assert "connectivity through buildings, line-of-sight formation" in table


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["--speeds", "x"], "--speeds"),
        (["--speeds", "-2"], "--speeds"),
        (["--leaders", "1.5"], "--leaders"),
        (["--mission", "missing.yaml"], "missing.yaml"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(gcs_main, tmp_path, args, flag):
    result = gcs_main("eval", "paper", "--out", tmp_path / "eval", *args)
    assert result.returncode == 2
    assert result.stdout == "" and flag in result.stderr and result.stderr.count("\n") == 1
    assert not (tmp_path / "eval").exists()
