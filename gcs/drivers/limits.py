"""What bounds the position controller an autopilot tracks our setpoints with, read from its
own parameters, against what the mission assumes (`vehicle.max_speed`, `max_acceleration`).

ArduCopter's GUIDED mode shapes position/velocity targets with the waypoint navigator's
defaults (`ModeGuided::pva_control_start`: `WPNAV_SPEED` cm/s and `WPNAV_ACCEL` cm/s^2, the
horizontal ones); PX4's offboard position control saturates velocity at `MPC_XY_VEL_MAX` (m/s)
and horizontal acceleration at `MPC_ACC_HOR_MAX` (m/s^2). A mission that assumes more than
these lets the autopilot fall behind its targets: an ArduCopter accelerating at 2.5 m/s^2 was
9 m behind one second after departure with a plan made for 8 m/s^2, against rho_c = 5 m.
The simulated vehicles speak ArduCopter's parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Mission values this close above a limit pass (float32 parameters, unit conversions).
TOLERANCE = 1e-3


@dataclass(frozen=True)
class LimitParameter:
    """One parameter that bounds tracking: its name, unit, and the factor to SI units."""

    name: str
    unit: str
    to_si: float

    def si(self, value: float) -> float:
        return value * self.to_si

    def from_si(self, value: float) -> float:
        return value / self.to_si


@dataclass(frozen=True)
class LimitParameters:
    """A family's parameters bounding horizontal speed and acceleration."""

    speed: LimitParameter
    acceleration: LimitParameter

    @property
    def names(self) -> tuple[str, str]:
        return (self.speed.name, self.acceleration.name)


ARDUCOPTER = LimitParameters(
    speed=LimitParameter("WPNAV_SPEED", "cm/s", 0.01),
    acceleration=LimitParameter("WPNAV_ACCEL", "cm/s^2", 0.01),
)
PX4 = LimitParameters(
    speed=LimitParameter("MPC_XY_VEL_MAX", "m/s", 1.0),
    acceleration=LimitParameter("MPC_ACC_HOR_MAX", "m/s^2", 1.0),
)


@dataclass(frozen=True)
class AutopilotLimits:
    """What one UAV's autopilot allows (SI units), with the raw parameter values."""

    uav: int
    parameters: LimitParameters
    speed_raw: float
    acceleration_raw: float

    @property
    def max_speed(self) -> float:
        return self.parameters.speed.si(self.speed_raw)

    @property
    def max_acceleration(self) -> float:
        return self.parameters.acceleration.si(self.acceleration_raw)


@dataclass(frozen=True)
class LimitExceeded:
    """The mission assumes more than one UAV's autopilot allows."""

    uav: int
    parameter: LimitParameter
    raw_value: float
    allowed: float  # SI
    mission_key: str  # vehicle.max_speed | vehicle.max_acceleration
    assumed: float  # SI

    def text(self) -> str:
        unit = "m/s" if self.mission_key.endswith("speed") else "m/s^2"
        raw = f"{self.raw_value:g} {self.parameter.unit}"
        si = "" if self.parameter.to_si == 1.0 else f" ({self.allowed:g} {unit})"
        return (
            f"UAV {self.uav}: its autopilot's {self.parameter.name} = {raw}{si} is below "
            f"{self.mission_key} = {self.assumed:g} {unit}"
        )

    def expected(self) -> str:
        """The `expected ...` of the one-line refusal (`InputError`) naming the mission key."""
        unit = "m/s" if self.mission_key.endswith("speed") else "m/s^2"
        si = "" if self.parameter.to_si == 1.0 else f" ({self.allowed:g} {unit})"
        return (
            f"at most {self.allowed:g} {unit}, what UAV {self.uav}'s autopilot allows "
            f"({self.parameter.name} = {self.raw_value:g} {self.parameter.unit}{si}), got "
            f"{self.assumed:g}; raise {self.parameter.name} on the autopilot, lower "
            f"{self.mission_key}, fly with --cap-speed, or set vehicle.apply_limits: true"
        )


def exceeded(limits: AutopilotLimits, max_speed: float, max_acceleration: float):
    """The limits the mission's `max_speed` / `max_acceleration` go beyond (empty: none)."""
    p = limits.parameters
    checks = (
        (p.speed, limits.speed_raw, limits.max_speed, "vehicle.max_speed", max_speed),
        (
            p.acceleration,
            limits.acceleration_raw,
            limits.max_acceleration,
            "vehicle.max_acceleration",
            max_acceleration,
        ),
    )
    return [
        LimitExceeded(limits.uav, parameter, raw, allowed, key, assumed)
        for parameter, raw, allowed, key, assumed in checks
        if assumed > allowed * (1 + TOLERANCE)
    ]
