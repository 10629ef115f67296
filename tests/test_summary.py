"""The run summary states what the design promises a flown distance, from the run's own
tracking error (the virtual targets keep rho_c and 2 rho_c; a UAV strays from its target)."""

from __future__ import annotations

import io

from rich.console import Console

from gcs.flight.core import RunResult
from gcs.summary import summary_renderable


def _result(tracking_error: float | None) -> RunResult:
    return RunResult(
        completed=True,
        reason=None,
        fleet_size=2,
        duration_s=10.0,
        min_uav_uav_m=13.63,
        min_uav_obstacle_m=4.45,
        max_tracking_error_m=tracking_error,
        tracking_error_m=[tracking_error, tracking_error],
        control_error_m=[None, None],
        landing_error_m=[None, None],
        connected_fraction=1.0,
        speed_changes=[],
        events=[],
        phases=["landed", "landed"],
        smoothing_window_s=1.0,
        smoothing_error_m=2.95,
        noise_m=None,
        setpoints_sent=0,
        setpoint_rate_hz=None,
        setpoint_jitter_p99_ms=None,
        setpoint_period_ms=20.0,
        setpoint_max_gap_ms=None,
        ticks=0,
        interrupted=0,
        fatal=False,
    )


def _text(result: RunResult) -> str:
    out = io.StringIO()
    Console(file=out, width=240, color_system=None).print(summary_renderable(result, "x.mcap", 5.0))
    return out.getvalue()


def test_distances_are_held_against_the_margin_less_the_tracking_error():
    text = _text(_result(2.36))
    assert "4.45 m (at least rho_c - tracking error = 2.64 m by design)" in text
    assert "13.63 m (at least 2 rho_c - 2 x tracking error = 5.28 m by design)" in text


def test_without_a_tracking_error_the_targets_clearance_is_stated():
    text = _text(_result(None))
    assert "4.45 m (targets keep rho_c = 5 m)" in text
    assert "13.63 m (targets keep 2 rho_c = 10 m)" in text
