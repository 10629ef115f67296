"""How the formation resumes after a ground-station stall (`gcs.flight.stall`): pure, on a
straight line formation of three UAVs 20 m apart flying at 8 m/s, window 1 s, braking 8 m/s^2.
The candidates and the instant are judged by the worst tracking error they cause."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.flight.stall import PAUSE_FRACTIONS, Resume, resume_point

SPEED, WINDOW, BRAKING = 8.0, 1.0, 8.0
TIMES = np.linspace(10.0, 14.0, 201)  # every 0.02 s


def targets(times: np.ndarray) -> np.ndarray:
    """(T, 3, 2): UAV n's target at x = v t - 20 n, y = 0."""
    x = SPEED * times[:, None] - 20.0 * np.arange(3)[None]
    return np.stack([x, np.zeros_like(x)], axis=-1)


def at_time(t: float, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """The UAVs exactly on their targets of time t, moving along the line at `speed`."""
    positions = targets(np.array([t]))[0]
    velocities = np.tile([speed, 0.0], (3, 1))
    return positions, velocities


def resume(t: float, speed: float) -> Resume:
    positions, velocities = at_time(t, speed)
    return resume_point(TIMES, targets(TIMES), positions, velocities, WINDOW, BRAKING)


def test_uavs_that_stopped_get_a_standing_start_where_they_stand():
    found = resume(11.5, 0.0)
    assert found.at == pytest.approx(11.5)
    assert found.pause_s == WINDOW and found.clock_at == pytest.approx(12.0)
    assert found.worst_error_m == pytest.approx(0.0, abs=1e-9)


def test_uavs_that_flew_on_at_full_speed_are_not_stopped():
    """A stall shorter than the vehicles' setpoint timeout: they still fly the last setpoint.
    A standing reference would make them overshoot by v^2 / 2a = 4 m."""
    found = resume(12.3, SPEED)
    assert found.at == pytest.approx(12.3) and found.pause_s == 0.0
    assert found.worst_error_m == pytest.approx(0.0, abs=1e-6)


def test_uavs_still_braking_are_picked_up_at_their_speed():
    found = resume(12.0, SPEED / 2)
    assert found.pause_s == pytest.approx(WINDOW / 2)
    assert found.at == pytest.approx(12.0)
    assert found.worst_error_m == pytest.approx(0.0, abs=1e-6)


def test_uavs_that_ran_ahead_are_matched_ahead():
    """Times past the stall's end are offered (the caller's lookahead); UAVs ahead of the
    formation are matched there, not pulled back."""
    found = resume(13.7, SPEED)
    assert found.at == pytest.approx(13.7)


def test_uavs_scattered_along_the_line_get_the_least_worst_instant():
    """UAV 1 stopped 2 m behind UAV 0's spacing: no instant matches both; the error is split."""
    positions, velocities = at_time(12.0, 0.0)
    positions[1, 0] -= 2.0
    found = resume_point(TIMES, targets(TIMES), positions, velocities, WINDOW, BRAKING)
    assert found.worst_error_m == pytest.approx(1.0, abs=0.1)
    assert found.pause_s == WINDOW


@settings(max_examples=60, deadline=None)
@given(
    t=st.floats(10.5, 13.5),
    speed=st.floats(0.0, SPEED),
    jitter=st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6),
)
def test_the_chosen_resume_is_no_worse_than_any_candidate_at_any_instant(t, speed, jitter):
    """The result is the minimum over every pause and instant of the predicted worst error
    (computed here independently, one candidate at a time)."""
    positions, velocities = at_time(t, speed)
    positions = positions + np.reshape(jitter, (3, 2))
    found = resume_point(TIMES, targets(TIMES), positions, velocities, WINDOW, BRAKING)
    for fraction in PAUSE_FRACTIONS:
        for k in range(len(TIMES)):
            target = targets(TIMES[k : k + 1])[0]
            reference = np.array([(1 - fraction) * SPEED, 0.0])
            worst = 0.0
            for n in range(3):
                relative = velocities[n] - reference
                offset = positions[n] - target[n]
                settled = offset + relative * np.linalg.norm(relative) / (2 * BRAKING)
                worst = max(worst, np.linalg.norm(offset), np.linalg.norm(settled))
            assert found.worst_error_m <= worst + 1e-6
