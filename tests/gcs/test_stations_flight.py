"""Monitoring-station missions flown by the ground-station core (fast mode, in process).

The mission (`tests/missions/stations.yaml`): 4 UAVs on a 169 m route A -> north -> east,
UAV 3 holds `north` (dwell 5 s), UAV 1 `east` (dwell 8 s), UAVs 2 and 4 relay. The fleet
flies out, holds (the formation stops once every UAV is on station: nobody lands there),
returns when the longest dwell is over (every UAV flies its way out backwards, UAV 4 nearest
A first) and lands on its start slot. The guarantees are checked on the true positions at
every sampled instant (0.1 s): out, closing up, holding and home. While the fleet holds, an
operator's speed change is refused. An operator's return before everyone is on station ends
the same way; a second return, a return on an A -> B mission and a return while everyone
lands are refused. The operator socket's `return` and `relieve` commands and the refusals of
`gcs return` and `gcs relieve` close the file (the round trip over a real mission is
tests/flights/test_stations_e2e.py).
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from gcs.flight.answers import AnswerResult, OperatorAnswer, OperatorCommand
from gcs.flight.live import LiveLoop
from gcs.flight.records import ReturnRecord
from gcs.mission import load_mission
from gcs.planning import plan_json, plan_mission
from gcs.recording.logreader import read_recording
from gcs.recording.report import flight_metrics, load_flight
from gcs.sim.fastsim import FastOptions, Faults, _LockstepMission, fly_fast, with_fleet_size
from gcs.speed import OperatorSocket, send_operator_command, socket_path_for
from tests.conftest import MISSIONS

MISSION = MISSIONS / "stations.yaml"


@pytest.fixture(scope="module")
def plan():
    return plan_mission(load_mission(MISSION))


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("stations") / "stations.mcap"


@pytest.fixture(scope="module")
def flown(plan, log):
    """Out, the dwell, home: recorded, as `gcs mission run --log` records. The operator asks
    for 3 m/s at 36 s, while the fleet holds."""
    return fly_fast(
        plan, FastOptions(log=log, faults=Faults(operator_requests=((36.0, 3.0, None),)))
    )


@pytest.fixture(scope="module")
def early(plan):
    """The operator asks for the return at 20 s (UAV 4 just left its slot, nobody on station
    yet) and again at 22 s."""
    return fly_fast(plan, FastOptions(faults=Faults(operator_returns=((20.0, None), (22.0, None)))))


def planned_stations(plan) -> dict:
    return plan_json(plan)["stations"]


def assert_guarantees(run, plan) -> None:
    """The planner's guarantees at every sampled instant, on the true positions (as
    tests/gcs/test_fastsim.py): tracking below rho_c, UAV-UAV and UAV-obstacle distances within
    what that tracking allows, every UAV chained to a base station."""
    rho = plan.mission.safety_margin
    tracking = float(run.tracking_error_m.max())
    assert tracking < rho
    checks = run.checks
    assert len(checks.min_uav_uav_m) == len(run.times) > 100
    assert (checks.min_uav_uav_m >= 2 * rho - 2 * tracking).all()
    assert (checks.min_uav_obstacle_m >= rho - tracking).all()
    assert checks.connected.all()
    summary = run.run_json
    assert summary["connected_fraction"] == 1.0
    assert summary["max_tracking_error_m"] < rho


def assert_home(run, plan) -> None:
    """Completed: every UAV landed on its start slot (true positions)."""
    summary = run.run_json
    assert summary["completed"] is True, summary.get("reason")
    assert [u["phase"] for u in summary["per_uav"]] == ["landed"] * plan.fleet_size
    final = run.positions[-1]
    assert np.hypot(*(final[:, :2] - plan.formation.start_slots).T).max() < 1.0
    assert (final[:, 2] < 0.5).all()
    assert all(u["landing_error_m"] < 1.0 for u in summary["per_uav"])


def test_the_fleet_holds_every_station_then_lands_on_its_start_slots(flown, plan):
    assert_home(flown, plan)
    planned = planned_stations(plan)
    stations = flown.run_json["stations"]
    names = [p["name"] for p in planned["points"]]
    assert names == ["north", "east"]
    assert [(p["name"], p["uav"]) for p in stations["points"]] == [
        (p["name"], p["uav"]) for p in planned["points"]
    ]
    for point, asked in zip(stations["points"], planned["points"], strict=True):
        assert point["on_station_s"] >= asked["dwell_s"]
    # the hold starts when every UAV is on station; the return when the longest dwell is over
    on_station = planned["on_station_s"]
    assert stations["return_s"] == pytest.approx(on_station + 8.0)
    assert stations["held_connected_fraction"] == 1.0
    window = flown.result.smoothing_window_s
    changes = [(c["source"], c["speed"], c["effective_s"]) for c in flown.speed_changes]
    assert changes == [
        ("hold", 0.0, pytest.approx(on_station)),
        ("return", 0.0, pytest.approx(on_station + 8.0)),
        ("return", 6.0, pytest.approx(on_station + 8.0 + window)),
    ]
    # while holding, the formation stands still: the operator's speed change was refused
    (refused,) = flown.operator_answers
    assert refused.ok is False and refused.reason.startswith("every UAV holds its station")
    # nobody landed on a station: every landing came after the way home
    assert (flown.landed_s > stations["return_s"] + window).all()
    # while holding, each UAV sat on its station (true positions, within rho_c)
    slots = plan.formation.station_slots
    holding = (flown.times > on_station + 2.0) & (flown.times < stations["return_s"])
    assert holding.sum() > 40
    offsets = np.hypot(*np.moveaxis(flown.positions[holding][..., :2] - slots, -1, 0))
    assert offsets.max() < plan.mission.safety_margin


def test_every_sampled_instant_keeps_the_guarantees_out_holding_and_home(flown, plan):
    assert_guarantees(flown, plan)
    stations = flown.run_json["stations"]
    on_station, back = planned_stations(plan)["on_station_s"], stations["return_s"]
    times = flown.times
    for phase in (times < on_station - 5, (times > on_station) & (times < back), times > back + 5):
        assert phase.sum() > 20  # samples in each phase
    # the flown formation is the one with its way home: the targets end on the start slots
    assert flown.formation.returning
    end = flown.formation.positions(flown.profile.distance(times[-1]))
    np.testing.assert_allclose(end, plan.formation.start_slots, atol=1e-9)


def test_uav_n_nearest_a_leaves_its_station_first(flown, plan):
    back = flown.run_json["stations"]["return_s"]
    slots = plan.formation.station_slots
    after = flown.times > back
    away = np.hypot(*np.moveaxis(flown.positions[after][..., :2] - slots, -1, 0)) > 2.0
    assert away[-1].all()
    leaves = flown.times[after][np.argmax(away, axis=0)]  # first sample away, per UAV
    assert (np.diff(leaves) < 0).all(), leaves  # UAV N first, UAV 1 last
    assert leaves[-1] < back + flown.result.smoothing_window_s + 1.5


def test_the_return_is_recorded_and_the_report_flies_it_again(flown, plan, log):
    recording = read_recording(log)
    (record,) = [m for _, m in recording.messages("/return")]
    stations = flown.run_json["stations"]
    assert record["source"] == "dwell"
    assert record["effective_s"] == stations["return_s"]
    # the formation stood still on station: it returns from S_out
    assert record["distance"] == pytest.approx(plan.formation.outbound_distance, abs=1e-6)
    assert record["t"] < record["effective_s"]  # asked ahead, as a scheduled change
    sources = [m["source"] for _, m in recording.messages("/speed") if m["kind"] == "request"]
    assert sources == ["hold", "return", "return"]
    events = [m.message for _, m in recording.messages("/events")]
    assert any(text.startswith("every UAV on station") for text in events)
    assert any(text.startswith("return home (once the longest dwell_s is over)") for text in events)
    assert recording.json_attachment("run.json")["stations"] == stations
    # `gcs log report` rebuilds the formation with its way home from the recording
    flight = load_flight(recording)
    times = np.linspace(-5.0, flown.times[-1], 400)
    np.testing.assert_allclose(
        flight.formation.positions(flight.profile.distance(times)),
        flown.formation.positions(flown.profile.distance(times)),
        atol=1e-6,
    )
    errors = flight_metrics(flight).tracking_error_m
    assert max(float(np.nanmax(e)) for e in errors) < plan.mission.safety_margin


def test_a_return_asked_before_everyone_is_on_station_brings_everyone_home(early, plan):
    first, second = early.operator_answers
    assert first.ok is True and first.effective_s == pytest.approx(20.5)
    assert first.distance < plan.formation.outbound_distance
    assert second.ok is False and "already returning" in second.reason
    assert_home(early, plan)
    assert_guarantees(early, plan)
    stations = early.run_json["stations"]
    assert stations["return_s"] == first.effective_s
    assert stations["held_connected_fraction"] is None  # never all on station
    assert [c["source"] for c in early.speed_changes] == ["return", "return"]


def test_a_return_before_some_uavs_left_keeps_them_down(plan):
    """At 5 s: UAVs 2 and 3 are airborne over their slots (take-off lead), UAV 4 not yet."""
    run = fly_fast(plan, FastOptions(faults=Faults(operator_returns=((5.0, None),))))
    assert run.operator_answers[0].ok is True
    assert_home(run, plan)
    assert_guarantees(run, plan)
    assert np.isnan(run.takeoff_s[3]) and not np.isnan(run.takeoff_s[:3]).any()


def test_a_return_is_refused_on_an_a_to_b_mission_and_while_everyone_lands(plan):
    a_to_b = plan_mission(load_mission(MISSIONS / "core.yaml"))
    run = fly_fast(
        a_to_b, FastOptions(time_limit_s=12.0, faults=Faults(operator_returns=((10.0, 11.0),)))
    )
    (answer,) = run.operator_answers
    assert answer.ok is False and "no stations" in answer.reason
    assert "stations" not in run.run_json
    assert run.speed_changes[0]["source"] == "schedule"  # nothing else was issued
    landing = fly_fast(
        plan,
        FastOptions(
            time_limit_s=15.0,
            faults=Faults(interrupts=(10.0, 10.5), operator_returns=((12.0, None),)),
        ),
    )
    (answer,) = landing.operator_answers
    assert answer.ok is False and "the fleet is landing" in answer.reason


def test_a_stations_plan_is_flown_by_its_own_fleet_only(plan):
    assert with_fleet_size(plan, plan.fleet_size) is plan
    with pytest.raises(ValueError, match="one per station"):
        with_fleet_size(plan, plan.fleet_size - 1)


# ---------------------------------------------------------------------- the operator socket
def _ask(path: Path, request: dict) -> tuple:
    """`request` sent by a client thread; the server's parse of it, and what the client got."""
    server = OperatorSocket(path)
    answers: dict = {}
    client = threading.Thread(target=lambda: answers.update(send_operator_command(path, request)))
    try:
        client.start()
        deadline = time.monotonic() + 5.0
        requests = []
        while not requests and time.monotonic() < deadline:
            requests = server.poll()
        (parsed,) = requests
        command = OperatorCommand(parsed.command) if parsed.error is None else OperatorCommand.SPEED
        if parsed.error is None:
            parsed.reply(OperatorAnswer(command, AnswerResult.ACCEPTED, effective_s=1.0))
        else:
            parsed.reply(OperatorAnswer.refused(command, AnswerResult.BAD_REQUEST, parsed.error))
        client.join(5.0)
    finally:
        server.close()
    return parsed, answers


