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


def test_every_error_of_ours_has_the_one_root_and_an_exit_status():
    """Each exception class defined in our packages is a `FleetlineError` (so a command ends
    on one line with its `exit_status`), whatever built-in base callers also catch it by."""
    code = """
import importlib, inspect, json, pkgutil
import fleetline, fleetwire, gcs, medium, planner, vehicles
from fleetline.errors import FleetlineError
found = {}
for package in (fleetline, fleetwire, gcs, medium, planner, vehicles):
    for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
        if info.name.endswith("__main__"):  # runs its command when imported
            continue
        try:
            module = importlib.import_module(info.name)
        except ImportError:  # an optional extra not installed here
            continue
        for name, value in vars(module).items():
            if inspect.isclass(value) and issubclass(value, BaseException) and value.__module__ == info.name:
                status = getattr(value, "exit_status", None) if issubclass(value, FleetlineError) else None
                found[f"{info.name}.{name}"] = status
print(json.dumps(found))
"""
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300
    )
    found = json.loads(done.stdout.splitlines()[-1])
    assert len(found) >= 18
    yaml_internal = {"gcs.mission.parser._DuplicateKey"}  # raised and caught inside the YAML loader
    rootless = sorted(name for name, status in found.items() if status is None)
    assert set(rootless) <= yaml_internal, rootless
    assert {found["gcs.errors.InputError"], found["fleetline.errors.UsageError"]} == {2}
