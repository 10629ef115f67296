"""Many simulated vehicles in one process: sockets, the simulated clock and the main loop.

The simulated clock runs ``speedup`` times faster than the wall clock. The dynamics of every
vehicle of the process advance together (vectorised) in fixed steps; the autopilots run at the
control rate; at each wake-up the loop integrates as many steps as the wall clock asks for, so a
high speedup costs no more wake-ups than real time. Every datagram keeps its kernel arrival
time and each message reaches its autopilot when the simulated clock reaches that time,
interleaved with the steps: a process briefly starved of CPU replays its input in order instead
of flying on stale setpoints, over as many wake-ups as the catching up takes (a message waits for
the wake-up whose steps reach its arrival). If the process falls more than ``max_lag_s`` (wall
clock) behind, the simulated clock slips instead of racing to catch up, and every vehicle
reports it.

With a world clock (``SimConfig.world_clock``, `fleetwire.worldclock`) the simulated clock is
the world's once the ground station's mission clock runs: it never passes the ground station's
last tick by more than a lead (a stopped ground station pauses these vehicles instead of
letting their setpoint timeouts fire), it reports how far it has got (a starved vehicle process
makes the ground station wait instead of tearing the formation), and it never slips. Orphaned
(the ground station gone), it runs on the wall clock again: the failsafes bring the vehicles
down.
"""

from __future__ import annotations

import logging
import selectors
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fleetwire.geodesy import Origin
from fleetwire.worldclock import FollowerClock, WorldClockFollower
from vehicles.autopilot import Autopilot, AutopilotConfig, Stamp
from vehicles.dynamics import DynamicsConfig, FleetDynamics
from vehicles.fleet_speed import LeaderRequest
from vehicles.link import Address, VehicleLink
from vehicles.signing import deliver_setup_signing, report_refusals
from vehicles.telemetry import FleetSnapshot

log = logging.getLogger(__name__)

DEFAULT_ORIGIN = Origin(45.7640, 4.8357, 170.0)
_EPOLL_RESOLUTION_S = 0.001
_MAX_TICKS_PER_WAKE = 10
#: Clock slips are reported at most this often (wall s), each report with the total since the
#: last: the ground station moves its vehicle clocks by it (a slip held back 5 s, as before,
#: left its samples mapped a second early for that long).
_SLIP_REPORT_INTERVAL_S = 1.0
#: Longest wait (wall s) while the world clock holds this process at its cap.
_WORLD_POLL_S = 0.002


@dataclass(frozen=True)
class VehicleSpec:
    """One vehicle: its system id, UDP port, start position (local ENU metres) and battery
    capacity (mAh; None: the airframe's)."""

    sysid: int
    port: int
    start_enu: tuple[float, float, float]
    battery_mah: float | None = None


@dataclass(frozen=True)
class SimConfig:
    """A process worth of vehicles and how to run them."""

    vehicles: tuple[VehicleSpec, ...]
    host: str = "127.0.0.1"
    out: Address | None = None
    speedup: float = 1.0
    seed: int = 0
    origin: Origin = DEFAULT_ORIGIN
    dynamics: DynamicsConfig = field(default_factory=DynamicsConfig)
    autopilot: AutopilotConfig = field(default_factory=AutopilotConfig)
    leader_sysid: int | None = None
    leader_requests: tuple[LeaderRequest, ...] = ()
    control_rate_hz: float = 50.0
    max_lag_s: float = 5.0
    signing_key: bytes | None = None  # MAVLink 2 signing for every vehicle (see link.make_codec)
    world_clock: Path | None = None  # the run's world clock file (fleetwire.worldclock)
    world_slot: int = 0  # this process's slot in it


@dataclass(frozen=True)
class Arrival:
    """A message read from vehicle ``vehicle``'s socket, stamped with when it arrived."""

    stamp: Stamp
    vehicle: int
    message: object


@dataclass
class SimStats:
    wall_s: float = 0.0
    sim_s: float = 0.0
    slipped_sim_s: float = 0.0
    wakeups: int = 0


