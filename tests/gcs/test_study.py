"""`gcs eval study` and `gcs eval study-report` in this process (no Ray, no process): the study
file's validation, the axes' expansion and stable ids, a tiny study of
tests/missions/core.yaml (8 fast-mode flights), a run that fails recorded as a row, resume,
and the report's means and confidence intervals."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from gcs.errors import InputError
from gcs.study.report import axis_table, mean_ci, t95, write_report
from gcs.study.studyfile import load_study
from gcs.study.table import RowWriter, read_rows

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
TINY = MISSIONS / "study-tiny.yaml"
FAIL = MISSIONS / "study-fail.yaml"


def _without_meta(path: Path) -> dict[str, dict]:
    return {r["id"]: {k: v for k, v in r.items() if k != "meta"} for r in read_rows(path)}


@pytest.fixture(scope="module")
def tiny_out(tmp_path_factory) -> Path:
    """The tiny study flown once in this process (8 flights, ~12 s), shared by the tests."""
    from gcs.cli import main

    out = tmp_path_factory.mktemp("tiny")
    assert main(["eval", "study", str(TINY), "--out", str(out), "--engine", "process"]) == 0
    return out


# --------------------------------------------------------------------------- the study file
def _write(tmp_path: Path, text: str) -> Path:
    shutil.copy(MISSIONS / "core.yaml", tmp_path / "core.yaml")
    path = tmp_path / "study.yaml"
    path.write_text(text)
    return path


GOOD = "version: 1\nbase: core.yaml\naxes:\n  seed: [1, 2]\n"


@pytest.mark.parametrize(
    ("text", "key", "expected"),
    [
        ("version: 2\nbase: core.yaml\naxes: {seed: [1]}\n", "version", "1, got 2"),
        ("version: 1\naxes: {seed: [1]}\n", "base", "this required key"),
        ("version: 1\nbase: nope.yaml\naxes: {seed: [1]}\n", "base", "an existing mission file"),
        ("version: 1\nbase: core.yaml\naxes: {sed: [1]}\n", "axes.sed", "a known key"),
        ("version: 1\nbase: core.yaml\naxes: {seed: []}\n", "axes.seed", "a non-empty list"),
        ("version: 1\nbase: core.yaml\naxes: {seed: [1, x]}\n", "axes.seed[1]", "an integer >= 0"),
        ("version: 1\nbase: core.yaml\naxes: {seed: [1, 1]}\n", "axes.seed", "each value once"),
        ("version: 1\nbase: core.yaml\naxes: {speed: [0]}\n", "axes.speed[0]", "> 0"),
        ("version: 1\nbase: core.yaml\naxes: {leader: [0]}\n", "axes.leader[0]", ">= 1"),
        ("version: 1\nbase: core.yaml\naxes: {network: [wifi]}\n", "axes.network[0]", "medium, ns3"),
        ("version: 1\nbase: core.yaml\naxes: {planner: [fast]}\n", "axes.planner[0]", "exact"),
        ("version: 1\nbase: core.yaml\naxes: {map_seed: [1]}\n", "axes.map_seed", "map generator"),
        ("version: 1\nbase: core.yaml\naxes: {radio: [{loss: 2}]}\n", "axes.radio[0]", "radio.loss"),
        ("version: 1\nbase: core.yaml\naxes: {radio_range: [3]}\n", "axes.radio_range[0]", "radio_range"),
        ("version: 1\nbase: core.yaml\naxes: {seed: [1]}\nmetrics: [speed]\n", "metrics[0]", "one of"),
        ("version: 1\nbase: core.yaml\naxes: {seed: [1]}\nmap: {generator: moon}\n", "map.generator", "table-ii"),
        ("version: 1\nbase: core.yaml\naxes: {seed: [1]}\nmap: {generator: table-ii, blocks: 3}\n", "map.blocks", "city-grid"),
        ("version: 1\nbase: core.yaml\naxes: {seed: [1]}\nleader_requests: [[1]]\n", "leader_requests[0]", "[time s, speed m/s]"),
        ("version: 1\nbase: core.yaml\naxes: {seed: [1]}\nns3: {routing: rip}\n", "ns3.routing", "aodv"),
        ("version: 1\nbase: core.yaml\naxes: {seed: [1]\n", "", "valid YAML"),
    ],
)  # fmt: skip
def test_a_bad_study_file_names_the_key_and_what_is_expected(tmp_path, text, key, expected):
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as error:
        load_study(path)
    assert error.value.file == str(path)
    assert error.value.key_path == key
    assert expected in error.value.expected


def test_a_bad_study_file_is_one_line_and_exit_2(gcs_main, tmp_path):
    path = _write(tmp_path, "version: 1\nbase: core.yaml\naxes: {speed: [fast]}\n")
    code, out, err = gcs_main("eval", "study", path, "--out", tmp_path / "out")
    assert code == 2 and out == ""
    assert (
        err.strip()
        == f"{path}: axes.speed[0]: expected a finite number > 0 (m/s), got 'fast' (a string)"
    )
    assert not (tmp_path / "out").exists()  # refused before anything is written


def test_bad_flags_are_one_line_and_exit_2(gcs_main, tmp_path):
    path = _write(tmp_path, GOOD)
    code, _, err = gcs_main("eval", "study", path, "--out", tmp_path / "o", "--workers", "0")
    assert code == 2 and err.strip() == "--workers: expected an integer >= 1, got 0"
    code, _, err = gcs_main("eval", "study", path, "--out", tmp_path / "o", "--engine",
                            "process", "--address", "auto")  # fmt: skip
    assert code == 2 and err.strip().startswith("--address: expected")
    code, _, err = gcs_main("eval", "study-report", tmp_path)
    assert code == 2 and "study.json" in err and len(err.strip().splitlines()) == 1


def test_without_ray_the_address_flag_is_one_line_and_exit_2(gcs_main, tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` fails as without the extra
    path = _write(tmp_path, GOOD)
    code, _, err = gcs_main("eval", "study", path, "--out", tmp_path / "o", "--address", "auto")
    assert code == 2
    assert err.strip() == "--address: expected Ray installed (pip install 'fleetline[study]')"


def test_axes_expand_to_every_combination_with_stable_ids(tmp_path):
    path = _write(tmp_path, "version: 1\nbase: core.yaml\naxes:\n  seed: [1, 2]\n"
                  "  speed: [5, 8, 6]\n  leader: [null, 2]\n  radio: [{loss: 0.1}]\n")  # fmt: skip
    study = load_study(path)
    runs = study.runs()
    assert len(runs) == 12 and len({r.id for r in runs}) == 12
    assert runs[0].params == {"seed": 1, "speed": 5.0, "leader": None, "radio": {"loss": 0.1}}
    assert runs[1].params["leader"] == 2 and runs[2].params["speed"] == 8.0  # the last fastest
    assert [r.id for r in load_study(path).runs()] == [r.id for r in runs]  # stable
    # the same parameters in another axis order: the same ids; another base mission: others
    path.write_text("version: 1\nbase: core.yaml\naxes:\n  radio: [{loss: 0.1}]\n"
                    "  leader: [null, 2]\n  speed: [5, 8, 6]\n  seed: [1, 2]\n")  # fmt: skip
    assert {r.id for r in load_study(path).runs()} == {r.id for r in runs}
    (tmp_path / "core.yaml").write_text((tmp_path / "core.yaml").read_text() + "\n# edited\n")
    assert not {r.id for r in load_study(path).runs()} & {r.id for r in runs}


def test_map_generators_make_the_runs_maps(tmp_path):
    from gcs.study.runs import build_mission

    path = _write(tmp_path, "version: 1\nbase: core.yaml\nmap: {generator: city-grid, "
                  "block_m: 30, street_m: 20}\naxes:\n  map_size: [2, 3]\n")  # fmt: skip
    study = load_study(path)
    maps = [build_mission(study, spec) for spec in study.runs()]
    assert [m.obstacles.geometries.size for m, _ in maps] == [4, 9]
    assert [info["name"] for _, info in maps] == ["city-grid-2x2", "city-grid-3x3"]
    assert maps[0][1]["density"] == pytest.approx(4 * 30**2 / (20 + 2 * 50) ** 2)
    path.write_text("version: 1\nbase: core.yaml\nmap: {generator: table-ii}\n"
                    "axes: {map_seed: [8], safety_margin: [5]}\n")  # fmt: skip
    mission, info = build_mission(load_study(path), load_study(path).runs()[0])
    assert info["name"] == "paper-table-ii-seed8" and info["obstacles"] == 10
    assert tuple(mission.goal.xy) == (700.0, 700.0)


# --------------------------------------------------------------------------- flying studies
def test_the_tiny_study_writes_one_row_per_run(tiny_out):
    rows = read_rows(tiny_out / "runs.jsonl")
    study = load_study(TINY)
    assert sorted(r["id"] for r in rows) == sorted(s.id for s in study.runs())
    for row in rows:
        assert row["error"] is None, row["error"]
        assert row["metrics"]["completed"] is True and row["metrics"]["fleet_size"] == 4
        assert set(row["metrics"]) == set(study.metrics)
        assert row["meta"]["wall_s"] > 0
        led = row["params"]["leader"] is not None
        assert (row["metrics"]["reaction_worst_s"] is not None) == led
    assert (tiny_out / "study.yaml").read_text() == TINY.read_text()
    assert json.loads((tiny_out / "study.json").read_text())["axes"]["leader"] == [None, 2]


def test_resume_flies_only_the_missing_rows(gcs_main, tiny_out, tmp_path):
    out = tmp_path / "again"
    shutil.copytree(tiny_out, out)
    code, stdout, _ = gcs_main("eval", "study", TINY, "--out", out, "--engine", "process", "--json")
    assert code == 0 and json.loads(stdout)["flown"] == 0  # nothing new
    lines = (out / "runs.jsonl").read_text().splitlines(keepends=True)
    # interrupted: two rows missing and the last one cut short in the middle of its line
    (out / "runs.jsonl").write_text("".join(lines[:5]) + lines[5][:40])
    code, stdout, _ = gcs_main("eval", "study", TINY, "--out", out, "--engine", "process", "--json")
    summary = json.loads(stdout)
    assert code == 0 and summary["done_before"] == 5 and summary["flown"] == 3
    assert _without_meta(out / "runs.jsonl") == _without_meta(tiny_out / "runs.jsonl")


def test_a_failing_run_is_a_row_with_its_error_and_the_study_goes_on(gcs_main, tmp_path):
    out = tmp_path / "fail"
    code, stdout, err = gcs_main(
        "eval", "study", FAIL, "--out", out, "--engine", "process", "--json"
    )
    assert code == 1, err
    summary = json.loads(stdout)
    assert summary["runs"] == 2 and summary["failed"] == 1 and summary["flown"] == 2
    bad, good = read_rows(out / "runs.jsonl")
    assert bad["params"]["fleet_size"] == 1 and "fleet.size" in bad["error"]
    assert bad["error"].startswith("InputError: ") and "\n" not in bad["error"]
    assert bad["metrics"] == {"fleet_size": None, "completed": None}
    assert "Traceback" in bad["meta"]["traceback"]
    assert good["error"] is None and good["metrics"]["completed"] is True
    # resume skips the failed row too (exit 1 still); --retry-failed flies it again
    code, stdout, _ = gcs_main("eval", "study", FAIL, "--out", out, "--engine", "process", "--json")
    assert code == 1 and json.loads(stdout)["flown"] == 0
    code, stdout, _ = gcs_main("eval", "study", FAIL, "--out", out, "--engine", "process",
                               "--json", "--retry-failed")  # fmt: skip
    assert code == 1 and json.loads(stdout)["flown"] == 1
    assert (
        len((out / "runs.jsonl").read_text().splitlines()) == 3
        and len(read_rows(out / "runs.jsonl")) == 2
    )


def test_an_exception_anywhere_in_a_run_is_a_row(monkeypatch):
    import gcs.planning
    from gcs.study.engines import InProcessEngine

    def boom(*args, **kwargs):
        raise RuntimeError("planner exploded\non two lines")

    monkeypatch.setattr(gcs.planning, "plan_mission", boom)
    study = load_study(FAIL)
    rows = []
    InProcessEngine().run(study, study.runs(), rows.append)
    assert [r["id"] for r in rows] == [s.id for s in study.runs()]  # the study went on
    assert [r["error"] for r in rows] == ["RuntimeError: planner exploded on two lines"] * 2
    assert rows[1]["map"]["obstacles"] == 1 and rows[1]["metrics"]["completed"] is None


# --------------------------------------------------------------------------- the report
def test_mean_and_confidence_interval_by_hand():
    e = mean_ci(np.array([1.0, 2.0, 3.0, 4.0, np.nan]))
    half = 3.182446305 * math.sqrt(5 / 3) / 2  # t(3) x s / sqrt(n)
    assert (e.n, e.mean) == (4, 2.5)
    assert e.low == pytest.approx(2.5 - half) and e.high == pytest.approx(2.5 + half)
    assert mean_ci(np.array([7.0])).n == 1 and math.isnan(mean_ci(np.array([7.0])).low)
    assert mean_ci(np.array([])).n == 0
    assert t95(30) == pytest.approx(2.042272456) and t95(31) == pytest.approx(2.039513446, abs=1e-6)
    assert t95(100) == pytest.approx(1.983971519, abs=1e-6)


def _row(i, speed, leader, value, error=None):
    return {"id": f"r{i}", "index": i, "params": {"speed": speed, "leader": leader},
            "map": {"density": 0.1 * (i % 2), "obstacles": 3}, "error": error,
            "metrics": {"duration_s": None if error else value, "completed": error is None},
            "meta": {"plan_s": 0.5}}  # fmt: skip


def test_axis_tables_pool_the_other_axes_and_leave_out_failed_runs():
    rows = [_row(0, 10.0, None, 100.0), _row(1, 10.0, 1, 110.0), _row(2, 5.0, None, 200.0),
            _row(3, 5.0, 1, 220.0), _row(4, 5.0, 1, 999.0, error="boom"), _row(5, 10.0, 1, 120.0)]  # fmt: skip
    table = axis_table(rows, "speed", [10.0, 5.0], ["duration_s", "completed"])
    assert table.values == (5.0, 10.0)  # sorted
    assert table.runs == (3, 3) and table.failed == (1, 0)
    five, ten = table.columns["duration_s"]
    assert (five.n, five.mean) == (2, 210.0) and (ten.n, ten.mean) == (3, 110.0)
    assert ten.high - ten.mean == pytest.approx(4.302652730 * 10 / math.sqrt(3))
    assert [e.mean for e in table.columns["completed"]] == [1.0, 1.0]
    leaders = axis_table(rows, "leader", [1, None], ["duration_s"])
    assert leaders.values == (None, 1) and leaders.runs == (2, 4)
    assert leaders.columns["duration_s"][1].mean == pytest.approx(450 / 3)
    assert leaders.columns["plan_s"][0].mean == 0.5


def test_the_report_writes_tables_and_figures(gcs_main, tiny_out, tmp_path):
    out = tmp_path / "report"
    code, stdout, err = gcs_main("eval", "study-report", tiny_out, "--out", out, "--json")
    assert code == 0, err
    files = {Path(f).name for f in json.loads(stdout)["files"]}
    assert {
        "report.md",
        "report.json",
        "axis_seed.png",
        "axis_speed.png",
        "axis_leader.png",
    } <= files
    for name in files - {"report.md", "report.json"}:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    numbers = json.loads((out / "report.json").read_text())
    speed = numbers["axes"]["speed"]
    assert speed["values"] == [5.0, 8.0] and speed["runs"] == [4, 4]
    rows = read_rows(tiny_out / "runs.jsonl")
    at_8 = [r["metrics"]["duration_s"] for r in rows if r["params"]["speed"] == 8.0]
    assert speed["metrics"]["duration_s"]["mean"][1] == pytest.approx(np.mean(at_8))
    report = (out / "report.md").read_text()
    assert "### leader" in report and "| reaction_worst_s | n/a |" in report


def test_the_report_ignores_rows_of_another_study(tmp_path):
    rows = [_row(0, 10.0, None, 100.0), _row(1, 5.0, None, 200.0)]
    summary = {"name": "s", "axes": {"speed": [5.0, 10.0]}, "metrics": ["duration_s"],
               "runs": ["r0"]}  # fmt: skip
    report = write_report(summary, rows, tmp_path)
    assert report.runs == 1 and report.ignored == 1
    assert report.tables[0].runs == (0, 1)


def test_the_table_survives_a_row_cut_short(tmp_path):
    path = tmp_path / "runs.jsonl"
    with RowWriter(path, sync=False) as writer:
        writer.append({"id": "a", "v": 1})
    path.write_text(path.read_text() + '{"id": "b", "v"')
    with RowWriter(path, sync=False) as writer:
        writer.append({"id": "c", "v": 3})
    assert [r["id"] for r in read_rows(path)] == ["a", "c"]


def test_a_connectivity_axis_plans_and_flies_both_rules(gcs_main, tmp_path):
    """`axes.connectivity: [disk, line_of_sight]` on the small mission: the line-of-sight run
    is connected by line of sight at every sample, the disk run is not; a rule that does not
    exist is refused with the axis named."""
    shutil.copy(Path(__file__).resolve().parents[2] / "examples" / "small.yaml", tmp_path)
    study = tmp_path / "study.yaml"
    study.write_text(
        "version: 1\nbase: small.yaml\naxes:\n  connectivity: [disk, line_of_sight]\n"
        "metrics: [fleet_size, completed, connected_fraction, los_connected_fraction]\n"
    )
    out = tmp_path / "out"
    result = gcs_main("eval", "study", study, "--out", out, "--engine", "process")
    assert result.returncode == 0, result.stderr
    rows = {r["params"]["connectivity"]: r for r in read_rows(out / "runs.jsonl")}
    assert rows["line_of_sight"]["metrics"]["los_connected_fraction"] == 1.0
    assert rows["disk"]["metrics"]["los_connected_fraction"] < 0.95
    assert all(r["metrics"]["completed"] for r in rows.values())
    study.write_text("version: 1\nbase: small.yaml\naxes:\n  connectivity: [sight]\n")
    bad = gcs_main("eval", "study", study, "--out", out)
    assert bad.returncode == 2 and "axes.connectivity[0]" in bad.stderr