def test_the_operator_socket_reads_return_requests_and_speed_requests_as_before(tmp_path):
    path = socket_path_for(tmp_path / "run.mcap")
    parsed, answer = _ask(path, {"command": "return", "at": 300})
    assert (parsed.command, parsed.at, parsed.speed, parsed.error) == ("return", 300.0, None, None)
    assert answer == {"ok": True, "result": "accepted", "effective_s": 1.0, "distance": None}
    parsed, _ = _ask(path, {"command": "return"})
    assert (parsed.command, parsed.at, parsed.error) == ("return", None, None)
    parsed, _ = _ask(path, {"speed": 5, "at": 120})
    assert (parsed.command, parsed.speed, parsed.at, parsed.error) == ("speed", 5.0, 120.0, None)
    parsed, answer = _ask(path, {"command": "go home"})
    assert parsed.error.startswith("bad request: command must be one of speed, return")
    assert answer == {"ok": False, "result": "bad_request", "reason": parsed.error}
    parsed, _ = _ask(path, {"command": "return", "at": "soon"})
    assert parsed.command == "return" and parsed.error == "bad request: at must be a number"


def test_the_operator_socket_reads_relieve_requests(tmp_path):
    path = socket_path_for(tmp_path / "run.mcap")
    parsed, answer = _ask(path, {"command": "relieve", "uav": 2})
    assert (parsed.command, parsed.uav, parsed.speed, parsed.at, parsed.error) == (
        "relieve",
        2,
        None,
        None,
        None,
    )
    assert answer == {
        "ok": True, "result": "accepted", "uav": None, "effective_s": 1.0, "landing_xy": None
    }  # fmt: skip
    for uav in (True, 2.0, "2", 0, -1, None):
        request = {"command": "relieve"} if uav is None else {"command": "relieve", "uav": uav}
        parsed, answer = _ask(path, request)
        assert (parsed.command, parsed.uav) == ("relieve", None)
        assert parsed.error == "bad request: uav must be a positive integer"
        assert answer["ok"] is False and answer["result"] == "bad_request"
    parsed, _ = _ask(path, {"command": "return", "uav": 2})
    assert (parsed.command, parsed.uav, parsed.error) == ("return", None, None)


