"""A flight as a network scenario: what ns-3 needs to replay it (no ns-3 here).

A `NetScenario` holds the UAVs' true trajectories on a 10 Hz grid of mission time, the fixed
nodes (base stations, A first, and ground users, on the ground at z = 0), the radio range
rho_R, and the leaders' speed requests (when each leader sent one). It comes from a recording
of `gcs mission run` (`scenario_from_recording`) or from a fast run
(`scenario_from_fast_run`); `gcs.netsim.ns3.run_network` flies it in ns-3.

Positions are local ENU metres of the mission frame (x east, y north, z up from the take-off
ground). Before a UAV's first known sample it holds that first position, after its last one
the last (no NaN). A UAV is *flying* where it is more than `FLYING_ABOVE_M` above the ground
(`NetScenario.flying`): the handover gaps are measured there only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: Sample rate of the trajectories handed to ns-3 (Hz).
SAMPLE_HZ = 10.0
#: A UAV higher than this above the ground (z, m) is flying.
FLYING_ABOVE_M = 1.0


@dataclass(frozen=True)
class SpeedRequest:
    """A leader's speed-change request: the mission time `t` the leader sent it, and the
    leader's UAV id (1-based)."""

    t: float
    leader: int


@dataclass(frozen=True, eq=False)
class NetScenario:
    """One flight as ns-3 replays it (see the module docstring).

    `times` (T,) mission s on a 10 Hz grid; `uav_positions` (T, N, 3) local ENU m, finite;
    `base_stations` (B, 2), A first; `ground_users` (G, 2); `radio_range` rho_R (m);
    `altitude` the mission altitude (m, for the record: the range model's distance is the
    horizontal one unless `NetOptions.geometry` is "3d"); `requests` the leaders' speed
    requests; each UAV and each ground user sends `data_rate_bps` of UDP payload in packets of
    `packet_bytes`.
    """

    name: str
    times: np.ndarray
    uav_positions: np.ndarray
    base_stations: np.ndarray
    ground_users: np.ndarray
    radio_range: float
    altitude: float
    requests: tuple[SpeedRequest, ...]
    data_rate_bps: float = 800.0
    packet_bytes: int = 100
    #: `radio.buildings`: the obstacles that block links (`planner.sight.sight_json`), None:
    #: nothing; links through them live up to `nlos_range_m` (`medium.pathloss`; 0: cut)
    buildings: dict | None = None
    nlos_range_m: float = 0.0

    def __post_init__(self) -> None:
        times = np.asarray(self.times, dtype=float)
        positions = np.asarray(self.uav_positions, dtype=float)
        stations = np.asarray(self.base_stations, dtype=float).reshape(-1, 2)
        users = np.asarray(self.ground_users, dtype=float).reshape(-1, 2)
        if times.ndim != 1 or len(times) < 2:
            raise ValueError("times: expected at least two samples")
        if not (np.isfinite(times).all() and (np.diff(times) > 0).all()):
            raise ValueError("times: expected finite, increasing mission times")
        if positions.ndim != 3 or positions.shape[0] != len(times) or positions.shape[2] != 3:
            raise ValueError(f"uav_positions: expected ({len(times)}, N, 3), got {positions.shape}")
        if positions.shape[1] < 1:
            raise ValueError("uav_positions: expected at least one UAV")
        if not np.isfinite(positions).all():
            raise ValueError("uav_positions: expected finite positions (hold the first known)")
        if len(stations) < 1 or not np.isfinite(stations).all():
            raise ValueError("base_stations: expected at least one finite (x, y), A first")
        if not np.isfinite(users).all():
            raise ValueError("ground_users: expected finite (x, y)")
        if not (math.isfinite(self.radio_range) and self.radio_range > 0):
            raise ValueError(f"radio_range: expected a number > 0, got {self.radio_range}")
        if not (math.isfinite(self.data_rate_bps) and self.data_rate_bps > 0):
            raise ValueError(f"data_rate_bps: expected a number > 0, got {self.data_rate_bps}")
        if not 32 <= int(self.packet_bytes) <= 1400:
            raise ValueError(f"packet_bytes: expected 32 to 1400, got {self.packet_bytes}")
        for request in self.requests:
            if not 1 <= request.leader <= positions.shape[1]:
                raise ValueError(f"requests: leader {request.leader} is not a UAV of the fleet")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "uav_positions", positions)
        object.__setattr__(self, "base_stations", stations)
        object.__setattr__(self, "ground_users", users)
        object.__setattr__(self, "requests", tuple(sorted(self.requests, key=lambda r: r.t)))

    @property
    def fleet_size(self) -> int:
        return int(self.uav_positions.shape[1])

    @property
    def flying(self) -> np.ndarray:
        """(T, N) bool: the UAV is more than `FLYING_ABOVE_M` above the ground."""
        return self.uav_positions[..., 2] > FLYING_ABOVE_M

    @property
    def packet_interval_s(self) -> float:
        """Seconds between two data packets of one source."""
        return 8.0 * self.packet_bytes / self.data_rate_bps

    def describe(self) -> dict:
        """The scenario in a few JSON numbers."""
        return {
            "name": self.name,
            "uavs": self.fleet_size,
            "base_stations": self.base_stations.round(3).tolist(),
            "ground_users": self.ground_users.round(3).tolist(),
            "radio_range_m": float(self.radio_range),
            "altitude_m": float(self.altitude),
            "start_s": float(self.times[0]),
            "end_s": float(self.times[-1]),
            "samples": int(len(self.times)),
            "requests": [{"t": r.t, "leader": r.leader} for r in self.requests],
            "data_rate_bps": float(self.data_rate_bps),
            "packet_bytes": int(self.packet_bytes),
        }


