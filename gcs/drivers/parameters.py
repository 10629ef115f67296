"""The MAVLink parameter protocol for a few named parameters (no sockets, no clock).

A driver reads the parameters that bound what its autopilot can follow (`gcs.drivers.limits`)
and, with `vehicle.apply_limits`, sets them for the flight and puts them back after landing.
`ParameterTable` keeps what was asked and what came back; the driver sends what `due(now)`
returns (PARAM_REQUEST_READ by name, or PARAM_SET) and hands it every PARAM_VALUE.

Values on the wire are float32. Integer parameters are encoded two ways (both recorded):
ArduPilot casts the integer to float (`COMPASS_DEV_ID` 97539 arrives as 97539.0, type INT32);
PX4 copies its bytes into the float (`CAL_BARO0_ID` arrives as 9.3e-39, type INT32), which
AUTOPILOT_VERSION announces with MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass, field

from gcs.drivers.commands import Backoff
from gcs.transport.link import mavutil

mavlink = mavutil.mavlink

#: Integer MAV_PARAM_TYPEs and their struct formats (for the bytewise encoding).
_INTEGER_FORMATS = {
    mavlink.MAV_PARAM_TYPE_UINT8: "<B3x",
    mavlink.MAV_PARAM_TYPE_INT8: "<b3x",
    mavlink.MAV_PARAM_TYPE_UINT16: "<H2x",
    mavlink.MAV_PARAM_TYPE_INT16: "<h2x",
    mavlink.MAV_PARAM_TYPE_UINT32: "<I",
    mavlink.MAV_PARAM_TYPE_INT32: "<i",
}


class Encoding(enum.Enum):
    """How an autopilot puts an integer parameter into PARAM_VALUE's float."""

    C_CAST = "c_cast"  # ArduPilot
    BYTEWISE = "bytewise"  # PX4


def decode_value(value: float, param_type: int, encoding: Encoding) -> float:
    """The parameter's value from PARAM_VALUE's `param_value` and `param_type`."""
    fmt = _INTEGER_FORMATS.get(param_type)
    if fmt is None or encoding is Encoding.C_CAST:
        return float(value)
    return float(struct.unpack(fmt, struct.pack("<f", value))[0])


def encode_value(value: float, param_type: int, encoding: Encoding) -> float:
    """PARAM_SET's `param_value` for `value` of `param_type` (see `decode_value`)."""
    fmt = _INTEGER_FORMATS.get(param_type)
    if fmt is None or encoding is Encoding.C_CAST:
        return float(value)
    return float(struct.unpack("<f", struct.pack(fmt, int(round(value))))[0])


def param_id(name: str) -> str:
    """A parameter name as PARAM_VALUE carries it (char[16], NUL padding stripped)."""
    return name.rstrip("\x00")


@dataclass
class _Entry:
    name: str
    wanted: float | None = None  # a value to set; None: only read
    value: float | None = None  # as last reported by the vehicle
    param_type: int | None = None
    attempts: int = 0
    next_send: float = 0.0
    done: bool = False  # read (and, if wanted, reported at the wanted value) or given up
    failed: bool = False  # no answer after `max_attempts`


@dataclass
class ParameterTable:
    """Named parameters of one vehicle being read or set (see the module docstring).

    `due(now)` lists the requests to send now: ("read", name) or ("set", name, value, type);
    a set is confirmed by a PARAM_VALUE showing the value (ArduPilot and PX4 both answer a
    PARAM_SET with PARAM_VALUE). After `max_attempts` unanswered sends a name is given up.
    Times are the driver's wall clock; `retry` is already in wall seconds."""

    encoding: Encoding
    retry: Backoff = field(default_factory=lambda: Backoff(1.0, 1.5, 3.0))
    max_attempts: int = 5
    _entries: dict[str, _Entry] = field(default_factory=dict)

    def read(self, *names: str) -> None:
        """Ask for `names` (again, if they were read before)."""
        for name in names:
            self._entries[name] = _Entry(name)

    def set(self, name: str, value: float, param_type: int) -> None:
        """Set `name` to `value` (its type as the vehicle reported it)."""
        self._entries[name] = _Entry(name, wanted=float(value), param_type=param_type)

    def due(self, now: float) -> list[tuple]:
        out: list[tuple] = []
        for entry in self._entries.values():
            if entry.done or now < entry.next_send:
                continue
            if entry.attempts >= self.max_attempts:
                entry.done = entry.failed = True
                continue
            entry.attempts += 1
            entry.next_send = now + self.retry.delay(entry.attempts)
            if entry.wanted is None:
                out.append(("read", entry.name))
            else:
                value = encode_value(entry.wanted, entry.param_type, self.encoding)
                out.append(("set", entry.name, value, entry.param_type))
        return out

    def on_param_value(self, msg) -> None:
        """A PARAM_VALUE from the vehicle (asked for or not)."""
        name = param_id(msg.param_id)
        entry = self._entries.get(name)
        if entry is None:
            return
        value = decode_value(msg.param_value, msg.param_type, self.encoding)
        entry.value = value
        entry.param_type = msg.param_type
        if entry.wanted is None or _same(value, entry.wanted):
            entry.done = True
            entry.failed = False

    def settled(self) -> bool:
        """Every name read or set, or given up."""
        return all(entry.done for entry in self._entries.values())

    def value(self, name: str) -> float | None:
        entry = self._entries.get(name)
        return None if entry is None else entry.value

    def param_type(self, name: str) -> int | None:
        entry = self._entries.get(name)
        return None if entry is None else entry.param_type

    def failed(self) -> list[str]:
        """Names the vehicle never answered for (or never showed at the wanted value)."""
        return [entry.name for entry in self._entries.values() if entry.failed]


def _same(a: float, b: float) -> bool:
    """Float32 round trip: what was set comes back rounded."""
    return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-6)
