"""Reading and setting an autopilot's limit parameters (gcs/drivers/parameters.py,
gcs/drivers/limits.py): the encodings recorded from real autopilots, retries, give-up, and
the mission compared with what the autopilot allows."""

from __future__ import annotations

import gzip
import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from gcs.drivers.commands import Backoff
from gcs.drivers.limits import ARDUCOPTER, PX4, AutopilotLimits, exceeded
from gcs.drivers.parameters import Encoding, ParameterTable, decode_value, encode_value
from gcs.transport.link import mavutil

mavlink = mavutil.mavlink
SITL = Path(__file__).resolve().parents[1] / "sitl"


def _transcript_params(name: str) -> list[dict]:
    path = SITL / name
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt") as handle:
        return [json.loads(line)["fields"] for line in handle if '"type":"PARAM_VALUE"' in line]


def test_integer_parameters_decode_as_each_autopilot_encodes_them():
    px4 = {f["param_id"]: f for f in _transcript_params("px4-refusals.jsonl.gz")}
    baro = px4["CAL_BARO0_ID"]  # INT32 copied bytewise into the float (PX4)
    assert baro["param_type"] == mavlink.MAV_PARAM_TYPE_INT32
    assert decode_value(baro["param_value"], baro["param_type"], Encoding.BYTEWISE) == 6620172
    assert decode_value(px4["CAL_BARO0_PRIO"]["param_value"], 6, Encoding.BYTEWISE) == 50
    ardupilot = {f["param_id"]: f for f in _transcript_params("ardupilot-session.jsonl.gz")}
    compass = ardupilot["COMPASS_DEV_ID"]  # INT32 cast to float (ArduPilot)
    assert decode_value(compass["param_value"], compass["param_type"], Encoding.C_CAST) == 97539
    # floats are floats either way, and an encoded value decodes back
    assert decode_value(2.5, mavlink.MAV_PARAM_TYPE_REAL32, Encoding.BYTEWISE) == 2.5
    for encoding in Encoding:
        sent = encode_value(6620172, mavlink.MAV_PARAM_TYPE_INT32, encoding)
        assert decode_value(sent, mavlink.MAV_PARAM_TYPE_INT32, encoding) == 6620172


def _value(name: str, value: float, param_type: int = mavlink.MAV_PARAM_TYPE_REAL32):
    return SimpleNamespace(param_id=name, param_value=value, param_type=param_type)


def test_a_read_is_retried_then_given_up_and_an_answer_settles_it():
    table = ParameterTable(Encoding.C_CAST, retry=Backoff(1.0, 1.0, 1.0), max_attempts=3)
    table.read("WPNAV_SPEED", "WPNAV_ACCEL")
    assert table.due(0.0) == [("read", "WPNAV_SPEED"), ("read", "WPNAV_ACCEL")]
    assert table.due(0.5) == []  # paced
    table.on_param_value(_value("WPNAV_SPEED", 1000.0))
    assert table.value("WPNAV_SPEED") == 1000.0
    assert table.due(1.0) == [("read", "WPNAV_ACCEL")]
    assert table.due(2.0) == [("read", "WPNAV_ACCEL")]
    assert not table.settled()
    assert table.due(3.0) == []  # third attempt was the last
    assert table.settled() and table.failed() == ["WPNAV_ACCEL"]


def test_a_set_is_confirmed_only_by_the_value_coming_back():
    table = ParameterTable(Encoding.BYTEWISE, retry=Backoff(1.0, 1.0, 1.0))
    table.set("MPC_ACC_HOR_MAX", 8.0, mavlink.MAV_PARAM_TYPE_REAL32)
    assert table.due(0.0) == [("set", "MPC_ACC_HOR_MAX", 8.0, mavlink.MAV_PARAM_TYPE_REAL32)]
    table.on_param_value(_value("MPC_ACC_HOR_MAX", 5.0))  # an older value: not yet
    assert not table.settled()
    table.on_param_value(_value("MPC_ACC_HOR_MAX", 8.0))
    assert table.settled() and table.value("MPC_ACC_HOR_MAX") == 8.0


def test_a_mission_assuming_more_than_the_autopilot_names_uav_parameter_value_and_key():
    limits = AutopilotLimits(uav=2, parameters=ARDUCOPTER, speed_raw=1000.0, acceleration_raw=250.0)
    assert (limits.max_speed, limits.max_acceleration) == (10.0, 2.5)
    assert exceeded(limits, 10.0, 2.5) == []  # equal is allowed
    (too_fast,) = exceeded(limits, 10.0, 8.0)
    assert too_fast.text() == (
        "UAV 2: its autopilot's WPNAV_ACCEL = 250 cm/s^2 (2.5 m/s^2) is below "
        "vehicle.max_acceleration = 8 m/s^2"
    )
    px4 = AutopilotLimits(uav=1, parameters=PX4, speed_raw=12.0, acceleration_raw=5.0)
    (speed,) = exceeded(px4, 15.0, 5.0)
    assert speed.mission_key == "vehicle.max_speed"
    assert speed.text() == (
        "UAV 1: its autopilot's MPC_XY_VEL_MAX = 12 m/s is below vehicle.max_speed = 15 m/s"
    )


@pytest.mark.parametrize("value", [1000.0, 1000.0004])  # float32 rounding of 10 m/s
def test_float32_rounding_is_not_a_refusal(value):
    limits = AutopilotLimits(uav=1, parameters=ARDUCOPTER, speed_raw=value, acceleration_raw=600)
    assert exceeded(limits, 10.0000001, 6.0) == []
