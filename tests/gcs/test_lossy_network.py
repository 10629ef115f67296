"""A lossy network between the ground station and its fleet, in the fast mode on simulated time:
every packet each way lost with probability 30 % (seeded), as the proxy of the live fault test
(`tests/flights/test_faults_e2e.py`) loses them. Over 40 seeds the worst tracking error is 4.46 m
(BENCHMARKS.md, "Faults"); before the fixes below, 4 of 12 seeds broke rho_c.

Faults of the ground station that showed only there (fast mode, `examples/small.yaml`); the
first two fail these tests without their fix:

* SIM_STATE carries no time: it took the vehicle time of the last timed message, which the
  loss may have taken several ticks earlier. The ground station measured 5.36 m of tracking
  error where the truth was 0.34 m, held the formation for nothing, and the restart broke
  rho_c for real (6.63 m; 30 % loss, seed 9).
* A UAV that lost the setpoints of the formation's start lagged a target already at 4 m/s: a
  hold decided on the error alone (3.9 m) came too late, it peaked at 5.13 m (30 %, seed 12).
  The hold now looks at the error's growth (`gcs.flight.hold`).
* A UAV told to land at its arrival slot whose LAND request was lost carried on the last
  setpoint it had heard, a braking one, and flew back along the path: 10.28 m (40 %, seed 13).
  The ground station stopped the stream when it asked; it now streams until a heartbeat shows
  LAND (`gcs.drivers.base.Driver.wants_setpoints`, tested in `tests/gcs/test_drivers_sim.py`).
  With 40 % loss the same reversal still happens mid-path, at the end of a hold's braking
  (seed 4): 6 of 20 seeds break rho_c, worst 7.78 m, a known limit (BENCHMARKS.md, "Faults").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gcs.mission import load_mission
from gcs.planning import plan_mission
from gcs.sim.fastsim import FastOptions, Faults, fly_fast

SMALL = Path(__file__).resolve().parents[2] / "examples" / "small.yaml"


@pytest.fixture(scope="module")
def plan():
    return plan_mission(load_mission(SMALL))


@pytest.mark.parametrize("seed", [9, 12])
def test_a_lossy_network_is_measured_as_it_is_and_flown_within_rho_c(plan, seed):
    run = fly_fast(plan, FastOptions(faults=Faults(link_loss=0.3, link_loss_seed=seed)))
    result = run.run_json
    truth = float(np.nanmax(run.tracking_error_m))
    assert result["completed"], (result.get("reason"), result["holds"])
    assert truth < plan.mission.safety_margin
    # what the ground station measured is what happened: never an error that was not there;
    # its samples (0.1 s apart, 30-40 % of them lost) may miss the very peak
    measured = result["max_tracking_error_m"]
    assert truth - 0.5 <= measured <= truth + 0.2
    assert all(hold["outcome"] == "resumed" for hold in result["holds"])
