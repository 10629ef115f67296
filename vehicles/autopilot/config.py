"""The autopilot's behaviour parameters: failsafe timings and ArduCopter-like settings."""

from __future__ import annotations

from dataclasses import dataclass, field

from fleetwire.messages import GCS_SYSTEM_ID
from vehicles.telemetry import TelemetryRates


@dataclass(frozen=True)
class FailsafeConfig:
    """Failsafe timings (simulated seconds) and the wall-clock floor of every timeout."""

    #: GUID_TIMEOUT: velocity/acceleration targets stop after this (position-only targets never
    #: do, as in ArduCopter). ArduCopter's default is 3 s; the fleetline ground station relies on
    #: 1 s (its stall detection and the radio medium's loss-of-link hold), so 1 s is the default
    #: here and `vehicles sim --setpoint-timeout 3` gives ArduCopter's.
    setpoint_timeout_s: float = 1.0
    gcs_timeout_s: float = 5.0
    gcs_hold_s: float = 5.0  # hold this long after the GCS is lost, then land
    wall_floor_s: float = 0.25
    gcs_system: int = GCS_SYSTEM_ID


@dataclass(frozen=True)
class AutopilotConfig:
    """Behaviour parameters (ArduCopter parameter names in comments)."""

    failsafe: FailsafeConfig = field(default_factory=FailsafeConfig)
    telemetry: TelemetryRates = field(default_factory=TelemetryRates)
    boot_time_s: float = 1.0
    disarm_delay_s: float = 10.0  # DISARM_DELAY: landed and armed this long -> disarm
    land_detect_s: float = 1.0
    land_speed_mps: float = 0.5  # LAND_SPEED
    land_speed_high_mps: float = 1.5  # LAND_SPEED_HIGH / WPNAV_SPEED_DN
    land_slow_below_m: float = 10.0
    takeoff_speed_mps: float = 2.5  # PILOT_SPEED_UP / WPNAV_SPEED_UP
    waypoint_speed_mps: float = 10.0  # WPNAV_SPEED
    waypoint_radius_m: float = 2.0  # WPNAV_RADIUS: an AUTO waypoint is reached within it
    rtl_altitude_m: float = 15.0  # RTL_ALT
    max_altitude_m: float = 1000.0  # takeoff / setpoint altitude above home
    max_range_m: float = 50_000.0  # setpoint distance from the origin
    max_setpoint_speed_mps: float = 100.0
    max_setpoint_acceleration_mps2: float = 50.0
    refusal_text_interval_s: float = 2.0  # at most one STATUSTEXT per refusal kind per interval
    leader_retry_s: float = 1.0
    leader_max_tries: int = 10
    mission_capacity: int = 700  # mission items, home included (more: MISSION_ACK NO_SPACE)
    mission_request_retry_s: float = 1.0  # an unanswered MISSION_REQUEST_INT is sent again
    mission_upload_timeout_s: float = 8.0  # no item for this long: the upload is cancelled
