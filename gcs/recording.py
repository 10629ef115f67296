"""Flight recording: one MCAP file per run, written with foxglove-sdk (CONTRACTS.md, MCAP).

Topics. Foxglove's well-known schemas (protobuf), so its panels work without configuration:
* `/uav<n>/fix` (`foxglove.LocationFix`): the position UAV n reports (Map panel);
  `/uav<n>/target`: the setpoint streamed to it, same type;
* `/scene` (`foxglove.SceneUpdate`): obstacles, margins, planned path, parking rows, base
  stations, ground users, UAVs, virtual targets and radio links (see `gcs.scene`);
* `/tf` (`foxglove.FrameTransforms`): `map -> uav<n>` and `map -> uav<n>/target` every tick;
* `/events` (`foxglove.Log`); `/map/obstacles` and `/map/plan` (`foxglove.GeoJSON`, lon/lat:
  building footprints and walls; path, rows, stations), repeated every `GEOJSON_PERIOD_S`.
JSON with a titled JSON schema (`SCHEMAS`): `/plan`, `/uav<n>/setpoint`, `/uav<n>/state`,
`/speed` (requests, acknowledgements), `/metrics` (per tick, with the fleet positions the
monitors sampled), `/fleet` (per tick: the instant's smallest distances and radio links),
`/radio` (radio-medium counters, when a medium reports them), `/mavlink/<n>/rx|tx` (every
MAVLink message: raw bytes in base64 plus the decoded fields).

Attachments: the mission file (`mission.yaml`), the GeoJSON files it names
(`geojson/<name as written in the mission>`), the plan JSON (`plan.json`) and, at the end, the
run JSON (`run.json`). Metadata records: `mission` (name, source, fleet size...), `clock`
(Unix ns at mission time 0, speedup; written when the clock is anchored) and `outcome`
(completed, exit status, reason; written at the end: a recording without it did not finish).
foxglove-sdk 0.30's `MCAPWriter` writes attachments and metadata into the live file itself
(`attach`, `write_metadata`), so a recording killed mid-flight keeps everything written up to
its last flush; nothing is added afterwards.

Durability: chunked, zstd-compressed (foxglove-sdk's defaults), and flushed (the chunk is
closed and written to the file) at least every `FLUSH_PERIOD_S` of wall time while messages
arrive: a GCS killed with SIGKILL leaves a file readable up to about a second before.

Time base: log time = the GCS's wall clock (Unix ns) at mission time 0 plus the mission time,
for every topic. The mission clock is anchored only once the fleet is connected; what is
recorded before that (the connection handshake) is kept in memory and written, with its
proper log time, as soon as the clock is anchored.

foxglove-sdk traps avoided here: every channel gets this recorder's own `foxglove.Context`
(never the global one), channels are created and used only after `open_mcap` attached the
file sink (messages logged with no sink are dropped silently), an existing file is refused
unless `force`, and JSON schemas carry a `title`.
"""

from __future__ import annotations

import base64
import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import foxglove
import numpy as np
from foxglove.channels import FrameTransformsChannel, GeoJsonChannel, LocationFixChannel, LogChannel
from foxglove.messages import GeoJson, LocationFix, Log, LogLevel, SceneUpdate, Timestamp

from gcs import scene

#: Recording profile written in the MCAP header.
PROFILE = "fleetline"
#: The writer is flushed at least this often (wall seconds) so a crash loses little.
FLUSH_PERIOD_S = 1.0
#: The GeoJSON map layers are repeated this often (mission seconds): late live clients and
#: a seek in Foxglove find them without going back to the start.
GEOJSON_PERIOD_S = 5.0


class TimeBase(Protocol):
    """What the recorder needs of the mission clock."""

    @property
    def anchored(self) -> bool: ...

    def log_time_ns(self, wall: float) -> int: ...

    def mission_time(self, wall: float) -> float: ...


