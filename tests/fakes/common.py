"""What both fake autopilots share: the MAVLink 2 dialect, an output queue, simple kinematics,
geodesy, and `FakeEndpoint`, which runs a model on a real UDP socket in a thread.

Time: a model is told `now`, seconds since its first HEARTBEAT (wall clock, unscaled). Its
`speedup` runs the vehicle faster, as SITL's own speedup does: boot, GPS fix, EKF convergence,
spool-up, kinematics (speeds and feed-forward velocities are in vehicle-time m/s, like the
runtime's setpoints under `--speedup`), landing detection, heartbeat and telemetry rates.
Link-level timeouts that judge the ground station (PX4's COM_OF_LOSS_T, ArduPilot's
GUID_TIMEOUT) stay in wall-clock seconds, so a driver's stream is held to the real numbers
whatever the speedup.
"""

from __future__ import annotations

import math
import os
import selectors
import struct
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pymap3d

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import all as mavlink  # noqa: E402
from pymavlink.generator import mavparse  # noqa: E402

#: MAV_RESULT values.
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
DENIED = mavlink.MAV_RESULT_DENIED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
FAILED = mavlink.MAV_RESULT_FAILED

#: SYS_STATUS health bit of the pre-arm checks (MAV_SYS_STATUS_PREARM_CHECK).
PREARM_CHECK = mavlink.MAV_SYS_STATUS_PREARM_CHECK
#: MAV_MODE_FLAG_SAFETY_ARMED.
ARMED_FLAG = mavlink.MAV_MODE_FLAG_SAFETY_ARMED

#: Setpoint type_mask bits (POSITION_TARGET_TYPEMASK).
IGNORE_POSITION = 0b111
IGNORE_VELOCITY = 0b111 << 3


def message_from_fields(type_name: str, fields: dict) -> mavlink.MAVLink_message:
    """Build a pymavlink message from a transcript's `fields` (NaN as "NaN", char[] as str)."""
    cls = mavlink.mavlink_map[getattr(mavlink, f"MAVLINK_MSG_ID_{type_name}")]
    args = []
    for name, ftype, length in zip(
        cls.fieldnames, cls.fieldtypes, _array_lengths(cls), strict=True
    ):
        value = fields.get(name, 0)
        if ftype == "char":
            value = str(value).encode("latin-1")
        elif ftype in ("float", "double"):
            value = _to_float(value, length)
        args.append(value)
    return cls(*args)


def _array_lengths(cls) -> list[int]:
    by_ordered = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    return [by_ordered[name] for name in cls.fieldnames]


def _to_float(value, length: int):
    if length:
        return [float(v) for v in value]
    return float(value)


def text(severity: int, message: str, *, ident: int = 0, chunk_seq: int = 0):
    """A STATUSTEXT message (text verbatim, up to 50 characters)."""
    return mavlink.MAVLink_statustext_message(
        severity, message.encode("latin-1"), id=ident, chunk_seq=chunk_seq
    )


def command_ack(command: int, result: int, target_system: int, target_component: int):
    """A COMMAND_ACK addressed to the sender of the command."""
    return mavlink.MAVLink_command_ack_message(
        command, result, progress=0, result_param2=0,
        target_system=target_system, target_component=target_component,
    )  # fmt: skip


# --- PX4's EVENT messages: not in pymavlink 2.4.50's dialects ---------------------------------

_EVENT_XML = Path(__file__).with_name("px4_events.xml")
_EVENT_DEFINITIONS = {
    m.name: m for m in mavparse.MAVXML(str(_EVENT_XML), mavparse.PROTOCOL_2_0).message
}
_STRUCT_CODES = {"uint8_t": "B", "uint16_t": "H", "uint32_t": "I"}


