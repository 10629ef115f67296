"""The radio medium process: forwards MAVLink between the ground station and each UAV only
while a multi-hop radio path exists (the simulated world's network; model in `medium.radio`).

For UAV k the medium listens on its own UDP port (the ground station's link to UAV k points
there) and talks to the vehicle's port from that same socket, so the vehicle replies to it.
Every datagram, either way, is forwarded if and only if UAV k has a path to a base station at
the instant it arrives (the ground station is wired to every base station), after the hops'
delay, in order per direction; otherwise it is dropped. Hops, delays and drops are counted on
the simulated clock (`speedup` times the wall clock).

The UAVs' TRUE positions come from the vehicles' own `SIM_STATE` (the simulator's truth, 10 Hz)
as they pass through, moved on by their velocity for up to `position_horizon_s`; before the
first one a UAV is at its start point. Ground users send their packets here too (no datagrams:
they are counted as the model says). Every `report_period_s` the medium hands a report (the run
JSON's `radio` object, the instant's hops and positions, the recent packets' delays and hops)
to `report`.

`MediumModel` is the medium without its sockets (positions, paths, each packet's fate, data
sources, counters): this process and the fast in-process mode (`gcs.sim.fastsim`) both run it.
"""

from __future__ import annotations

import errno
import logging
import math
import selectors
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetline.errors import EXIT_BAD_INPUT, FleetlineError
from fleetwire.frames import frames
from fleetwire.geodesy import Origin
from fleetwire.worldclock import FollowerClock, WorldClockFollower
from medium.ground_users import (
    DEFAULT_PACKET_BYTES,
    CbrTraffic,
    GroundUser,
    GroundUsers,
    offer,
)
from medium.radio import Channel, DelayLine, RadioConfig, Topology, topology
from medium.radio_stats import RadioStats

log = logging.getLogger(__name__)

MAX_DATAGRAM = 65535
MAX_DATAGRAMS_PER_READ = 256
RECEIVE_BUFFER_BYTES = 1 << 20
_WORLD_POLL_S = 0.002  # longest wait (wall s) while the world clock holds the medium at its cap
_SIM_STATE = mavlink.MAVLink_sim_state_message
_SIM_STATE_FIELDS = {name: i for i, name in enumerate(_SIM_STATE.ordered_fieldnames)}
_TOPOLOGY_MAX_AGE_S = 0.01  # simulated seconds a computed topology is reused for


class MediumPortInUse(FleetlineError, OSError):
    """A port the medium must listen on is taken."""

    exit_status = EXIT_BAD_INPUT


@dataclass(frozen=True)
class MediumUav:
    """One UAV behind the medium: system id, the vehicle's UDP port, the medium's port for it
    (where the ground station sends), start position (local x, y)."""

    sysid: int
    vehicle_port: int
    listen_port: int
    start_xy: tuple[float, float]


@dataclass(frozen=True)
class MediumConfig:
    """Everything the medium process needs."""

    radio: RadioConfig
    stations: tuple[tuple[float, float], ...]
    uavs: tuple[MediumUav, ...]
    origin: Origin
    speedup: float = 1.0
    host: str = "127.0.0.1"
    ground_users: tuple[GroundUser, ...] = ()
    packet_bytes: int = DEFAULT_PACKET_BYTES
    sample_period_s: float = 0.1  # connectivity samples and ground-user sends (simulated s)
    report_period_s: float = 1.0  # simulated s
    position_horizon_s: float = 1.0
    world_clock: Path | None = None  # lockstep with the run's world clock (fleetwire.worldclock)
    world_slot: int = 0


