"""What the real-autopilot drivers (ArduPilot, PX4) share on top of `Driver`.

* Stream requests: `MAV_CMD_SET_MESSAGE_INTERVAL` for the messages the GCS needs, once the
  first heartbeat arrived (`stream_rates_hz`).
* A back-off after a refusal: a refused mode change or arming is tried again after
  `refusal_backoff_s` (vehicle time), never at the scheduler's tick rate; heartbeats and
  retransmissions go on meanwhile. The refusal is reported with the vehicle's reason, the
  STATUSTEXT that may arrive just before or just after the refusing ACK.
* An arming gate (`arm_allowed`): the family says when an ARM command can succeed (PX4: its
  pre-arm bit, which needs the setpoint stream in OFFBOARD).
* Mode changes the vehicle makes by itself while the GCS expects guided flight (PX4's
  offboard-loss failsafe, an ArduPilot GCS or battery failsafe) become a `failsafe` event and
  a phase change (`vehicle_mode_phase`), so the runtime sees them at once.

Nothing blocks; `now` is the wall clock, delays go through `DriverTiming.wall`.
"""

from __future__ import annotations

import math
from typing import ClassVar

from gcs.drivers.base import (
    CommandSpec,
    Driver,
    DriverTiming,
    FlightMode,
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
    #: Vehicle-time seconds to wait after a refused mode change or arming.
    refusal_backoff_s: ClassVar[float] = 1.0
    #: Vehicle-time seconds to wait after a refusing ACK for the STATUSTEXT that explains it.
    refusal_text_grace_s: ClassVar[float] = 0.2
    #: Vehicle-time seconds an accepted mode change may take to show in the heartbeat.
    mode_confirm_s: ClassVar[float] = 1.5
    #: Vehicle-time seconds between HOME_POSITION requests while the home is unknown.
    home_request_period_s: ClassVar[float] = 2.0

    def __init__(self, spec: UavSpec, link: Link, timing: DriverTiming | None = None) -> None:
        super().__init__(spec, link, timing)
        self.failsafes: list[tuple[float, str]] = []  # (wall time, what happened)
        self._backoff_until = -math.inf
        self._guided_confirmed = False  # a heartbeat showed GUIDED since our last mode request
        self._refusals: list[tuple[float, float, str, int | None]] = []  # (due, ack, what, result)
        self._home_asked: float | None = None  # last time a HOME_POSITION request was pending
        self._mode_confirm_until = -math.inf

    # ------------------------------------------------------------------ family hooks
    def arm_allowed(self, now: float) -> bool:
        """Whether an ARM command can be sent now (the mode is already guided/offboard)."""
        return True

    def vehicle_mode_phase(self) -> Phase:
        """The phase to take when the vehicle leaves guided flight by itself."""
        return Phase.LANDING if self.current_mode() == FlightMode.LAND else Phase.HOLDING

    def describe_mode(self) -> str:
        """The vehicle's current mode, for messages."""
        return str(self.telemetry.custom_mode)

    # ------------------------------------------------------------------ Driver overrides
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
                lambda result, when, what=name: self._on_interval_result(what, result, when),
            )

    def on_message(self, msg, now: float) -> None:
        super().on_message(msg, now)
        if msg.get_type() == "HEARTBEAT" and self.telemetry.heartbeat_time == now:
            self._watch_mode(now)

    def step(self, now: float) -> None:
        self._flush_refusals(now)
        if self._arming_waits(now) or self._home_request_waits(now):
            self._keep_alive(now)
            return
        super().step(now)
        if "home" in self._pending:
            self._home_asked = now

    def _request_mode(self, mode: FlightMode, now: float) -> None:
        self._guided_confirmed = False
        super()._request_mode(mode, now)

    def _on_mode_result(self, mode: FlightMode, result: int | None, now: float) -> None:
        if result in (mavlink.MAV_RESULT_ACCEPTED, None):
            super()._on_mode_result(mode, result, now)
            # The heartbeat shows the new mode up to a period later (PX4): do not ask again
            # before it had a chance to.
            self._mode_confirm_until = now + self.timing.wall(self.mode_confirm_s)
            return
        self._back_off(now)
        self._report_refusal(f"mode {mode.value} refused", result, now)

    def _on_arm_result(self, result: int | None, now: float) -> None:
        if result == mavlink.MAV_RESULT_ACCEPTED:
            return
        self._arm_requested = False  # arm again once the back-off is over
        self._back_off(now)
        self._report_refusal("arming refused", result, now)

    # ------------------------------------------------------------------ helpers
    def _report_refusal(self, what: str, result: int | None, now: float) -> None:
        """Report a refusal with the vehicle's reason, which may come just after the ACK
        (ArduPilot's `No such mode`, PX4's `Arming denied: ...`): wait `refusal_text_grace_s`."""
        due = now + self.timing.wall(self.refusal_text_grace_s, floor=0.1)
        self._refusals.append((due, now, what, result))

    def _flush_refusals(self, now: float) -> None:
        while self._refusals and self._refusals[0][0] <= now:
            _, acked, what, result = self._refusals.pop(0)
            since = acked - self.timing.wall(2.0)
            texts = [(w, sev, t) for w, sev, t in self.statustexts if w >= since]
            urgent = [t for _, sev, t in texts if sev <= mavlink.MAV_SEVERITY_WARNING]
            if urgent or texts:
                reason = (urgent or [t for _, _, t in texts])[-1]
            else:
                entry = mavlink.enums["MAV_RESULT"].get(result)
                reason = entry.name if entry else str(result)
            self.emit("command", f"{what}: {reason}", now, mavlink.MAV_SEVERITY_WARNING)

    def _back_off(self, now: float) -> None:
        self._backoff_until = now + self.timing.wall(self.refusal_backoff_s)

    def _arming_waits(self, now: float) -> bool:
        """While arming: wait out a back-off, or the family's gate before sending ARM. The
        arming timeout still applies (the base step reports it)."""
        if self.phase != Phase.ARMING or self.telemetry.armed:
            return False
        if now - self.phase_since > self.timing.wall(self.arming_timeout_s):
            return False
        if now < self._backoff_until:
            return True
        if self.current_mode() != FlightMode.GUIDED:
            return now < self._mode_confirm_until and "mode" not in self._pending
        return not self.arm_allowed(now)

    def _home_request_waits(self, now: float) -> bool:
        """Pace HOME_POSITION requests: an autopilot without a home yet acknowledges the
        request and sends nothing (ArduPilot before its EKF origin); ask again every 2 s, not
        at every step."""
        if self.phase != Phase.INITIALISING or self.telemetry.home_enu is not None:
            return False
        if "home" in self._pending or self._home_asked is None:
            return False
        return now - self._home_asked < self.timing.wall(self.home_request_period_s)

    def _keep_alive(self, now: float) -> None:
        """The part of `Driver.step` that must go on while the sequence waits."""
        period = self.timing.wall(self.heartbeat_period_s, floor=0.02)
        if self._last_heartbeat_sent is None or now - self._last_heartbeat_sent >= period:
            self._send_heartbeat(now)
        self._retransmit(now)

    def _watch_mode(self, now: float) -> None:
        mode = self.current_mode()
        if mode == FlightMode.GUIDED:
            self._guided_confirmed = True
            return
        if self.phase not in GUIDED_PHASES or not self._guided_confirmed:
            return
        if "mode" in self._pending:
            return
        what = f"the vehicle left guided flight by itself: mode {self.describe_mode()}"
        self.failsafes.append((now, what))
        self.emit("failsafe", what, now, mavlink.MAV_SEVERITY_CRITICAL)
        self._guided_confirmed = False
        self._set_phase(self.vehicle_mode_phase(), now, "failsafe")

    def _on_interval_result(self, what: str, result: int | None, now: float) -> None:
        if result != mavlink.MAV_RESULT_ACCEPTED:
            reason = "no answer" if result is None else mavlink.enums["MAV_RESULT"][result].name
            self.emit("command", f"stream {what}: {reason}", now, mavlink.MAV_SEVERITY_WARNING)