class ExtraMessage(mavlink.MAVLink_message):
    """A message pymavlink's dialect lacks, packed from its XML definition (crc_extra included)."""

    def __init__(self, name: str, **values) -> None:
        definition = _EVENT_DEFINITIONS[name]
        super().__init__(definition.id, definition.name)
        self._definition = definition
        self._fieldnames = [f.name for f in definition.fields]
        for f in definition.fields:
            setattr(self, f.name, values.get(f.name, [0] * f.array_length if f.array_length else 0))

    def pack(self, mav, force_mavlink1: bool = False) -> bytes:
        codes, values = "<", []
        for f in self._definition.ordered_fields:
            value = getattr(self, f.name)
            if f.array_length:
                codes += f"{f.array_length}s"
                values.append(bytes(value))
            else:
                codes += _STRUCT_CODES[f.type]
                values.append(value)
        payload = struct.pack(codes, *values)
        return self._pack(mav, self._definition.crc_extra, payload, force_mavlink1=force_mavlink1)


# --- output queue -------------------------------------------------------------------------------


@dataclass
class Outbox:
    """Messages a model wants sent, each with the time it is due (for delayed replies)."""

    items: list[tuple[float, int, object]] = field(default_factory=list)
    _order: int = 0

    def send(self, due: float, *messages) -> None:
        for message in messages:
            self._order += 1
            self.items.append((due, self._order, message))

    def pop_due(self, now: float) -> list:
        """Messages due at `now`, in the order they were queued."""
        due = sorted((item for item in self.items if item[0] <= now), key=lambda i: (i[0], i[1]))
        if due:
            self.items = [item for item in self.items if item[0] > now]
        return [message for _, _, message in due]


# --- kinematics and geodesy ---------------------------------------------------------------------


@dataclass(frozen=True)
class Home:
    """Where a simulated vehicle boots: WGS84 degrees and metres AMSL."""

    lat: float
    lon: float
    alt: float


@dataclass
class PointMass:
    """A vehicle reduced to a point moving toward its target (ENU metres from the boot spot).

    Velocity = feed-forward + gain x position error, limited horizontally and vertically. Good
    enough for a driver's state machine: targets are reached, streams are followed.
    """

    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gain: float = 2.0

    def step(
        self,
        dt: float,
        target: np.ndarray,
        feed_forward: np.ndarray,
        max_horizontal: float,
        max_up: float,
        max_down: float,
    ) -> None:
        gain = min(self.gain, 1.0 / dt) if dt > 0 else self.gain  # never overshoot in a step
        command = feed_forward + gain * (target - self.position)
        horizontal = math.hypot(command[0], command[1])
        if horizontal > max_horizontal:
            command[:2] *= max_horizontal / horizontal
        command[2] = min(max(command[2], -max_down), max_up)
        self.velocity = command
        self.position = self.position + command * dt
        if self.position[2] < 0.0:
            self.position[2] = 0.0
            self.velocity[2] = 0.0


def enu_to_global(home: Home, enu: np.ndarray) -> tuple[float, float, float]:
    """ENU metres from `home` -> latitude, longitude (degrees), altitude AMSL (m)."""
    lat, lon, alt = pymap3d.enu2geodetic(enu[0], enu[1], enu[2], home.lat, home.lon, home.alt)
    return float(lat), float(lon), float(alt)


def global_to_enu(home: Home, lat: float, lon: float, alt: float) -> np.ndarray:
    """Latitude, longitude (degrees), altitude AMSL -> ENU metres from `home`."""
    e, n, u = pymap3d.geodetic2enu(lat, lon, alt, home.lat, home.lon, home.alt)
    return np.array([e, n, u], dtype=float)


def heading_cdeg(velocity: np.ndarray) -> int:
    """Course over ground in centidegrees (0 = north), 0 when still."""
    if math.hypot(velocity[0], velocity[1]) < 0.2:
        return 0
    return int(round(math.degrees(math.atan2(velocity[0], velocity[1])) % 360.0 * 100)) % 36000


def setpoint_enu(msg, origin: Home, home_alt: float) -> tuple[np.ndarray, np.ndarray] | None:
    """A SET_POSITION_TARGET_GLOBAL_INT / _LOCAL_NED as ENU position and velocity (m, m/s) from
    `origin`; None in a frame neither fake follows. Relative altitudes count from `home_alt`."""
    if msg.get_type() == "SET_POSITION_TARGET_GLOBAL_INT":
        if msg.coordinate_frame not in (0, 3, 5, 6):
            return None
        relative = msg.coordinate_frame in (3, 6)
        alt = msg.alt + (home_alt if relative else 0.0)
        position = global_to_enu(origin, msg.lat_int / 1e7, msg.lon_int / 1e7, alt)
    else:
        if msg.coordinate_frame != 1:
            return None
        position = np.array([msg.y, msg.x, -msg.z], dtype=float)
    velocity = np.array([msg.vy, msg.vx, -msg.vz], dtype=float)  # NED -> ENU
    return position, velocity


