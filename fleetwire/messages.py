"""The fleet's MAVLink conventions (docs/outputs.md, MAVLink): the ground station's identity, the
mission-time value, the setpoint type masks, and the speed-change command's encoding."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

#: The ground station's MAVLink identity (docs/outputs.md: the GCS is system 255).
GCS_SYSTEM_ID = 255
GCS_COMPONENT_ID = mavlink.MAV_COMP_ID_MISSIONPLANNER  # 190

#: NAMED_VALUE_INT name carrying the GCS's mission time, in ms, when it sends it.
MISSION_TIME_NAME = b"MSN_TIME"
_INT32 = (-(2**31), 2**31 - 1)

#: STATUSTEXT of a simulated vehicle whose simulation could not keep up: its clock fell this
#: many seconds behind (the ground station moves its clock mapping by as much).
CLOCK_SLIPPED_TEXT = "Sim: clock slipped"


def clock_slipped_text(seconds: float) -> str:
    return f"{CLOCK_SLIPPED_TEXT} {seconds:.2f} s (CPU overload)"


def parse_clock_slipped(text: str) -> float | None:
    """The seconds a `clock_slipped_text` says, None for any other text."""
    if not text.startswith(CLOCK_SLIPPED_TEXT + " "):
        return None
    try:
        seconds = float(text[len(CLOCK_SLIPPED_TEXT) + 1 :].split(" ", 1)[0])
    except ValueError:
        return None
    return seconds if math.isfinite(seconds) and seconds > 0 else None


#: Seconds our simulated vehicles fly a setpoint's velocity and acceleration on when the stream
#: stops (at most; then their setpoint timeout brakes them): the ground station dead-reckons a
#: silent UAV over the same span (`gcs.flight.silent`).
SETPOINT_EXTRAPOLATION_S = 1.0

#: type_mask bits of SET_POSITION_TARGET_* (MAVLink POSITION_TARGET_TYPEMASK).
IGNORE_ACCELERATION = (
    mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE
)
IGNORE_YAW = (
    mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)
#: Position + velocity (docs/outputs.md: accepted by both real autopilots).
MASK_POSITION_VELOCITY = IGNORE_ACCELERATION | IGNORE_YAW  # 3520
#: Position + velocity + acceleration feed-forward.
MASK_POSITION_VELOCITY_ACCELERATION = IGNORE_YAW  # 3072

#: A speed change is this command, as COMMAND_INT in this frame (param1 1: ground speed).
SPEED_CHANGE_COMMAND = mavlink.MAV_CMD_DO_CHANGE_SPEED
SPEED_CHANGE_FRAME = mavlink.MAV_FRAME_MISSION
_GROUND_SPEED = 1.0
_THROTTLE_UNCHANGED = -1.0


def _text(value: object) -> str:
    """A MAVLink char[] field as text (pymavlink gives bytes or str, NUL-padded or not)."""
    if isinstance(value, bytes | bytearray):
        return value.split(b"\x00", 1)[0].decode("ascii", "replace")
    return str(value).split("\x00", 1)[0]


# --------------------------------------------------------------------------- mission time
def encode_mission_time(mission_time_s: float) -> int:
    """MSN_TIME's value: the mission time in ms, rounded, within int32 (0 if not finite)."""
    if not math.isfinite(mission_time_s):
        return 0
    return int(max(_INT32[0], min(_INT32[1], round(mission_time_s * 1000))))


def decode_mission_time(msg) -> float | None:
    """The mission time (s) a NAMED_VALUE_INT carries, None if it is not MSN_TIME."""
    if _text(msg.name) != MISSION_TIME_NAME.decode():
        return None
    return int(msg.value) / 1000.0


# --------------------------------------------------------------------------- speed changes
def encode_speed_change(
    speed: float, effective_ms: int = 0, seq: int = 0
) -> tuple[float, float, float, float, int, int, float]:
    """param1-4, x, y, z of the COMMAND_INT `SPEED_CHANGE_COMMAND` (frame `SPEED_CHANGE_FRAME`):
    ground speed `speed` (m/s) from mission time `effective_ms` (0: at once), sequence number
    `seq`. A leader's request is the same, sent to the GCS's system id, with `effective_ms` 0."""
    return (_GROUND_SPEED, float(speed), _THROTTLE_UNCHANGED, 0.0, int(effective_ms), int(seq), 0.0)


@dataclass(frozen=True)
class SpeedChangeCommand:
    """A DO_CHANGE_SPEED as received (COMMAND_INT, or COMMAND_LONG: no `x`, `y`)."""

    speed: float  # param2, m/s (-1: no change, -2: default)
    effective_ms: int | None  # x: mission time it takes effect, 0 at once; None: COMMAND_LONG
    seq: int | None  # y: sequence number, 0 unsequenced; None: COMMAND_LONG

    @property
    def effective_s(self) -> float | None:
        """Mission time (s) it takes effect; None: at once."""
        return self.effective_ms / 1000.0 if self.effective_ms else None

    @property
    def sequence(self) -> int:
        """Its sequence number, 0 if none: what the answering COMMAND_ACK's `result_param2`
        echoes (0 acknowledges the oldest pending request)."""
        return self.seq or 0


def decode_speed_change(msg) -> SpeedChangeCommand | None:
    """A COMMAND_INT or COMMAND_LONG as a speed change; None if it is another command."""
    if msg.command != SPEED_CHANGE_COMMAND:
        return None
    if msg.get_type() == "COMMAND_INT":
        return SpeedChangeCommand(float(msg.param2), int(msg.x), int(msg.y))
    return SpeedChangeCommand(float(msg.param2), None, None)
