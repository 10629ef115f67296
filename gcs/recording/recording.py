"""Flight recording: one MCAP file per run, written with foxglove-sdk (docs/outputs.md, MCAP).

Topics. Foxglove's well-known schemas (protobuf), so its panels work without configuration:
* `/uav<n>/fix` (`foxglove.LocationFix`): the position UAV n reports (Map panel);
  `/uav<n>/target`: the setpoint streamed to it, same type;
* `/scene` (`foxglove.SceneUpdate`): obstacles, margins, planned path, parking rows, base
  stations, ground users, UAVs, virtual targets and radio links (see `gcs.recording.scene`);
* `/tf` (`foxglove.FrameTransforms`): `map -> uav<n>` and `map -> uav<n>/target` every tick;
* `/events` (`foxglove.Log`); `/map/obstacles` and `/map/plan` (`foxglove.GeoJSON`, lon/lat:
  building footprints and walls; path, rows, stations), repeated every `GEOJSON_PERIOD_S`.
JSON with a titled JSON schema (`SCHEMAS`): `/plan`, `/uav<n>/setpoint`, `/uav<n>/state`,
`/speed` (requests, acknowledgements), `/return` (a stations mission's return home),
`/relief` (a UAV relieved from its station),
`/metrics` (per tick, with the fleet positions the monitors sampled), `/fleet` (per tick: the instant's smallest distances and radio links),
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
import logging
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import foxglove
import numpy as np
import yaml
from foxglove.channels import FrameTransformsChannel, GeoJsonChannel, LocationFixChannel, LogChannel
from foxglove.messages import GeoJson, LocationFix, Log, LogLevel, SceneUpdate, Timestamp

from fleetline.errors import FleetlineError
from gcs.flight.records import (
    MetricsRecord,
    RadioRecord,
    ReliefRecord,
    ReturnRecord,
    SetpointRecord,
    SpeedRecord,
    UavStateRecord,
)
from gcs.recording import scene
from gcs.recording.foxglove_front import FoxgloveFront
from planner.sight import Sight

log = logging.getLogger(__name__)

#: Recording profile written in the MCAP header.
PROFILE = "fleetline"
#: The writer is flushed at least this often (wall seconds) so a crash loses little.
FLUSH_PERIOD_S = 1.0
#: The GeoJSON map layers are repeated this often (mission seconds): late live clients and
#: a seek in Foxglove find them without going back to the start.
GEOJSON_PERIOD_S = 5.0


class LiveServerError(FleetlineError):
    """The live Foxglove server could not start (its port is taken)."""


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
    "return": _schema(
        "fleetline.Return",
        {"t": _NUM, "effective_s": _NUM, "distance": _NUM, "source": _STR},
        ["t", "effective_s", "distance", "source"],
    ),
    "relief": _schema(
        "fleetline.Relief",
        {
            "t": _NUM,
            "uav": _INT,
            "source": _STR,
            "start_s": _NUM,
            "climbed_s": _NUM,
            "closed_s": _NUM,
            "home_s": _NUM,
            "landing": _VEC,
            "lane_offset_m": _NUM,
            "stations": {"type": "array", "items": _NUM_OR_NULL},
            "holders": {"type": "array", "items": _INT},
            "members": {"type": "array", "items": _INT},
        },
        ["t", "uav", "source", "start_s", "closed_s", "home_s", "landing"],
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
            "out_of_fleet": {"type": "array", "items": _INT},
            "holding": {"type": "array", "items": _INT},
            "world_held_s": _NUM,
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
            "blocked_uav_links": {"type": "array", "items": _VEC},
            "blocked_station_links": {"type": "array", "items": _VEC},
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
    """Writes one run to an MCAP file (and, with `serve_port`, serves the same channels live
    over Foxglove's WebSocket protocol on 127.0.0.1; port 0 picks a free one, `server_port`).

    Every method takes the wall clock (`time.monotonic()`) of the thing recorded; the mission
    clock turns it into the log time. `describe(plan, ...)` records what the run is about
    (attachments, metadata, the static scene and map layers), `fleet(...)` the fleet at each
    tick, `outcome(...)` how it ended. `channel(topic, schema_key)` gives a JSON channel on this
    recorder's context, `write(channel, payload, wall)` logs with the shared time base.
    """

    #: Every setpoint and position sample is recorded (`gcs.flight.core.Recorder`).
    keeps_samples = True

    def __init__(
        self,
        path: Path,
        clock: TimeBase,
        *,
        force: bool = False,
        serve_port: int | None = None,
        allowed_origins: tuple[str, ...] = (),
        unix_now: Callable[[], int] = time.time_ns,
    ) -> None:
        self.path = Path(path)
        self.clock = clock
        self.context = foxglove.Context()
        # The sinks before any channel: anything logged on this context from now on is kept.
        # The server first: a port in use is refused before the file is created.
        self._server = None
        self._front: FoxgloveFront | None = None
        if serve_port is not None:
            self._server, self._front = _serve_live(self.context, serve_port, allowed_origins)
        try:
            self._writer = foxglove.open_mcap(
                self.path,
                allow_overwrite=force,
                context=self.context,
                writer_options=foxglove.mcap.MCAPWriteOptions(profile=PROFILE),
            )
        except BaseException:
            self._stop_serving()
            raise
        self._json: dict[str, foxglove.Channel] = {}
        self._fixes: dict[str, LocationFixChannel] = {}
        self._events = LogChannel("/events", context=self.context)
        self._tf = FrameTransformsChannel("/tf", context=self.context)
        self._scene = foxglove.Channel(
            "/scene",
            schema=SceneUpdate.get_schema(),
            message_encoding="protobuf",
            context=self.context,
        )
        self._geo = {
            topic: GeoJsonChannel(topic, context=self.context)
            for topic in ("/map/obstacles", "/map/plan")
        }
        self._geometry: scene.SceneGeometry | None = None
        self._static_scene = b""
        self._geojson: dict[str, str] = {}
        self._last_geojson: float | None = None
        self._pending: list[tuple[Callable[[int], None], float]] = []
        self._last_flush = time.monotonic()
        self._unix_now = unix_now
        self._clock_noted = False
        self.messages = 0
        self.closed = False
        #: why the file stopped being written (a full disk, an I/O error), None while it is
        self.error: str | None = None
        #: told once, with `error`, when writing fails (the run's events)
        self.on_error: Callable[[str], None] | None = None

    def _safely(self, action: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """`action(...)`, unless writing the file failed already; a failure (a full disk, an
        I/O error: foxglove-sdk raises RuntimeError, Python OSError) stops the file where it
        is, never the flight: the recording is what it wrote so far (readable up to its last
        chunk, like a cut one), the live server goes on."""
        if self.error is not None and self._server is None:
            return None
        try:
            return action(*args, **kwargs)
        except (RuntimeError, OSError) as error:
            self._failed(error)
            return None

    def _failed(self, error: BaseException) -> None:
        if self.error is not None:
            return
        self.error = f"writing {self.path} failed: {error}"
        log.error("%s: the recording stops here, the flight goes on", self.error)
        try:
            self._writer.close()
        except (RuntimeError, OSError):
            pass  # the file is cut where it was cut
        if self.on_error is not None:
            self.on_error(self.error)

    @property
    def server_port(self) -> int | None:
        """TCP port of the live Foxglove server (None without one)."""
        return None if self._front is None else self._front.port

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
        """Log `payload`: a dict (JSON channels), a foxglove message (typed channels) or bytes
        already encoded for the channel."""
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
        if self._pending or not self._clock_noted:
            self._drain_pending()
        self._safely(emit, self.clock.log_time_ns(wall))
        self.messages += 1
        if wall - self._last_flush >= FLUSH_PERIOD_S:
            self.flush(wall)

    def flush(self, wall: float | None = None) -> None:
        """Close the current chunk and write it to the file now."""
        self._last_flush = time.monotonic() if wall is None else wall
        if self.error is None:
            self._safely(self._writer.flush)

    def _drain_pending(self) -> None:
        if not self._clock_noted:
            self._clock_noted = True
            epoch = getattr(self.clock, "epoch_ns", None)
            speedup = getattr(self.clock, "speedup", None)
            self.metadata(
                "clock",
                {
                    "epoch_ns": str(epoch),
                    "speedup": repr(speedup),
                    "time_base": "log time = Unix ns at mission time 0 + mission time",
                },
            )
        pending, self._pending = self._pending, []
        for emit, wall in pending:
            self._safely(emit, self.clock.log_time_ns(wall))
            self.messages += 1

    def _t(self, wall: float) -> float | None:
        return round(self.clock.mission_time(wall), 6) if self.clock.anchored else None

    # ------------------------------------------------------------------ topics
    def plan(self, plan: dict, wall: float) -> None:
        self.write(self.channel("/plan", "plan"), plan, wall)

    def setpoint(self, record: SetpointRecord, wall: float) -> None:
        """The setpoint streamed to one UAV on `/uav<n>/setpoint`, and its geodetic position
        as a `foxglove.LocationFix` on `/uav<n>/target` (the commanded track on the Map panel)."""
        uav = record.uav
        self.write(self.channel(f"/uav{uav}/setpoint", "setpoint"), record.to_json(), wall)
        self._location(
            f"/uav{uav}/target",
            f"uav{uav}/target",
            record.latitude,
            record.longitude,
            record.altitude,
            wall,
        )

    def state(self, record: UavStateRecord, wall: float) -> None:
        self.write(self.channel(f"/uav{record.uav}/state", "state"), record.to_json(), wall)

    def speed(self, record: SpeedRecord, wall: float) -> None:
        self.write(self.channel("/speed", "speed"), record.to_json(), wall)

    def metrics(self, record: MetricsRecord, wall: float) -> None:
        self.write(self.channel("/metrics", "metrics"), record.to_json(), wall)

    def return_home(self, record: ReturnRecord, wall: float) -> None:
        """A stations mission's return home (`fleetline.Return` on `/return`)."""
        self.write(self.channel("/return", "return"), record.to_json(), wall)

    def relief(self, record: ReliefRecord, wall: float) -> None:
        """A UAV relieved from its station (`fleetline.Relief` on `/relief`)."""
        self.write(self.channel("/relief", "relief"), record.to_json(), wall)

    def fix(self, uav: int, latitude: float, longitude: float, altitude: float, wall: float):
        """A `foxglove.LocationFix` on `/uav<n>/fix` (Foxglove's Map panel)."""
        self._location(f"/uav{uav}/fix", f"uav{uav}", latitude, longitude, altitude, wall)

    def _location(
        self, topic: str, frame: str, latitude: float, longitude: float, altitude: float, wall
    ) -> None:
        channel = self._fixes.get(topic)
        if channel is None:
            channel = LocationFixChannel(topic, context=self.context)
            self._fixes[topic] = channel

        def emit(log_time: int) -> None:
            stamp = Timestamp(log_time // 1_000_000_000, log_time % 1_000_000_000)
            channel.log(
                LocationFix(
                    timestamp=stamp,
                    frame_id=frame,
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

    # ------------------------------------------------------------------ the run
    def describe(self, plan, plan_data: dict, wall: float) -> None:
        """What the run is about, recorded first so that the file stands alone: the mission
        file and its GeoJSON files and the plan JSON as attachments, `mission` metadata, the
        `/plan` message, the static scene and the map layers. `plan` is a valid
        `gcs.planning.MissionPlan`."""
        mission = plan.mission
        self.attach("mission.yaml", "application/yaml", mission.text.encode())
        for name, data in mission_geojson_files(mission).items():
            self.attach(f"geojson/{name}", "application/geo+json", data)
        self.attach("plan.json", "application/json", json.dumps(plan_data).encode())
        self.metadata(
            "mission",
            {
                "name": mission.name,
                "source": str(mission.source),
                "fleet_size": str(plan.fleet_size),
                "backend": mission.fleet.backend,
                "safety_margin_m": repr(mission.safety_margin),
                "radio_range_m": repr(mission.radio_range),
                "origin": json.dumps(
                    {
                        "lat": mission.origin.lat,
                        "lon": mission.origin.lon,
                        "alt": mission.origin.alt,
                    }
                ),
            },
        )
        self.plan(plan_data, wall)
        geometry = scene.SceneGeometry.from_plan(plan)
        self._geometry = geometry
        self._sight = Sight(geometry.obstacles)
        self._static_scene = scene.encode_static_scene(geometry)
        self._geojson = {
            "/map/obstacles": scene.obstacles_geojson(geometry),
            "/map/plan": scene.plan_geojson(geometry),
        }
        self.write(self._scene, self._static_scene, wall)
        self._write_geojson(wall)
        self.flush()

    def _write_geojson(self, wall: float) -> None:
        for topic, text in self._geojson.items():
            self.write(self._geo[topic], GeoJson(geojson=text), wall)

    def fleet(
        self, t: float, positions: np.ndarray, targets: np.ndarray | None, wall: float
    ) -> None:
        """The fleet at mission time `t`: positions (N, 3) in the local frame (NaN = unknown)
        and virtual targets V_n(t) (N, 2). Writes `/tf`, and once `describe` was called, the
        complete `/scene` with this instant's radio links and `/fleet` (the instant's smallest
        UAV-UAV and UAV-obstacle distances)."""
        positions = np.asarray(positions, float)

        def emit_tf(log_time: int) -> None:
            stamp = Timestamp(log_time // 1_000_000_000, log_time % 1_000_000_000)
            altitude = self._geometry.altitude if self._geometry is not None else 0.0
            self._tf.log(scene.transforms(positions, targets, altitude, stamp), log_time=log_time)

        self._emit(emit_tf, wall)
        geometry = self._geometry
        if geometry is None:
            return
        uav_pairs, station_pairs = scene.radio_links(
            positions, geometry.stations, geometry.radio_range
        )
        xy = positions[:, :2]
        blocked = ~self._sight.clear(
            np.concatenate([xy[uav_pairs[:, 0]], xy[station_pairs[:, 0]]]),
            np.concatenate([xy[uav_pairs[:, 1]], geometry.stations[station_pairs[:, 1]]]),
        )
        links = scene.links_update(positions, geometry.stations, uav_pairs, station_pairs, blocked)
        self.write(self._scene, self._static_scene + links, wall)
        xy = positions[:, :2]
        known = xy[np.isfinite(xy).all(axis=1)]
        if len(known):
            gaps = np.hypot(*(known[:, None, :] - known[None, :, :]).transpose(2, 0, 1))
            gaps[np.diag_indices(len(known))] = np.inf
            pair = float(gaps.min())
            obstacle = float(geometry.obstacles.distance_to_points(known).min())
        else:
            pair = obstacle = math.inf
        self.write(
            self.channel("/fleet", "fleet"),
            {
                "t": t,
                "uav_uav_m": pair if math.isfinite(pair) else None,
                "uav_obstacle_m": obstacle if math.isfinite(obstacle) else None,
                "radio_links": len(uav_pairs) + len(station_pairs),
                "uav_links": (uav_pairs + 1).tolist(),
                "station_links": [[u + 1, s] for u, s in station_pairs.tolist()],
                # ... of those, the ones whose chord meets an obstacle (no line of sight)
                "blocked_uav_links": (uav_pairs[blocked[: len(uav_pairs)]] + 1).tolist(),
                "blocked_station_links": [
                    [u + 1, s] for u, s in station_pairs[blocked[len(uav_pairs) :]].tolist()
                ],
            },
            wall,
        )
        if self._last_geojson is None or t - self._last_geojson >= GEOJSON_PERIOD_S:
            self._last_geojson = t
            self._write_geojson(wall)

    def radio(self, record: RadioRecord, wall: float) -> None:
        """Radio-medium counters (`fleetline.RadioCounters`: cumulative `packets` sent,
        received and dropped, `ground_users` likewise, optional `delay_ms` and `per_uav`) on
        `/radio`: `gcs log report` draws the packets received at base stations from them."""
        self.write(self.channel("/radio", "radio"), record.to_json(), wall)

    def outcome(self, run_data: dict) -> None:
        """How the run ended: the run JSON as an attachment and `outcome` metadata."""
        self.attach("run.json", "application/json", json.dumps(run_data).encode())
        keys = (
            "completed",
            "exit_status",
            "reason",
            "fleet_size",
            "duration_s",
            "min_uav_uav_m",
            "min_uav_obstacle_m",
            "max_tracking_error_m",
            "connected_fraction",
        )
        self.metadata("outcome", {k: json.dumps(run_data[k]) for k in keys if k in run_data})

    def attach(self, name: str, media_type: str, data: bytes) -> None:
        """An MCAP attachment (mission file, plan JSON...)."""
        now = self._unix_now()
        if self.error is None:
            self._safely(
                self._writer.attach,
                log_time=now,
                create_time=now,
                name=name,
                media_type=media_type,
                data=data,
            )

    def metadata(self, name: str, values: dict[str, str]) -> None:
        """An MCAP metadata record."""
        if self.error is None:
            self._safely(self._writer.write_metadata, name, values)

    def close(self) -> None:
        """Write what is still pending (with the wall clock if never anchored) and finish."""
        if self.closed:
            return
        if self._pending and not self.clock.anchored:
            # never anchored (the fleet never connected): keep the records on the Unix clock
            offset = self._unix_now() - int(time.monotonic() * 1e9)
            for emit, wall in self._pending:
                self._safely(emit, offset + int(wall * 1e9))
            self._pending = []
        elif self._pending:
            self._drain_pending()
        self.closed = True
        self._stop_serving()
        if self.error is None:
            self._safely(self._writer.close)

    def _stop_serving(self) -> None:
        if self._front is not None:
            self._front.close()
        if self._server is not None:
            self._server.stop()


def _serve_live(context: foxglove.Context, port: int, allowed_origins: tuple[str, ...] = ()):
    """foxglove-sdk's WebSocket server on a private loopback port behind a `FoxgloveFront` on
    127.0.0.1:`port` (clients of both subprotocol names; see `gcs.recording.foxglove_front`). A
    taken port is refused (`LiveServerError`) before anything else starts."""
    try:
        front = FoxgloveFront("127.0.0.1", port, allowed_origins)
    except OSError as error:
        raise LiveServerError(f"127.0.0.1:{port}: {error.strerror or error}") from None
    try:
        server = foxglove.start_server(context=context, host="127.0.0.1", port=0, name="fleetline")
    except BaseException:
        front.close()
        raise
    front.start(server.port)
    return server, front


def mission_geojson_files(mission) -> dict[str, bytes]:
    """The footprint files the mission names (`obstacles[i].geojson`, as a file name or as
    `{file: ...}`), by the name written in the mission file, read from beside it (the mission
    was validated: they exist). A shapefile brings its side files (`.shx`, `.dbf`, ...)."""
    from gcs.mission.footprints import SHAPEFILE_SIDES, footprint_file

    try:
        data = yaml.safe_load(mission.text) or {}
    except yaml.YAMLError:
        return {}
    files = {}
    folder = Path(mission.source).parent
    for item in data.get("obstacles") or []:
        name = footprint_file(item)
        if name is None:
            continue
        names = [name]
        if name.lower().endswith(".shp"):
            stem = name[: -len(".shp")]
            names += [stem + side for side in SHAPEFILE_SIDES if (folder / (stem + side)).exists()]
        for each in names:
            try:
                files[each] = (folder / each).read_bytes()
            except OSError:
                continue
    return files
