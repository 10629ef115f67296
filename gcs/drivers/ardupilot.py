"""ArduPilot Copter driver (as recorded from ArduCopter 4.7 SITL, `tests/sitl/README.md`).

* Connecting: ArduPilot streams almost nothing on a fresh link, so the driver asks with
  `MAV_CMD_SET_MESSAGE_INTERVAL` for GLOBAL_POSITION_INT, SYS_STATUS, GPS_RAW_INT,
  EKF_STATUS_REPORT, EXTENDED_SYS_STATE and HOME_POSITION.
* A usable position (about 40 s after boot in SITL): a 3-D GPS fix, EKF_STATUS_REPORT with an
  absolute horizontal position and not in constant-position mode (`EKF3 IMU0 is using GPS`),
  the SYS_STATUS pre-arm bit, and a home. Before that, arming in GUIDED fails with
  `Arm: Need Position Estimate`, so the driver does not try.
* GUIDED, HOLD (BRAKE) and LAND through `MAV_CMD_DO_SET_MODE` (acknowledged; the SET_MODE
  message never is), ARM, `MAV_CMD_NAV_TAKEOFF` to the altitude above home, then
  SET_POSITION_TARGET_GLOBAL_INT in frame 6 with type_mask 3520 (position + velocity). Position
  targets never time out in GUIDED (GUID_TIMEOUT applies to velocity/acceleration targets
  only): if the GCS stops, the copter hovers at the last target, so the runtime's monitors are
  what notice. Landing is LAND mode, and ArduPilot disarms by itself after touch-down.
* Refusals (`Arm: Need Position Estimate`, `No such mode 17`) are reported with that text and
  tried again after a growing back-off; an INFO text near the ACK (`Arming motors`) never
  counts as the reason.
* A mode change the copter makes by itself (GCS/battery failsafe: RTL, LAND, ...) during
  guided flight is reported as a `failsafe` event.
"""

from __future__ import annotations

from typing import ClassVar

from fleetwire.modes import COPTER_MODE, COPTER_MODE_NAME
from gcs.drivers.base import CommandSpec, Driver, FlightMode, Phase, RetryPolicy, mavlink

#: Copter mode numbers (HEARTBEAT custom_mode) the driver uses (pymavlink's).
GUIDED, RTL, LAND, BRAKE, SMART_RTL = (
    COPTER_MODE[name] for name in ("GUIDED", "RTL", "LAND", "BRAKE", "SMART_RTL")
)
COPTER_MODES = {FlightMode.GUIDED: GUIDED, FlightMode.HOLD: BRAKE, FlightMode.LAND: LAND}
_MODE_OF_NUMBER = {number: mode for mode, number in COPTER_MODES.items()}
#: Modes that end on the ground by themselves.
_LANDING_MODES = frozenset({LAND, RTL, SMART_RTL})

#: EKF_STATUS_REPORT flags (EKF_STATUS_FLAGS).
EKF_POS_HORIZ_ABS = mavlink.EKF_POS_HORIZ_ABS
EKF_CONST_POS_MODE = mavlink.EKF_CONST_POS_MODE
#: GPS_RAW_INT fix_type of a 3-D fix.
GPS_FIX_3D = mavlink.GPS_FIX_TYPE_3D_FIX


class ArduPilotDriver(Driver):
    """Driver of one ArduCopter (SITL or real) over MAVLink."""

    family = "ardupilot"
    connect_timeout_s = 30.0
    connect_wall_floor_s = 15.0
    #: SITL needs ~42 s from boot to a position estimate (A1: EKF uses GPS at +40.6 s).
    initialise_timeout_s = 120.0
    arming_timeout_s = 20.0
    takeoff_timeout_s = 120.0
    #: A mode change shows in a HEARTBEAT sent at once, an accepted ARM in the next one (A1:
    #: 42.61 -> 42.94); the `Arm: ...` / `No such mode` text comes within 1 ms of the refusing
    #: ACK, before it on the recorded link. HOME_POSITION is acknowledged but not sent before
    #: the EKF origin (+19 s from boot).
    retry_policy = RetryPolicy(confirm_s=2.0, reason_before_s=0.1, reason_after_s=0.3)

    stream_rates_hz: ClassVar[dict[int, float]] = {
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
        mavlink.MAVLINK_MSG_ID_SYS_STATUS: 2.0,
        mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: 2.0,
        mavlink.MAVLINK_MSG_ID_EKF_STATUS_REPORT: 2.0,
        mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 2.0,
        mavlink.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    }

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.ekf_flags: int | None = None
        self.gps_fix_type: int | None = None

    # ------------------------------------------------------------------ family hooks
    def mode_command(self, mode: FlightMode) -> CommandSpec:
        return CommandSpec(
            mavlink.MAV_CMD_DO_SET_MODE,
            (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, COPTER_MODES[mode], 0, 0, 0, 0, 0),
            label=f"mode {COPTER_MODE_NAME[COPTER_MODES[mode]]}",
        )

    def current_mode(self) -> FlightMode | None:
        return _MODE_OF_NUMBER.get(self.telemetry.custom_mode)

    def takeoff_command(self, relative_altitude: float) -> CommandSpec | None:
        return CommandSpec(
            mavlink.MAV_CMD_NAV_TAKEOFF,
            (0, 0, 0, 0, 0, 0, float(relative_altitude)),
            label=f"takeoff to {relative_altitude:.1f} m",
        )

    def position_ready(self) -> bool:
        flags = self.ekf_flags
        return (
            super().position_ready()
            and self.gps_fix_type is not None
            and self.gps_fix_type >= GPS_FIX_3D
            and flags is not None
            and bool(flags & EKF_POS_HORIZ_ABS)
            and not flags & EKF_CONST_POS_MODE
            and self.telemetry.prearm_ok is not False
        )

    def on_family_message(self, msg, now: float) -> None:
        kind = msg.get_type()
        if kind == "EKF_STATUS_REPORT":
            self.ekf_flags = int(msg.flags)
        elif kind == "GPS_RAW_INT":
            self.gps_fix_type = int(msg.fix_type)

    def vehicle_mode_phase(self) -> Phase:
        if self.telemetry.custom_mode in _LANDING_MODES:
            return Phase.LANDING
        return Phase.HOLDING

    def describe_mode(self) -> str:
        number = self.telemetry.custom_mode
        return COPTER_MODE_NAME.get(number, str(number))

    # ------------------------------------------------------------------ capabilities
    @property
    def setpoints_time_out_on_vehicle(self) -> bool:
        return False  # GUIDED position targets are held forever

    @property
    def setpoint_horizon_s(self) -> float:
        return 3.0  # GUID_TIMEOUT's default: the guided target moves on at its velocity

    @property
    def home_tolerance_m(self) -> float:
        return 1.0  # SITL puts home exactly where --custom-location says
