"""The relief policy (`gcs.flight.relief`), in process: why a UAV cannot be relieved now (in
the order the operator is told), which UAV its battery sends home, and when the relieved UAV
lands."""

from __future__ import annotations

import pytest

from gcs.flight.relief import BatteryWatch, ReliefState, lands_now, refusal

READY = ReliefState(
    size=4,
    landing=None,
    returning=False,
    relieved=frozenset(),
    active=None,
    holding=True,
    frozen_by=None,
)


@pytest.mark.parametrize(
    "uav, changes, why",
    [
        (2, {}, None),
        (5, {}, "there is no UAV 5 (the fleet has UAVs 1 to 4)"),
        (None, {}, "there is no UAV None (the fleet has UAVs 1 to 4)"),
        (2, {"landing": "UAV 3 lost"}, "the fleet is landing (UAV 3 lost)"),
        (2, {"returning": True}, "the fleet is returning home already"),
        (2, {"relieved": frozenset({1})}, "UAV 2 was relieved already"),
        (2, {"active": (0, 42.0)}, "UAV 1 is being relieved (home at about t=42.00 s)"),
        (2, {"holding": False}, "wait until every UAV holds its station"),
        (2, {"frozen_by": "link"}, "the formation is frozen (link)"),
        (2, {"unavailable": {2: "link lost"}}, "UAV 3 is not flying the formation (link lost)"),
        # several reasons: the first in that order is given
        (2, {"holding": False, "frozen_by": "link"}, "wait until every UAV holds its station"),
    ],
)
def test_why_a_uav_cannot_be_relieved_now(uav, changes, why):
    state = ReliefState(**{**READY.__dict__, **changes})
    said = refusal(uav, state)
    assert (said is None) if why is None else (said is not None and why in said)


def test_the_battery_sends_home_each_uav_below_the_threshold_once():
    watch = BatteryWatch(threshold_pct=30.0)
    levels = [80.0, 25.0, None, 20.0]
    assert watch.due(levels, frozenset()) == 1
    assert watch.due(levels, frozenset()) == 3  # UAV 2 acted on (relieved or refused) once
    assert watch.due(levels, frozenset()) is None
    assert BatteryWatch(threshold_pct=None).due(levels, frozenset()) is None
    assert BatteryWatch(threshold_pct=30.0).due(levels, frozenset({1, 3})) is None


def test_the_relieved_uav_lands_above_its_slot_or_after_the_settle_time():
    assert not lands_now(9.9, 10.0, 0.1, tolerance_m=0.5, settle_s=5.0)  # not home yet
    assert lands_now(10.0, 10.0, 0.4, tolerance_m=0.5, settle_s=5.0)
    assert not lands_now(14.9, 10.0, 2.0, tolerance_m=0.5, settle_s=5.0)
    assert lands_now(15.0, 10.0, 2.0, tolerance_m=0.5, settle_s=5.0)
