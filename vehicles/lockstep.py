"""Simulated vehicles stepped by their caller, without sockets or clocks (the fast mode).

The same dynamics (`vehicles.dynamics.FleetDynamics`) and the same ArduCopter-like autopilots
(`vehicles.autopilot.Autopilot`) as `vehicles sim`, run in lockstep: the caller integrates one
control period at a time (`control_tick`), hands decoded MAVLink messages to a vehicle
(`deliver`) and collects what the vehicles send (pymavlink message objects). Simulated time is
the only clock (a `Stamp`'s wall time is the simulated time too).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.geodesy import Origin
from vehicles.autopilot import Autopilot, AutopilotConfig, Stamp
from vehicles.dynamics import DynamicsConfig, FleetDynamics
from vehicles.fleet_speed import LeaderRequest
from vehicles.telemetry import FleetSnapshot

#: Streams a ground station in the same process has no use for (it reads the truth directly):
#: off by default, so the fast mode spends its time on dynamics, not on geodesy.
QUIET_STREAMS = (
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    mavlink.MAVLINK_MSG_ID_ATTITUDE,
    mavlink.MAVLINK_MSG_ID_SIM_STATE,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS,
    mavlink.MAVLINK_MSG_ID_VFR_HUD,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION,
)


@dataclass(frozen=True)
class LockstepConfig:
    """The vehicles: start positions (N, 3) local ENU, system ids, seed, behaviour."""

    starts: tuple[tuple[float, float, float], ...]
    sysids: tuple[int, ...]
    origin: Origin
    seed: int = 0
    dynamics: DynamicsConfig = field(default_factory=DynamicsConfig)
    autopilot: AutopilotConfig = field(default_factory=AutopilotConfig)
    leader_requests: dict[int, tuple[LeaderRequest, ...]] = field(default_factory=dict)
    control_rate_hz: float = 50.0
    quiet_streams: tuple[int, ...] = QUIET_STREAMS
    #: (message id, interval in simulated s) of streams sent at another rate than by default
    stream_intervals: tuple[tuple[int, float], ...] = ()
    #: battery capacity of each vehicle, mAh (None: the airframe's)
    battery_mah: tuple[float, ...] | None = None


class LockstepFleet:
    """N vehicles in one process, advanced by `control_tick`."""

    def __init__(self, config: LockstepConfig) -> None:
        self.config = config
        starts = np.asarray(config.starts, dtype=float).reshape(-1, 3)
        count = len(starts)
        self.dynamics = FleetDynamics(
            config.dynamics,
            starts,
            [(config.seed, sysid) for sysid in config.sysids],
            config.battery_mah,
        )
        self.autopilots = [
            Autopilot(
                sysid=sysid,
                index=k,
                count=count,
                config=config.autopilot,
                dynamics=self.dynamics,
                origin=config.origin,
                leader_requests=config.leader_requests.get(sysid, ()),
            )
            for k, sysid in enumerate(config.sysids)
        ]
        for autopilot in self.autopilots:
            for msg_id in config.quiet_streams:
                autopilot.telemetry.set_interval(msg_id, 0.0, 0.0)
            for msg_id, interval_s in config.stream_intervals:
                autopilot.telemetry.set_interval(msg_id, interval_s, 0.0)
        self.steps_per_tick = max(1, round(1.0 / (config.control_rate_hz * config.dynamics.step_s)))
        self._steps = 0

    @property
    def count(self) -> int:
        return len(self.autopilots)

    @property
    def sim_s(self) -> float:
        return self._steps * self.config.dynamics.step_s

    @property
    def tick_s(self) -> float:
        return self.steps_per_tick * self.config.dynamics.step_s

    def deliver(self, index: int, message: mavlink.MAVLink_message, sim_s: float) -> None:
        """Vehicle `index` receives `message` (it arrived at `sim_s`)."""
        self.autopilots[index].handle(message, Stamp(sim_s, sim_s))

    def control_tick(self) -> list[tuple[int, mavlink.MAVLink_message]]:
        """Run every autopilot and its due telemetry now, then integrate one control period;
        returns (vehicle index, message) of everything the vehicles sent, in order."""
        sim_s = self.sim_s
        stamp = Stamp(sim_s, sim_s)
        due_lists = []
        for autopilot in self.autopilots:
            autopilot.update(stamp)
            due_lists.append(autopilot.telemetry.due(sim_s))
        snapshot = FleetSnapshot.for_due(self.dynamics, self.config.origin, due_lists)
        sent: list[tuple[int, mavlink.MAVLink_message]] = []
        for k, (autopilot, due) in enumerate(zip(self.autopilots, due_lists, strict=True)):
            if due:
                autopilot.emit_due(due, snapshot, stamp)
            outbox = autopilot.outbox
            if outbox:
                sent.extend((k, message) for message in outbox)
                outbox.clear()
        self.dynamics.step(self.steps_per_tick)
        self._steps += self.steps_per_tick
        return sent

    def drain(self) -> list[tuple[int, mavlink.MAVLink_message]]:
        """Messages the vehicles sent while handling deliveries (acks, texts)."""
        sent = []
        for k, autopilot in enumerate(self.autopilots):
            outbox = autopilot.outbox
            if outbox:
                sent.extend((k, message) for message in outbox)
                outbox.clear()
        return sent

    def true_xy(self) -> np.ndarray:
        """True horizontal positions (N, 2), a copy."""
        return self.dynamics.position[:, :2].copy()
