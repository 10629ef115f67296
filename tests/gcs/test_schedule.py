"""The take-off and landing schedule alone (`gcs.flight.schedule`), on mission time: take-off
a lead before departure, a UAV not up by its departure is late, landing after the formation
has been still at the arrival, on the slot or after the settle time, and a UAV the return
came before stays."""

from __future__ import annotations

import math

import numpy as np

from gcs.flight.schedule import STILL_BEFORE_LANDING_S, Schedule, UavProgress

SCHEDULE = Schedule(takeoff_lead_s=8.0, landing_tolerance_m=1.0, landing_settle_s=20.0)
WINDOW = 2.0


def uav(**changes) -> UavProgress:
    fields = dict(relieved=False, stays=False, not_up=False, following=False,
                  takeoff_sent=False, land_sent=False)  # fmt: skip
    fields.update(changes)
    return UavProgress(**fields)


def decide(
    t, uavs, departures, arrivals=None, offsets=None, lands=True, horizon=None,
    frozen_for=frozenset(),
):  # fmt: skip
    count = len(uavs)
    arrivals = np.full(count, math.inf) if arrivals is None else np.asarray(arrivals, float)
    offsets = np.zeros(count) if offsets is None else np.asarray(offsets, float)
    asked = []

    def offset(index):
        asked.append(index)
        return float(offsets[index])

    decision = SCHEDULE.decide(
        t, uavs, np.asarray(departures, float), arrivals,
        t + 1.0 if horizon is None else horizon, WINDOW, lands, offset, frozen_for,
    )  # fmt: skip
    return decision, asked


def test_each_uav_takes_off_its_lead_before_its_departure_once():
    fleet = [uav(not_up=True), uav(not_up=True), uav(not_up=True, takeoff_sent=True)]
    decision, _ = decide(12.0, fleet, [20.0, 20.5, 10.0])
    assert decision.takeoff == (0,)  # 20 - 8 = 12: now; 12.5 not yet; the third already sent


def test_a_uav_not_up_by_its_departure_is_late():
    fleet = [uav(not_up=True), uav(not_up=False), uav(not_up=True)]
    decision, _ = decide(30.0, fleet, [30.5, 30.5, 40.0], horizon=31.0)
    assert decision.late == (1,)  # UAV 1 (1-based): departs within the horizon, not up


def test_landing_waits_for_the_formation_to_be_still_then_for_the_slot_or_the_settle_time():
    arrival = 100.0
    still = arrival + WINDOW / 2 + STILL_BEFORE_LANDING_S
    fleet = [uav(following=True), uav(following=True)]
    early, asked = decide(still - 0.01, fleet, [0.0, 0.0], [arrival, arrival], [0.2, 5.0])
    assert early.land == () and asked == []  # the slot is not even looked at before
    on_slot, _ = decide(still, fleet, [0.0, 0.0], [arrival, arrival], [0.2, 5.0])
    assert on_slot.land == (0,)  # within 1 m; UAV 2 is 5 m off
    settled, _ = decide(arrival + WINDOW / 2 + 20.0, fleet, [0, 0], [arrival, arrival], [0.2, 5.0])
    assert settled.land == (0, 1)  # the settle time is up: where it is


def test_a_stations_fleet_lands_only_when_it_returns_and_a_uav_the_return_came_before_stays():
    fleet = [uav(following=True), uav(stays=True), uav(stays=True, land_sent=True)]
    held, _ = decide(500.0, fleet, [0.0, 0.0, 0.0], [10.0, 10.0, 10.0], lands=False)
    assert held.land == () and held.stay == (1,)  # the third was told already


def test_a_relieved_uav_flies_its_own_schedule():
    fleet = [uav(relieved=True, not_up=True), uav(not_up=True)]
    decision, _ = decide(50.0, fleet, [50.0, 50.0])
    assert decision.takeoff == (1,) and decision.late == (2,)


def test_a_uav_the_formation_froze_for_stays_late_until_it_is_up():
    """Frozen, the late UAV's departure reads inf (the profile stands still): it is still late,
    so the formation does not resume and freeze again every tick; once up, it is not."""
    frozen = [uav(following=True), uav(not_up=True)]
    decision, _ = decide(40.0, frozen, [0.0, math.inf], frozen_for=frozenset({1}))
    assert decision.late == (2,)
    up = [uav(following=True), uav(following=True, takeoff_sent=True)]
    decision, _ = decide(41.0, up, [0.0, math.inf], frozen_for=frozenset({1}))
    assert decision.late == ()
    unfrozen, _ = decide(40.0, frozen, [0.0, math.inf])
    assert unfrozen.late == ()  # without the freeze, an unreached departure is not late
