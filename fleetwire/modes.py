"""Autopilot mode numbers (HEARTBEAT `custom_mode`, MAV_CMD_DO_SET_MODE) taken from pymavlink's
own maps, never retyped: ArduCopter's (`mavutil.mode_mapping_acm`) and PX4's (`mavutil.px4_map`)."""

from __future__ import annotations

from types import MappingProxyType

from pymavlink import mavutil  # after fleetwire/__init__.py asked mavutil for MAVLink 2

#: ArduCopter custom mode number -> name (pymavlink's `mode_mapping_acm`).
COPTER_MODE_NAME = MappingProxyType(dict(mavutil.mode_mapping_acm))
#: ArduCopter custom mode name -> number: `COPTER_MODE["GUIDED"]` is 4.
COPTER_MODE = MappingProxyType({name: number for number, name in COPTER_MODE_NAME.items()})


def px4_custom_mode(main: int, sub: int = 0) -> int:
    """HEARTBEAT custom_mode of a PX4 main mode and sub-mode (px4_custom_mode.h)."""
    return (main << 16) | (sub << 24)


def _constants(prefix: str) -> MappingProxyType:
    names = {k.removeprefix(prefix): v for k, v in vars(mavutil).items() if k.startswith(prefix)}
    return MappingProxyType(names)


#: PX4 main modes, name -> number (pymavlink's `PX4_CUSTOM_MAIN_MODE_*`): "AUTO" is 4.
PX4_MAIN_MODE = _constants("PX4_CUSTOM_MAIN_MODE_")
#: PX4 sub-modes of AUTO, name -> number (pymavlink's `PX4_CUSTOM_SUB_MODE_AUTO_*`).
PX4_AUTO_SUB_MODE = _constants("PX4_CUSTOM_SUB_MODE_AUTO_")
#: PX4 modes, pymavlink's name ("OFFBOARD", "LOITER", "LAND", ...) -> (main mode, sub-mode).
PX4_MODE_PARTS = MappingProxyType(
    {name: (main, sub) for name, (_base, main, sub) in mavutil.px4_map.items()}
)
#: PX4 modes, pymavlink's name -> HEARTBEAT custom_mode.
PX4_MODE = MappingProxyType({name: px4_custom_mode(*p) for name, p in PX4_MODE_PARTS.items()})


def px4_mode_name(custom_mode: int) -> str:
    """pymavlink's name of a PX4 custom_mode ("UNKNOWN" if it has none)."""
    return mavutil.interpret_px4_mode(0, custom_mode)
