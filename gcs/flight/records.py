"""What the ground-station core hands its recorder: typed, frozen records.

The core (`gcs.flight.core.GroundStation`) decides what happened; a recorder decides how to
keep it. Between them travel these value types, never loose dicts. Each record knows its own
JSON form (`to_json`), the payload of its MCAP topic (docs/outputs.md, "MCAP topics"): the
fields that are always written appear even when they are null, the optional ones are left out
when they are None. The JSON schemas the recorder registers (`gcs.recording.recording.SCHEMAS`) list
the same field names; a test keeps the two in step.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from enum import StrEnum
from typing import Any, ClassVar

Vector = list[float]


def _json(record: Any, always: frozenset[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name in record._FIELDS:
        value = getattr(record, name)
        if value is None and name not in always:
            continue
        out[name] = value.value if isinstance(value, StrEnum) else value
    return out


class _Record:
    """JSON form shared by the records: field order as declared, optional Nones left out."""

    __slots__ = ()
    _FIELDS: ClassVar[tuple[str, ...]] = ()
    #: Fields written even when None (the schema's required ones and the always-present ones).
    ALWAYS: ClassVar[frozenset[str]] = frozenset()

    def to_json(self) -> dict[str, Any]:
        return _json(self, self.ALWAYS)


def _declare(cls):
    """Freeze `cls` as a slotted dataclass and remember its field order for `to_json`."""
    cls = dataclass(frozen=True, slots=True)(cls)
    cls._FIELDS = tuple(f.name for f in fields(cls))
    return cls


@_declare
class SetpointRecord(_Record):
    """The setpoint streamed to one UAV at mission time `t` (topic `/uav<n>/setpoint`)."""

    ALWAYS: ClassVar[frozenset[str]] = frozenset(
        {"t", "uav", "position", "velocity", "acceleration", "virtual_target"}
    )

    t: float
    uav: int
    position: Vector  # local ENU, m
    velocity: Vector  # m/s
    acceleration: Vector  # m/s^2
    virtual_target: Vector  # the UAV's virtual target V_n(t) (eq. 27), m
    formation_speed: float
    distance: float  # the formation's travelled distance along the path, m
    latitude: float
    longitude: float
    altitude: float  # AMSL, m
    relative_altitude: float  # above the UAV's home, m


@_declare
class UavStateRecord(_Record):
    """One UAV's state (topic `/uav<n>/state`): a position sample the monitors checked, or,
    before the mission clock is anchored, what the UAV reported while connecting (`t` None)."""

    ALWAYS: ClassVar[frozenset[str]] = frozenset(
        {"t", "uav", "phase", "position", "true_position", "armed", "mode", "landed_state"}
    )

    t: float | None
    uav: int
    phase: str
    position: Vector | None  # as the UAV reports it (with its navigation noise)
    true_position: Vector | None  # the simulator's truth (SIM_STATE), when there is one
    armed: bool
    mode: int | None  # the autopilot's custom mode
    landed_state: int  # MAV_LANDED_STATE
    velocity: Vector | None = None
    virtual_target: Vector | None = None
    tracking_error_m: float | None = None


class SpeedRecordKind(StrEnum):
    """What a `/speed` record says about a speed change."""

    REQUEST = "request"  # the ground station broadcast it
    ACK = "ack"  # a UAV acknowledged it (and showed it in its telemetry)
    REFUSED = "refused"  # a UAV answered with a refusal
    UNANSWERED = "unanswered"  # a UAV never answered


@_declare
class SpeedRecord(_Record):
    """A speed change broadcast, or one UAV's answer to it (topic `/speed`)."""

    ALWAYS: ClassVar[frozenset[str]] = frozenset({"t", "kind", "seq"})

    t: float
    kind: SpeedRecordKind
    seq: int
    effective_s: float | None = None  # request: the mission time every UAV applies it
    speed: float | None = None  # request: m/s
    source: str | None = None  # request: schedule, operator, leader
    uav: int | None = None  # answers: which UAV
    reaction_s: float | None = None  # ack: mission seconds from broadcast to acknowledgement


