"""PX4 multicopter driver (as recorded from PX4 SITL SIH, `tests/sitl/README.md`).

* PX4 streams its telemetry on its offboard/API link (instance i sends towards UDP 14540+i);
  the driver only raises GLOBAL_POSITION_INT to 10 Hz.
* OFFBOARD needs a setpoint stream first: the runtime streams (this family
  `needs_setpoint_stream_before_offboard`), the driver selects OFFBOARD once the stream is
  established and arms when the SYS_STATUS pre-arm bit is set (PX4 sets it in health only; in
  OFFBOARD it means "offboard signal present"). While disarmed PX4 accepts OFFBOARD without a
  stream and refuses at arming (`Arming denied: Resolve system health failures first`), so the
  driver never relies on the mode ack alone.
* Every MAV_CMD_DO_SET_MODE is answered twice: the first ACCEPTED, the second the verdict; the
  mode shows in the next heartbeat (about 1 Hz), so a mode request is confirmed only then
  (`retry_policy.confirm_s`) and never repeated meanwhile.
* The stream must stay above 2 Hz: after COM_OF_LOSS_T (1 s) without a setpoint PX4 falls back
  to position control (POSCTL, system status CRITICAL); the driver reports it as a `failsafe`
  event and goes to HOLDING. Back in FOLLOWING (the runtime's `resume`), it asks for OFFBOARD
  at once, and after a refusal (PX4 refuses OFFBOARD while armed without a stream: `Switching
  to Offboard is currently not available`) again once the back-off is over and the stream
  flows.
* Take-off is by the stream (OFFBOARD climbs to the setpoint altitude), landing with
  MAV_CMD_NAV_LAND (AUTO.LAND); PX4 stays armed after `Landing detected` until it is
  disarmed, so the driver disarms once landed.
* PX4's home carries a metre or two of GPS noise: the home check tolerates 3 m.
* PX4's EVENT messages (id 410) are not in pymavlink's dialect: the link counts them as bad data
  and the STATUSTEXT that accompanies each one carries the text, just after the refusing ACK
  (in chunks of 50 characters sharing an id), or up to 1.5 s later while PX4's logger is not
  running yet (P2 1.42): then the refusal is reported with its MAV_RESULT.
"""

from __future__ import annotations

import math
from typing import ClassVar

from fleetwire.modes import PX4_MODE, PX4_MODE_PARTS, px4_custom_mode
from gcs.drivers.base import CommandSpec, Driver, FlightMode, Phase, RetryPolicy, mavlink
from gcs.drivers.limits import PX4 as PX4_LIMITS
from gcs.drivers.parameters import Encoding

#: HEARTBEAT custom_mode of the PX4 modes the driver meets (pymavlink's `px4_map`).
OFFBOARD, AUTO_LOITER, AUTO_LAND, AUTO_RTL, AUTO_TAKEOFF, POSCTL = (
    PX4_MODE[name] for name in ("OFFBOARD", "LOITER", "LAND", "RTL", "TAKEOFF", "POSCTL")
)
#: Logical mode -> (main mode, sub-mode) for MAV_CMD_DO_SET_MODE params 2 and 3.
PX4_MODES = {
    FlightMode.GUIDED: PX4_MODE_PARTS["OFFBOARD"],
    FlightMode.HOLD: PX4_MODE_PARTS["LOITER"],
    FlightMode.LAND: PX4_MODE_PARTS["LAND"],
}
_MODE_OF_CUSTOM = {px4_custom_mode(*pair): mode for mode, pair in PX4_MODES.items()}
_MODE_NAMES = {OFFBOARD: "OFFBOARD", AUTO_LOITER: "AUTO.LOITER", AUTO_LAND: "AUTO.LAND",
               AUTO_RTL: "AUTO.RTL", POSCTL: "POSCTL", AUTO_TAKEOFF: "AUTO.TAKEOFF"}  # fmt: skip


