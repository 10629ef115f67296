"""The run's summary: the run JSON of docs/outputs.md and the human table (rich).

Run JSON fields (docs/outputs.md), all times in mission seconds:
* `completed`: every UAV landed on its arrival slot, nothing aborted, no safety bound broken;
* `fleet_size`; `duration_s`: from the first take-off to the last landing;
* `min_uav_uav_m`, `min_uav_obstacle_m`: horizontal, over every UAV (parked ones included),
  from the positions the vehicles report;
* `max_tracking_error_m`: max |position - V_n(t)| (the paper's virtual target, not the
  smoothed reference);
* `connected_fraction`: fraction of samples at which every UAV had a multi-hop radio path
  (hops <= radio range) to a base station;
* `speed_changes`: `[{seq, effective_s, speed, source, requested_s, acks: {"<uav>": T_dv}}]`,
  T_dv from the request to that UAV's acknowledgement;
* `log`: the MCAP file.
Extra fields: `reason` (when not completed), `exit_status`, `per_uav` (tracking, control and
landing errors, final phase), `budget` (smoothing window and bound, worst control error,
navigation noise, against rho_c), `setpoints` (sent, achieved rate, p99 period jitter), `events`
(the monitors' errors and warnings), `radio` (when the radio medium ran: `gcs.sim.medium_process`),
`stations` (a stations mission: each point's holder and time on station, when the return
started, the connectivity while everyone held; docs/outputs.md).
"""

from __future__ import annotations

import math
from typing import Any

from rich.console import Group
from rich.table import Table

from gcs.flight.result import RunResult, StationsResult

EXIT_COMPLETED, EXIT_ABORTED = 0, 1


def exit_status(result: RunResult) -> int:
    """0 completed; 1 aborted or a safety bound broken (docs/cli.md)."""
    return EXIT_COMPLETED if result.completed and not result.fatal else EXIT_ABORTED


def run_json(result: RunResult, log_path: str, safety_margin: float) -> dict[str, Any]:
    """The run JSON (strict JSON: no NaN or infinity)."""
    out: dict[str, Any] = {
        "completed": result.completed,
        "fleet_size": result.fleet_size,
        "duration_s": _num(result.duration_s),
        "min_uav_uav_m": _num(result.min_uav_uav_m),
        "min_uav_obstacle_m": _num(result.min_uav_obstacle_m),
        "max_tracking_error_m": _num(result.max_tracking_error_m),
        "connected_fraction": _num(result.connected_fraction),
        "los_connected_fraction": _num(result.los_connected_fraction),
        "speed_changes": result.speed_changes,
        "log": log_path,
        "exit_status": exit_status(result),
        "per_uav": [
            {
                "uav": i + 1,
                "phase": result.phases[i],
                "max_tracking_error_m": _num(result.tracking_error_m[i]),
                "max_control_error_m": _num(result.control_error_m[i]),
                "landing_error_m": _num(result.landing_error_m[i]),
            }
            for i in range(result.fleet_size)
        ],
        "budget": {
            "safety_margin_m": safety_margin,
            "smoothing_window_s": result.smoothing_window_s,
            "smoothing_error_m": _num(result.smoothing_error_m),
            "control_error_m": _num(_max(result.control_error_m)),
            "navigation_noise_m": _num(result.noise_m),
        },
        "setpoints": {
            "sent": result.setpoints_sent,
            "rate_hz": _num(result.setpoint_rate_hz),
            "period_ms": result.setpoint_period_ms,
            "jitter_p99_ms": _num(result.setpoint_jitter_p99_ms),
            "max_gap_ms": _num(result.setpoint_max_gap_ms),
        },
        "stalls": [
            {
                "t": _num(s.stood_at),
                "paused_s": _num(s.paused_at),
                "resumed_s": _num(s.resumed_at),
                "held_back_s": s.held_back_s,
            }
            for s in result.stalls
        ],
        "holds": [hold.to_json() for hold in result.holds],
        "telemetry_shed": result.telemetry_shed,
        "events": [
            {"t": _num(e.t), "level": e.level, "kind": e.kind, "text": e.text, "uav": e.uav}
            for e in result.events
            if e.level in ("error", "warning")
        ],
    }
    if result.radio is not None:  # the radio medium ran (docs/outputs.md)
        out["radio"] = result.radio
    if result.stations is not None:
        out["stations"] = stations_json(result.stations)
    if not result.completed:
        out["reason"] = result.reason or "the mission did not complete"
    return out


