"""The run summary states what the design promises a flown distance, from the run's own
tracking error (the virtual targets keep rho_c and 2 rho_c; a UAV strays from its target), and
no promise once a tracking error reached rho_c: which UAV's, since when."""

from __future__ import annotations

import dataclasses
import io
import re

from rich.console import Console

from gcs.flight.result import RunResult
from gcs.monitors import MonitorEvent
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
        los_connected_fraction=0.5,
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


def _rows(text: str) -> dict[str, str]:
    """The top table's rows: label -> value."""
    cells = (line.split("│") for line in text.splitlines())
    return {c[1].strip(): c[2].strip() for c in cells if len(c) == 4 and c[1].strip()}


def _breach(errors: list[float], events: list[MonitorEvent]) -> RunResult:
    return dataclasses.replace(
        _result(max(errors)),
        completed=False,
        reason="UAV 2: tracking error 5.02 m >= safety margin 5 m (the guarantees no longer hold)",
        min_uav_obstacle_m=3.1,
        tracking_error_m=errors,
        events=events,
        fatal=True,
    )


def _tracking_event(t: float, uav: int, error: float) -> MonitorEvent:
    text = f"UAV {uav}: tracking error {error:.2f} m >= safety margin 5 m (the guarantees no longer hold)"
    return MonitorEvent(t, "error", "tracking", text, uav, fatal=True)


def test_within_budget_every_line_is_what_it_always_was():
    near = MonitorEvent(3.0, "warning", "near_obstacle", "UAV 1: 4.45 m from an obstacle", 1)
    text = _text(dataclasses.replace(_result(2.36), events=[near]))
    assert _rows(text) == {
        "fleet": "2 UAVs",
        "duration": "10.0 s (first take-off to last landing)",
        "min UAV-UAV": "13.63 m (at least 2 rho_c - 2 x tracking error = 5.28 m by design)",
        "min UAV-obstacle": "4.45 m (at least rho_c - tracking error = 2.64 m by design)",
        "max tracking error": "2.36 m (must stay < rho_c = 5 m)",
        "connected": "100.0 % of samples, 50.0 % by line of sight",
        "setpoints": "0 sent, n/a mission-time rate, p99 period jitter n/a, longest gap n/a"
        " (period 20.0 ms wall)",
        "log": "x.mcap",
    }


def test_a_tracking_error_at_rho_c_voids_the_bound_and_says_whose_and_since_when():
    events = [_tracking_event(52.0, 1, 5.01), _tracking_event(41.3, 2, 5.02)]
    rows = _rows(_text(_breach([5.01, 5.1], events)))
    breach = (
        ": the guarantee did not hold: UAV 2's tracking error reached 5.10 m >= safety margin"
        " 5 m, since t=41.30 s"
    )
    assert rows["min UAV-obstacle"] == "3.10 m" + breach
    assert rows["min UAV-UAV"] == "13.63 m" + breach
    text = _text(_breach([5.01, 5.1], events))
    assert "by design" not in text
    assert not re.search(r"= -\d", text)


def test_a_tracking_error_exactly_at_rho_c_is_a_breach():
    rows = _rows(_text(_breach([5.0, 1.0], [_tracking_event(7.5, 1, 5.0)])))
    assert rows["min UAV-obstacle"] == (
        "3.10 m: the guarantee did not hold: UAV 1's tracking error reached 5.00 m >= safety"
        " margin 5 m, since t=7.50 s"
    )


def test_without_a_tracking_event_the_time_of_the_breach_is_unknown():
    rows = _rows(_text(_breach([1.0, 56.03 + 5], [])))
    assert rows["min UAV-obstacle"] == (
        "3.10 m: the guarantee did not hold: UAV 2's tracking error reached 61.03 m >= safety"
        " margin 5 m, time of the first breach unknown"
    )


def test_a_distance_below_the_bound_is_not_called_a_bound_by_design():
    result = dataclasses.replace(_result(2.36), min_uav_obstacle_m=2.0)
    rows = _rows(_text(result))
    assert rows["min UAV-obstacle"] == (
        "2.00 m: the guarantee did not hold: below rho_c - tracking error = 2.64 m, time unknown"
    )
    assert rows["min UAV-UAV"].endswith("= 5.28 m by design)")
