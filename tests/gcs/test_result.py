"""The result's arithmetic (`gcs.flight.result`), in process: whether a flight completed and
why not, each UAV's landing error, and the setpoint stream as achieved."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.flight.result import completion, landing_errors, setpoint_timing

SLOTS = np.array([[0.0, 0.0], [10.0, 0.0]])


def test_landing_errors_are_horizontal_distances_from_the_slots_none_when_unknown():
    ended = [np.array([3.0, 4.0]), None]
    assert landing_errors(ended, SLOTS) == [5.0, None]


def flight(**changes):
    facts = dict(
        aborting=False,
        started=True,
        all_landed=True,
        all_told_to_land=True,
        landing_error_m=[0.5, 1.0],
        safety_margin=5.0,
    )
    return completion(**(facts | changes))


def test_a_flight_completes_when_every_uav_was_told_to_land_and_landed_on_its_slot():
    assert flight() == (True, None)
    assert flight(landing_error_m=[0.5, 5.0]) == (False, "a UAV landed off its arrival slot")
    assert flight(landing_error_m=[0.5, None]) == (False, "a UAV landed off its arrival slot")
    for fact in ("all_landed", "all_told_to_land", "started"):
        assert flight(**{fact: False}) == (False, "the mission did not complete")
    assert flight(aborting=True) == (False, "the mission did not complete")


def test_the_setpoint_stream_rate_jitter_and_longest_gap():
    walls = [0.0, 0.1, 0.2, 0.35, 0.45]  # one late tick: a 150 ms period
    timing = setpoint_timing(walls, nominal_s=0.1, speedup=2.0)
    assert timing.rate_hz == pytest.approx(1 / (0.45 / 4) / 2.0)
    assert timing.max_gap_ms == pytest.approx(150.0)
    assert 40.0 < timing.jitter_p99_ms <= 50.0
    assert setpoint_timing([0.0, 0.1], 0.1, 1.0).rate_hz is None  # under 3 ticks