def summary_renderable(result: RunResult, log_path: str, safety_margin: float) -> Group:
    """The human summary: outcome, distances, budget per UAV, speed changes, setpoints."""
    status = "completed" if result.completed else f"NOT completed: {result.reason}"
    top = Table(title=f"run: {status}", show_header=False)
    top.add_column("", style="bold")
    top.add_column("")
    top.add_row("fleet", f"{result.fleet_size} UAVs")
    top.add_row("duration", _fmt(result.duration_s, "s", 1) + " (first take-off to last landing)")
    top.add_row(
        "min UAV-UAV",
        _fmt(result.min_uav_uav_m, "m") + _design(result.min_uav_uav_m, 2, result, safety_margin),
    )
    top.add_row(
        "min UAV-obstacle",
        _fmt(result.min_uav_obstacle_m, "m")
        + _design(result.min_uav_obstacle_m, 1, result, safety_margin),
    )
    top.add_row(
        "max tracking error",
        _fmt(result.max_tracking_error_m, "m") + f" (must stay < rho_c = {safety_margin:g} m)",
    )
    connected = result.connected_fraction
    sight = result.los_connected_fraction
    top.add_row(
        "connected",
        "n/a"
        if connected is None
        else f"{100 * connected:.1f} % of samples, {100 * sight:.1f} % by line of sight",
    )
    stations = result.stations
    if stations is not None:
        back, held = stations.return_s, stations.held_connected_fraction
        top.add_row(
            "return home", "not flown" if back is None else f"from mission time {back:.2f} s"
        )
        top.add_row(
            "connected on station",
            "n/a" if held is None else f"{100 * held:.1f} % of samples while everyone held",
        )
    if result.radio is not None:
        top.add_row("radio medium", radio_line(result.radio))
    rate = result.setpoint_rate_hz
    top.add_row(
        "setpoints",
        f"{result.setpoints_sent} sent, "
        + ("n/a" if rate is None else f"{rate:.1f} Hz")
        + " mission-time rate, p99 period jitter "
        + _fmt(result.setpoint_jitter_p99_ms, "ms", 2)
        + f", longest gap {_fmt(result.setpoint_max_gap_ms, 'ms', 1)}"
        + f" (period {result.setpoint_period_ms:.1f} ms wall)",
    )
    top.add_row("log", log_path)

    budget = Table(title="error budget per UAV (m)")
    for name in (
        "UAV",
        "phase",
        "tracking |R-V|",
        "smoothing",
        "control |R-ref|",
        "noise",
        "landing",
    ):
        budget.add_column(name, justify="right")
    for i in range(result.fleet_size):
        budget.add_row(
            str(i + 1),
            result.phases[i],
            _fmt(result.tracking_error_m[i]),
            _fmt(result.smoothing_error_m),
            _fmt(result.control_error_m[i]),
            _fmt(result.noise_m),
            _fmt(result.landing_error_m[i]),
        )
    parts: list[Any] = [top, budget]
    if result.stations is not None:
        parts.append(stations_table(result.stations))

    if result.speed_changes:
        speeds = Table(title="speed changes (T_dv = request -> acknowledgement, mission s)")
        for name in ("seq", "source", "speed", "requested", "effective", "acks", "worst T_dv"):
            speeds.add_column(name, justify="right")
        for change in result.speed_changes:
            acks = change["acks"]
            worst = max(acks.values()) if acks else None
            speeds.add_row(
                str(change["seq"]),
                change["source"],
                f"{change['speed']:g} m/s",
                f"{change['requested_s']:.2f}",
                f"{change['effective_s']:.2f}",
                f"{len(acks)}/{result.fleet_size}",
                _fmt(worst, "s", 3),
            )
        parts.append(speeds)

    bad = [e for e in result.events if e.level in ("error", "warning")]
    if bad:
        events = Table(title="events")
        for name in ("t (s)", "level", "event"):
            events.add_column(name)
        for e in bad[:30]:
            events.add_row(f"{e.t:.2f}", e.level, e.text)
        if len(bad) > 30:
            events.add_row("", "", f"... {len(bad) - 30} more in the log")
        parts.append(events)
    return Group(*parts)