# --- telemetry ----------------------------------------------------------------------------------


def gps_raw_int(
    origin: Home, enu: np.ndarray, velocity: np.ndarray, time_usec: int, fix_type: int,
    eph: int, epv: int,
) -> mavlink.MAVLink_gps_raw_int_message:  # fmt: skip
    """GPS_RAW_INT of a vehicle at `enu` metres from `origin`, moving at `velocity` (ENU)."""
    lat, lon, alt = enu_to_global(origin, enu)
    return mavlink.MAVLink_gps_raw_int_message(
        time_usec, fix_type, int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)),
        eph, epv, int(np.hypot(velocity[0], velocity[1]) * 100), heading_cdeg(velocity), 10,
    )  # fmt: skip


def global_position_int(
    origin: Home, enu: np.ndarray, velocity: np.ndarray, time_boot_ms: int, home_alt: float
) -> mavlink.MAVLink_global_position_int_message:
    """GLOBAL_POSITION_INT of a vehicle at `enu` metres from `origin` (relative_alt from
    `home_alt`), moving at `velocity` (ENU)."""
    lat, lon, alt = enu_to_global(origin, enu)
    return mavlink.MAVLink_global_position_int_message(
        time_boot_ms, int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)),
        int(round((alt - home_alt) * 1000)), int(round(velocity[1] * 100)),
        int(round(velocity[0] * 100)), int(round(-velocity[2] * 100)), heading_cdeg(velocity),
    )  # fmt: skip


def local_position_ned(
    enu: np.ndarray, velocity: np.ndarray, time_boot_ms: int
) -> mavlink.MAVLink_local_position_ned_message:
    """LOCAL_POSITION_NED of an ENU position and velocity."""
    return mavlink.MAVLink_local_position_ned_message(
        time_boot_ms, enu[1], enu[0], -enu[2], velocity[1], velocity[0], -velocity[2]
    )


def position_target_local_ned(
    target: np.ndarray, feed_forward: np.ndarray, type_mask: int, time_boot_ms: int
) -> mavlink.MAVLink_position_target_local_ned_message:
    """POSITION_TARGET_LOCAL_NED (MAV_FRAME_LOCAL_NED) of an ENU target and feed-forward."""
    return mavlink.MAVLink_position_target_local_ned_message(
        time_boot_ms, 1, type_mask, target[1], target[0], -target[2],
        feed_forward[1], feed_forward[0], -feed_forward[2], 0.0, 0.0, 0.0, 0.0, 0.0,
    )  # fmt: skip


@dataclass
class StreamScheduler:
    """Periodic telemetry on a fixed phase, each stream at the interval a ground station set.

    `intervals`: what MAV_CMD_SET_MESSAGE_INTERVAL asked, in microseconds (negative: off, 0:
    the autopilot's default rate). A stream that falls behind catches up at most one period.
    """

    intervals: dict[int, float] = field(default_factory=dict)
    _last_sent: dict[int, float] = field(default_factory=dict)

    def send_due(
        self,
        now: float,
        default_rates_hz: Mapping[int, float],
        speedup: float,
        build: Callable[[int, float], object | None],
        outbox: Outbox,
    ) -> None:
        """Queue in `outbox` every stream of `default_rates_hz` that is due at `now`; `build`
        makes the message (None: nothing to send now, try again on the next tick)."""
        for message_id, rate_hz in default_rates_hz.items():
            interval_us = self.intervals.get(message_id, 0.0)
            if interval_us < 0:
                continue
            period = (interval_us / 1e6 if interval_us > 0 else 1.0 / rate_hz) / speedup
            last = self._last_sent.get(message_id)
            if last is not None and now - last < period:
                continue
            message = build(message_id, now)
            if message is None:
                continue
            self._last_sent[message_id] = now if last is None else max(last + period, now - period)
            outbox.send(now, message)


# --- the model's common part -------------------------------------------------------------------

