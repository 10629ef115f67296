"""`gcs sitl launch-plan`: one SITL command per UAV, homes on the parking slots, system ids,
each autopilot's multi-vehicle ports, and `fleet.connections` the mission then accepts."""

from __future__ import annotations

import dataclasses
import functools
import re
import shlex

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs import cli
from gcs.geodesy import Origin, enu_to_geodetic, geodetic_to_enu
from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.sim.sitl import plan_for_launch, slot_poses
from tests.conftest import EXAMPLES, MISSIONS

TABLE_II = EXAMPLES / "table-ii.yaml"


@pytest.fixture
def sitl(gcs_main, monkeypatch):
    """`gcs ...` in-process, with the `sitl` group registered (cli.GROUPS lists it)."""
    if "gcs.cli.cmd_sitl" not in cli.GROUPS:
        monkeypatch.setattr(cli, "GROUPS", (*cli.GROUPS, "gcs.cli.cmd_sitl"))
    return gcs_main


@pytest.fixture(scope="module")
def table_ii():
    mission = load_mission(TABLE_II)
    return mission, plan_for_launch(mission).formation.start_slots


def _fleet_yaml(stdout: str) -> dict:
    return yaml.safe_load(stdout[stdout.index("\nfleet:") :])["fleet"]


def test_ardupilot_plan_homes_sysids_ports_and_connections(sitl, table_ii, tmp_path):
    mission, slots = table_ii
    result = sitl("sitl", "launch-plan", TABLE_II, "--autopilot", "ardupilot")
    assert result.returncode == 0, result.stderr
    commands = [line for line in result.stdout.splitlines() if "sim_vehicle.py" in line]
    assert len(commands) == len(slots) == 9
    for index, line in enumerate(commands):
        argv = shlex.split(line)
        assert argv[argv.index("-I") + 1] == str(index)
        assert argv[argv.index("--sysid") + 1] == str(index + 1)
        assert "--no-mavproxy" in argv  # SERIAL0 (TCP 5760+10i) is the GCS's
        (location,) = [a for a in argv if a.startswith("--custom-location=")]
        lat, lon, alt, heading = map(float, location.split("=")[1].split(","))
        local = geodetic_to_enu(lat, lon, alt, mission.origin)
        assert np.hypot(*(local[:2] - slots[index])) < 0.02  # 7 decimals: ~1 cm
        assert abs(local[2]) < 0.02 and heading == pytest.approx(45.0)  # along the row, NE
    fleet = _fleet_yaml(result.stdout)
    assert fleet["backend"] == "ardupilot"
    assert fleet["connections"] == [f"tcp:127.0.0.1:{5760 + 10 * i}" for i in range(9)]
    watch = re.findall(r"--master=tcp:127.0.0.1:(\d+)", result.stdout)
    assert watch == [str(5762 + 10 * i) for i in range(9)]  # SERIAL1, for MAVProxy/QGC

    # The printed fleet section makes the mission flyable on that backend.
    data = yaml.safe_load(TABLE_II.read_text())
    data["fleet"] = fleet
    pasted = tmp_path / "table-ii-ardupilot.yaml"
    pasted.write_text(yaml.safe_dump(data))
    plan = plan_mission(load_mission(pasted))
    assert plan.valid and plan.fleet_size == 9


def test_px4_plan_homes_instances_and_offboard_ports(sitl, table_ii):
    mission, slots = table_ii
    result = sitl("sitl", "launch-plan", TABLE_II, "--autopilot", "px4", "--speedup", "2")
    assert result.returncode == 0, result.stderr
    commands = [line for line in result.stdout.splitlines() if "/bin/px4" in line]
    assert len(commands) == 9
    for index, line in enumerate(commands):
        env = dict(re.findall(r"(PX4_[A-Z_]+)=(\S+)", line))
        assert env["PX4_SIM_MODEL"] == "sihsim_quadx" and env["PX4_SYS_AUTOSTART"] == "10040"
        assert env["PX4_SIM_SPEED_FACTOR"] == "2"
        assert f"../bin/px4 -i {index} -d ../etc" in line  # MAV_SYS_ID = instance + 1
        lat, lon, alt = (float(env[k]) for k in ("PX4_HOME_LAT", "PX4_HOME_LON", "PX4_HOME_ALT"))
        local = geodetic_to_enu(lat, lon, alt, mission.origin)
        assert np.hypot(*(local[:2] - slots[index])) < 0.02
    fleet = _fleet_yaml(result.stdout)
    assert fleet["backend"] == "px4"
    assert fleet["connections"] == [f"udpin:127.0.0.1:{14540 + i}" for i in range(9)]


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["missing.yaml", "--autopilot", "px4"], "missing.yaml: expected a readable file"),
        ([str(TABLE_II), "--autopilot", "inav"], "argument --autopilot: invalid choice"),
        ([str(TABLE_II)], "the following arguments are required: --autopilot"),
        ([str(TABLE_II), "--autopilot", "px4", "--speedup", "0"], "--speedup: expected a finite"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(sitl, args, expected):
    result = sitl("sitl", "launch-plan", *args)
    assert result.returncode == 2
    assert result.stdout == ""
    assert expected in result.stderr and result.stderr.count("\n") == 1


def test_px4_fleet_above_ten_is_refused(sitl, tmp_path):
    data = yaml.safe_load(TABLE_II.read_text())
    data["fleet"]["size"] = 11
    big = tmp_path / "eleven.yaml"
    big.write_text(yaml.safe_dump(data))
    result = sitl("sitl", "launch-plan", big, "--autopilot", "px4")
    assert result.returncode == 2 and result.stdout == ""
    assert "--autopilot px4: expected at most 10 UAVs" in result.stderr
    assert sitl("sitl", "launch-plan", big, "--autopilot", "ardupilot").returncode == 0


def test_mission_without_a_valid_path_exits_1(sitl):
    result = sitl("sitl", "launch-plan", MISSIONS / "no-path.yaml", "--autopilot", "ardupilot")
    assert result.returncode == 1 and result.stdout == ""
    assert "no valid path" in result.stderr


@functools.cache
def _table_ii_plan():
    return plan_for_launch(load_mission(TABLE_II))


@settings(max_examples=25, derandomize=True, deadline=None)
@given(
    lat=st.floats(-60.0, 60.0),
    lon=st.floats(-179.0, 179.0),
    alt=st.floats(-100.0, 3000.0),
)
def test_every_home_converts_back_to_its_slot(lat, lon, alt):
    """Wherever the origin is, the printed homes (7 decimals) land within 2 cm of the slots."""
    plan = _table_ii_plan()
    origin = Origin(lat, lon, alt)
    moved = dataclasses.replace(plan, mission=dataclasses.replace(plan.mission, origin=origin))
    poses = slot_poses(moved)
    rounded = np.round(poses[:, :2], 7)
    local = geodetic_to_enu(rounded[:, 0], rounded[:, 1], poses[:, 2], origin)
    slots = plan.formation.start_slots
    assert np.all(np.hypot(*(local[:, :2] - slots).T) < 0.02)
    expected = enu_to_geodetic(slots[:, 0], slots[:, 1], 0.0, origin)
    assert np.allclose(poses[:, 2], expected[:, 2])