def test_gcs_return_bad_input_and_no_mission(gcs_main, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = gcs_main("return", "--at", "nan")
    assert code == 2 and out == "" and err.strip() == "--at: expected a finite number, got 'nan'"
    code, out, err = gcs_main("return", "--json")
    assert code == 1 and out == ""
    assert (
        err.strip()
        == "gcs return: no running mission (no socket under ./logs; use --socket or --log)"
    )
    code, _, err = gcs_main("return", "--socket", str(tmp_path / "none.sock"))
    assert code == 1 and "no running mission answered" in err
    code, _, err = gcs_main("speed", "3", "--socket", str(tmp_path / "none.sock"))
    assert code == 1 and err.startswith("gcs speed: no running mission answered")


def test_gcs_relieve_bad_input_and_no_mission(gcs_main, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for text in ("0", "-1", "2.5", "two", ""):
        code, out, err = gcs_main("relieve", text)
        assert code == 2 and out == ""
        assert err.strip() == f"N: expected a positive integer, got {text!r}"
    code, out, err = gcs_main("relieve")
    assert code == 2 and out == "" and "required: N" in err and len(err.splitlines()) == 1
    code, out, err = gcs_main("relieve", "2", "--json")
    assert code == 1 and out == ""
    assert (
        err.strip()
        == "gcs relieve: no running mission (no socket under ./logs; use --socket or --log)"
    )
    code, _, err = gcs_main("relieve", "2", "--socket", str(tmp_path / "none.sock"))
    assert code == 1 and err.startswith("gcs relieve: no running mission answered")


def test_gcs_relieve_is_refused_by_a_mission_not_flying_yet(gcs_main, plan, tmp_path):
    """A real ground station behind the live loop's operator socket, before take-off."""
    path = socket_path_for(tmp_path / "run.mcap")
    station = _LockstepMission(plan, FastOptions()).station
    loop = LiveLoop(station, operator=OperatorSocket(path))
    stop = threading.Event()

    def serve():
        while not stop.is_set():
            loop._poll_operator(time.monotonic())
            time.sleep(0.005)

    server = threading.Thread(target=serve)
    server.start()
    try:
        code, out, err = gcs_main("relieve", "2", "--socket", path)
        assert (code, out) == (1, "")
        assert err.strip() == "gcs relieve: refused: the fleet is not flying yet"
        code, out, err = gcs_main("relieve", "3", "--socket", path, "--json")
        assert code == 1
        assert json.loads(out) == {
            "ok": False, "result": "not_flying", "reason": "the fleet is not flying yet"
        }  # fmt: skip
        answer = send_operator_command(path, {"command": "relieve", "uav": 1.5})
        assert answer == {
            "ok": False,
            "result": "bad_request",
            "reason": "bad request: uav must be a positive integer",
        }
    finally:
        stop.set()
        server.join(5.0)
        loop.operator.close()


def test_the_return_record_json():
    record = ReturnRecord(t=1.0, effective_s=2.0, distance=3.0, source="operator")
    assert record.to_json() == {"t": 1.0, "effective_s": 2.0, "distance": 3.0, "source": "operator"}
