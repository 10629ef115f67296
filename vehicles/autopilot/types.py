"""The autopilot's identity and small value types: its MAVLink component, a moment
(:class:`Stamp`), the ArduCopter flight modes it implements, the modes it arms in and what
GUIDED is doing."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from fleetwire.modes import COPTER_MODE

AUTOPILOT_COMPONENT = 1  # MAV_COMP_ID_AUTOPILOT1


#: ArduCopter flight modes the simulation implements (custom_mode numbers, pymavlink's).
Mode = IntEnum(
    "Mode",
    {
        name: COPTER_MODE[name]
        for name in ("STABILIZE", "AUTO", "GUIDED", "LOITER", "RTL", "LAND", "BRAKE")
    },
    module=__name__,
)


#: The modes ArduCopter arms in (``Mode::allows_arming``): STABILIZE (it boots in it), GUIDED and
#: LOITER; AUTO only with AUTO_OPTIONS bit 0 (0 here), RTL, LAND and BRAKE never.
ARMABLE_MODES = (Mode.STABILIZE, Mode.GUIDED, Mode.LOITER)


class Guided(IntEnum):
    """What GUIDED is doing."""

    IDLE = 0  # on the ground (armed or not), waiting for a takeoff
    TAKEOFF = 1
    HOLD = 2  # holding a point (after takeoff, on entry, after a setpoint timeout)
    SETPOINTS = 3  # velocity/acceleration SET_POSITION_TARGET_* (GUID_TIMEOUT applies)
    GOTO = 4  # flying to a point: DO_REPOSITION, guided mission item, position-only target
    #         (no timeout, like ArduCopter's position targets)


@dataclass(frozen=True)
class Stamp:
    """A moment: simulated seconds since the start and wall-clock (monotonic) seconds."""

    sim_s: float
    wall_s: float
