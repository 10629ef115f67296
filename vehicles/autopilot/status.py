"""What the autopilot shows the outside at one moment: the frozen :class:`AutopilotStatus` the
telemetry builders read, with the MAVLink state words (base mode, system status, landed state)
and the battery derived from it, and the battery model (pure).

:meth:`vehicles.autopilot.Autopilot.status` builds the status: once per control tick for the
telemetry due then, once for a message sent on request. Building it is on the simulator's hot
path (every tick that sends anything), so it only copies the autopilot's state; what is derived
from that state is computed when a builder reads it.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.autopilot.types import Guided, Mode
from vehicles.dynamics import Airframe, FleetDynamics

_BASE_MODE = (
    mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
    | mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
)


@dataclass(frozen=True)
class BatteryState:
    voltage_v: float
    current_a: float
    remaining_fraction: float
    consumed_mah: float
    consumed_j: float
    time_remaining_s: float


def battery_state(
    airframe: Airframe, used_j: float, power_w: float, capacity_mah: float | None = None
) -> BatteryState:
    """The battery of ``airframe`` (of ``capacity_mah``, default the airframe's) after
    ``used_j`` joules, drawing ``power_w`` watts."""
    nominal_v = 3.7 * airframe.battery_cells
    if capacity_mah is None:
        capacity_mah = airframe.battery_capacity_mah
    capacity_j = capacity_mah * 3.6 * nominal_v
    remaining = max(0.0, 1.0 - used_j / capacity_j)
    voltage = airframe.battery_cells * (3.5 + 0.7 * remaining)
    return BatteryState(
        voltage_v=voltage,
        current_a=power_w / voltage,
        remaining_fraction=remaining,
        consumed_mah=used_j / nominal_v / 3.6,
        consumed_j=used_j,
        time_remaining_s=remaining * capacity_j / max(power_w, 1e-3),
    )


def battery_of(dynamics: FleetDynamics, index: int) -> BatteryState:
    """Vehicle ``index``'s battery from the energy its dynamics used and the power it draws."""
    return battery_state(
        dynamics.config.airframe,
        float(dynamics.energy_used_j[index]),
        float(dynamics.power_w[index]),
        float(dynamics.battery_capacity_mah[index]),
    )


@dataclass(frozen=True)
class AutopilotStatus:
    """One autopilot as its telemetry sees it at one moment (a value: reading it cannot change
    the autopilot). Positions are local ENU metres, as plain floats."""

    sysid: int
    index: int  # the vehicle's row in the fleet's dynamics
    booting: bool
    mode: Mode
    guided: Guided
    rtl_phase: str  # "", "climb", "return", "land"
    auto_phase: str  # AUTO's item in progress: "", "takeoff_wait", "takeoff", "wp", "land", ...
    armed: bool
    landed: bool
    gcs_failsafe: bool  # the GCS failsafe is on (holding or landing)
    comm_errors: int
    airframe: Airframe
    energy_used_j: float
    power_w: float
    battery_capacity_mah: float
    home_enu: tuple[float, float, float]
    ekf_origin_enu: tuple[float, float, float]
    fleet_speed_mps: float | None  # the fleet speed in force, None before any speed change
    mission_time_s: float | None  # the GCS's mission time, None before it was synchronised
    #: (simulated s, roll, pitch, yaw) of the last ATTITUDE sent: ATTITUDE's rates are the
    #: differences between the attitudes reported
    reported_attitude: tuple[float, float, float, float] | None
    mission_count: int  # items of the stored mission, home (item 0) included
    mission_nav: int  # the navigation item AUTO is at (0: none yet)
    mission_running: bool  # AUTO is flying the mission
    mission_complete: bool

    @property
    def airborne(self) -> bool:
        return self.armed and not self.landed

    @property
    def base_mode(self) -> int:
        """HEARTBEAT base_mode: custom mode enabled, GUIDED outside STABILIZE, armed."""
        base = _BASE_MODE
        if self.mode != Mode.STABILIZE or self.booting:
            base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
        if self.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        return base

    @property
    def system_status(self) -> int:
        """MAV_STATE: booting, critical (armed in a GCS failsafe), active (flying), standby."""
        if self.booting:
            return mavlink.MAV_STATE_BOOT
        if self.armed and self.gcs_failsafe:
            return mavlink.MAV_STATE_CRITICAL
        if self.airborne:
            return mavlink.MAV_STATE_ACTIVE
        return mavlink.MAV_STATE_STANDBY

    @property
    def landed_state(self) -> int:
        """MAV_LANDED_STATE: on the ground, taking off, landing (LAND, RTL's last leg), in the
        air."""
        if not self.airborne:
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        mode = self.mode
        if (mode == Mode.GUIDED and self.guided == Guided.TAKEOFF) or (
            mode == Mode.AUTO and self.auto_phase == "takeoff"
        ):
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if (
            mode == Mode.LAND
            or (mode == Mode.RTL and self.rtl_phase == "land")
            or (mode == Mode.AUTO and self.auto_phase == "land")
            or (mode == Mode.AUTO and self.auto_phase == "rtl" and self.rtl_phase == "land")
        ):
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    @property
    def mission_state(self) -> int:
        """MISSION_CURRENT's MISSION_STATE (``GCS_MAVLINK::mission_state``)."""
        if self.mission_count <= 1:
            return mavlink.MISSION_STATE_NO_MISSION
        if self.mission_complete:
            return mavlink.MISSION_STATE_COMPLETE
        if self.mission_running:
            return mavlink.MISSION_STATE_ACTIVE
        if self.mission_nav > 0:
            return mavlink.MISSION_STATE_PAUSED
        return mavlink.MISSION_STATE_NOT_STARTED

    @property
    def battery(self) -> BatteryState:
        return battery_state(
            self.airframe, self.energy_used_j, self.power_w, self.battery_capacity_mah
        )

    @property
    def prearm_ok(self) -> bool:
        """Booted, battery above 10 %."""
        return not self.booting and self.battery.remaining_fraction > 0.1
