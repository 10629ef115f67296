"""`gcs eval study` on local Ray (the `study` extra; CI installs it) and without Ray: the tiny
study (tests/missions/study-tiny.yaml, 8 fast-mode flights of core.yaml) gives the same table
as in this process, apart from the wall times and the row order."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from gcs.study.table import read_rows

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / "tests" / "missions" / "study-tiny.yaml"
FAIL = REPO / "tests" / "missions" / "study-fail.yaml"


def _table(path: Path) -> dict[str, dict]:
    """Rows by id, without `meta` (wall times, host, process)."""
    return {r["id"]: {k: v for k, v in r.items() if k != "meta"} for r in read_rows(path)}


@pytest.fixture(scope="module")
def in_process(tmp_path_factory) -> Path:
    from gcs.cli import main

    out = tmp_path_factory.mktemp("process")
    assert main(["eval", "study", str(TINY), "--out", str(out), "--engine", "process"]) == 0
    return out


def test_the_tiny_study_on_local_ray_gives_the_in_process_table(gcs_main, in_process, tmp_path):
    pytest.importorskip("ray")  # CI installs the study extra; a developer may not have it
    out = tmp_path / "ray"
    code, stdout, err = gcs_main("eval", "study", TINY, "--out", out, "--workers", "2", "--json")
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["engine"] == "local Ray, 2 workers" and summary["flown"] == 8
    assert _table(out / "runs.jsonl") == _table(in_process / "runs.jsonl")
    assert len({r["meta"]["pid"] for r in read_rows(out / "runs.jsonl")}) >= 1
    assert all(r["meta"]["pid"] != os.getpid() for r in read_rows(out / "runs.jsonl"))


def test_a_failing_run_on_ray_is_a_row_and_the_study_goes_on(gcs_main, tmp_path):
    pytest.importorskip("ray")
    code, stdout, err = gcs_main(
        "eval", "study", FAIL, "--out", tmp_path, "--workers", "2", "--json"
    )
    assert code == 1, err
    assert json.loads(stdout)["failed"] == 1
    errors = [r["error"] for r in read_rows(tmp_path / "runs.jsonl")]
    assert sorted(e is None for e in errors) == [False, True]


def test_without_ray_the_study_runs_in_process_with_a_one_line_note(in_process, tmp_path):
    out = tmp_path / "noray"
    script = (
        "import sys; sys.modules['ray'] = None\n"
        "from gcs.cli import main\n"
        f"sys.exit(main(['eval', 'study', {str(TINY)!r}, '--out', {str(out)!r}]))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          cwd=REPO, timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr
    note = (
        "ray is not installed (pip install 'fleetline[study]'): running the study in this process"
    )
    assert done.stderr.splitlines()[0] == note
    assert done.stderr.count("ray is not installed") == 1
    assert _table(out / "runs.jsonl") == _table(in_process / "runs.jsonl")


def test_a_network_axis_replays_its_runs_in_ns3(gcs_main, tmp_path):
    """`network: [medium, ns3]` on one flight: the ns3 row carries ns-3's numbers (every UAV
    packet counted, T_BS of 802.11b: below the medium's 2 ms a hop), the medium row none."""
    study = tmp_path / "study.yaml"
    study.write_text(
        TINY.read_text().replace("seed: [1, 2]", "seed: [1]").replace("speed: [5, 8]", "speed: [8]")
        .replace("leader: [null, 2]", "leader: [2]\n  network: [medium, ns3]")
        .replace("base: core.yaml", f"base: {REPO / 'tests' / 'missions' / 'core.yaml'}")
        .replace("reaction_mean_s]", "reaction_mean_s, ns3_uav_delivery, ns3_uav_delay_mean_ms,\n"
                 "          ns3_reaction_worst_s]")
    )  # fmt: skip
    out = tmp_path / "out"
    code, _, stderr = gcs_main("eval", "study", study, "--out", out, "--engine", "process")
    assert code == 0, stderr
    rows = {r["params"]["network"]: r for r in read_rows(out / "runs.jsonl")}
    assert set(rows) == {"medium", "ns3"}
    ns3 = rows["ns3"]["metrics"]
    assert ns3["ns3_uav_delivery"] > 0.9 and 0.1 < ns3["ns3_uav_delay_mean_ms"] < 50
    assert 0 < ns3["ns3_reaction_worst_s"] < 1
    assert rows["medium"]["metrics"].get("ns3_uav_delivery") is None
    assert rows["medium"]["metrics"]["fleet_size"] == ns3["fleet_size"]
