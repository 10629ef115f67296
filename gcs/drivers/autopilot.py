"""What the real-autopilot drivers (ArduPilot, PX4) share on top of `Driver`.

* Stream requests: `MAV_CMD_SET_MESSAGE_INTERVAL` for the messages the GCS needs, once the
  first heartbeat arrived (`stream_rates_hz`).
* Mode changes the vehicle makes by itself (`Driver.on_mode_changed`): PX4's offboard-loss
  failsafe, an ArduPilot GCS or battery failsafe; the families say which phase a mode means
  (`vehicle_mode_phase`) and how to name it (`describe_mode`).

Pacing (back-off after a refusal, waiting for the heartbeat to show a mode, HOME_POSITION
requests) and refusal reasons are the base's (`Driver`, `RetryPolicy`). Nothing blocks; `now`
is the wall clock.
"""

from __future__ import annotations

from typing import ClassVar

from gcs.drivers.base import (
    CommandSpec,
    Driver,
    Outcome,
    mavlink,
)


class AutopilotDriver(Driver):
    """Common behaviour of the ArduPilot and PX4 drivers (see the module docstring)."""

    #: Message id -> rate (Hz, vehicle time) requested once connected.
    stream_rates_hz: ClassVar[dict[int, float]] = {}

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

    # ------------------------------------------------------------------ helpers
    def _on_interval_result(self, what: str, outcome: Outcome, now: float) -> None:
        if outcome.refused:
            text = f"stream {what}: {outcome.describe()}"
            self.emit("command", text, now, mavlink.MAV_SEVERITY_WARNING)
