"""The ground-station core's flight policy, flown in process on simulated time.

The fast mode drives THE core (`gcs.flight.core.GroundStation`, the drivers of the simulated
backend) with the lockstep vehicles and radio medium; its clock is the simulation's, so every
run is deterministic and needs no sleep. Faults (a stalled ground station, a cut link) and
operator actions are injected at fixed times on the vehicles' clock (`gcs.sim.fastsim.Faults`).
The mission (`tests/missions/core.yaml`): 4 UAVs, 172 m with one bend, 8 m/s, a scheduled
change to 5 m/s at 8 s and UAV 2 asking for 8 m/s at 16 s as leader.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.flight.answers import AnswerResult
from gcs.flight.hold import HOLD_LAG_S
from gcs.flight.rejoin import REJOIN_SETTLE_S
from gcs.flight.schedule import STILL_BEFORE_LANDING_S
from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.sim.fastsim import FastOptions, Faults, fly_fast
from gcs.transport.link import MemoryLink

MISSION = Path(__file__).resolve().parents[1] / "missions" / "core.yaml"


@pytest.fixture(scope="module")
def plan():
    return plan_mission(load_mission(MISSION))


def fly(plan, **faults):
    options = {k: faults.pop(k) for k in ("link_wait_s", "takeoff_lead_s") if k in faults}
    return fly_fast(plan, FastOptions(faults=Faults(**faults), **options))


def kinds(run) -> list[str]:
    return [e["kind"] for e in run.run_json["events"]]


def sources(run) -> list[str]:
    return [c["source"] for c in run.speed_changes]


@pytest.fixture(scope="module")
def clean(plan):
    return fly(plan)


def test_a_clean_flight_keeps_every_guarantee_and_lands_each_uav_on_its_slot(clean, plan):
    run = clean.run_json
    rho = plan.mission.safety_margin
    assert run["completed"] is True and run["fleet_size"] == 4
    assert run["max_tracking_error_m"] < rho
    assert run["min_uav_uav_m"] >= 2 * rho - 2 * run["max_tracking_error_m"]
    assert run["connected_fraction"] == 1.0
    assert sources(clean) == ["schedule", "leader:2"]
    for change in clean.speed_changes:  # every UAV acknowledged every change
        assert sorted(change["acks"]) == ["1", "2", "3", "4"]
    # the landing rule: each UAV lands once its reference has been still for a while
    formation, profile = clean.formation, clean.profile
    arrivals = profile.time_at_distance(formation.arrival_distance)
    window = clean.result.smoothing_window_s
    assert (clean.landed_s >= arrivals + window / 2 + STILL_BEFORE_LANDING_S).all()
    final = clean.positions[-1]
    assert np.hypot(*(final[:, :2] - formation.goal_slots).T).max() < 1.0


def test_a_stall_pauses_the_mission_where_the_uavs_stand(plan):
    """The ground station stops for 3 s of the vehicles' time while the formation flies at
    5 m/s: the vehicles carry their last setpoint 1 s, then brake and hold. The mission clock
    stands still while the backlog is read, then resumes where the UAVs stand: later than
    where it stopped (never backwards), earlier than the wall clock would say."""
    run = fly(plan, gcs_stalls=((13.0, 16.0),))
    (stall,) = run.stalls
    stalled = stall.until - stall.since  # from the last tick (speedup 1: mission seconds)
    assert 3.0 <= stalled <= 3.0 + 0.11
    # the UAVs flew about 1 s of it and stood where the formation was at `paused_at`: the
    # rest is taken off the clock, which resumes half a window later (a standing start)
    assert stall.stood_at + 0.5 <= stall.paused_at <= stall.stood_at + stalled - 0.5
    window = run.result.smoothing_window_s
    assert stall.resumed_at == pytest.approx(stall.paused_at + window / 2)
    assert stall.held_back_s == pytest.approx(stalled - (stall.resumed_at - stall.stood_at))
    assert (np.diff(run.times) >= 0).all()  # the mission clock never ran backwards
    assert "stall" in kinds(run)
    assert run.run_json["completed"] is True
    assert run.run_json["max_tracking_error_m"] < plan.mission.safety_margin


@pytest.mark.parametrize("start", [5.0, 13.0])
def test_a_stall_as_long_as_the_setpoint_timeout_picks_the_uavs_up_at_their_speed(plan, start):
    """The ground station stops 1 s (a 1 s SIGSTOP at 1x), the vehicles' setpoint timeout:
    they flew their last setpoints on (UAV 2, joining at 5 s, accelerating) and had just
    begun to brake when the backlog was read. A standing start there (the old rule) left the
    reference still while they flew on at up to 8 m/s: 10.2 m at 5 s, 3.5 m and a hold at
    13 s. The formation resumes at their speed, no hold, well within rho_c."""
    run = fly(plan, gcs_stalls=((start, start + 1.0),))
    (stall,) = run.stalls
    window = run.result.smoothing_window_s
    assert stall.paused_at <= stall.resumed_at < stall.paused_at + window / 2  # not stopped
    assert stall.paused_at >= stall.stood_at + 0.9  # they flew nearly all of it
    assert "hold" not in kinds(run) and "tracking" not in kinds(run)
    assert run.run_json["completed"] is True
    assert run.run_json["max_tracking_error_m"] < 3.0


@pytest.mark.parametrize("uav", [2, 3])
def test_a_stall_with_a_uav_not_heard_lately_resumes_where_it_was_heading(plan, uav):
    """One UAV's link is cut from 0.7 s before a 1 s stall until after it: its latest sample
    is 1.7 s old when the backlog is read. It flew its last setpoint on meanwhile, so it is
    matched where that sample was heading (moved on by its velocity, at most 0.5 s), not where
    it was last heard: 3.2 m. Taken to stand where it was last heard, with a standing start
    for everyone, it was 6.6 m, past rho_c."""
    run = fly(plan, link_cuts=((uav, 12.3, 14.5),), gcs_stalls=((13.0, 14.0),))
    assert run.stalls and run.run_json["max_tracking_error_m"] < 4.0


@pytest.mark.parametrize("late_s", [0.05, 0.3])
def test_a_stall_whose_telemetry_was_lost_waits_for_where_the_uavs_stand(plan, late_s):
    """The ground station stops 3 s and what every UAV sends meanwhile is lost (a socket
    buffer that overflowed while the process was stopped, as in a live fault test): at the
    wake-up its samples are from before the stall. Resolved at once, the formation resumed
    where those samples were heading (0.5 s into the stall) while the UAVs had flown 1 s on and
    braked: 8.5 m here (4.5 m on examples/small.yaml; 5.03 m, past rho_c, in a live flight of
    the fault tests). It now waits, the clock still frozen, for a fresh sample of each, and
    resumes where they stand (1.45 s into the stall): 2.2 m, no hold."""
    cuts = tuple((uav, 21.0, 24.0 + late_s) for uav in (1, 2, 3, 4))
    run = fly(plan, gcs_stalls=((21.0, 24.0),), link_cuts=cuts)
    (stall,) = run.stalls
    assert stall.paused_at >= stall.stood_at + 1.0  # they flew on about 1 s, then braked
    assert "hold" not in kinds(run)
    assert run.run_json["completed"] is True
    assert np.nanmax(run.tracking_error_m) < 3.0


def test_a_stall_longer_than_the_gcs_failsafe_resumes_where_the_uavs_stand(plan):
    """The ground station stops for 6.5 s (no lockstep: SITL, real vehicles): longer than the
    vehicles' GCS failsafe (5 s), so they brake (BRAKE, out of guided flight) before the
    backlog is read. They flew the formation until it stopped: it resumes where they stand,
    not at the last tick (which pulled them 9 m back along the path, past rho_c), and each
    is taken back to guided flight."""
    run = fly(plan, gcs_stalls=((13.0, 19.5),))
    (stall,) = run.stalls
    assert stall.paused_at >= stall.stood_at + 1.0  # they flew on about 1 s, then braked
    assert "rejoin" in kinds(run)
    assert run.run_json["completed"] is True
    assert run.run_json["max_tracking_error_m"] < plan.mission.safety_margin


def test_a_stall_that_ends_in_the_tick_waits_for_the_backlog(plan):
    """The ground station stopped after reading its links and before its tick (the window
    where a SIGSTOP or a starved CPU hits a busy loop): it wakes up in the tick with the
    stall's telemetry unread. It must not fly on from a clock that ran on: it stands still,
    reads the backlog, and resumes where the UAVs stand, as when it wakes up reading."""
    reading = fly(plan, gcs_stalls=((13.0, 16.0),))
    ticking = fly(plan, gcs_stalls=((13.0, 16.0),), gcs_stalls_before_tick=True)
    (stall,) = ticking.stalls
    (same,) = reading.stalls
    assert stall.since == same.since
    assert abs(stall.paused_at - same.paused_at) <= 0.1
    assert "stall" in kinds(ticking)
    assert (np.diff(ticking.times) >= 0).all()
    assert ticking.run_json["completed"] is True
    assert ticking.run_json["max_tracking_error_m"] < plan.mission.safety_margin
    # the true positions too: the fast mode samples none while the clock stands at the stall's
    # start (it paired the UAVs that flew on with V_n there: 9.4 m that never were)
    assert np.nanmax(ticking.tracking_error_m) < plan.mission.safety_margin


def test_a_stall_before_anyone_follows_holds_the_whole_stall_back(plan):
    """No UAV was following the formation: none of the stalled time was flown (nor were the
    take-offs it should have started), so all of it is held back."""
    run = fly(plan, gcs_stalls=((-5.0, -2.0),))
    (stall,) = run.stalls
    assert stall.resumed_at == stall.paused_at == pytest.approx(stall.stood_at)
    assert stall.held_back_s == pytest.approx(stall.until - stall.since)
    assert run.run_json["completed"] is True


def test_a_lost_link_freezes_and_the_uav_rejoins_before_the_formation_resumes(plan):
    """UAV 2 is cut off for 5 s: it holds (its setpoint timeout, then its own GCS failsafe),
    the formation holds (its telemetry lags), then freezes (its link is lost); when the link is back the UAV is taken back to guided flight and
    the formation resumes only once it is back on its target, at the leader's speed that came
    in meanwhile (deferred, not flown while frozen)."""
    run = fly(plan, link_cuts=((2, 12.0, 17.0),))
    events = run.run_json["events"]
    assert "link_lost" in kinds(run) and "rejoin" in kinds(run)
    assert sources(run)[-2:] == ["freeze:link", "resume"]
    freeze, resume = run.speed_changes[-2:]
    assert freeze["speed"] == 0.0 and resume["speed"] == 8.0  # the leader's, deferred
    assert "speed_deferred" in kinds(run)
    back = next(e["t"] for e in events if e["kind"] == "link_back")
    rejoined = next(e["t"] for e in events if e["kind"] == "rejoin")
    # its BRAKE (taken while cut off) is read after the link is back: the formation waits
    # for it to fly guided within its allowance for REJOIN_SETTLE_S
    assert back < rejoined and resume["requested_s"] >= rejoined + REJOIN_SETTLE_S
    # UAV 2 acknowledged the freeze 2 s late, after its outage: that is no reaction time, and
    # the resume keeps the usual lead (half a smoothing window), not twice the outage
    assert resume["effective_s"] - resume["requested_s"] <= 0.5 + 1e-6
    # UAV 2 was back within its allowance of the (frozen) target when the formation resumed
    at = np.searchsorted(run.times, resume["requested_s"])
    allowance = plan.mission.vehicle.tracking_allowance
    assert run.tracking_error_m[at, 1] <= allowance + 0.3
    # no UAV came near another, and every UAV landed on its slot
    assert run.run_json["min_uav_uav_m"] > 2 * plan.mission.safety_margin
    final = run.positions[-1]
    assert np.hypot(*(final[:, :2] - run.formation.goal_slots).T).max() < 1.0
    # the formation held as soon as UAV 2's telemetry lagged a second (before its link was
    # declared lost), so its tracking error stayed within rho_c; the lost link is still an
    # error: exit status 1
    (hold,) = run.run_json["holds"]
    assert hold["uavs"] == [2] and hold["outcome"] == "superseded"
    assert 12.0 + HOLD_LAG_S <= hold["since_s"] <= 12.0 + HOLD_LAG_S + 0.2
    assert run.run_json["max_tracking_error_m"] < plan.mission.safety_margin
    assert run.run_json["completed"] is False
    assert "link lost" in run.run_json["reason"]


def test_a_link_lost_longer_than_the_wait_lands_everyone(plan):
    run = fly(plan, link_cuts=((3, 12.0, 42.0),), link_wait_s=5.0)
    result = run.run_json
    assert result["completed"] is False
    assert "UAV 3" in result["reason"] and "link lost" in result["reason"]
    abort = next(e for e in result["events"] if e["kind"] == "abort")
    lost = next(e for e in result["events"] if e["kind"] == "link_lost")
    assert abort["t"] == pytest.approx(lost["t"] + 5.0, abs=0.15)
    # everyone is down: the others landed where they were, UAV 3 by its own failsafe
    assert (run.positions[-1][:, 2] < 0.5).all()


def test_a_late_take_off_freezes_the_formation_until_the_uav_is_up(plan):
    """A take-off lead too short for the climb: each UAV is still climbing at its departure,
    so the formation waits (speed 0) for it, then resumes; nobody is left behind."""
    run = fly(plan, takeoff_lead_s=2.0)
    assert "late_takeoff" in kinds(run)
    assert "freeze:takeoff" in sources(run) and "resume" in sources(run)
    # one freeze per late UAV: the freeze's own standstill (every departure not yet reached
    # reads inf) never counts as the UAV being up (it flapped: 11 freezes for 4 UAVs)
    assert kinds(run).count("late_takeoff") == sources(run).count("freeze:takeoff") == 4
    assert run.run_json["completed"] is True
    assert run.run_json["max_tracking_error_m"] < plan.mission.safety_margin


def test_operator_requests_are_answered_and_flown_and_a_short_link_cut_is_ridden_through(plan):
    run = fly(
        plan,
        operator_requests=((20.0, 3.0, None), (24.0, 99.0, None), (26.0, 6.0, 30.0)),
        link_cuts=((2, 12.0, 13.5),),  # shorter than the link timeout: no loss, no freeze
    )
    assert "link_lost" not in kinds(run) and not any(s.startswith("freeze") for s in sources(run))
    first, refused, timed = run.operator_answers
    assert first.ok is True and first.speed == 3.0
    assert refused.ok is False and "99" in refused.reason
    assert timed.to_json() == {
        "ok": True, "result": "accepted", "seq": timed.seq, "effective_s": 30.0, "speed": 6.0
    }  # fmt: skip
    assert refused.result is AnswerResult.REFUSED
    assert refused.to_json() == {"ok": False, "result": "refused", "reason": refused.reason}
    operator = [c for c in run.speed_changes if c["source"] == "operator"]
    assert len(operator) == 2
    for change in operator:
        assert sorted(change["acks"]) == ["1", "2", "3", "4"]
        assert all(t < change["effective_s"] for t in change["received_s"].values())
    assert run.profile.speed_at(np.array([31.0]))[0] == 6.0
    assert run.run_json["completed"] is True


def test_the_leaders_request_reaches_every_uav_before_it_takes_effect(clean):
    leader = clean.speed_changes[1]
    assert leader["source"] == "leader:2"
    assert 16.0 <= leader["leader_sent_s"] <= leader["requested_s"]
    assert all(
        leader["requested_s"] <= t < leader["effective_s"] for t in leader["received_s"].values()
    )


def test_ctrl_c_once_freezes_twice_lands_everyone(plan):
    run = fly(plan, interrupts=(20.0, 25.0))
    assert sources(run)[-1] == "freeze:operator"
    assert [k for k in kinds(run) if k in ("interrupt", "abort")] == ["interrupt", "abort"]
    assert run.run_json["completed"] is False
    assert run.run_json["reason"] == "interrupted by the operator"
    assert (run.positions[-1][:, 2] < 0.5).all()


def test_frames_from_another_system_never_keep_a_link_alive():
    link = MemoryLink("memory:2", 2)
    codec = mavlink.MAVLink(None, srcSystem=7, srcComponent=1)
    forged = codec.heartbeat_encode(2, 3, 0, 0, 0)
    forged.pack(codec)
    assert link.accept([forged], 10.0) == []
    assert link.counters.foreign == 1 and link.silent_for(11.0) == float("inf")
    own = mavlink.MAVLink(None, srcSystem=2, srcComponent=1)
    beat = own.heartbeat_encode(2, 3, 0, 0, 0)
    beat.pack(own)
    assert link.accept([beat], 12.0) == [beat] and link.silent_for(13.0) == 1.0
