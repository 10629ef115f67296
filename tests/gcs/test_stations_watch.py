"""Time on station (`gcs.flight.stations.StationWatch`), on simulated time: a UAV counts the
seconds its target holds its station and its reported position is within rho_c of it; the fleet
holds from S_out until the first UAV leaves for home (2 M - S_out); the first tick every UAV is
on station is said once; connectivity is tallied while the fleet holds."""

from __future__ import annotations

import math

import numpy as np

from gcs.flight.stations import StationWatch

SLOTS = np.array([[0.0, 0.0], [100.0, 0.0]])
OUTBOUND = 500.0


def tick(watch, t, positions, distance=OUTBOUND, return_distance=None, connected=True):
    return watch.update(
        t, SLOTS, SLOTS.copy(), np.array(positions), distance, OUTBOUND, return_distance, connected
    )


def test_time_on_station_counts_targets_held_and_uavs_within_rho_c():
    watch = StationWatch(2, safety_margin=5.0)
    assert tick(watch, 10.0, [[0.0, 1.0], [100.0, 4.9]]) is True  # first tick: reached
    assert tick(watch, 10.5, [[0.0, 1.0], [100.0, 6.0]]) is False  # UAV 2 out of rho_c
    assert tick(watch, 11.0, [[0.0, 1.0], [math.nan, math.nan]]) is False  # UAV 2 unheard
    assert watch.on_station_s.tolist() == [1.0, 0.0]
    assert watch.holding and watch.reached


def test_the_fleet_holds_from_s_out_until_the_first_uav_leaves_for_home():
    watch = StationWatch(2, safety_margin=5.0)
    near = [[0.0, 0.0], [100.0, 0.0]]
    assert tick(watch, 0.0, near, distance=OUTBOUND - 10.0) is False
    assert not watch.holding and watch.held_connected_fraction is None
    assert tick(watch, 1.0, near, connected=True) is True
    tick(watch, 2.0, near, connected=False)
    tick(watch, 2.5, near, connected=None)  # no sample this tick: not tallied
    # the return asked at M = 520: the first UAV leaves at 2 M - S_out = 540
    tick(watch, 3.0, near, distance=539.0, return_distance=520.0, connected=True)
    assert watch.holding and watch.held_connected_fraction == 2 / 3
    tick(watch, 4.0, near, distance=541.0, return_distance=520.0, connected=False)
    assert not watch.holding and watch.held_connected_fraction == 2 / 3