def sim_state_position(payload: bytes, origin: Origin) -> tuple[np.ndarray, np.ndarray] | None:
    """True local (x, y) and velocity (east, north) from a `SIM_STATE` payload (MAVLink 2
    trims trailing zeros: they are put back); None if it holds no finite position."""
    size = _SIM_STATE.unpacker.size
    values = _SIM_STATE.unpacker.unpack(payload[:size].ljust(size, b"\0"))
    f = _SIM_STATE_FIELDS
    lat_int, lon_int = values[f["lat_int"]], values[f["lon_int"]]
    if lat_int or lon_int:
        lat, lon = lat_int * 1e-7, lon_int * 1e-7
    else:
        lat, lon = values[f["lat"]], values[f["lon"]]
    if not (math.isfinite(lat) and math.isfinite(lon)):
        return None
    local = origin.to_local(lat, lon, origin.alt)
    velocity = np.array([values[f["ve"]], values[f["vn"]]], dtype=float)
    if not np.isfinite(velocity).all():
        velocity = np.zeros(2)
    return local[:2], velocity


def offered_data_bps(
    ground_users: tuple[GroundUser, ...], uav_data_bps: float | None, fleet_size: int
) -> float:
    """The data the medium's sources offer together (bit/s): every UAV's data (when the
    medium sends it: the fast mode) and every ground user's. It picks the load level of the
    calibrated radio model (`medium.calibration`), measured with every UAV of a line sending
    data; the MAVLink traffic between the ground station and the UAVs is not counted."""
    users = sum(float(user.rate_bps) for user in ground_users)
    return users + (float(uav_data_bps) * fleet_size if uav_data_bps else 0.0)


class MediumModel:
    """The medium's decisions without sockets: where the UAVs are, which paths exist, each
    packet's hops and fate, the data sources and the counters. The medium process and the fast
    in-process mode (`gcs.sim.fastsim`) both run this."""

    def __init__(
        self,
        radio: RadioConfig,
        stations: np.ndarray,
        start_xy: np.ndarray,
        *,
        ground_users: tuple[GroundUser, ...] = (),
        uav_data_bps: float | None = None,
        packet_bytes: int = DEFAULT_PACKET_BYTES,
        sample_period_s: float = 0.1,
        position_horizon_s: float = 1.0,
        keep_packets: bool = False,
    ) -> None:
        self.radio = radio
        self.stations = np.asarray(stations, dtype=float).reshape(-1, 2)
        self.position = np.array(start_xy, dtype=float).reshape(-1, 2)
        count = len(self.position)
        self.velocity = np.zeros((count, 2))
        self.position_time = np.zeros(count)  # simulated s of each position sample
        self.position_horizon_s = position_horizon_s
        self.sample_period_s = sample_period_s
        self.stats = RadioStats(count, keep_packets=keep_packets)
        self.channel = Channel(
            radio, offered_load_bps=offered_data_bps(ground_users, uav_data_bps, count)
        )
        self.ground_users = GroundUsers(ground_users, packet_bytes)
        self.uav_data = CbrTraffic([uav_data_bps] * count, packet_bytes) if uav_data_bps else None
        self._topology: Topology | None = None  # None: the positions changed since
        self._last_topology: Topology | None = None  # the last one computed
        self._topology_time = -math.inf
        self._next_sample = 0.0
        self._reported = 0  # fleet packets already listed in a report

    def observe(self, uav: int, xy: np.ndarray, velocity: np.ndarray, sim_s: float) -> None:
        """A true position (and velocity) of UAV `uav` at `sim_s`."""
        self.position[uav], self.velocity[uav] = xy, velocity
        self.position_time[uav] = sim_s
        self._topology = None

    def observe_all(self, xy: np.ndarray, sim_s: float) -> None:
        """True positions (N, 2) of every UAV at `sim_s` (in-process: the truth itself)."""
        self.position[:] = xy
        self.velocity[:] = 0.0
        self.position_time[:] = sim_s
        self._topology = None

    def positions_at(self, sim_s: float) -> np.ndarray:
        """True horizontal positions (N, 2) at `sim_s`: last sample moved on by its velocity."""
        age = np.minimum(np.maximum(sim_s - self.position_time, 0.0), self.position_horizon_s)
        return self.position + self.velocity * age[:, None]

    def topology_at(self, sim_s: float) -> Topology:
        """The radio graph at `sim_s` (reused for _TOPOLOGY_MAX_AGE_S if nothing moved)."""
        if self._topology is None or abs(sim_s - self._topology_time) > _TOPOLOGY_MAX_AGE_S:
            self._topology = topology(
                self.stations,
                self.positions_at(sim_s),
                self.radio.range_m,
                self._last_topology,
                self.radio.sight,
            )
            self._last_topology = self._topology
            self._topology_time = sim_s
        return self._topology

    def route(self, kind: str, uav: int, sim_s: float) -> tuple[int, float | None]:
        """Hops and delay (s) of one packet to/from UAV `uav` sent at `sim_s` (delay None:
        dropped, no path or lost on a hop); counted in `stats`."""
        current = self._topology
        if current is None or abs(sim_s - self._topology_time) > _TOPOLOGY_MAX_AGE_S:
            current = self.topology_at(sim_s)
        hops = current.hop_counts[uav]
        delay = self.channel.transit(hops) if hops > 0 else None
        self.stats.packet(kind, uav, sim_s, hops, delay)
        return hops, delay

    def next_sample_s(self) -> float:
        return self._next_sample

    def periodic(self, sim_s: float) -> None:
        """When due: one connectivity sample, and the data sources' packets."""
        if sim_s < self._next_sample:
            return
        current = self.topology_at(sim_s)
        self.stats.sample(current)
        self.ground_users.send_due(sim_s, current, self.channel, self.stats)
        if self.uav_data is not None:
            offer(self.uav_data, sim_s, current.hops, "uav_data", self.channel, self.stats)
        self._next_sample = sim_s + self.sample_period_s

    def report(self, sim_s: float) -> dict:
        """The counters' summary, the instant's hops and positions, and the delays and hops of
        the packets delivered since the last report (`recent`: T_BS per packet)."""
        current = self.topology_at(sim_s)
        self._reported, recent = self.stats.recent(self._reported)
        return {
            "sim_s": sim_s,
            "connected": current.connected,
            **self.stats.summary(),
            "recent": recent,
            "hops_now": current.hops.tolist(),
            "positions": np.round(current.uav_xy, 3).tolist(),
            "links": len(current.uav_links) + len(current.station_links),
        }