def stations_json(stations: StationsResult) -> dict[str, Any]:
    """The run JSON's `stations` object (docs/outputs.md)."""
    return {
        "points": [
            {"name": p.name, "uav": p.uav, "on_station_s": p.on_station_s} for p in stations.points
        ],
        "return_s": _num(stations.return_s),
        "held_connected_fraction": _num(stations.held_connected_fraction),
        "relieved": [
            {
                "uav": r.uav,
                "source": r.source,
                "asked_s": r.asked_s,
                "landing": list(r.landing),
                "landed_s": _num(r.landed_s),
                "on_station_s": r.on_station_s,
            }
            for r in stations.relieved
        ],
    }


def stations_table(stations: StationsResult) -> Table:
    """The human table of a stations mission: each point, its UAV and time on station."""
    table = Table(title="points held")
    for name in ("point", "UAV", "on station"):
        table.add_column(name, justify="right")
    for point in stations.points:
        table.add_row(point.name, str(point.uav), _fmt(point.on_station_s, "s", 1))
    for relief in stations.relieved:
        landed = "not landed" if relief.landed_s is None else f"landed t={relief.landed_s:.1f} s"
        table.add_row(
            f"relieved ({relief.source}, {landed})",
            str(relief.uav),
            _fmt(relief.on_station_s, "s", 1),
        )
    return table


def radio_line(radio: dict) -> str:
    """One line of the radio medium's figures (connectivity, packets, delay, ground users)."""
    connected = radio.get("connected_fraction")
    packets = radio.get("packets") or {}
    delay = radio.get("delay_ms") or {}
    users = radio.get("ground_users") or {}
    line = (
        ("n/a" if connected is None else f"{100 * connected:.1f} %")
        + f" of samples connected, {packets.get('received', 0)}/{packets.get('sent', 0)} packets"
        + f" delivered, delay mean {_fmt(delay.get('mean'), 'ms')} p95 {_fmt(delay.get('p95'), 'ms')}"
    )
    if users.get("sent"):
        line += f", ground users {users['received']}/{users['sent']} delivered"
    return line


def _num(value: float | None) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def _max(values: list[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return max(known) if known else None


def _design(measured: float | None, uavs: int, result: RunResult, safety_margin: float) -> str:
    """What the design promises a flown distance, or that it promised nothing. The virtual
    targets keep `uavs` x rho_c (rho_c from obstacles, 2 rho_c between two UAVs), and each of
    the `uavs` UAVs involved strays from its target by at most the run's largest tracking error,
    so the distance stays above their difference (docs/design.md 3.4-3.5). Flying a corner at rho_c,
    a UAV is inside the margin by design. The promise assumes every tracking error below rho_c:
    when one reached it, or the `measured` distance is below the promise, the promise did not
    hold, and the line says why and since when."""
    target_m = uavs * safety_margin
    name = "rho_c" if uavs == 1 else f"{uavs} rho_c"
    error = result.max_tracking_error_m
    if error is None:
        return f" (targets keep {name} = {target_m:g} m)"
    floor = target_m - uavs * error
    less = "tracking error" if uavs == 1 else f"{uavs} x tracking error"
    if error >= safety_margin:  # then floor <= 0: no promise
        return ": the guarantee did not hold: " + _tracking_breach(result, safety_margin)
    if measured is not None and measured < floor:
        return f": the guarantee did not hold: below {name} - {less} = {floor:.2f} m, time unknown"
    return f" (at least {name} - {less} = {floor:.2f} m by design)"


def _tracking_breach(result: RunResult, safety_margin: float) -> str:
    """Which UAV's tracking error reached `safety_margin`, its largest, and since when: the
    first fatal tracking event's UAV and mission time; without one, the UAV with the largest
    error, time unknown."""
    breaches = [e for e in result.events if e.kind == "tracking" and e.level == "error"]
    first = min(breaches, key=lambda e: e.t, default=None)
    errors = {i + 1: e for i, e in enumerate(result.tracking_error_m) if e is not None}
    uav = first.uav if first is not None else max(errors, key=errors.get, default=None)
    error = errors.get(uav, result.max_tracking_error_m)
    who = "a UAV's" if uav is None else f"UAV {uav}'s"
    when = (
        f"since t={first.t:.2f} s"
        if first is not None and math.isfinite(first.t)
        else "time of the first breach unknown"
    )
    return (
        f"{who} tracking error reached {error:.2f} m >= safety margin {safety_margin:g} m, {when}"
    )


def _fmt(value: float | None, unit: str = "", digits: int = 2) -> str:
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value:.{digits}f}" + (f" {unit}" if unit else "")
