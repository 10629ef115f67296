"""`gcs eval calibrate` in ns-3 (the `ns3` extra; each run imports ns-3, ~10 s): the quick
calibration, a real `python -m gcs` process, writes a table of hop counts 1..3 with little loss
on its static line and a median delay growing with the hops; the same seed writes the same
file byte for byte; the shipped table is what the command writes; without the extra the
command says so on one line (exit 2).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from gcs.netsim.calibrate import QUANTILES
from medium.calibration import DEFAULT_CALIBRATION, load_calibration

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]


def calibrate(*args: str | Path) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run(
        [sys.executable, "-m", "gcs", "eval", "calibrate", *map(str, args)],
        capture_output=True, text=True, cwd=REPO, env=env, timeout=120,
    )  # fmt: skip


@pytest.fixture(scope="module")
def quick(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    out = tmp_path_factory.mktemp("calibration") / "quick.json"
    return out, calibrate("--quick", "--out", out, "--seed", "1", "--json")


def test_the_quick_calibration_measures_one_to_three_hops_on_a_static_line(quick):
    out, done = quick
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    printed = json.loads(done.stdout)  # --json: the table, alone on stdout
    assert printed == json.loads(out.read_text())
    table = load_calibration(out)
    (level,) = table.levels
    assert level.max_hops == 3 and level.rate_bps_per_node == 800.0
    assert level.offered_load_bps == 3 * 800.0
    assert (level.sent >= 10).all()
    assert (level.loss_ratio <= 0.1).all()  # a static line, far below saturation
    medians = level.quantiles_s[:, QUANTILES.index(0.5)]
    assert medians[0] < medians[1] < medians[2] < 0.05
    assert 0.0001 < medians[0] < 0.002  # 802.11b at 11 Mbit/s: under a millisecond a hop
    assert printed["made_by"]["command"] == "gcs eval calibrate --quick --seed 1"
    assert printed["seed"] == 1 and printed["ns3"]["version"].startswith("3.44")
    assert printed["levels"][0]["packets_over_other_hop_counts"] == 0
    assert "per-hop delay and loss in ns-3" in done.stderr  # the table, on stderr with --json


def test_the_same_seed_writes_the_same_file(quick, tmp_path):
    out, done = quick
    assert done.returncode == 0, done.stderr
    again = tmp_path / "again.json"
    repeated = calibrate("--quick", "--out", again, "--seed", "1")
    assert repeated.returncode == 0, repeated.stderr
    assert again.read_bytes() == out.read_bytes()
    assert "hops" in repeated.stdout  # without --json: the table on stdout


def test_the_shipped_table_is_the_default_calibration(quick):
    out, _ = quick
    shipped = json.loads(DEFAULT_CALIBRATION.read_text())
    quick_table = json.loads(out.read_text())
    assert set(shipped) == set(quick_table)
    assert shipped["made_by"]["command"] == "gcs eval calibrate --seed 1"
    assert shipped["quantiles"] == quick_table["quantiles"] == list(QUANTILES)
    for level in shipped["levels"]:
        assert set(level) == set(quick_table["levels"][0])
        assert [row["hops"] for row in level["hops"]] == list(range(1, 11))
    table = load_calibration()
    assert [level.rate_bps_per_node for level in table.levels] == [800.0, 3200.0, 12800.0, 51200.0]
    assert len(DEFAULT_CALIBRATION.read_bytes()) < 16_000
