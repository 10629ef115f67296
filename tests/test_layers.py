"""The layers stay apart (docs/ARCHITECTURE.md): each import is checked in a fresh interpreter
(a real subprocess: this test process has imported everything already)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow  # each check starts an interpreter


def modules_after(statement: str) -> set[str]:
    code = f"import sys, json\n{statement}\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    return set(json.loads(done.stdout.splitlines()[-1]))


@pytest.mark.parametrize(
    ("statement", "absent"),
    [
        # the ground-station core: no process launchers, no subprocess, no fast mode
        ("import gcs.flight.core", ("subprocess", "gcs.sim", "gcs.sim.children", "gcs.cli")),
        # validating a study file: no figures, no evaluation, no fast mode
        ("import gcs.study.studyfile", ("matplotlib", "gcs.sim.eval", "gcs.sim.fastsim")),
        # the planner: numbers in, numbers out
        ("import planner.search, planner.elastic, planner.kinematics", ("socket", "gcs")),
    ],
)
def test_a_layer_does_not_import_what_it_must_not_know(statement, absent):
    loaded = modules_after(statement)
    assert not [name for name in absent if name in loaded], statement
