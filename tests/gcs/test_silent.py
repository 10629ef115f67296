"""Dead reckoning of a UAV the ground station no longer hears (`gcs.flight.silent`), the hold
policy's use of it (`gcs.flight.hold`), and link cuts flown in the fast mode: the cut UAV flies
its last setpoint on alone, then brakes at WPNAV_ACCEL, and the formation's hold is timed so
that its targets stop near where it stops."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs.flight.hold import HoldPolicy, UavState
from gcs.flight.silent import OnItsOwn, SentSetpoint, dead_reckon, hold_errors
from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.sim.fastsim import FastOptions, Faults, fly_fast

SMALL = Path(__file__).resolve().parents[2] / "examples" / "small.yaml"
ALONE = OnItsOwn(horizon_s=1.0, brake_mps2=8.0)


def setpoint(t=0.0, position=(0.0, 0.0), velocity=(0.0, 0.0), acceleration=(0.0, 0.0)):
    return SentSetpoint(t, np.array(position), np.array(velocity), np.array(acceleration))


def test_a_silent_uav_flies_its_setpoint_on_for_the_horizon_then_brakes_to_a_stop():
    sent = setpoint(t=10.0, position=(5.0, 0.0), velocity=(6.0, 0.0), acceleration=(2.0, 0.0))
    times = np.array([9.0, 10.0, 10.5, 11.0, 11.5, 12.0, 20.0])
    xy = dead_reckon(sent, ALONE, times)
    # before it was sent: where it was sent; then p + v t + a t^2 / 2 for the horizon
    assert xy[0] == pytest.approx([5.0, 0.0]) and xy[1] == pytest.approx([5.0, 0.0])
    assert xy[2] == pytest.approx([5.0 + 3.0 + 0.25, 0.0])
    assert xy[3] == pytest.approx([12.0, 0.0])  # 8 m/s at the end of the horizon
    # then braking at 8 m/s^2 along its velocity: 8 m/s -> stopped 1 s later, 4 m on
    assert xy[4] == pytest.approx([12.0 + 4.0 - 1.0, 0.0])
    assert xy[5] == pytest.approx([16.0, 0.0]) and xy[6] == pytest.approx([16.0, 0.0])
    assert sent.stop_time(ALONE) == pytest.approx(12.0)


def test_a_uav_left_standing_is_held_at_once_one_carrying_on_later():
    """A UAV at rest whose targets start moving: every tick of waiting moves the targets on, so
    holding now is better than a tick later. A UAV flying faster than its targets: holding now
    stops the targets short of where it stops, a tick later is better."""

    def moving_targets(speed):
        def targets(decided, times):  # the targets move at `speed` until the hold stops them
            stop = decided + 0.5
            return np.column_stack([speed * np.minimum(times, stop), np.zeros_like(times)])

        return targets

    standing = setpoint(t=0.0)
    now_m, next_m = hold_errors(standing, ALONE, 0.5, 0.1, moving_targets(8.0), 1.0)
    assert now_m == pytest.approx(8.0) and next_m == pytest.approx(8.8)
    ahead = setpoint(t=0.0, velocity=(12.0, 0.0))  # stops at 12 + 9 = 21 m, at t = 2.5 s
    now_m, next_m = hold_errors(ahead, ALONE, 0.5, 0.1, moving_targets(8.0), 1.0)
    assert now_m > next_m


def state(errors, heard=10.0):
    return UavState(0, True, 0.2, heard, silent_errors_m=errors)


@pytest.mark.parametrize(
    "errors, heard, held",
    [
        ((3.0, 3.6), 10.5, True),  # waiting breaks the threshold (3.5 m): hold now
        ((3.0, 3.4), 10.5, False),  # waiting costs nothing yet
        ((2.0, 2.1), 9.8, True),  # silent past lag_s, waiting no better
        ((4.0, 3.8), 9.5, False),  # it flies on past its targets: waiting brings them closer
    ],
)
def test_the_hold_policy_holds_for_a_silent_uav_when_waiting_would_not_help(errors, heard, held):
    policy = HoldPolicy.for_budget(5.0, 1.5, give_up_s=10.0, max_acceleration=8.0)
    behind = policy.behind(11.0, [state(errors, heard)])
    assert bool(behind) is held
    if held:
        assert "its telemetry lags mission time by" in behind[0][1]
        assert "flying its last setpoint on alone" in behind[0][1]


# ------------------------------------------------------------------ the fast mode
@pytest.fixture(scope="module")
def plan():
    return plan_mission(load_mission(SMALL))


@pytest.mark.parametrize(
    "uav, start, length",
    [
        (1, -0.6, 3.5),  # cut before the start: it stays at A while the formation would go
        (1, 0.4, 3.5),  # cut while it joins at 12 m/s: it carries an accelerating setpoint
        (1, 0.2, 2.5),
        (3, 40.0, 2.5),  # cut in cruise
    ],
)
def test_a_uav_cut_off_stays_within_rho_c(plan, uav, start, length):
    """Before: 7.26 m (cut at -0.6 s), 18.89 m (0.4 s), 13.9 m (0.2 s), 5.35 m (UAV 3 at 40 s):
    the cut UAV braked at 3 m/s^2 from 12 m/s (24 m), and the formation held on a fixed 1 s
    lag, too late for a UAV left standing and too early for one carrying on."""
    run = fly_fast(plan, FastOptions(faults=Faults(link_cuts=((uav, start, start + length),))))
    truth = float(np.nanmax(run.tracking_error_m))
    assert truth < plan.mission.safety_margin - 1.0
    assert run.run_json["holds"], "the formation held for the silent UAV"
    if length < 3.0:  # shorter than the link timeout: flown on to the end
        assert run.run_json["completed"], run.run_json.get("reason")