def _schema(title: str, properties: dict[str, Any], required: list[str] | None = None) -> dict:
    schema: dict[str, Any] = {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "type": "object",
        "properties": properties,
    }
    if required:
        schema["required"] = required
    return schema


_NUM = {"type": "number"}
_NUM_OR_NULL = {"type": ["number", "null"]}
_VEC = {"type": "array", "items": {"type": "number"}}
_VEC_OR_NULL = {"type": ["array", "null"], "items": {"type": "number"}}
_INT = {"type": "integer"}
_STR = {"type": "string"}

#: JSON schemas of the JSON topics (titles are what Foxglove shows as schema names).
SCHEMAS: dict[str, dict] = {
    "plan": _schema("fleetline.Plan", {"path": {"type": "array"}, "fleet_size": _INT}),
    "setpoint": _schema(
        "fleetline.Setpoint",
        {
            "t": _NUM,
            "uav": _INT,
            "position": _VEC,
            "velocity": _VEC,
            "acceleration": _VEC,
            "virtual_target": _VEC,
            "formation_speed": _NUM,
            "distance": _NUM,
            "latitude": _NUM,
            "longitude": _NUM,
            "altitude": _NUM,
            "relative_altitude": _NUM,
        },
        ["t", "uav", "position"],
    ),
    "state": _schema(
        "fleetline.UavState",
        {
            "t": _NUM,
            "uav": _INT,
            "phase": _STR,
            "position": _VEC_OR_NULL,
            "true_position": _VEC_OR_NULL,
            "velocity": _VEC_OR_NULL,
            "virtual_target": _VEC_OR_NULL,
            "tracking_error_m": _NUM_OR_NULL,
            "armed": {"type": "boolean"},
            "mode": {"type": ["integer", "null"]},
            "landed_state": _INT,
        },
        ["t", "uav", "phase"],
    ),
    "speed": _schema(
        "fleetline.SpeedChange",
        {
            "t": _NUM,
            "kind": {"enum": ["request", "ack", "refused", "unanswered"]},
            "seq": _INT,
            "effective_s": _NUM,
            "speed": _NUM,
            "source": _STR,
            "uav": _INT,
            "reaction_s": _NUM,
        },
        ["t", "kind"],
    ),
    "metrics": _schema(
        "fleetline.Metrics",
        {
            "t": _NUM,
            "formation_speed": _NUM,
            "distance": _NUM,
            "min_uav_uav_m": _NUM_OR_NULL,
            "min_uav_obstacle_m": _NUM_OR_NULL,
            "max_tracking_error_m": _NUM_OR_NULL,
            "tracking_error_m": {"type": "array", "items": _NUM_OR_NULL},
            "connected": {"type": ["boolean", "null"]},
            "positions": {"type": "array", "items": _VEC_OR_NULL},
        },
        ["t"],
    ),
    "fleet": _schema(
        "fleetline.FleetSample",
        {
            "t": _NUM,
            "uav_uav_m": _NUM_OR_NULL,
            "uav_obstacle_m": _NUM_OR_NULL,
            "radio_links": _INT,
            "uav_links": {"type": "array", "items": _VEC},
            "station_links": {"type": "array", "items": _VEC},
        },
        ["t"],
    ),
    "radio": _schema(
        "fleetline.RadioCounters",
        {
            "t": _NUM,
            "packets": {"type": "object"},
            "ground_users": {"type": "object"},
            "delay_ms": {"type": "object"},
            "per_uav": {"type": "array"},
        },
        ["t"],
    ),
    "mavlink": _schema(
        "fleetline.MavlinkMessage",
        {
            "t": _NUM_OR_NULL,
            "direction": {"enum": ["rx", "tx"]},
            "msgid": _INT,
            "type": _STR,
            "sysid": _INT,
            "compid": _INT,
            "raw": {"type": "string", "contentEncoding": "base64"},
            "fields": {"type": "object"},
        },
        ["direction", "msgid", "type", "raw"],
    ),
}

