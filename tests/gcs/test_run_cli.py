"""`gcs mission run` and `gcs speed`: bad input is one line and exit 2, nothing starts."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import gcs.cli
import gcs.cli.cmd_mission

REPO = Path(__file__).resolve().parents[2]
SMALL = REPO / "examples" / "small.yaml"
NO_PATH = REPO / "tests" / "missions" / "no-path.yaml"


@pytest.fixture
def gcs_run(monkeypatch, capsys, tmp_path):
    """`gcs ARGS` in this process, in `tmp_path`."""
    monkeypatch.chdir(tmp_path)

    def run(*args):
        capsys.readouterr()
        code = gcs.cli.main([str(a) for a in args])
        out, err = capsys.readouterr()
        return code, out, err

    return run


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--speedup", "0"], "--speedup"),
        (["--speedup", "nan"], "--speedup"),
        (["--link-wait", "-1"], "--link-wait"),
        (["--vehicles-per-process", "0"], "--vehicles-per-process"),
        (["--log", "run.txt"], "--log"),
        (["--log", "missing/dir/run.mcap"], "--log"),
        (["--foxglove", "70000"], "--foxglove"),
        (["--out-readonly"], "--out-readonly"),
        (["--out", "nonsense:x"], "--out"),
        (["--out", "udpout:nohost.invalid:14550"], "nohost.invalid"),
    ],
)
def test_bad_flags_exit_2_with_one_line(gcs_run, args, names):
    code, out, err = gcs_run("mission", "run", SMALL, "--json", *args)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1 and names in err


def test_an_existing_log_is_refused_without_force(gcs_run, tmp_path):
    (tmp_path / "run.mcap").write_bytes(b"keep me")
    code, out, err = gcs_run("mission", "run", SMALL, "--log", "run.mcap")
    assert code == 2 and out == ""
    assert "--force" in err and err.count("\n") == 1
    assert (tmp_path / "run.mcap").read_bytes() == b"keep me"
    assert not (tmp_path / "logs").exists()


def test_a_setpoint_rate_above_50_hz_is_refused(gcs_run, tmp_path):
    mission = tmp_path / "fast.yaml"
    mission.write_text(SMALL.read_text().replace("setpoint_rate_hz: 10", "setpoint_rate_hz: 60"))
    code, _, err = gcs_run("mission", "run", mission)
    assert code == 2
    assert "sim.setpoint_rate_hz" in err and "50" in err


def test_a_bad_mission_file_is_refused(gcs_run, tmp_path):
    code, out, err = gcs_run("mission", "run", tmp_path / "nowhere.yaml", "--json")
    assert code == 2 and out == "" and err.count("\n") == 1


def test_no_valid_path_exits_1_with_the_run_json(gcs_run):
    code, out, err = gcs_run("mission", "run", NO_PATH, "--json")
    assert code == 1
    run = json.loads(out)
    assert run["completed"] is False and "no valid path" in run["reason"]


def test_speed_without_a_running_mission(gcs_run):
    code, out, err = gcs_run("speed", "5")
    assert code == 1 and "no running mission" in err
    code, _, err = gcs_run("speed", "fast")
    assert code == 2 and "V" in err
    code, _, err = gcs_run("speed", "5", "--at", "soon")
    assert code == 2 and "--at" in err
    code, _, err = gcs_run("speed", "5", "--log", "logs/gone.mcap")
    assert code == 1 and "no running mission answered" in err
