"""Start-up: `gcs mission plan` imports only what planning needs (issue 13.3).

The flight stack (pymavlink, the drivers and the core), the MCAP recorder and reader, and
matplotlib are imported when a command that uses them runs, never when `gcs` starts or plans.
Checked on `sys.modules` in a fresh interpreter (deterministic; no timing assertion).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
import yaml

import gcs.mission.parser
from tests.conftest import REPO

#: Top-level packages (and gcs modules) that planning a mission must not import.
HEAVY = (
    "pymavlink",
    "matplotlib",
    "mcap",
    "mcap_protobuf",
    "gcs.transport.link",
    "gcs.drivers",
    "gcs.flight",
    "gcs.recording",
    "gcs.plot",
    "gcs.sim.eval",
    "gcs.sim.fastsim",
    "scipy",
    "networkx",
)

TRIVIAL = """\
version: 1
name: trivial
start: {x: 0, y: 0, theta_deg: 0}
goal: {x: 300, y: 100, theta_deg: 0}
safety_margin: 5
radio_range: 120
altitude: 20
speed: {max: 8}
obstacles: []
"""

#: Runs in a fresh interpreter: builds the whole parser, plans the mission through `gcs`'s
#: entry point, then prints the heavy modules that got imported.
PROBE = """
import json, sys
import gcs.cli
gcs.cli.build_parser()
after_parser = sorted(sys.modules)
code = gcs.cli.main(["mission", "plan", sys.argv[1], "--json"])
heavy = json.loads(sys.argv[2])
def loaded(names):
    return sorted(m for m in names if any(m == h or m.startswith(h + ".") for h in heavy))
print(json.dumps({"code": code, "parser": loaded(after_parser), "plan": loaded(sys.modules)}))
"""


@pytest.mark.slow  # starts a Python process (the fast tier starts none: tests/conftest.py)
def test_planning_imports_no_flight_stack_mcap_or_matplotlib(tmp_path):
    mission = tmp_path / "trivial.yaml"
    mission.write_text(TRIVIAL)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    done = subprocess.run(
        [sys.executable, "-c", PROBE, str(mission), json.dumps(HEAVY)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    *plan_json, report = done.stdout.strip().splitlines()
    result = json.loads(report)
    assert result["code"] == 0
    assert json.loads(plan_json[-1])["valid"] is True
    assert result["parser"] == [], "registering the commands imported these"
    assert result["plan"] == [], "`gcs mission plan` imported these"


@pytest.mark.skipif(not yaml.__with_libyaml__, reason="PyYAML built without libyaml")
def test_mission_files_are_read_by_libyaml():
    assert issubclass(gcs.mission.parser._Loader, yaml.CSafeLoader)


def test_the_yaml_loader_keeps_line_numbers_and_yaml_1_2_floats():
    text = "a: 1e3\nb:\n  c: 1\n  c: 2\n"
    with pytest.raises(gcs.mission.parser._DuplicateKey) as found:
        yaml.load(text, Loader=gcs.mission.parser._Loader)  # noqa: S506 - a safe loader
    assert (found.value.key, found.value.line) == ("c", 4)
    assert yaml.load("a: 1e3\n", Loader=gcs.mission.parser._Loader) == {"a": 1000.0}  # noqa: S506
