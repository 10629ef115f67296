"""`vehicles sim` command line: bad input is one line and exit 2, a port in use too, signals
stop it cleanly, `--battery-mah` sizes every vehicle's battery or each one's, and `--count`
hosts several vehicles (own port, own system id, own start) that also push to an `--out`
address."""

from __future__ import annotations

import json
import signal
import socket
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.cli import build_parser, config_from_args, main
from vehicles.testing import GroundStation, VehicleProcess, free_udp_ports, local_of


@pytest.mark.parametrize(
    ("argv", "names"),
    [
        (["sim"], "--base-port"),
        (["sim", "--base-port", "x"], "--base-port"),
        (["sim", "--base-port", "70000"], "--base-port"),
        (["sim", "--base-port", "65535", "--count", "2"], "--base-port"),
        (["sim", "--base-port", "14560", "--count", "0"], "--count"),
        (["sim", "--base-port", "14560", "--speedup", "-2"], "--speedup"),
        (["sim", "--base-port", "14560", "--speedup", "nan"], "--speedup"),
        (["sim", "--base-port", "14560", "--sysid-base", "254", "--count", "3"], "--sysid-base"),
        (["sim", "--base-port", "14560", "--out", "14550"], "--out"),
        (["sim", "--base-port", "14560", "--home", "95,4,170"], "--home"),
        (["sim", "--base-port", "14560", "--count", "2", "--positions", "0,0"], "--positions"),
        (["sim", "--base-port", "14560", "--positions", "0,a"], "--positions[0]"),
        (["sim", "--base-port", "14560", "--leader-requests", "3"], "--leader-requests"),
        (["sim", "--base-port", "14560", "--leader-requests", "-3:4"], "--leader-requests"),
        (
            ["sim", "--base-port", "14560", "--leader-requests", "3:4", "--leader-sysid", "9"],
            "--leader-sysid",
        ),
        (["sim", "--base-port", "14560", "--gcs-sysid", "1"], "--gcs-sysid"),
        (["sim", "--base-port", "14560", "--wind", "1"], "--wind"),
        (["sim", "--base-port", "14560", "--setpoint-timeout", "0"], "--setpoint-timeout"),
        (["sim", "--base-port", "14560", "--battery-mah", "0"], "--battery-mah"),
        (["sim", "--base-port", "14560", "--battery-mah", "500,x"], "--battery-mah"),
        (["sim", "--base-port", "14560", "--battery-mah", "nan"], "--battery-mah"),
        (
            ["sim", "--base-port", "14560", "--count", "2", "--battery-mah", "1,2,3"],
            "--battery-mah",
        ),
        (["fly"], "fly"),
    ],
)
def test_bad_flags_are_one_line_naming_the_flag_and_exit_2(argv, names, capsys):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and names in lines[0] and lines[0].startswith("vehicles sim: error: ")


def test_battery_mah_sizes_every_vehicle_or_each_one():
    def capacities(*flags: str) -> list:
        args = build_parser().parse_args(["sim", "--base-port", "14560", "--count", "3", *flags])
        return [spec.battery_mah for spec in config_from_args(args).vehicles]

    assert capacities() == [None, None, None]  # the airframe's
    assert capacities("--battery-mah", "500") == [500.0, 500.0, 500.0]
    assert capacities("--battery-mah", "8000,250,1e3") == [8000.0, 250.0, 1000.0]


def test_a_bad_positions_file_names_the_file(tmp_path, capsys):
    path = tmp_path / "slots.json"
    path.write_text(json.dumps([[0, 0], [1, "a"]]))
    assert main(["sim", "--base-port", "14560", "--count", "2", "--positions-file", str(path)]) == 2
    line = capsys.readouterr().err.strip()
    assert f"{path}[1]" in line and "\n" not in line
    path.write_text("{not json")
    assert main(["sim", "--base-port", "14560", "--positions-file", str(path)]) == 2
    assert str(path) in capsys.readouterr().err


@pytest.mark.slow
def test_a_port_in_use_is_exit_2_with_one_line():
    base = free_udp_ports(3)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", base + 2))
        process = VehicleProcess(count=3, base_port=base)
        process.process.wait(timeout=20)
        code, stderr = process.stop()
    assert code == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and f"127.0.0.1:{base + 2}" in lines[0] and "in use" in lines[0]
    assert "--base-port" in lines[0] and "Traceback" not in stderr


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signals_stop_the_simulation_cleanly(sig):
    process = VehicleProcess(count=2, speedup=1.0)
    gcs = GroundStation(process.port(1), target=2)
    gcs.connect()
    code, stderr = process.stop(sig)
    gcs.close()
    assert code == 0
    assert "Traceback" not in stderr and "stopped after" in stderr


@pytest.mark.slow
def test_count_hosts_vehicles_on_their_own_ports_ids_and_slots_and_pushes_to_out():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
        out.bind(("127.0.0.1", 0))
        out.settimeout(0.2)
        out_port = out.getsockname()[1]
        args = [
            "--sysid-base",
            "11",
            "--positions",
            "0,0;10,0;20,5",
            "--out",
            f"udpout:127.0.0.1:{out_port}",
        ]
        with VehicleProcess(count=3, speedup=5.0, args=args) as process:
            decoder = mavlink.MAVLink(None)
            decoder.robust_parsing = True
            seen: dict[int, int] = {}
            deadline = time.monotonic() + 10.0
            while len(seen) < 3 and time.monotonic() < deadline:  # nobody talked to them yet
                try:
                    data, address = out.recvfrom(65535)
                except TimeoutError:
                    continue
                for message in decoder.parse_buffer(data) or []:
                    if message.get_type() == "HEARTBEAT":
                        seen[message.get_srcSystem()] = address[1]
            assert seen == {11: process.port(0), 12: process.port(1), 13: process.port(2)}
            gcs = GroundStation(process.port(2), speedup=5.0, target=13)
            gcs.connect()
            home = gcs.home()
            assert np.allclose(
                local_of((45.7640, 4.8357, 170.0), *home), [20.0, 5.0, 0.0], atol=1.0
            )
            assert (
                gcs.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 4).result == mavlink.MAV_RESULT_ACCEPTED
            )
            gcs.wait_for(lambda: gcs.heartbeat_is(custom_mode=4), 5.0, "vehicle 13 in GUIDED")
            gcs.close()