class Simulation:
    """Binds every vehicle's socket at construction (a port in use raises PortInUseError)."""

    def __init__(self, config: SimConfig) -> None:
        self.config = config
        self.links: list[VehicleLink] = []
        world = None  # opened first: a bad file is refused before any socket is bound
        if config.world_clock is not None:
            world = WorldClockFollower(config.world_clock, config.world_slot)
        try:
            for spec in config.vehicles:
                self.links.append(
                    VehicleLink(spec.sysid, config.host, spec.port, config.out, config.signing_key)
                )
        except OSError:
            self.close()
            raise
        starts = np.array([spec.start_enu for spec in config.vehicles], dtype=float).reshape(-1, 3)
        seeds = [(config.seed, spec.sysid) for spec in config.vehicles]
        default_mah = config.dynamics.airframe.battery_capacity_mah
        capacities = [
            default_mah if spec.battery_mah is None else spec.battery_mah
            for spec in config.vehicles
        ]
        self.dynamics = FleetDynamics(config.dynamics, starts, seeds, capacities)
        count = len(config.vehicles)
        self.autopilots = [
            Autopilot(
                sysid=spec.sysid,
                index=k,
                count=count,
                config=config.autopilot,
                dynamics=self.dynamics,
                origin=config.origin,
                leader_requests=config.leader_requests if spec.sysid == config.leader_sysid else (),
            )
            for k, spec in enumerate(config.vehicles)
        ]
        self.stats = SimStats()
        self._selector = selectors.DefaultSelector()
        for k, link in enumerate(self.links):
            self._selector.register(link.socket, selectors.EVENT_READ, k)
        step_s = config.dynamics.step_s
        self._steps_per_tick = max(1, round(1.0 / (config.control_rate_hz * step_s)))
        self._steps = 0
        self.clock = FollowerClock(config.speedup, 0.0, world)
        self._slip_unreported = 0.0
        self._slip_reported_wall = float("-inf")
        self._waiting: list[Arrival] = []  # read, not yet due (the clock is catching up)

    def close(self) -> None:
        for link in self.links:
            link.close()
        if hasattr(self, "_selector"):
            self._selector.close()
        if hasattr(self, "clock"):
            self.clock.leave(time.monotonic())

    def land_before_stopping(self) -> bool:
        """Asked to stop: every vehicle still in the air lands first (on the wall clock: the
        ground station that held the world may be gone). True once none is armed any more:
        the process may stop then."""
        if not any(autopilot.armed for autopilot in self.autopilots):
            return True
        self.leave_world()
        stamp = Stamp(self.sim_time(), time.monotonic())
        for autopilot in self.autopilots:
            autopilot.land_before_stopping(stamp)
        return False

    def leave_world(self) -> None:
        """Run on the wall clock from now on (the ground station is gone)."""
        if self.clock.world is not None:
            log.warning("ground station gone: the vehicles leave the world clock")
            self.clock.leave(time.monotonic())

    def sim_time(self) -> float:
        return self._steps * self.config.dynamics.step_s

    def _sim_now(self, wall: float) -> float:
        """The exact simulated time at wall-clock ``wall`` (between steps)."""
        return self.clock.now(wall)

    def run(self, should_stop: Callable[[], bool]) -> SimStats:
        """Run until ``should_stop()`` is true (checked at every wake-up)."""
        cfg = self.config
        step_s = cfg.dynamics.step_s
        tick_s = self._steps_per_tick * step_s
        max_lag_steps = max(self._steps_per_tick, int(cfg.max_lag_s * cfg.speedup / step_s))
        max_steps_per_wake = _MAX_TICKS_PER_WAKE * self._steps_per_tick  # stay responsive
        start = time.monotonic()
        clock = self.clock
        clock.wall0 = start - self.sim_time() / cfg.speedup
        while not should_stop():
            self.stats.wakeups += 1
            now = time.monotonic()
            clock.refresh(now)
            due = max(int(self._sim_now(now) / step_s), self._steps)
            if due - self._steps > max_lag_steps and not clock.joined:
                self._slip(due - self._steps - max_lag_steps, now)
                due = self._steps + max_lag_steps
            elif self._slip_unreported:
                self._report_slip(now)
            self.advance(min(due, self._steps + max_steps_per_wake), self._receive())
            clock.advanced_to(self.sim_time())
            next_tick = (self._steps // self._steps_per_tick + 1) * tick_s
            wait = clock.wall_at(next_tick) - time.monotonic()
            if clock.joined:  # the world may hold us at its cap: look again soon
                wait = min(wait, _WORLD_POLL_S)
            if wait > _EPOLL_RESOLUTION_S:  # epoll rounds up to whole milliseconds
                self._selector.select(wait - _EPOLL_RESOLUTION_S)
            elif wait > 0:
                time.sleep(wait)  # datagrams keep their kernel arrival time meanwhile
        self.stats.wall_s = time.monotonic() - start
        self.stats.sim_s = self.sim_time()
        return self.stats

    def _slip(self, steps: int, now: float) -> None:
        """Give up catching up ``steps`` steps: the simulated clock slips (and says so:
        `_report_slip`)."""
        cfg = self.config
        seconds = steps * cfg.dynamics.step_s
        self.clock.wall0 += seconds / cfg.speedup
        self._waiting = [  # the messages still to come keep their place on the slipped clock
            Arrival(Stamp(a.stamp.sim_s - seconds, a.stamp.wall_s), a.vehicle, a.message)
            for a in self._waiting
        ]
        self.stats.slipped_sim_s += seconds
        self._slip_unreported += seconds
        self._report_slip(now)

    def _report_slip(self, now: float) -> None:
        """Say how far the clock slipped since the last report, at most every
        `_SLIP_REPORT_INTERVAL_S` of wall clock; a slip that fell inside the interval is said
        as soon as it is over (the run loop asks at every wake-up), never dropped."""
        if self._slip_unreported <= 0 or now - self._slip_reported_wall < _SLIP_REPORT_INTERVAL_S:
            return
        log.warning("simulation %.2f s behind: the simulated clock slips", self._slip_unreported)
        stamp = Stamp(self.sim_time(), now)
        for autopilot in self.autopilots:
            autopilot.clock_slipped(self._slip_unreported, stamp)
        self._slip_reported_wall = now
        self._slip_unreported = 0.0

    def advance(self, due_steps: int, arrivals: list[Arrival]) -> None:
        """Integrate up to ``due_steps``, running the autopilots at every control tick and
        handing each message to its autopilot when the simulated clock reaches its arrival
        (so a process that was late to read its sockets still applies them in order). A
        message that arrived later than ``due_steps`` (the clock catches up over several
        wake-ups) waits for the wake-up that reaches it: delivered now, a setpoint of the end
        of a stall would pull its vehicle seconds ahead of the mission."""
        per_tick = self._steps_per_tick
        step_s = self.config.dynamics.step_s
        arrivals = self._waiting + arrivals  # both in arrival order, the waiting ones earlier
        self._waiting = []
        pending = 0
        while True:
            now_s = self.sim_time()
            while pending < len(arrivals) and arrivals[pending].stamp.sim_s <= now_s + 1e-9:
                self._deliver(arrivals[pending])
                pending += 1
            if self._steps >= due_steps:
                break
            chunk = min(per_tick - self._steps % per_tick, due_steps - self._steps)
            if pending < len(arrivals):
                until = int((arrivals[pending].stamp.sim_s - now_s) / step_s) + 1
                chunk = max(1, min(chunk, until))
            self.dynamics.step(chunk)
            self._steps += chunk
            if self._steps % per_tick == 0:
                self._tick(Stamp(self.sim_time(), time.monotonic()))
        reached = self.sim_time() + step_s  # arrived during the current step: due now
        for arrival in arrivals[pending:]:
            if arrival.stamp.sim_s < reached:
                self._deliver(arrival)
            else:
                self._waiting.append(arrival)
        for autopilot, link in zip(self.autopilots, self.links, strict=True):
            self._flush(autopilot, link)

    def _tick(self, stamp: Stamp) -> None:
        """Run every autopilot, then build and send the telemetry that is due."""
        due_lists = []
        for autopilot, link in zip(self.autopilots, self.links, strict=True):
            autopilot.comm_errors = link.stats.bad_datagrams
            autopilot.update(stamp)
            report_refusals(link, autopilot, stamp)  # refused (unsigned...) frames: STATUSTEXT
            due_lists.append(autopilot.telemetry.due(stamp.sim_s))
        snapshot = FleetSnapshot.for_due(self.dynamics, self.config.origin, due_lists)
        for autopilot, link, due in zip(self.autopilots, self.links, due_lists, strict=True):
            autopilot.emit_due(due, snapshot, stamp)
            self._flush(autopilot, link)

    def _receive(self) -> list[Arrival]:
        """Every waiting message of every vehicle, stamped with its arrival, in arrival order."""
        arrivals: list[Arrival] = []
        for key, _ in self._selector.select(0):
            k = key.data
            for message, arrival in self.links[k].receive():
                arrivals.append(Arrival(Stamp(self._sim_now(arrival), arrival), k, message))
        arrivals.sort(key=lambda a: a.stamp.wall_s)
        return arrivals

    def _deliver(self, arrival: Arrival) -> None:
        autopilot = self.autopilots[arrival.vehicle]
        link = self.links[arrival.vehicle]
        try:
            if deliver_setup_signing(link, autopilot, arrival.message, arrival.stamp):
                return  # the key is the link's business (vehicles.signing)
            autopilot.handle(arrival.message, arrival.stamp)
        except Exception:  # a message must never take the vehicle down
            log.exception(
                "sysid %d: error handling %s", autopilot.sysid, arrival.message.get_type()
            )

    @staticmethod
    def _flush(autopilot: Autopilot, link: VehicleLink) -> None:
        if autopilot.outbox:
            link.send(autopilot.outbox)
            autopilot.outbox.clear()