class Medium:
    """The medium process's sockets around a `MediumModel`. Binds one UDP port per UAV at
    construction (a port in use raises `MediumPortInUse`)."""

    def __init__(self, config: MediumConfig) -> None:
        self.config = config
        count = len(config.uavs)
        self.model = MediumModel(
            config.radio,
            np.array(config.stations, dtype=float).reshape(-1, 2),
            np.array([u.start_xy for u in config.uavs], dtype=float).reshape(count, 2),
            ground_users=config.ground_users,
            packet_bytes=config.packet_bytes,
            sample_period_s=config.sample_period_s,
            position_horizon_s=config.position_horizon_s,
        )
        self._index_of_sysid = {u.sysid: k for k, u in enumerate(config.uavs)}
        self._vehicle = [(config.host, u.vehicle_port) for u in config.uavs]
        self._gcs: list[tuple[str, int] | None] = [None] * count
        self._delay = DelayLine()
        self._trace: Callable[[dict], None] | None = None
        world = None  # opened first: a bad file is refused before any socket is bound
        if config.world_clock is not None:
            world = WorldClockFollower(config.world_clock, config.world_slot)
        self.clock = FollowerClock(config.speedup, time.monotonic(), world)
        self.sockets: list[socket.socket] = []
        self._selector = selectors.DefaultSelector()
        try:
            for k, uav in enumerate(config.uavs):
                sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                self.sockets.append(sock)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
                try:
                    sock.bind((config.host, uav.listen_port))
                except OSError as exc:
                    if exc.errno == errno.EADDRINUSE:
                        raise MediumPortInUse(
                            exc.errno, f"UDP {config.host}:{uav.listen_port} is already in use"
                        ) from exc
                    raise
                sock.setblocking(False)
                self._selector.register(sock, selectors.EVENT_READ, k)
        except OSError:
            self.close()
            raise

    def close(self) -> None:
        for sock in self.sockets:
            sock.close()
        self._selector.close()
        self.clock.leave(time.monotonic())

    # ------------------------------------------------------------------ clock
    def sim_now(self, wall: float | None = None) -> float:
        """Simulated seconds since the medium started (the world's time plus an offset, once
        the world clock runs: the medium never forwards ahead of the ground station)."""
        return self.clock.now(time.monotonic() if wall is None else wall)

    def _wall_at(self, sim_s: float) -> float:
        return self.clock.wall_at(sim_s)

    # ------------------------------------------------------------------ the loop
    def run(
        self,
        should_stop: Callable[[], bool],
        report: Callable[[dict], None] | None = None,
        trace: Callable[[dict], None] | None = None,
    ) -> None:
        """Forward until `should_stop()`; `report` gets the periodic reports (and a last one),
        `trace` (tests, debugging) one record per datagram."""
        cfg = self.config
        model = self.model
        self._trace = trace
        next_report = cfg.report_period_s
        clock = self.clock
        while not should_stop():
            now = time.monotonic()
            clock.refresh(now)
            due = self._delay.next_due()
            wake = min(model.next_sample_s(), next_report, due)
            timeout = min(max(self._wall_at(wake) - now, 0.0), 0.1)
            if clock.joined:  # the world may hold the medium at its cap: look again soon
                timeout = min(timeout, _WORLD_POLL_S)
            for key, _ in self._selector.select(timeout):
                self._read(key.data)
            sim_s = self.sim_now()
            self._deliver(sim_s)
            clock.advanced_to(sim_s)
            model.periodic(sim_s)
            if sim_s >= next_report:
                if report is not None:
                    report(model.report(sim_s))
                next_report = sim_s + cfg.report_period_s
        if report is not None:
            report(model.report(self.sim_now()))

    def _read(self, uav: int) -> None:
        sock = self.sockets[uav]
        for _ in range(MAX_DATAGRAMS_PER_READ):
            try:
                data, address = sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # e.g. ICMP port unreachable from a vanished peer
                log.debug("UAV %d: receive error %s", uav + 1, exc)
                continue
            sim_s = self.sim_now()
            if address == self._vehicle[uav]:
                self._uplink(uav, data, sim_s)
            else:
                self._gcs[uav] = address
                self._forward("downlink", uav, data, sim_s, self._vehicle[uav])
            self._deliver(sim_s)

    def _uplink(self, uav: int, data: bytes, sim_s: float) -> None:
        for msgid, sysid, payload in frames(data):
            if msgid == _SIM_STATE.id and self._index_of_sysid.get(sysid) == uav:
                truth = sim_state_position(payload, self.config.origin)
                if truth is not None:
                    self.model.observe(uav, truth[0], truth[1], sim_s)
        destination = self._gcs[uav]
        if destination is None:  # nobody to talk to yet (the GCS has not spoken)
            return
        self._forward("uplink", uav, data, sim_s, destination)

    def _forward(
        self, kind: str, uav: int, data: bytes, sim_s: float, destination: tuple[str, int]
    ) -> None:
        hops, delay = self.model.route(kind, uav, sim_s)
        if self._trace is not None:
            x, y = self.model.positions_at(sim_s)[uav].tolist()
            self._trace(
                {
                    "sim_s": sim_s,
                    "kind": kind,
                    "uav": uav + 1,
                    "msgids": [msgid for msgid, _, _ in frames(data)],
                    "hops": hops,
                    "delay_ms": None if delay is None else delay * 1000.0,
                    "xy": [x, y],
                }
            )
        if delay is not None:
            self._delay.put((uav, kind), sim_s + delay, (uav, data, destination))

    def _deliver(self, sim_s: float) -> None:
        for _, (uav, data, destination) in self._delay.pop_due(sim_s):
            try:
                self.sockets[uav].sendto(data, destination)
            except OSError as exc:  # a vanished peer, a full buffer: UDP drops it
                log.debug("UAV %d: send to %s failed: %s", uav + 1, destination, exc)
