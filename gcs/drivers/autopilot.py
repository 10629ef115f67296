"""What the real-autopilot drivers (ArduPilot, PX4) share on top of `Driver`.

* Stream requests: `MAV_CMD_SET_MESSAGE_INTERVAL` for the messages the GCS needs, once the
  first heartbeat arrived (`stream_rates_hz`).
* Mode changes the vehicle makes by itself while the GCS expects guided flight (PX4's
  offboard-loss failsafe, an ArduPilot GCS or battery failsafe) become a `failsafe` event and
  a phase change (`vehicle_mode_phase`), so the runtime sees them at once.

Pacing (back-off after a refusal, waiting for the heartbeat to show a mode, HOME_POSITION
requests) and refusal reasons are the base's (`Driver`, `RetryPolicy`). Nothing blocks; `now`
is the wall clock.
"""

from __future__ import annotations

from typing import ClassVar

from gcs.drivers.base import (
    CommandSpec,
    Driver,
    DriverTiming,
    FlightMode,
    Outcome,
    Phase,
    UavSpec,
    mavlink,
)
from gcs.link import Link

#: Phases in which the vehicle is expected to be in its guided/offboard mode.
GUIDED_PHASES = frozenset({Phase.TAKING_OFF, Phase.FOLLOWING})


class AutopilotDriver(Driver):
    """Common behaviour of the ArduPilot and PX4 drivers (see the module docstring)."""

    #: Message id -> rate (Hz, vehicle time) requested once connected.
    stream_rates_hz: ClassVar[dict[int, float]] = {}

    def __init__(self, spec: UavSpec, link: Link, timing: DriverTiming | None = None) -> None:
        super().__init__(spec, link, timing)
        self.failsafes: list[tuple[float, str]] = []  # (wall time, what happened)

    # ------------------------------------------------------------------ family hooks
    def vehicle_mode_phase(self) -> Phase:
        """The phase to take when the vehicle leaves guided flight by itself."""
        return Phase.LANDING if self.current_mode() == FlightMode.LAND else Phase.HOLDING

    def describe_mode(self) -> str:
        """The vehicle's current mode, for messages."""
        return str(self.telemetry.custom_mode)

    # ------------------------------------------------------------------ Driver hooks
    def on_connected(self, now: float) -> None:
        for message_id, rate in self.stream_rates_hz.items():
            entry = mavlink.mavlink_map.get(message_id)
            name = entry.msgname if entry is not None else str(message_id)
            self.send_command(
                CommandSpec(
                    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                    (message_id, 1e6 / rate, 0, 0, 0, 0, 0),
                    label=f"{name} at {rate:g} Hz",
                    key=("interval", message_id),
                ),
                now,
                lambda outcome, when, what=name: self._on_interval_result(what, outcome, when),
            )

    def on_mode_changed(self, previous: FlightMode | None, now: float) -> None:
        """Leaving guided flight without being asked (no mode goal) is a failsafe."""
        if previous != FlightMode.GUIDED or self.phase not in GUIDED_PHASES:
            return
        if self.mode_goal is not None:
            return  # our own request
        what = f"the vehicle left guided flight by itself: mode {self.describe_mode()}"
        self.failsafes.append((now, what))
        self.emit("failsafe", what, now, mavlink.MAV_SEVERITY_CRITICAL)
        self.set_phase(self.vehicle_mode_phase(), now, "failsafe")

    # ------------------------------------------------------------------ helpers
    def _on_interval_result(self, what: str, outcome: Outcome, now: float) -> None:
        if outcome.refused:
            text = f"stream {what}: {outcome.describe()}"
            self.emit("command", text, now, mavlink.MAV_SEVERITY_WARNING)