def station_table(scenario: NetScenario) -> np.ndarray:
    """(T, N + G) int: at each sample, the base station each UAV, then each ground user, sends
    to: of the stations it reaches in the disk graph of rho_R (horizontal distances, ground
    users relaying nothing: `medium.radio`), the fewest hops away, the closest of those on a
    tie; the closest of all when it reaches none."""
    from medium.radio import topology

    stations = scenario.base_stations
    users = scenario.ground_users
    count = len(stations)
    table = np.empty((len(scenario.times), scenario.fleet_size + len(users)), dtype=np.int32)
    previous: list = [None] * count
    for k in range(len(scenario.times)):
        xy = scenario.uav_positions[k, :, :2]
        points = np.concatenate([xy, users])
        hops = np.empty((count, len(points)))
        for s in range(count):
            graph = topology(stations[s : s + 1], xy, scenario.radio_range, previous[s])
            previous[s] = graph
            hops[s] = np.concatenate([graph.hops, graph.hops_of_ground_nodes(users)])
        distance = np.hypot(*(points[None, :, :] - stations[:, None, :]).transpose(2, 0, 1))
        reached = hops >= 0
        # fewest hops first, then distance; unreachable stations after every reachable one
        key = np.where(reached, hops, np.inf) * 1e12 + distance
        key = np.where(reached.any(axis=0), key, distance)
        table[k] = np.argmin(key, axis=0)
    return table