#: The messages that carry a position/velocity target.
SETPOINT_TYPES = ("SET_POSITION_TARGET_GLOBAL_INT", "SET_POSITION_TARGET_LOCAL_NED")


@dataclass(frozen=True)
class ParameterSet:
    """A firmware's parameters as the parameter protocol shows them (recorded: ArduCopter
    4.7-dev announces 1349 parameters, floats as REAL32 and integers cast to float; PX4 905,
    integers copied bytewise into the float). `values`: name -> (value, MAV_PARAM_TYPE); the
    ones not listed exist (they are counted) but are never asked for here."""

    count: int
    bytewise: bool
    values: Mapping[str, tuple[float, int]]


#: struct formats of the integer MAV_PARAM_TYPEs 1-6, for the bytewise encoding.
_INTEGER_FORMATS = {1: "<B3x", 2: "<b3x", 3: "<H2x", 4: "<h2x", 5: "<I", 6: "<i"}


def _wire_value(value: float, param_type: int, bytewise: bool) -> float:
    if not bytewise or param_type not in _INTEGER_FORMATS:
        return float(value)
    return struct.unpack("<f", struct.pack(_INTEGER_FORMATS[param_type], int(value)))[0]


def _from_wire(value: float, param_type: int, bytewise: bool) -> float:
    if not bytewise or param_type not in _INTEGER_FORMATS:
        return float(value)
    return float(struct.unpack(_INTEGER_FORMATS[param_type], struct.pack("<f", value))[0])


class FakeAutopilot:
    """What both fake autopilots do alike: messages for another system are ignored, ACKs go to
    the sender of the last command, the boot timeline is compressed by `speedup`, the vehicle is
    a `PointMass`, telemetry streams run on a `StreamScheduler`, the parameter protocol answers
    from the family's `ParameterSet` (PARAM_REQUEST_READ by name or index, PARAM_SET: one
    PARAM_VALUE each; an unknown name gets no answer).

    A subclass answers `_command`, `_mode_message` (SET_MODE) and `_setpoint`.
    """

    #: The family's parameters (a subclass sets its own).
    parameter_set: ParameterSet = ParameterSet(count=0, bytewise=False, values={})

    def __init__(self, *, system_id: int, speedup: float) -> None:
        self.system_id = system_id
        self.speedup = speedup
        self.outbox = Outbox()
        self.body = PointMass(gain=1.0)
        self.landed_state = mavlink.MAV_LANDED_STATE_ON_GROUND
        self.commands: list[tuple[float, int, int]] = []  # (t, command, result) answered
        self.streams = StreamScheduler()
        self._gcs = (255, 190)  # (system, component) of the last command's sender
        self._last_tick: float | None = None
        self.parameters: dict[str, tuple[float, int]] = dict(self.parameter_set.values)
        self.param_sets: list[tuple[float, str, float]] = []  # (t, name, value) set by a GCS

    @property
    def intervals(self) -> dict[int, float]:
        """Message intervals a ground station set (microseconds, by message id)."""
        return self.streams.intervals

    def _after(self, now: float, event: float) -> bool:
        """Whether `event` (seconds after the first HEARTBEAT at speedup 1) has happened."""
        return now * self.speedup >= event

    def flying(self) -> bool:
        return self.landed_state != mavlink.MAV_LANDED_STATE_ON_GROUND

    def handle(self, msg, now: float) -> None:
        """React to one message from a ground station."""
        kind = msg.get_type()
        target = getattr(msg, "target_system", self.system_id)
        if target not in (0, self.system_id):
            return
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            self._gcs = (msg.get_srcSystem(), msg.get_srcComponent())
            self._command(msg, now)
        elif kind == "SET_MODE":
            self._gcs = (msg.get_srcSystem(), msg.get_srcComponent())
            self._mode_message(msg, now)
        elif kind in SETPOINT_TYPES:
            self._setpoint(msg, now)
        elif kind == "PARAM_REQUEST_READ":
            names = list(self.parameters)
            index = int(msg.param_index)
            name = msg.param_id.rstrip("\x00") if index < 0 else None
            if name is None and 0 <= index < len(names):
                name = names[index]
            if name in self.parameters:
                self.outbox.send(now, self._param_value(name))
        elif kind == "PARAM_SET":
            name = msg.param_id.rstrip("\x00")
            if name in self.parameters:
                param_type = self.parameters[name][1]
                value = _from_wire(msg.param_value, param_type, self.parameter_set.bytewise)
                self.parameters[name] = (value, param_type)
                self.param_sets.append((now, name, value))
                self.outbox.send(now, self._param_value(name))

    def _param_value(self, name: str):
        value, param_type = self.parameters[name]
        names = list(self.parameters)
        wire = _wire_value(value, param_type, self.parameter_set.bytewise)
        return mavlink.MAVLink_param_value_message(
            name.encode(), wire, param_type, self.parameter_set.count, names.index(name)
        )

    def _command(self, msg, now: float) -> None:
        raise NotImplementedError

    def _mode_message(self, msg, now: float) -> None:
        raise NotImplementedError

    def _setpoint(self, msg, now: float) -> None:
        raise NotImplementedError

    def _elapsed(self, now: float) -> float:
        """Seconds since the previous tick: 0 on the first, at most 0.2 (a stalled thread
        does not make the vehicle jump)."""
        dt = 0.0 if self._last_tick is None else min(max(now - self._last_tick, 0.0), 0.2)
        self._last_tick = now
        return dt


