"""A hostile-input corpus: files and values made to crash, hang or exhaust the ground station
(devices, FIFOs, oversized and deeply nested files, numbers past every range). Each case: exit
2, one line naming the file and the key or flag, no traceback, in bounded time and memory.
In process (`gcs.cli.main`), no socket, no child process."""

from __future__ import annotations

import json
import os
import resource
import time
from pathlib import Path

import pytest
import yaml

import gcs.cli
from fleetwire.files import MAX_NESTING, MISSION_BYTES
from medium.calibration import load_calibration

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "small.yaml"
#: Generous bounds: a refusal is immediate; reading /dev/zero took 7.6 GB before.
SECONDS = 10.0
MEGABYTES = 300


def mission(folder: Path, **changes) -> Path:
    data = yaml.safe_load(EXAMPLE.read_text())
    data.update(changes)
    path = folder / "m.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def refused(capsys, args: list[str], *names: str) -> str:
    """Run `gcs ARGS`: exit 2, one line on stderr naming `names`, nothing on stdout, no
    traceback, within the time and memory bounds; the line."""
    capsys.readouterr()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # kB, the high-water mark
    began = time.perf_counter()
    code = gcs.cli.main(args)
    elapsed = time.perf_counter() - began
    out, err = capsys.readouterr()
    assert code == 2, err
    assert out == "" and err.count("\n") == 1 and "Traceback" not in err, err
    for name in names:
        assert name in err, err
    assert elapsed < SECONDS, elapsed
    grown = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss) / 1024
    assert grown < MEGABYTES, grown
    assert len(err) < 400, err  # an excerpt, never the hostile input itself
    return err


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom", "/dev/null"])
def test_a_device_as_the_mission_is_refused_before_it_is_read(capsys, device):
    if not Path(device).exists():
        pytest.skip(f"no {device}")
    assert "a regular file, got a device" in refused(capsys, ["mission", "check", device], device)


def test_a_fifo_as_the_mission_is_refused_without_blocking(capsys, tmp_path):
    fifo = tmp_path / "mission.yaml"
    os.mkfifo(fifo)  # nobody writes: opening it would block forever
    assert "got a FIFO" in refused(capsys, ["mission", "check", str(fifo)], str(fifo))


def test_an_oversized_mission_is_refused_without_reading_it_all(capsys, tmp_path):
    path = tmp_path / "huge.yaml"
    with open(path, "wb") as file:
        file.truncate(MISSION_BYTES + 1)  # sparse: no disk used
    refused(capsys, ["mission", "check", str(path)], str(path), "at most 16.0 MB")


@pytest.mark.parametrize(
    "text",
    [
        "name: " + "[" * 100_000,  # flow nesting: libyaml's recursion
        "name:\n  " + "- " * 100_000 + "x",  # block nesting on one line: crashed the process
        "name: " + "{a: " * 1_000 + "1" + "}" * 1_000,
    ],
    ids=["flow-lists", "block-sequences", "flow-mappings"],
)
def test_yaml_nested_deeper_than_a_parser_takes_is_refused(capsys, tmp_path, text):
    path = tmp_path / "deep.yaml"
    path.write_text(text)
    refused(capsys, ["mission", "check", str(path)], str(path), "nested at most" if "[" in text
            or "{" in text else "indented at most")  # fmt: skip


@pytest.mark.parametrize(
    ("changes", "key"),
    [
        ({"goal": {"x": 1e308, "y": 100, "theta_deg": 0}}, "goal.x"),
        ({"start": {"x": -2e6, "y": 0, "theta_deg": 0}}, "start.x"),
        ({"radio_range": 1e300}, "radio_range"),
        ({"fleet": {"size": 300, "backend": "sim"}}, "fleet.size"),
        ({"fleet": {"size": 10**30, "backend": "sim"}}, "fleet.size"),
        ({"sim": {"seed": 2**70}}, "sim.seed"),
    ],
    ids=["goal-1e308", "start-2000km", "radio-1e300", "fleet-300", "fleet-1e30", "seed-2^70"],
)
def test_numbers_past_their_range_are_refused_by_check(capsys, tmp_path, changes, key):
    path = mission(tmp_path, **changes)
    refused(capsys, ["mission", "check", str(path)], str(path), key)


def test_a_long_name_is_quoted_as_an_excerpt(capsys, tmp_path):
    path = mission(tmp_path, name=["x" * 1_000_000])  # a list: refused, shown by its length
    err = refused(capsys, ["mission", "check", str(path)], str(path), "name")
    assert "xxxx" not in err


@pytest.mark.parametrize("case", ["device", "deep", "fifo"])
def test_a_hostile_footprint_file_is_refused(capsys, tmp_path, case):
    footprints = tmp_path / "city.geojson"
    if case == "device":
        footprints.symlink_to("/dev/zero")
    elif case == "fifo":
        os.mkfifo(footprints)
    else:
        footprints.write_text('{"type": "FeatureCollection", "features": ' + "[" * 10_000)
    path = mission(tmp_path, obstacles=[{"geojson": "city.geojson"}])
    refused(capsys, ["mission", "check", str(path)], str(path), "obstacles[0]")


def test_a_hostile_calibration_table_is_refused_in_one_line(tmp_path):
    deep = tmp_path / "deep.json"
    deep.write_text(json.dumps({"a": 1})[:-1] + ', "b": ' + "[" * (MAX_NESTING + 1) + "}")
    for path in (Path("/dev/zero"), deep):
        with pytest.raises(ValueError) as refusal:
            load_calibration(path)
        assert str(path) in str(refusal.value) and "\n" not in str(refusal.value)


def test_bounds_of_the_run_flags(capsys, tmp_path):
    path = mission(tmp_path)
    refused(capsys, ["mission", "run", str(path), "--takeoff-lead", "1e308"], "--takeoff-lead")
    refused(capsys, ["eval", "paper", "--leaders", "99", "--out", str(tmp_path / "o")],
            "--leaders")  # fmt: skip