@_declare
class MetricsRecord(_Record):
    """The monitors' figures at mission time `t` (topic `/metrics`)."""

    ALWAYS: ClassVar[frozenset[str]] = frozenset(
        {
            "t",
            "formation_speed",
            "distance",
            "min_uav_uav_m",
            "min_uav_obstacle_m",
            "max_tracking_error_m",
            "tracking_error_m",
            "connected",
            "positions",
        }
    )

    t: float
    formation_speed: float
    distance: float
    min_uav_uav_m: float | None  # smallest so far (None before any sample)
    min_uav_obstacle_m: float | None
    max_tracking_error_m: float | None
    tracking_error_m: list[float | None]  # per UAV, now
    connected: bool | None  # is every UAV chained to a base station now
    positions: list[Vector | None]  # the fleet the monitors checked (x, y, z; None: unknown)
    # since a relief: the UAVs out of the fleet (relieved and landed), left out of the checks;
    # while a relieved UAV flies above the chain the positions are (x, y, z), the checks 3-D
    out_of_fleet: list[int] | None = None
    # while the formation holds for UAVs behind (gcs.flight.hold): the UAVs it holds for
    holding: list[int] | None = None
    # lockstep (gcs.flight.lockstep): mission seconds the clock was held back for the
    # simulated world so far (log time = epoch + mission time lags the wall clock by this much
    # over the speed-up)
    world_held_s: float | None = None


@_declare
class RadioRecord(_Record):
    """The radio medium's counters at mission time `t` (topic `/radio`); `counters` is the
    medium's report as it sent it (packets, ground users, delays, per UAV)."""

    t: float
    counters: Mapping[str, Any]

    def to_json(self) -> dict[str, Any]:
        return {**self.counters, "t": self.t}


@_declare
class ReturnRecord(_Record):
    """The fleet's return home from its stations (topic `/return`, stations missions only):
    asked at mission time `t` by `source` (`schedule`: the mission's `return.at`; `dwell`:
    after every point's `dwell_s`; `on_station`: at once, nobody to ask; `operator`), flown
    from `effective_s` on, the formation standing still at distance `distance` (M) for one
    smoothing window before every UAV flies its way out backwards."""

    ALWAYS: ClassVar[frozenset[str]] = frozenset({"t", "effective_s", "distance", "source"})

    t: float
    effective_s: float
    distance: float  # M, m: V_n(S) = V_n(2 M - S) from there on
    source: str


@_declare
class ReliefRecord(_Record):
    """One UAV relieved from its station (topic `/relief`, stations missions only), asked at
    mission time `t` by `source` ("operator": `gcs relieve`; "battery": its battery below
    `stations.relieve_below_pct`): from `start_s` it climbs `lane_offset_m` above the chain
    (done at `climbed_s`), the UAVs of its gap close up (done at `closed_s`), it flies home
    above the route and stands above `landing` (a start-row slot) at `home_s`, then lands.
    `stations` is s_n per UAV afterwards (null: relieved), `holders` the UAV on each point
    (visiting order), `members` the UAVs still on station, by rank."""

    ALWAYS: ClassVar[frozenset[str]] = frozenset(
        {"t", "uav", "source", "start_s", "closed_s", "home_s", "landing"}
    )

    t: float
    uav: int
    source: str
    start_s: float
    climbed_s: float
    closed_s: float
    home_s: float
    landing: Vector
    lane_offset_m: float
    stations: list[float | None]
    holders: list[int]
    members: list[int]


#: The radio medium's report fields the run JSON's `radio` object keeps (docs/outputs.md).
RUN_JSON_KEYS = ("connected_fraction", "packets", "delay_ms", "ground_users", "hops", "per_uav")


def run_json_radio(report: dict | None) -> dict | None:
    """The run JSON's `radio` object from the medium's last report."""
    if report is None:
        return None
    return {key: report[key] for key in RUN_JSON_KEYS if key in report}