# --- the UDP endpoint ---------------------------------------------------------------------------


@dataclass
class Exchange:
    """One message seen by the endpoint: wall time since start, direction, the message."""

    t: float
    direction: str  # "rx" (from the GCS) | "tx" (sent by the fake)
    message: object


class FakeEndpoint:
    """Runs a fake autopilot model on a mavutil connection in a background thread.

    `url` is a mavutil connection string: `udpin:127.0.0.1:0` listens (ArduPilot-style, the
    ground station connects with `udpout:` and the fake replies to the last sender; the bound
    port is `port`), `udpout:127.0.0.1:P` pushes to a ground station listening on P (PX4-style,
    its offboard link towards 14540+i). Use as a context manager; `lock` guards the model.
    """

    def __init__(self, model, url: str, *, tick_s: float = 0.005) -> None:
        self.model = model
        self.lock = threading.RLock()
        self.exchanges: list[Exchange] = []
        self._tick_s = tick_s
        self._conn = mavutil.mavlink_connection(
            url, source_system=model.system_id, source_component=1
        )
        # MAVLink 2 whatever the process-wide default, and never auto-switch.
        self._conn.mav = mavlink.MAVLink(self._conn, srcSystem=model.system_id, srcComponent=1)
        self._conn.mav.robust_parsing = True
        self._conn.WIRE_PROTOCOL_VERSION = "2.0"
        self._conn.first_byte = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"fake-{url}", daemon=True)
        self._start = 0.0

    @property
    def port(self) -> int:
        """The local UDP port of the fake's socket."""
        return self._conn.port.getsockname()[1]

    def __enter__(self) -> FakeEndpoint:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def start(self) -> None:
        self._start = time.monotonic()
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)
        self._conn.close()

    def now(self) -> float:
        return time.monotonic() - self._start

    def received(self, type_name: str) -> list[Exchange]:
        """What the fake received of one message type, in order."""
        with self.lock:
            return [
                e for e in self.exchanges
                if e.direction == "rx" and e.message.get_type() == type_name
            ]  # fmt: skip

    def _run(self) -> None:
        selector = selectors.DefaultSelector()
        selector.register(self._conn.fd, selectors.EVENT_READ)
        try:
            while not self._stop.is_set():
                selector.select(self._tick_s)
                with self.lock:
                    now = self.now()
                    while True:
                        try:
                            message = self._conn.recv_msg()
                        except OSError:
                            break
                        if message is None:
                            break
                        if message.get_type() == "BAD_DATA":
                            continue
                        self.exchanges.append(Exchange(now, "rx", message))
                        self.model.handle(message, now)
                    self.model.tick(now)
                    for message in self.model.outbox.pop_due(now):
                        self.exchanges.append(Exchange(now, "tx", message))
                        try:
                            self._conn.mav.send(message)
                        except OSError:
                            pass  # nobody listening yet: UDP drops it, as it would
        finally:
            selector.close()
