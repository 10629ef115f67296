"""`gcs mission check|plan`: plan JSON, written files, exit statuses, the malformed corpus."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import EXAMPLES, MISSIONS, REPO

BAD = sorted((MISSIONS / "bad").glob("*.yaml"))
CONTRACT_KEYS = {
    "path",
    "length_m",
    "fleet_size",
    "min_fleet_size",
    "duration_s",
    "safe_speed_mps",
    "parking_rows",
    "iterations",
    "planning_time_s",
    "valid",
}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def expectation(path: Path) -> tuple[str, str | None]:
    """The `# expect: KEY.PATH` (and optional `# mentions: TEXT`) header of a corpus file."""
    header = path.read_bytes().decode("utf-8", errors="replace")
    key = re.search(r"^# expect:[ \t]*(.*)$", header, re.M)
    mentions = re.search(r"^# mentions:[ \t]*(.*)$", header, re.M)
    assert key, f"{path.name} has no '# expect:' header"
    return key.group(1).strip(), mentions.group(1).strip() if mentions else None


def assert_refused(result, path: Path) -> None:
    key, mentions = expectation(path)
    assert result.returncode == 2, (path.name, result)
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, (path.name, result.stderr)
    prefix = f"{path}: {key}: expected " if key else f"{path}: expected "
    assert lines[0].startswith(prefix), (path.name, lines[0], prefix)
    if mentions:
        assert mentions in lines[0], (path.name, lines[0])
    assert "Traceback" not in result.stderr


# --- the corpus ------------------------------------------------------------------------------


def test_corpus_is_large_enough():
    assert len(BAD) >= 25
    keys = {expectation(p)[0] for p in BAD}
    # Every refusal of docs/mission-file.md has a file naming its key (see each file's comment).
    for key in (
        "",  # unreadable / non-YAML / root not a mapping
        "speeed",  # unknown key
        "safety_margin",  # wrong type
        "version",  # missing required key
        "radio_range",  # eq. 9
        "speed.initial",  # initial > max
        "speed.changes[0].at",  # at < 0
        "speed.changes[2].at",  # not strictly increasing
        "speed.changes[0].speed",  # outside [0, max]
        "speed.changes[1].speed",  # last speed 0
        "goal",  # A == B, B in a margin
        "start",  # A inside an obstacle
        "start.theta_deg",  # eq. 14
        "goal.theta_deg",  # eq. 15
        "fleet.size",  # below the minimum
        "speed.changes[0].leader",  # outside 1..N
        "fleet.connections",  # count != N
        "obstacles[0].geojson",  # bad or missing GeoJSON
    ):
        assert key in keys, key


@pytest.mark.parametrize("command", ["check", "plan"])
@pytest.mark.parametrize("path", BAD, ids=lambda p: p.stem)
def test_corpus_is_refused_by_check_and_plan(gcs_main, command, path):
    assert_refused(gcs_main("mission", command, path), path)


@pytest.mark.slow
@pytest.mark.parametrize(
    "name", ["boolean-number", "row-near-obstacle", "leader-beyond-auto-fleet", "not-yaml"]
)
def test_corpus_sample_as_real_processes(gcs_process, name):
    path = MISSIONS / "bad" / f"{name}.yaml"
    for command in ("check", "plan"):
        assert_refused(gcs_process("mission", command, path, "--json"), path)


# --- plan ---------------------------------------------------------------------------------------


@pytest.mark.slow
def test_plan_json_of_the_paper_scenario(gcs_process, tmp_path):
    result = gcs_process("mission", "plan", EXAMPLES / "table-ii.yaml", "--json", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    plan = json.loads(result.stdout)  # exactly one JSON object, nothing else on stdout
    assert isinstance(plan, dict) and CONTRACT_KEYS <= plan.keys()
    assert plan["valid"] is True and plan["reason"] is None
    path = np.array(plan["path"])
    assert path[0].tolist() == [200, 200] and path[-1].tolist() == [700, 700]
    length = np.linalg.norm(np.diff(path, axis=0), axis=1).sum()
    assert plan["length_m"] == pytest.approx(length, rel=1e-12)
    assert plan["fleet_size"] == 9 and 1 <= plan["min_fleet_size"] <= 9
    assert plan["min_fleet_size"] == int(np.ceil(length / (220 - 2 * 5) - 1e-9))
    rows = plan["parking_rows"]
    assert rows["A"][0] == [200, 200] and rows["B"][0] == [700, 700]
    assert len(plan["parking_slots"]["A"]) == 9
    assert plan["safe_speed_mps"] >= 10 and plan["speed_capped"] is False
    # Everyone parked after len(P) + (N-1) dS_r at <= 10 m/s, with a slower stretch (eq. 25).
    assert plan["duration_s"] > (length + 8 * 210) / 10
    assert plan["iterations"] >= 1 and plan["planning_time_s"] > 0
    # Human text goes to stderr.
    assert "fleet size" in result.stderr and "safe" in result.stderr
    assert list(tmp_path.iterdir()) == []  # plan without --out/--plot writes nothing


def test_out_and_plot_are_written(gcs_main, tmp_path):
    out, plot = tmp_path / "plan.json", tmp_path / "plan.png"
    result = gcs_main(
        "mission", "plan", EXAMPLES / "small.yaml", "--json", "--out", out, "--plot", plot
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(out.read_text()) == json.loads(result.stdout)
    data = plot.read_bytes()
    assert data.startswith(PNG_MAGIC) and len(data) > 20_000
    import matplotlib.image

    height, width, _ = matplotlib.image.imread(plot).shape
    assert width > 1000 and height > 500


def test_human_summary_on_stdout_without_json(gcs_main):
    result = gcs_main("mission", "plan", EXAMPLES / "small.yaml")
    assert result.returncode == 0
    for word in ("path", "length", "fleet size", "duration", "safe", "planning"):
        assert word in result.stdout
    assert result.stderr == ""


def test_check_summarises_and_writes_nothing(gcs_main, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = gcs_main("mission", "check", EXAMPLES / "small.yaml")
    assert result.returncode == 0 and "fleet size" in result.stdout
    assert list(tmp_path.iterdir()) == []


def test_check_and_plan_agree_on_the_plan(gcs_main):
    check = json.loads(gcs_main("mission", "check", EXAMPLES / "small.yaml", "--json").stdout)
    plan = json.loads(gcs_main("mission", "plan", EXAMPLES / "small.yaml", "--json").stdout)
    for data in (check, plan):
        data.pop("planning_time_s")
    assert check == plan


@pytest.mark.timeout(30)
def test_no_valid_path_exits_1_with_the_reason(gcs_main, tmp_path):
    out = tmp_path / "plan.json"
    mission = MISSIONS / "no-path.yaml"
    result = gcs_main("mission", "plan", mission, "--json", "--out", out)
    assert result.returncode == 1
    plan = json.loads(result.stdout)
    assert plan["valid"] is False and plan["reason"]
    assert CONTRACT_KEYS <= plan.keys()
    assert json.loads(out.read_text())["valid"] is False
    assert plan["reason"] in result.stderr
    human = gcs_main("mission", "check", mission)
    assert human.returncode == 1 and "no valid path" in human.stdout


def test_cap_speed_caps_instead_of_refusing(gcs_main, tmp_path):
    text = (MISSIONS / "bad" / "speed-above-safe.yaml").read_text()
    refused = gcs_main("mission", "plan", MISSIONS / "bad" / "speed-above-safe.yaml", "--json")
    assert refused.returncode == 2 and "--cap-speed" in refused.stderr
    capped = gcs_main(
        "mission", "plan", MISSIONS / "bad" / "speed-above-safe.yaml", "--json", "--cap-speed"
    )
    assert capped.returncode == 0, capped.stderr
    plan = json.loads(capped.stdout)
    assert plan["speed_capped"] is True
    assert plan["max_speed_mps"] == pytest.approx(plan["safe_speed_mps"])
    assert plan["initial_speed_mps"] <= plan["safe_speed_mps"]
    path = tmp_path / "m.yaml"
    path.write_text(text.replace("speed: {max: 8}", "speed: {max: 8, cap_to_safe: true}"))
    assert json.loads(gcs_main("mission", "plan", path, "--json").stdout)["speed_capped"]


def test_connect_overrides_the_connections(gcs_main, tmp_path):
    path = MISSIONS / "bad" / "connections-missing-px4.yaml"
    plan = json.loads(gcs_main("mission", "plan", EXAMPLES / "small.yaml", "--json").stdout)
    urls = [f"udp:127.0.0.1:{14540 + i}" for i in range(plan["fleet_size"])]
    assert gcs_main("mission", "check", path, "--connect", *urls).returncode == 0
    result = gcs_main("mission", "check", path, "--connect", *urls[:-1])
    assert result.returncode == 2 and result.stderr.startswith("--connect: expected ")


@pytest.mark.parametrize(
    ("args", "start"),
    [
        (["mission", "plan"], "gcs mission plan: "),
        (["mission"], "gcs mission: "),
        (["mission", "fly", "x.yaml"], "gcs mission: "),
        (["mission", "plan", "x.yaml", "--method", "astar"], "gcs mission plan: "),
        (["mission", "plan", "examples/small.yaml", "--plot", "plan.txt"], "--plot: expected "),
        (["mission", "plan", "examples/small.yaml", "--out", "no/such/dir/p.json"], "--out: "),
        (["mission", "plan", "no-such-mission.yaml"], "no-such-mission.yaml: expected a readable"),
    ],
)
def test_usage_errors_are_one_line_exit_2(gcs_main, monkeypatch, args, start):
    monkeypatch.chdir(REPO)
    result = gcs_main(*args)
    assert result.returncode == 2 and result.stdout == ""
    assert len(result.stderr.splitlines()) == 1 and result.stderr.startswith(start)


@pytest.mark.slow
def test_usage_error_as_a_real_process(gcs_process):
    result = gcs_process("mission", "plan", "--json")
    assert result.returncode == 2 and result.stdout == ""
    assert len(result.stderr.splitlines()) == 1 and "Traceback" not in result.stderr


def test_city_blocks_plan(gcs_main):
    result = gcs_main("mission", "plan", EXAMPLES / "city-blocks.yaml", "--json")
    assert result.returncode == 0, result.stderr
    plan = json.loads(result.stdout)
    # line of sight (the example's rule): corners taken wider and the UAVs closing up at
    # them, one UAV more than eq. 28 (the rigid formation needs 64 on the shortest path)
    assert plan["valid"] and plan["fleet_size"] == plan["min_fleet_size"] + 1 == 9
    connectivity = plan["connectivity"]
    assert connectivity["rule"] == "line_of_sight" and connectivity["spacing"] == "elastic"
    assert connectivity["los_connected_fraction"] == 1.0


@pytest.mark.slow
def test_demo_plans_plots_and_flies_the_paper_scenario(tmp_path, monkeypatch, capsys):
    """`make demo`: exit 0 means the nine simulated UAVs flew Table II within every bound."""
    from gcs.cli import demo

    monkeypatch.chdir(tmp_path)
    assert demo.main() == 0
    assert (tmp_path / "logs" / "demo-plan.png").read_bytes().startswith(PNG_MAGIC)
    assert "fleet size" in capsys.readouterr().out
    (log,) = (tmp_path / "logs").glob("table-ii-*.mcap")
    assert log.stat().st_size > 100_000