def resample(tracks: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Each UAV's (times (K,), positions (K, 3)) on one 10 Hz grid spanning every track:
    (T,) and (T, N, 3), linear between samples, held before the first and after the last."""
    starts = [times[0] for times, _ in tracks]
    ends = [times[-1] for times, _ in tracks]
    step = 1.0 / SAMPLE_HZ
    first = math.floor(min(starts) * SAMPLE_HZ + 1e-6) / SAMPLE_HZ
    count = int(math.floor((max(ends) - first) * SAMPLE_HZ + 1e-6)) + 1
    grid = np.round(first + step * np.arange(max(count, 2)), 6)
    out = np.empty((len(grid), len(tracks), 3))
    for index, (times, positions) in enumerate(tracks):
        for axis in range(3):
            out[:, index, axis] = np.interp(grid, times, positions[:, axis])
    return grid, out


def _track(times: np.ndarray, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Finite samples, in time order, one per time (the last kept)."""
    times = np.asarray(times, dtype=float)
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    keep = np.isfinite(times) & np.isfinite(positions).all(axis=1)
    times, positions = times[keep], positions[keep]
    order = np.argsort(times, kind="stable")
    times, positions = times[order], positions[order]
    last = np.append(np.diff(times) > 0, True)
    return times[last], positions[last]


def scenario_from_fast_run(run, mission) -> NetScenario:
    """The scenario of a fast run (`gcs.sim.fastsim.FastRun`) of `mission`: its true
    positions, and each leader's request at the time the leader sent it."""
    times = np.asarray(run.times, dtype=float)
    positions = np.asarray(run.positions, dtype=float)
    if len(times) < 2:
        raise ValueError("the fast run has fewer than two samples")
    tracks = [_track(times, positions[:, k]) for k in range(positions.shape[1])]
    grid, resampled = resample(tracks)
    requests = []
    for change in run.speed_changes:
        source = str(change.get("source") or "")
        if not source.startswith("leader:"):
            continue
        sent = change.get("leader_sent_s")
        if sent is None:
            sent = change.get("requested_s")
        if sent is not None:
            requests.append(SpeedRequest(float(sent), int(source.split(":")[1])))
    return NetScenario(
        name=mission.name,
        times=grid,
        uav_positions=resampled,
        base_stations=mission.base_station_points,
        ground_users=_ground_users(mission),
        radio_range=float(mission.radio_range),
        altitude=float(mission.altitude),
        requests=tuple(requests),
        **_buildings(mission),
    )


def _buildings(mission) -> dict:
    """The scenario's `buildings` and `nlos_range_m` under the mission's `radio.buildings`."""
    from gcs.sim.medium_process import nlos_range
    from planner.sight import sight_json

    if mission is None or not mission.radio.buildings:
        return {}
    return {"buildings": sight_json(mission.obstacles), "nlos_range_m": nlos_range(mission)}


def _ground_users(mission) -> np.ndarray:
    return np.array([(u.x, u.y) for u in mission.ground_users], dtype=float).reshape(-1, 2)


def scenario_from_recording(path: Path) -> NetScenario:
    """The scenario of a recording of `gcs mission run` (MCAP): each UAV's true position
    (`/uav<n>/state` `true_position`, else `position`), the mission's base stations and ground
    users (the attached mission file; without it A and B from the plan, no ground user), and
    the leaders' requests (`/speed`). Bad input raises `InputError` (exit 2)."""
    from gcs.errors import InputError
    from gcs.recording.logreader import read_recording
    from gcs.recording.report import load_flight

    recording = read_recording(Path(path), keep=lambda topic: not topic.startswith("/mavlink/"))
    flight = load_flight(recording)  # InputError without a plan
    tracks = []
    for index, track in enumerate(flight.tracks):
        times, positions = _track(track.times, track.positions)
        if len(times) == 0:
            raise InputError(
                path, f"/uav{index + 1}/state", "the UAV's positions (the topic has none)"
            )
        tracks.append((times, positions))
    if max(len(times) for times, _ in tracks) < 2:
        raise InputError(path, "", "a recording with at least two samples of the UAVs")
    grid, resampled = resample(tracks)
    mission = flight.mission
    if mission is not None:
        stations = mission.base_station_points
        users = _ground_users(mission)
        altitude = float(mission.altitude)
    else:
        route = np.array(flight.plan["path"], dtype=float)
        stations = route[[0, -1]]
        users = np.zeros((0, 2))
        altitude = float(flight.plan.get("altitude_m") or np.nanmax(resampled[..., 2]))
    return NetScenario(
        name=flight.name,
        times=grid,
        uav_positions=resampled,
        base_stations=stations,
        ground_users=users,
        radio_range=float(flight.radio_range),
        altitude=altitude,
        requests=tuple(_recorded_requests(flight)),
        **_buildings(mission),
    )


def _recorded_requests(flight) -> list[SpeedRequest]:
    """Each leader's request of a recording. The ground station records when it received the
    request (`/speed` `t`); the mission file says when the leader sends it (its change's `at`):
    that time is used when the leader's changes in the mission and in the log match one to
    one, the recorded one otherwise."""
    recorded: dict[int, list[float]] = {}
    for request in flight.requests:
        source = str(request.get("source") or "")
        if source.startswith("leader:") and isinstance(request.get("t"), int | float):
            recorded.setdefault(int(source.split(":")[1]), []).append(float(request["t"]))
    planned: dict[int, list[float]] = {}
    if flight.mission is not None:
        for change in flight.mission.speed.changes:
            if change.leader is not None:
                planned.setdefault(change.leader, []).append(float(change.at))
    requests = []
    for leader, times in recorded.items():
        sent = sorted(planned.get(leader, []))
        received = sorted(times)
        if len(sent) == len(received) and all(
            s <= r + 1e-6 for s, r in zip(sent, received, strict=True)
        ):
            received = sent
        requests += [SpeedRequest(t, leader) for t in received]
    return requests
