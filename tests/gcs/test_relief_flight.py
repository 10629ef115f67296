"""Relief of one UAV flown by the ground-station core (fast mode, in process).

The mission (`tests/missions/stations-relief.yaml`): 5 UAVs where 3 would do, on the 169 m
route A -> north -> east; UAV 3 holds `north`, UAV 1 `east`. Once everyone holds, the
operator relieves UAV 2 (a relay of the gap north -> east, 3 UAVs closing to 2, 70.7 m apart):
it climbs dS_c above the chain, flies home above the route and lands on the last slot of the
start row. The mission's return (after the dwell) waits until it has landed, then the four
others come home as a formation of four onto the first four slots. The guarantees are checked
on the true positions at every sampled instant (3-D while UAV 2 flies above the chain; UAV 2
out of the fleet once landed).
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from gcs.mission import load_mission
from gcs.planning import plan_json, plan_mission
from gcs.recording.logreader import read_recording
from gcs.recording.report import flight_metrics, load_flight
from gcs.sim.fastsim import FastOptions, Faults, fly_fast
from planner.formation import collision_spacing
from tests.conftest import MISSIONS

MISSION = MISSIONS / "stations-relief.yaml"


@pytest.fixture(scope="module")
def plan():
    return plan_mission(load_mission(MISSION))


@pytest.fixture(scope="module")
def on_station(plan) -> float:
    return float(plan_json(plan)["stations"]["on_station_s"])


@pytest.fixture(scope="module")
def relieved(plan, on_station):
    """UAV 2 relieved 3 s after everyone is on station; UAV 5 asked for at once too (refused:
    one relief at a time), UAV 2 again later (refused: relieved already)."""
    faults = Faults(
        operator_reliefs=(
            (on_station - 10.0, 2),  # before everyone holds: refused
            (on_station + 3.0, 2),
            (on_station + 3.5, 4),  # during the first: refused
        )
    )
    return fly_fast(plan, FastOptions(faults=faults))


def test_the_relief_is_accepted_once_everyone_holds_and_one_at_a_time(relieved, plan):
    early, accepted, second = relieved.operator_answers
    assert early.ok is False and "holds its station" in early.reason
    assert accepted.ok is True and accepted.uav == 2
    assert accepted.landing_xy == pytest.approx(plan.formation.start_slots[-1].tolist())
    assert second.ok is False and "one relief at a time" in second.reason


def test_the_relieved_flight_keeps_every_guarantee_and_everyone_lands(relieved, plan):
    run, rho = relieved.run_json, plan.mission.safety_margin
    assert run["completed"] is True, run["reason"]
    tracking = float(np.nanmax(relieved.tracking_error_m))
    assert tracking < rho and run["max_tracking_error_m"] < rho
    checks = relieved.checks
    assert (checks.min_uav_uav_m >= 2 * rho - 2 * tracking).all()
    assert (checks.min_uav_obstacle_m >= rho - tracking).all()
    assert checks.connected.all() and run["connected_fraction"] == 1.0
    # UAV 2 flew dS_c above the others, then landed on the last slot; the four others came
    # home as a formation of four, onto the first four slots
    heights = relieved.positions[:, :, 2]
    lane = plan.mission.altitude + collision_spacing(rho)
    assert heights[:, 1].max() == pytest.approx(lane, abs=0.5)
    assert heights[:, [0, 2, 3, 4]].max() < plan.mission.altitude + 1.0
    final = relieved.positions[-1, :, :2]
    slots = plan.formation.start_slots
    assert np.hypot(*(final[1] - slots[4])) < 1.0
    assert np.hypot(*(final[[0, 2, 3, 4]] - slots[:4]).T).max() < 1.0


def test_the_run_json_reports_the_relief_and_the_points_held_after_it(relieved, on_station):
    stations = relieved.run_json["stations"]
    (relief,) = stations["relieved"]
    assert relief["uav"] == 2 and relief["source"] == "operator"
    assert relief["asked_s"] == pytest.approx(on_station + 3.0, abs=0.2)
    assert relief["landed_s"] > relief["asked_s"] and relief["on_station_s"] > 2.0
    assert [p["uav"] for p in stations["points"]] == [3, 1]
    (event,) = [e for e in relieved.result.events if e.kind == "relief"]
    assert event.uav == 2 and "lands on the start-row slot" in event.text
    # the return waited for UAV 2 to land, then brought the four others home
    assert stations["return_s"] > relief["landed_s"]


@pytest.fixture(scope="module")
def holder(plan, on_station, tmp_path_factory):
    """UAV 3, which holds `north`, relieved: UAV 4 moves up onto `north`, UAV 5 re-spaces
    between A and `north`. Recorded, as `gcs mission run --log` records."""
    log = tmp_path_factory.mktemp("relief") / "relief.mcap"
    faults = Faults(operator_reliefs=((on_station + 2.0, 3),))
    return fly_fast(plan, FastOptions(log=log, faults=faults)), log


def test_a_holder_relieved_hands_its_point_to_the_uav_behind(holder, plan):
    run, _ = holder
    (answer,) = run.operator_answers
    assert answer.ok is True
    data, rho = run.run_json, plan.mission.safety_margin
    assert data["completed"] is True, data["reason"]
    assert [p["uav"] for p in data["stations"]["points"]] == [4, 1]
    assert float(np.nanmax(run.tracking_error_m)) < rho
    assert run.checks.connected.all()
    # UAV 4 stood on `north` after the relief, UAV 5 halfway between A and it
    north = plan.formation.point_at(plan.route.point_distance[0])
    (relief,) = [e for e in run.result.events if e.kind == "relief"]
    assert "UAV 4, 5 close the gap" in relief.text
    before_return = run.times < data["stations"]["return_s"]
    at_north = np.hypot(*(run.positions[before_return, 3, :2] - north).T)
    assert at_north[-1] < 1.0
    final = run.positions[-1, :, :2]
    slots = plan.formation.start_slots
    assert np.hypot(*(final[2] - slots[4])) < 1.0  # UAV 3 on the last slot
    assert np.hypot(*(final[[0, 1, 3, 4]] - slots[:4]).T).max() < 1.0


def test_the_recording_of_a_relief_is_checked_again_by_the_report(holder, plan):
    run, log = holder
    recording = read_recording(log)
    (record,) = [m for _, m in recording.messages("/relief")]
    assert record["uav"] == 3 and record["source"] == "operator"
    assert record["holders"] == [4, 1] and record["members"] == [1, 2, 4, 5]
    assert record["stations"][2] is None
    assert record["start_s"] < record["climbed_s"] <= record["closed_s"] < record["home_s"]
    flight = load_flight(recording)
    metrics = flight_metrics(flight)
    rho = plan.mission.safety_margin
    worst = max(float(np.nanmax(e)) for e in metrics.tracking_error_m)
    assert worst < rho
    assert np.nanmin(metrics.uav_uav_m) >= 2 * rho - 2 * worst
    checked = metrics.connected[np.isfinite(metrics.connected)]
    assert len(checked) > 100 and checked.all()
    # the samples after UAV 3 landed leave it out; those while it flew above carry heights
    assert flight.sample_out[:, 2].any() and not flight.sample_out[:, [0, 1, 3, 4]].any()
    assert np.isfinite(flight.sample_heights).any()


def test_a_uav_whose_battery_runs_low_is_relieved_by_the_ground_station(tmp_path):
    """UAV 2 carries a 1000 mAh battery (the others 8000): once everyone holds and its
    reported charge is below `stations.relieve_below_pct` (60 %), the ground station relieves
    it; the others, still above, stay."""
    data = yaml.safe_load(MISSION.read_text())
    data["sim"]["battery_mah"] = [8000, 1000, 8000, 8000, 8000]
    data["stations"]["relieve_below_pct"] = 60
    path = tmp_path / "battery.yaml"
    path.write_text(yaml.safe_dump(data))
    plan = plan_mission(load_mission(path))
    run = fly_fast(plan, FastOptions())
    assert run.run_json["completed"] is True, run.run_json["reason"]
    (relief,) = run.run_json["stations"]["relieved"]
    assert relief["uav"] == 2 and relief["source"] == "battery"
    on_station = float(plan_json(plan)["stations"]["on_station_s"])
    assert relief["asked_s"] >= on_station - 0.5
    (event,) = [e for e in run.result.events if e.kind == "relief"]
    assert "its battery is low" in event.text
    assert not [e for e in run.result.events if e.kind == "relief_refused"]
    assert run.battery_remaining_pct[1] < 60 < run.battery_remaining_pct[[0, 2, 3, 4]].min()


def test_relieve_typed_in_the_live_view_relieves_that_uav(plan, on_station):
    """`relieve 4` typed once everyone holds (a malformed `relieve four` first changes
    nothing): UAV 4 goes home, UAV 5 re-spaces."""
    typed = ((on_station + 1.0, "relieve four"), (on_station + 2.0, "relieve 4"))
    run = fly_fast(plan, FastOptions(faults=Faults(typed=typed)))
    assert run.run_json["completed"] is True, run.run_json["reason"]
    (relief,) = run.run_json["stations"]["relieved"]
    assert relief["uav"] == 4 and relief["source"] == "operator"
    assert relief["asked_s"] == pytest.approx(on_station + 2.0, abs=0.2)