class PX4Driver(Driver):
    """Driver of one PX4 multicopter (SITL or real) over its offboard MAVLink link."""

    family = "px4"
    connect_timeout_s = 30.0
    initialise_timeout_s = 60.0
    arming_timeout_s = 20.0
    takeoff_timeout_s = 90.0
    #: The heartbeat comes every 1.018 s (P1) and shows a new mode at the next one; the
    #: refusal texts follow the refusing ACK within the same millisecond (P1 7.76, P2 29.92).
    retry_policy = RetryPolicy(confirm_s=2.5, reason_before_s=0.1, reason_after_s=0.3)
    #: Offboard tracking is bounded by MPC_XY_VEL_MAX and MPC_ACC_HOR_MAX; PX4 copies integer
    #: parameters bytewise into PARAM_VALUE's float (P1: CAL_BARO0_ID arrives as 9.3e-39).
    limit_parameters = PX4_LIMITS
    parameter_encoding = Encoding.BYTEWISE
    #: Without the pre-arm bit, ARM anyway after this long in OFFBOARD to learn why not.
    arm_without_prearm_after_s: ClassVar[float] = 5.0

    stream_rates_hz: ClassVar[dict[int, float]] = {
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
    }

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.prearm: bool | None = None  # SYS_STATUS health pre-arm bit (PX4: health only)

    # ------------------------------------------------------------------ family hooks
    def mode_command(self, mode: FlightMode) -> CommandSpec:
        main, sub = PX4_MODES[mode]
        return CommandSpec(
            mavlink.MAV_CMD_DO_SET_MODE,
            (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub, 0, 0, 0, 0),
            label=f"mode {_MODE_NAMES[px4_custom_mode(main, sub)]}",
            acks_needed=2,
        )

    def current_mode(self) -> FlightMode | None:
        return _MODE_OF_CUSTOM.get(self.telemetry.custom_mode)

    def takeoff_command(self, relative_altitude: float) -> CommandSpec | None:
        return None  # OFFBOARD climbs to the streamed setpoint

    def landing_command(self) -> CommandSpec:
        nan = math.nan
        return CommandSpec(
            mavlink.MAV_CMD_NAV_LAND, (0, 0, 0, nan, nan, nan, nan), label="land here"
        )

    def position_ready(self) -> bool:
        # In OFFBOARD the pre-arm bit says whether setpoints arrive: not a position matter.
        armable = self.prearm or self.telemetry.custom_mode == OFFBOARD
        return super().position_ready() and bool(armable)

    def arm_allowed(self, now: float) -> bool:
        if self.prearm:
            return True
        # In OFFBOARD (shown) since the later of arming's start and the mode change.
        since = max(self.phase_since, self.mode_since or self.phase_since)
        return now - since > self.timing.wall(self.arm_without_prearm_after_s)

    def vehicle_mode_phase(self) -> Phase:
        if self.telemetry.custom_mode in (AUTO_LAND, AUTO_RTL):
            return Phase.LANDING
        return Phase.HOLDING

    def describe_mode(self) -> str:
        custom = self.telemetry.custom_mode
        name = _MODE_NAMES.get(custom, f"0x{custom or 0:08X}")
        if custom == POSCTL and self.telemetry.system_status == mavlink.MAV_STATE_CRITICAL:
            return f"{name} (offboard-loss failsafe)"
        return name

    # ------------------------------------------------------------------ capabilities
    @property
    def needs_setpoint_stream_before_offboard(self) -> bool:
        return True

    @property
    def home_tolerance_m(self) -> float:
        return 3.0  # PX4's home carries a metre or two of GPS noise

    # ------------------------------------------------------------------ Driver hooks
    def on_message(self, msg, now: float) -> None:
        if msg.get_type() == "SYS_STATUS":
            self.prearm = bool(
                msg.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
            )
        super().on_message(msg, now)

    def _step_landed(self, now: float) -> None:
        """PX4 stays armed after `Landing detected`: disarm (again after a refusal, paced)."""
        if self.telemetry.armed and self.may_send("disarm", now):
            self.send_command(
                CommandSpec(
                    mavlink.MAV_CMD_COMPONENT_ARM_DISARM,
                    (0, 0, 0, 0, 0, 0, 0),
                    label="disarm",
                    key="disarm",
                ),
                now,
                confirm=lambda: not self.telemetry.armed,
            )