_LEVELS = {
    "debug": LogLevel.Debug,
    "info": LogLevel.Info,
    "warning": LogLevel.Warning,
    "error": LogLevel.Error,
    "fatal": LogLevel.Fatal,
}


def _fields_json(message) -> str:
    """The decoded fields of a pymavlink message as strict JSON (NaN -> null, char[] -> str)."""
    fields = {name: getattr(message, name) for name in message.get_fieldnames()}
    try:
        return json.dumps(fields, allow_nan=False, separators=(",", ":"))
    except (ValueError, TypeError):
        for key, value in fields.items():
            if isinstance(value, float) and not math.isfinite(value):
                fields[key] = None
            elif isinstance(value, bytes | bytearray):
                fields[key] = bytes(value).decode(errors="backslashreplace").rstrip("\x00")
            elif isinstance(value, list):
                fields[key] = [
                    None if isinstance(v, float) and not math.isfinite(v) else v for v in value
                ]
        return json.dumps(fields, allow_nan=False, separators=(",", ":"))


class FlightRecorder:
    """Writes one run to an MCAP file. Every method takes the wall clock (`time.monotonic()`)
    of the thing recorded; the mission clock turns it into the log time.

    Subclass or wrap it to add topics (scene, transforms, attachments): `channel(topic,
    schema_key)` gives a JSON channel on this recorder's context, `context` the foxglove
    context for typed channels, `write(channel, payload, wall)` logs with the shared time base.
    """

    def __init__(
        self,
        path: Path,
        clock: TimeBase,
        *,
        force: bool = False,
        serve_port: int | None = None,
        unix_now: Callable[[], int] = time.time_ns,
    ) -> None:
        self.path = Path(path)
        self.clock = clock
        self.context = foxglove.Context()
        # The sink first: anything logged on a channel of this context from now on is kept.
        self._writer = foxglove.open_mcap(
            self.path,
            allow_overwrite=force,
            context=self.context,
            writer_options=foxglove.mcap.MCAPWriteOptions(profile=PROFILE),
        )
        self._server = (
            foxglove.start_server(context=self.context, port=serve_port, name="fleetline")
            if serve_port is not None
            else None
        )
        self._json: dict[str, foxglove.Channel] = {}
        self._fixes: dict[int, LocationFixChannel] = {}
        self._events = LogChannel("/events", context=self.context)
        self._pending: list[tuple[Callable[[int], None], float]] = []
        self._last_flush = time.monotonic()
        self._unix_now = unix_now
        self.messages = 0
        self.closed = False

    # ------------------------------------------------------------------ generic
    def channel(self, topic: str, schema_key: str) -> foxglove.Channel:
        """The JSON channel of `topic` (created on first use) with schema `SCHEMAS[schema_key]`."""
        channel = self._json.get(topic)
        if channel is None:
            channel = foxglove.Channel(
                topic, schema=SCHEMAS[schema_key], message_encoding="json", context=self.context
            )
            self._json[topic] = channel
        return channel

    def write(self, channel, payload: Any, wall: float) -> None:
        """Log `payload` (a dict for JSON channels, a foxglove message for typed ones)."""
        if isinstance(payload, dict):
            data = json.dumps(payload, allow_nan=False, separators=(",", ":")).encode()
        else:
            data = payload

        def emit(log_time: int, channel=channel, data=data) -> None:
            channel.log(data, log_time=log_time)

        self._emit(emit, wall)

    def _emit(self, emit: Callable[[int], None], wall: float) -> None:
        if self.closed:
            return
        if not self.clock.anchored:
            self._pending.append((emit, wall))
            return
        if self._pending:
            self._drain_pending()
        emit(self.clock.log_time_ns(wall))
        self.messages += 1
        if wall - self._last_flush >= FLUSH_PERIOD_S:
            self._last_flush = wall
            self._writer.flush()

    def _drain_pending(self) -> None:
        pending, self._pending = self._pending, []
        for emit, wall in pending:
            emit(self.clock.log_time_ns(wall))
            self.messages += 1

    def _t(self, wall: float) -> float | None:
        return round(self.clock.mission_time(wall), 6) if self.clock.anchored else None

    # ------------------------------------------------------------------ topics
    def plan(self, plan: dict, wall: float) -> None:
        self.write(self.channel("/plan", "plan"), plan, wall)

    def setpoint(self, uav: int, payload: dict, wall: float) -> None:
        self.write(self.channel(f"/uav{uav}/setpoint", "setpoint"), payload, wall)

    def state(self, uav: int, payload: dict, wall: float) -> None:
        self.write(self.channel(f"/uav{uav}/state", "state"), payload, wall)

    def speed(self, payload: dict, wall: float) -> None:
        self.write(self.channel("/speed", "speed"), payload, wall)

    def metrics(self, payload: dict, wall: float) -> None:
        self.write(self.channel("/metrics", "metrics"), payload, wall)

    def fix(self, uav: int, latitude: float, longitude: float, altitude: float, wall: float):
        """A `foxglove.LocationFix` on `/uav<n>/fix` (Foxglove's Map panel)."""
        channel = self._fixes.get(uav)
        if channel is None:
            channel = LocationFixChannel(f"/uav{uav}/fix", context=self.context)
            self._fixes[uav] = channel

        def emit(log_time: int) -> None:
            stamp = Timestamp(log_time // 1_000_000_000, log_time % 1_000_000_000)
            channel.log(
                LocationFix(
                    timestamp=stamp,
                    frame_id=f"uav{uav}",
                    latitude=latitude,
                    longitude=longitude,
                    altitude=altitude,
                ),
                log_time=log_time,
            )

        self._emit(emit, wall)

    def event(self, level: str, message: str, wall: float, name: str = "gcs") -> None:
        """A `foxglove.Log` on `/events`: level is debug|info|warning|error|fatal."""

        def emit(log_time: int) -> None:
            stamp = Timestamp(log_time // 1_000_000_000, log_time % 1_000_000_000)
            self._events.log(
                Log(timestamp=stamp, level=_LEVELS[level], message=message, name=name),
                log_time=log_time,
            )

        self._emit(emit, wall)

    def mavlink(self, uav: int, direction: str, raw: bytes, message, wall: float) -> None:
        """One MAVLink message exchanged with UAV `uav` ("rx" or "tx"): raw bytes (base64) and
        the decoded fields. Built as a JSON string directly: this runs for every message."""
        t = self._t(wall)
        data = (
            f'{{"t":{"null" if t is None else repr(t)},"direction":"{direction}",'
            f'"msgid":{message.get_msgId()},"type":"{message.get_type()}",'
            f'"sysid":{message.get_srcSystem()},"compid":{message.get_srcComponent()},'
            f'"raw":"{base64.b64encode(raw).decode()}","fields":{_fields_json(message)}}}'
        ).encode()
        self.write(self.channel(f"/mavlink/{uav}/{direction}", "mavlink"), data, wall)

    def attach(self, name: str, media_type: str, data: bytes) -> None:
        """An MCAP attachment (mission file, plan JSON...)."""
        now = self._unix_now()
        self._writer.attach(
            log_time=now, create_time=now, name=name, media_type=media_type, data=data
        )

    def metadata(self, name: str, values: dict[str, str]) -> None:
        """An MCAP metadata record."""
        self._writer.write_metadata(name, values)

    def close(self) -> None:
        """Write what is still pending (with the wall clock if never anchored) and finish."""
        if self.closed:
            return
        if self._pending and not self.clock.anchored:
            # never anchored (the fleet never connected): keep the records on the Unix clock
            offset = self._unix_now() - int(time.monotonic() * 1e9)
            for emit, wall in self._pending:
                emit(offset + int(wall * 1e9))
            self._pending = []
        elif self._pending:
            self._drain_pending()
        self.closed = True
        if self._server is not None:
            self._server.stop()
        self._writer.close()

    def __enter__(self) -> FlightRecorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
