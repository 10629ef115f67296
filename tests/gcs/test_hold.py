"""The hold policy (gcs.flight.hold): the formation holds for a UAV that fell behind, resumes
when every UAV is back within its budget, and lands everyone when holding does not restore it.

The policy alone on injected numbers, then the ground-station core flown in the fast mode on
simulated time with the faults of a busy machine: one UAV's process late, the radio medium
late, one UAV starved of setpoints. Each fault breaks rho_c without the hold (measured: a 1 s
late UAV reaches 8.1 m of tracking error for rho_c = 5 m), so these tests fail without it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs.flight.hold import HOLD_LAG_S, HoldPolicy, UavState
from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.recording.logreader import read_recording
from gcs.sim.fastsim import FastOptions, Faults, fly_fast

MISSION = Path(__file__).resolve().parents[1] / "missions" / "core.yaml"
LATE_FROM, LATE_TO = 12.0, 16.0  # mission s: the fault's window (the formation is cruising)


@pytest.fixture(scope="module")
def plan():
    return plan_mission(load_mission(MISSION))


def fly(plan, **faults):
    log = faults.pop("log", None)
    return fly_fast(plan, FastOptions(faults=Faults(**faults), log=log))


def assert_stood_still_while_holding(run) -> None:
    """From the instant its reference stands still until it ends, a hold moves no UAV's target:
    the formation distance does not grow (it never flies on with a UAV behind)."""
    for hold in run.run_json["holds"]:
        since = hold["since_s"]
        until = hold["until_s"] if hold["until_s"] is not None else run.times[-1]
        standing = since + run.result.smoothing_window_s
        if until <= standing:
            continue
        times = np.linspace(standing, until, 50)
        distance = run.profile.distance(times)
        assert np.ptp(distance) < 1e-6, hold


# ------------------------------------------------------------------ the policy alone
def state(index=0, following=True, error=0.5, sample_time=10.0, growth=0.0) -> UavState:
    return UavState(index, following, error, sample_time, growth)


def test_the_thresholds_come_from_the_error_budget():
    policy = HoldPolicy.for_budget(
        safety_margin=5.0, tracking_allowance=1.5, give_up_s=10.0, max_acceleration=8.0
    )
    assert policy.hold_threshold_m == pytest.approx(3.5)  # rho_c less the allowance
    assert policy.resume_m == pytest.approx(1.5)  # back within the allowance
    # an allowance of most of the margin still leaves half of it before holding
    wide = HoldPolicy.for_budget(
        safety_margin=5.0, tracking_allowance=4.0, give_up_s=10.0, max_acceleration=8.0
    )
    assert wide.hold_threshold_m == pytest.approx(2.5) and wide.resume_m == pytest.approx(2.5)


def test_a_uav_is_behind_by_its_tracking_error_or_its_telemetry_lag():
    policy = HoldPolicy.for_budget(5.0, 1.5, 10.0, 8.0)
    t = 10.0
    assert policy.behind(t, [state(error=3.49)]) == []
    ((uav, why),) = policy.behind(t, [state(index=1, error=3.5)])
    assert uav == 2 and "tracking error 3.50 m" in why
    assert policy.behind(t, [state(sample_time=t - HOLD_LAG_S)]) == []
    ((uav, why),) = policy.behind(t, [state(sample_time=t - HOLD_LAG_S - 0.1)])
    assert uav == 1 and "telemetry lags mission time by 1.1 s" in why
    # a UAV not following (on the ground, landing, lost) is not the hold's business
    assert policy.behind(t, [state(following=False, error=20.0, sample_time=0.0)]) == []


def test_a_uav_is_behind_when_its_growing_error_will_reach_the_threshold_before_it_closes():
    """An error of 2 m growing 5.5 m/s reaches 2 + 5.5^2 / 16 = 3.89 m before a UAV
    accelerating at 8 m/s^2 matches its target's speed: behind now, not 0.3 s later. A closing
    error, or one growing slowly, is not."""
    policy = HoldPolicy.for_budget(5.0, 1.5, 10.0, 8.0)
    t = 10.0
    ((uav, why),) = policy.behind(t, [state(error=2.0, growth=5.5)])
    assert uav == 1 and "growing 5.5 m/s reaches 3.89 m" in why
    assert policy.reach_m(t, state(error=2.0, growth=5.5)) == pytest.approx(2.0 + 5.5**2 / 16)
    assert policy.behind(t, [state(error=2.0, growth=4.8)]) == []  # reaches 3.44 m
    # the same sample 0.2 s old: the error grew meanwhile (samples lost on the way)
    ((_, why),) = policy.behind(t, [state(error=2.0, growth=4.8, sample_time=t - 0.2)])
    assert "reaches 4.40 m" in why
    assert policy.behind(t, [state(error=3.4, growth=-6.0)]) == []  # closing
    # a UAV drifting away is not back, however close it is now
    policy.start(10.0, stop_s=10.5, standing_s=11.0, reasons=[(1, "x")])
    assert not policy.back(11.0, [state(error=0.5, sample_time=11.0, growth=5.0)])  # 2.06 m
    assert policy.back(11.0, [state(error=0.5, sample_time=11.0, growth=-4.0)])


def test_a_hold_resumes_only_once_standing_and_everyone_is_back():
    policy = HoldPolicy.for_budget(5.0, 1.5, 10.0, 8.0)
    policy.start(10.0, stop_s=10.5, standing_s=11.0, reasons=[(1, "x")])
    close = [state(error=0.2, sample_time=10.9)]
    assert not policy.back(10.9, close)  # the reference still moves: judged where it stops
    assert policy.back(11.0, [state(error=0.2, sample_time=11.0)])
    assert not policy.back(11.0, [state(error=1.6, sample_time=11.0)])
    assert not policy.back(11.0, [state(error=0.2, sample_time=11.0 - HOLD_LAG_S - 0.1)])
    assert not policy.back(11.0, [state(error=0.2, sample_time=None)])


def test_stop_and_go_counts_as_one_hold_towards_giving_up():
    """Holds within give_up_s of each other add their held seconds; the flight between them
    does not count (two faults 6 s apart once landed a fleet that had held 3.7 s)."""
    policy = HoldPolicy.for_budget(5.0, 1.5, give_up_s=10.0, max_acceleration=8.0)
    policy.start(10.0, 10.5, 11.0, [(1, "x")])
    assert not policy.overdue(19.9) and policy.overdue(20.0)
    policy.end(12.0, "resumed")  # held 2 s
    policy.start(15.0, 15.5, 16.0, [(1, "x")])  # within give_up_s of the previous end
    assert policy.held_s(20.0) == 7.0 and not policy.overdue(20.0)
    assert not policy.overdue(22.9) and policy.overdue(23.0)
    policy.end(16.0, "resumed")  # 3 s held in this episode
    policy.start(26.5, 27.0, 27.5, [(1, "x")])  # long after: a new episode
    assert policy.current.held_before_s == 0.0
    assert not policy.overdue(36.0) and policy.overdue(36.5)
    durations = [hold.duration_s for hold in policy.all_holds()]
    assert durations == [2.0, 1.0, None]  # the last one still holding


# ------------------------------------------------------------------ the core, simulated time
def test_a_late_vehicle_process_holds_the_formation_and_it_completes_within_rho_c(plan, tmp_path):
    """Everything UAV 2 sends and receives is 1 s late for 4 s (its process starved): its
    telemetry lags, the formation holds, every UAV waits on its target, the formation resumes
    once UAV 2 is back; the flight completes within rho_c. The hold is in the events, in the
    run JSON with its duration, and on /metrics (read back from the MCAP file)."""
    log = tmp_path / "late.mcap"
    run = fly(plan, late=((2, LATE_FROM, LATE_TO, 1.0),), log=log)
    result = run.run_json
    assert result["completed"] is True
    assert result["max_tracking_error_m"] < plan.mission.safety_margin
    (hold,) = result["holds"]
    assert hold["uavs"] == [2] and "telemetry lags" in hold["reason"]
    assert hold["outcome"] == "resumed"
    assert LATE_FROM + HOLD_LAG_S <= hold["since_s"] <= LATE_FROM + HOLD_LAG_S + 0.2
    assert hold["until_s"] >= LATE_TO  # not before UAV 2 is current again
    assert hold["duration_s"] == pytest.approx(hold["until_s"] - hold["since_s"])
    assert_stood_still_while_holding(run)
    assert [e["kind"] for e in result["events"]].count("hold") == 1
    recording = read_recording(log)
    holding = [m["t"] for _, m in recording.messages("/metrics") if m.get("holding") == [2]]
    assert holding and min(holding) >= hold["since_s"] - 1e-6
    assert max(holding) <= hold["until_s"] + 1e-6
    assert recording.outcome["completed"] is True


def test_a_late_radio_medium_holds_every_uav_and_completes_within_rho_c(plan):
    """Every packet 1 s late for 4 s (the medium process starved): the whole fleet lags,
    the formation holds for all of it and resumes; within rho_c."""
    run = fly(plan, late=((0, LATE_FROM, LATE_TO, 1.0),))
    result = run.run_json
    assert result["completed"] is True
    assert result["max_tracking_error_m"] < plan.mission.safety_margin
    (hold,) = result["holds"]
    assert hold["uavs"] == [1, 2, 3, 4] and hold["outcome"] == "resumed"
    assert_stood_still_while_holding(run)


def test_a_speed_change_due_while_holding_is_the_speed_it_resumes_with(plan):
    """The leader asks for 8 m/s at t = 16 while the formation holds: deferred, flown from
    the resumption (the hold's own stop is no broadcast speed change)."""
    run = fly(plan, late=((2, LATE_FROM, LATE_TO + 1.0, 1.0),))
    kinds = [e["kind"] for e in run.run_json["events"]]
    assert "speed_deferred" in kinds
    (hold,) = run.run_json["holds"]
    after = hold["until_s"] + run.result.smoothing_window_s
    assert float(run.profile.speed_at(after)) == 8.0
    assert all(not c["source"].startswith("freeze") for c in run.speed_changes)


def test_a_uav_late_for_good_makes_everyone_land_with_the_reason(plan):
    """UAV 2 stays 3 s late: holds follow each other (it catches up on a standing target, then
    falls behind again once the formation moves); as one episode their held seconds reach the
    give-up bound (the link wait, 10 s) and everyone lands where it is, saying why."""
    run = fly(plan, late=((2, LATE_FROM, 300.0, 3.0),))
    result = run.run_json
    assert result["completed"] is False
    abort = next(e for e in result["events"] if e["kind"] == "abort")
    assert "error budget was not restored" in abort["text"] and "UAV 2" in abort["text"]
    held = sum(hold["duration_s"] for hold in result["holds"])
    assert len(result["holds"]) > 1 and 10.0 - 1e-6 <= held <= 10.0 + 0.2
    assert "the formation held 10.0 s" in abort["text"] or "held 10.1 s" in abort["text"]
    assert result["holds"][-1]["outcome"] == "landed"
    assert_stood_still_while_holding(run)
    assert all(phase == "landed" for phase in run.result.phases)


def test_a_uav_starved_of_setpoints_stops_the_formation_for_good(plan):
    """UAV 2 receives nothing more from 12 s on, its telemetry still arrives: it carries its
    last setpoint on, brakes and holds, falls behind; the formation holds at once and never
    moves again (the link policy then lands everyone when UAV 2's own failsafe takes it out
    of guided flight)."""
    run = fly(plan, setpoint_cuts=((2, LATE_FROM, 300.0),))
    result = run.run_json
    (hold,) = result["holds"]
    assert hold["uavs"] == [2] and "tracking error" in hold["reason"]
    assert hold["outcome"] == "superseded"  # by the link policy's freeze
    standing = hold["since_s"] + run.result.smoothing_window_s
    later = run.times[run.times >= standing]
    assert np.ptp(run.profile.distance(later)) < 1e-6  # never flew on
    assert result["completed"] is False
    assert "UAV 2" in result["reason"]
    assert all(phase == "landed" for phase in run.result.phases)
