"""The fast in-process mode: a planned mission flown in lockstep, as fast as the CPU allows.

The same vehicles as the networked simulation (`vehicles.lockstep`: the dynamics and the
ArduCopter-like autopilots of `vehicles sim`), the same radio medium model
(`vehicles.medium.MediumModel`: unit-disk graph on the true positions, per-hop latency, jitter
and loss, ground users and UAV data) and a small ground-station loop that flies the plan the
way `gcs.runtime` does: the speed profile and speed changes of `gcs.speed`, setpoints from the
smoothed reference of `planner.kinematics` (position, velocity and acceleration feed-forward),
take-off a lead time before each departure, landing on the arrival slot. MAVLink messages are
pymavlink objects handed over in memory, through the medium: a packet with no path is dropped,
the others arrive after their hops' delay. No sockets, no wall clock: simulated time only.

Differences from a networked run, on purpose: no connection handshake (the vehicles boot, then
get GUIDED, ARM and TAKEOFF as commands), setpoints in `SET_POSITION_TARGET_LOCAL_NED` (no
geodesy), only the telemetry the loop needs (local position 10 Hz, heartbeat and landed state
1 Hz), no freeze of the formation on a lost link (the loss is reported; the vehicles' own
failsafes act). The result is the run JSON of CONTRACTS.md (`log` is null) plus the time series
the paper's figures need.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.link import GCS_COMPONENT_ID, GCS_SYSTEM_ID
from gcs.monitors import MonitorEvent
from gcs.planning import MissionPlan
from gcs.radio import run_json_radio
from gcs.runtime import RunOptions, RunResult
from gcs.speed import ScheduledChange, SpeedChanges, SpeedRecord
from gcs.summary import run_json
from planner.guarantees import GuaranteeSamples, check_positions
from planner.kinematics import (
    LineFormation,
    SpeedProfile,
    recommended_window,
    smoothed_reference,
    smoothing_error_bound,
)
from vehicles.autopilot import AutopilotConfig
from vehicles.dynamics import Airframe, Disturbances, DynamicsConfig
from vehicles.fleet_speed import LeaderRequest
from vehicles.frames import GeodeticOrigin
from vehicles.ground_users import DEFAULT_PACKET_BYTES, GroundUser
from vehicles.lockstep import LockstepConfig, LockstepFleet
from vehicles.medium import MediumModel
from vehicles.radio import DelayLine, RadioConfig

MASK_POSITION_VELOCITY_ACCELERATION = 3072  # yaw and yaw rate ignored (CONTRACTS.md)
GUIDED, LAND = 4, 9
BOOT_MARGIN_S = 2.0  # simulated seconds before UAV 1's take-off (the vehicles boot in 1 s)


@dataclass(frozen=True)
class FastOptions:
    """How to fly in the fast mode."""

    fleet_size: int | None = None  # None: the plan's; fewer breaks the guarantee (tests)
    uav_data_bps: float | None = 800.0  # each UAV also sends data (paper sec. VI-A); None: no
    packet_bytes: int = DEFAULT_PACKET_BYTES
    sample_period_s: float = 0.1  # metrics and connectivity samples (mission s)
    link_timeout_s: float = RunOptions.link_timeout_s
    landing_tolerance_m: float = RunOptions.landing_tolerance_m
    landing_settle_s: float = RunOptions.landing_settle_s
    climb_rate_mps: float = RunOptions.climb_rate_mps
    command_retry_s: float = 2.0
    speed_retry_s: float = 0.2  # as the drivers retransmit speed changes
    time_limit_s: float | None = None  # mission s; None: twice the planned duration + 300 s


@dataclass(frozen=True, eq=False)
class FastRun:
    """What a fast run produced: the run JSON and the time series behind the figures.

    `times` (T,) mission seconds of the samples; `positions` (T, N, 3) true; `hops` (T, N)
    from the medium (-1: no path); `checks` the planner's sampled guarantee metrics;
    `tracking_error_m` (T, N) |true - V_n(t)|; `packets` the medium's packet log (time in
    mission s; `kind` indexes `vehicles.radio_stats.KINDS`); `speed_changes` each change with
    the mission time each UAV received it (`received_s`) and, for a leader's request, the time
    the leader sent it (`leader_sent_s`).
    """

    run_json: dict
    result: RunResult
    formation: LineFormation
    profile: SpeedProfile
    times: np.ndarray
    positions: np.ndarray
    hops: np.ndarray
    checks: GuaranteeSamples
    tracking_error_m: np.ndarray
    packets: dict[str, np.ndarray]
    speed_changes: list[dict]
    takeoff_s: np.ndarray
    landed_s: np.ndarray


def with_fleet_size(plan: MissionPlan, fleet_size: int) -> MissionPlan:
    """The plan flown by `fleet_size` UAVs on the same path (a fleet smaller than eq. 28's
    minimum breaks the connectivity guarantee: tests use it to show a disconnection)."""
    formation = plan.formation
    return replace(
        plan,
        formation=LineFormation(
            path=formation.path,
            fleet_size=fleet_size,
            safety_margin=formation.safety_margin,
            radio_range=formation.radio_range,
            rows=formation.rows,
        ),
    )


def mission_dynamics(mission) -> DynamicsConfig:
    """The simulated airframe and noise of `mission`, as `gcs mission run` gives them to
    `vehicles sim` (vehicle limits, mean wind, gusts, navigation noise)."""
    noise = mission.sim.noise
    direction = math.radians(noise.wind_direction_deg)
    return DynamicsConfig(
        airframe=Airframe(
            max_speed_mps=mission.vehicle.max_speed,
            max_acceleration_mps2=mission.vehicle.max_acceleration,
        ),
        disturbances=Disturbances(
            wind_mean_mps=(
                noise.wind_mean_mps * math.cos(direction),
                noise.wind_mean_mps * math.sin(direction),
                0.0,
            ),
            gust_sigma_mps=noise.wind_gust_mps,
            gust_sigma_vertical_mps=0.3 * noise.wind_gust_mps,
            navigation_sigma_m=noise.position_m,
            navigation_sigma_vertical_m=1.5 * noise.position_m,
        ),
    )


def radio_config(mission) -> RadioConfig:
    """The medium of `mission`: its radio range and `radio:` section, seeded by `sim.seed`."""
    radio = mission.radio
    return RadioConfig(
        range_m=mission.radio_range,
        hop_latency_s=radio.hop_latency_ms / 1000.0,
        jitter_s=radio.jitter_ms / 1000.0,
        loss=radio.loss,
        seed=mission.sim.seed,
    )


def base_stations(mission) -> np.ndarray:
    """A, B and the extra base stations, (B, 2)."""
    return np.array(
        [mission.start.xy, mission.goal.xy] + [b.xy for b in mission.base_stations], dtype=float
    )


@dataclass
class _Uav:
    phase: str = "parked"  # parked, taking_off, following, landing, landed
    last_command_s: float = -math.inf
    takeoff_s: float = math.nan
    landed_s: float = math.nan
    known_xyz: np.ndarray | None = None
    armed: bool = False
    heartbeat_s: float = -math.inf  # mission time of the last heartbeat heard
    heard_s: float = -math.inf
    lost: bool = False


@dataclass
class _Change:
    record: SpeedRecord
    broadcast_s: float
    leader_sent_s: float | None
    unacked: set[int]
    last_sent_s: float
    received_s: dict[int, float] = field(default_factory=dict)


class _FastMission:
    """The lockstep loop: vehicles, medium and ground station (see the module docstring)."""

    def __init__(self, plan: MissionPlan, options: FastOptions) -> None:
        if options.fleet_size is not None:
            plan = with_fleet_size(plan, options.fleet_size)
        mission = plan.mission
        self.plan, self.mission, self.options = plan, mission, options
        self.formation = plan.formation
        size = self.formation.fleet_size
        self.size = size
        self.altitude = float(mission.altitude)
        self.rate_hz = mission.sim.setpoint_rate_hz
        self.window_s = float(
            recommended_window(plan.speeds.max, mission.vehicle.max_acceleration, self.formation)
        )
        self.profile = SpeedProfile.constant(plan.speeds.initial)
        schedule = [ScheduledChange(c.at, c.speed, c.leader) for c in plan.speeds.changes]
        self.speeds = SpeedChanges(
            max_speed=plan.speeds.max, window_s=self.window_s, schedule=schedule
        )
        leaders: dict[int, list[LeaderRequest]] = {}
        for change in plan.speeds.changes:
            if change.leader is not None:
                leaders.setdefault(change.leader, []).append(LeaderRequest(change.at, change.speed))
        self.starts = np.column_stack([self.formation.start_slots, np.zeros(size)])
        origin = mission.origin
        self.fleet = LockstepFleet(
            LockstepConfig(
                starts=tuple(map(tuple, self.starts.tolist())),
                sysids=tuple(range(1, size + 1)),
                origin=GeodeticOrigin(origin.lat, origin.lon, origin.alt),
                seed=mission.sim.seed,
                dynamics=mission_dynamics(mission),
                autopilot=AutopilotConfig(),
                leader_requests={uav: tuple(r) for uav, r in leaders.items()},
            )
        )
        self.medium = MediumModel(
            radio_config(mission),
            base_stations(mission),
            self.formation.start_slots,
            ground_users=tuple(GroundUser(u.x, u.y, u.rate_bps) for u in mission.ground_users),
            uav_data_bps=options.uav_data_bps,
            packet_bytes=options.packet_bytes,
            sample_period_s=options.sample_period_s,
            keep_packets=True,
        )
        self.delay = DelayLine()
        self.codec = mavlink.MAVLink(None, srcSystem=GCS_SYSTEM_ID, srcComponent=GCS_COMPONENT_ID)
        self.uavs = [_Uav() for _ in range(size)]
        self.changes: dict[int, _Change] = {}
        self.leader_seen: set[tuple[int, int]] = set()
        self.events: list[MonitorEvent] = []
        self.setpoints_sent = 0
        self.ticks = 0
        climb = self.altitude / options.climb_rate_mps
        self.lead_s = 5.0 + 1.5 * climb  # as gcs.runtime.MissionRun.takeoff_lead_s
        self.sim_zero = BOOT_MARGIN_S + self.lead_s  # simulated s at mission time 0
        planned = plan.duration_s if plan.duration_s and math.isfinite(plan.duration_s) else 600
        self.time_limit_s = (
            options.time_limit_s if options.time_limit_s is not None else 2 * planned + 300.0
        )
        self._times: list[float] = []
        self._positions: list[np.ndarray] = []
        self._hops: list[np.ndarray] = []
        self._last_heartbeat = -math.inf

    # ------------------------------------------------------------------ the loop
    def mission_time(self, sim_s: float) -> float:
        return sim_s - self.sim_zero

    def run(self) -> FastRun:
        fleet = self.fleet
        tick_period = 1.0 / self.rate_hz
        next_gcs = 0.0
        next_sample = 0.0
        while True:
            sim_s = fleet.sim_s
            t = self.mission_time(sim_s)
            self._deliver(sim_s)
            self.medium.observe_all(fleet.true_xy(), sim_s)
            if sim_s >= next_gcs - 1e-9:
                self._tick(t, sim_s)
                next_gcs += tick_period
            if sim_s >= next_sample - 1e-9:
                self._sample(t, sim_s)
                next_sample += self.options.sample_period_s
            self.medium.periodic(sim_s)
            for index, message in fleet.control_tick():
                self._send_up(index, message, sim_s)
            if all(u.phase == "landed" for u in self.uavs) or t > self.time_limit_s:
                break
        return self._finish()

    def _deliver(self, sim_s: float) -> None:
        for due, (direction, index, message, sent) in self.delay.pop_due(sim_s):
            if direction == "down":
                self._on_received_by_uav(index, message, due)
                self.fleet.deliver(index, message, due)
                for k, answer in self.fleet.drain():
                    self._send_up(k, answer, sim_s)
            else:
                self._on_message(index, message, self.mission_time(due), sent)

    def _send_up(self, index: int, message, sim_s: float) -> None:
        _, delay = self.medium.route("uplink", index, sim_s)
        if delay is not None:
            self.delay.put((index, "up"), sim_s + delay, ("up", index, message, sim_s))

    def _send_down(self, index: int, message, sim_s: float) -> None:
        message.pack(self.codec)  # stamps the GCS's system id and a sequence number
        self.codec.seq = (self.codec.seq + 1) % 256
        _, delay = self.medium.route("downlink", index, sim_s)
        if delay is not None:
            self.delay.put((index, "down"), sim_s + delay, ("down", index, message, sim_s))

    # ------------------------------------------------------------------ ground station
    def _tick(self, t: float, sim_s: float) -> None:
        self.ticks += 1
        codec = self.codec
        if sim_s - self._last_heartbeat >= 1.0:
            self._last_heartbeat = sim_s
            for k in range(self.size):
                self._send_down(
                    k,
                    codec.heartbeat_encode(
                        mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0
                    ),
                    sim_s,
                )
                self._send_down(
                    k,
                    codec.named_value_int_encode(
                        int(sim_s * 1000) & 0xFFFFFFFF, b"MSN_TIME", int(round(t * 1000))
                    ),
                    sim_s,
                )
        for scheduled in self.speeds.due(t):
            self._issue(
                scheduled.speed, t, sim_s, "schedule", max(scheduled.at, self.speeds.earliest(t))
            )
        self._retransmit_speed_changes(t, sim_s)
        self._schedule(t, sim_s)
        self._stream(t, sim_s)
        self._watch_links(t)

    def _command(self, k: int, command: int, *params: float, sim_s: float) -> None:
        values = list(params) + [0.0] * (7 - len(params))
        self._send_down(k, self.codec.command_long_encode(k + 1, 1, command, 0, *values), sim_s)

    def _schedule(self, t: float, sim_s: float) -> None:
        formation, options = self.formation, self.options
        departures = self.profile.time_at_distance(formation.departure_distance)
        arrivals = self.profile.time_at_distance(formation.arrival_distance)
        retry = options.command_retry_s
        for k, uav in enumerate(self.uavs):
            if uav.phase == "parked" and t >= departures[k] - self.lead_s:
                uav.phase, uav.takeoff_s = "taking_off", t
            if uav.phase == "taking_off":
                up = uav.known_xyz is not None and uav.known_xyz[2] >= self.altitude - 1.0
                # (again only if a heartbeat since the last try shows it still disarmed)
                refused = uav.heartbeat_s > uav.last_command_s + 0.5 and not uav.armed
                if up:
                    uav.phase = "following"
                elif uav.last_command_s == -math.inf or (
                    refused and t - uav.last_command_s >= retry
                ):
                    uav.last_command_s = t
                    flag = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                    self._command(k, mavlink.MAV_CMD_DO_SET_MODE, flag, GUIDED, sim_s=sim_s)
                    self._command(k, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, sim_s=sim_s)
                    self._command(
                        k, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, self.altitude, sim_s=sim_s
                    )
            if uav.phase == "following" and t >= arrivals[k] + self.window_s / 2:
                offset = math.inf
                if uav.known_xyz is not None:
                    offset = float(np.hypot(*(uav.known_xyz[:2] - formation.goal_slots[k])))
                settle = arrivals[k] + self.window_s / 2 + options.landing_settle_s
                if offset <= options.landing_tolerance_m or t >= settle:
                    uav.phase = "landing"
            if uav.phase == "landing":
                if uav.heartbeat_s > uav.last_command_s and not uav.armed:
                    uav.phase, uav.landed_s = "landed", t
                elif t - uav.last_command_s >= retry:
                    uav.last_command_s = t
                    flag = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                    self._command(k, mavlink.MAV_CMD_DO_SET_MODE, flag, LAND, sim_s=sim_s)

    def _stream(self, t: float, sim_s: float) -> None:
        following = [k for k, u in enumerate(self.uavs) if u.phase == "following"]
        if not following:
            return
        reference = smoothed_reference(self.formation, self.profile, [t], self.window_s)
        position, velocity = reference.positions[0], reference.velocities[0]
        acceleration = reference.accelerations[0]
        boot_ms = int(sim_s * 1000) & 0xFFFFFFFF
        for k in following:
            north, east = (position[k] - self.starts[k, :2])[::-1]
            message = self.codec.set_position_target_local_ned_encode(
                boot_ms,
                k + 1,
                1,
                mavlink.MAV_FRAME_LOCAL_NED,
                MASK_POSITION_VELOCITY_ACCELERATION,
                float(north),
                float(east),
                -self.altitude,
                float(velocity[k, 1]),
                float(velocity[k, 0]),
                0.0,
                float(acceleration[k, 1]),
                float(acceleration[k, 0]),
                0.0,
                0.0,
                0.0,
            )
            self._send_down(k, message, sim_s)
            self.setpoints_sent += 1

    def _watch_links(self, t: float) -> None:
        for k, uav in enumerate(self.uavs):
            if uav.phase in ("parked", "landed"):
                continue
            silent = t - uav.heard_s > self.options.link_timeout_s and uav.heard_s > -math.inf
            if silent and not uav.lost:
                uav.lost = True
                text = f"UAV {k + 1}: link lost (no valid message for {self.options.link_timeout_s:g} s)"
                self.events.append(MonitorEvent(t, "error", "link_lost", text, k + 1, fatal=True))
            elif not silent and uav.lost:
                uav.lost = False
                self.events.append(
                    MonitorEvent(t, "warning", "link_back", f"UAV {k + 1}: link back", k + 1)
                )

    # ------------------------------------------------------------------ speed changes
    def _issue(
        self,
        speed: float,
        t: float,
        sim_s: float,
        source: str,
        at: float | None = None,
        leader_sent_s: float | None = None,
    ) -> None:
        change = self.speeds.request(speed, t, source, at)
        self.profile = self.profile.with_change(change.effective_s, change.speed)
        record = self.speeds.record(change, t)
        self.changes[change.seq] = _Change(
            record, t, leader_sent_s, set(range(self.size)), -math.inf
        )
        self._retransmit_speed_changes(t, sim_s)

    def _retransmit_speed_changes(self, t: float, sim_s: float) -> None:
        for seq, pending in self.changes.items():
            if not pending.unacked or t - pending.last_sent_s < self.options.speed_retry_s:
                continue
            pending.last_sent_s = t
            change = pending.record.change
            for k in sorted(pending.unacked):
                message = self.codec.command_int_encode(
                    k + 1,
                    1,
                    mavlink.MAV_FRAME_MISSION,
                    mavlink.MAV_CMD_DO_CHANGE_SPEED,
                    0,
                    0,
                    1.0,
                    float(change.speed),
                    -1.0,
                    0.0,
                    int(round(change.effective_s * 1000)),
                    seq,
                    0.0,
                )
                self._send_down(k, message, sim_s)

    def _on_received_by_uav(self, k: int, message, due_sim_s: float) -> None:
        """T_dv is measured where it happens: the instant the UAV receives the change."""
        if (
            message.get_type() == "COMMAND_INT"
            and message.command == mavlink.MAV_CMD_DO_CHANGE_SPEED
        ):
            pending = self.changes.get(int(message.y))
            if pending is not None:
                pending.received_s.setdefault(k + 1, self.mission_time(due_sim_s))

    # ------------------------------------------------------------------ telemetry
    def _on_message(self, k: int, message, t: float, sent_sim_s: float) -> None:
        uav = self.uavs[k]
        uav.heard_s = t
        kind = message.get_type()
        if kind == "LOCAL_POSITION_NED":
            uav.known_xyz = self.starts[k] + np.array([message.y, message.x, -message.z])
        elif kind == "HEARTBEAT":
            uav.armed = bool(message.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            uav.heartbeat_s = t
        elif kind == "COMMAND_ACK" and message.command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            pending = self.changes.get(int(message.result_param2))
            if pending is not None and k in pending.unacked:
                pending.unacked.discard(k)
                if message.result == mavlink.MAV_RESULT_ACCEPTED:
                    self.speeds.acknowledge(pending.record, k + 1, t - pending.broadcast_s)
                else:
                    pending.record.refused[k + 1] = str(message.result)
        elif kind == "COMMAND_INT" and message.command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            seq = int(message.y)
            if (k, seq) not in self.leader_seen:
                self.leader_seen.add((k, seq))
                self._issue(
                    float(message.param2),
                    t,
                    t + self.sim_zero,
                    f"leader:{k + 1}",
                    leader_sent_s=self.mission_time(sent_sim_s),
                )
            ack = self.codec.command_ack_encode(
                mavlink.MAV_CMD_DO_CHANGE_SPEED, mavlink.MAV_RESULT_ACCEPTED, 0, seq, k + 1, 1
            )
            self._send_down(k, ack, t + self.sim_zero)
        elif kind == "STATUSTEXT" and message.severity <= mavlink.MAV_SEVERITY_WARNING:
            text = message.text if isinstance(message.text, str) else message.text.decode()
            self.events.append(MonitorEvent(t, "warning", "vehicle", f"UAV {k + 1}: {text}", k + 1))

    # ------------------------------------------------------------------ samples and result
    def _sample(self, t: float, sim_s: float) -> None:
        self._times.append(t)
        self._positions.append(self.fleet.dynamics.position.copy())
        self._hops.append(self.medium.topology_at(sim_s).hops.copy())

    def _finish(self) -> FastRun:
        mission, formation = self.mission, self.formation
        times = np.array(self._times)
        positions = np.array(self._positions).reshape(len(times), self.size, 3)
        hops = np.array(self._hops).reshape(len(times), self.size)
        xy = positions[..., :2]
        checks = check_positions(xy, mission.obstacles, base_stations(mission), mission.radio_range)
        virtual = formation.positions(self.profile.distance(times))
        tracking = np.hypot(*np.moveaxis(xy - virtual, -1, 0))
        reference = smoothed_reference(formation, self.profile, times, self.window_s).positions
        control = np.hypot(*np.moveaxis(xy - reference, -1, 0))
        final = xy[-1] if len(times) else formation.start_slots
        landing = np.hypot(*(final - formation.goal_slots).T)
        rho, radius = mission.safety_margin, mission.vehicle.radius
        summary = checks.summary()
        events = list(self.events)
        max_tracking = tracking.max(axis=0) if len(times) else np.zeros(self.size)
        if (max_tracking >= rho).any():
            worst = int(np.argmax(max_tracking))
            events.append(
                MonitorEvent(
                    float(times[np.argmax(tracking[:, worst])]),
                    "error",
                    "tracking",
                    f"UAV {worst + 1}: tracking error {max_tracking[worst]:.2f} m >= safety "
                    f"margin {rho:g} m (the guarantees no longer hold)",
                    worst + 1,
                    fatal=True,
                )
            )
        min_pair, min_obstacle = summary["min_uav_uav_m"], summary["min_uav_obstacle_m"]
        if min_pair is not None and min_pair < 2 * radius:
            events.append(MonitorEvent(0.0, "error", "collision_uav", "UAVs collided", fatal=True))
        if min_obstacle is not None and min_obstacle < radius:
            events.append(
                MonitorEvent(0.0, "error", "collision_obstacle", "obstacle hit", fatal=True)
            )
        fatal = any(e.fatal for e in events)
        landed = all(u.phase == "landed" for u in self.uavs)
        on_slots = bool((landing < rho).all())
        completed = landed and on_slots and not fatal
        reason = None
        if not completed:
            first_fatal = next((e.text for e in events if e.fatal), None)
            reason = first_fatal or (
                "a UAV landed off its arrival slot" if landed else "the mission did not complete"
            )
        takeoffs = np.array([u.takeoff_s for u in self.uavs])
        landings = np.array([u.landed_s for u in self.uavs])
        duration = (
            float(np.nanmax(landings) - np.nanmin(takeoffs))
            if np.isfinite(landings).any() and np.isfinite(takeoffs).any()
            else None
        )
        period_ms = 1000.0 / self.rate_hz
        result = RunResult(
            completed=completed,
            reason=reason,
            fleet_size=self.size,
            duration_s=duration,
            min_uav_uav_m=min_pair,
            min_uav_obstacle_m=min_obstacle,
            max_tracking_error_m=float(max_tracking.max()) if len(times) else None,
            tracking_error_m=[float(e) for e in max_tracking],
            control_error_m=[float(e) for e in control.max(axis=0)]
            if len(times)
            else [None] * self.size,
            landing_error_m=[float(e) for e in landing],
            connected_fraction=summary["connected_fraction"],
            speed_changes=self.speeds.as_json(),
            events=events,
            phases=[u.phase for u in self.uavs],
            smoothing_window_s=self.window_s,
            smoothing_error_m=float(smoothing_error_bound(formation, self.profile, self.window_s)),
            noise_m=mission.sim.noise.position_m,
            setpoints_sent=self.setpoints_sent,
            setpoint_rate_hz=self.rate_hz,
            setpoint_jitter_p99_ms=0.0,
            setpoint_period_ms=period_ms,
            setpoint_max_gap_ms=period_ms,
            ticks=self.ticks,
            interrupted=0,
            fatal=fatal,
            radio=run_json_radio(self.medium.stats.summary()),
        )
        data = run_json(result, "", mission.safety_margin)
        data["log"] = None
        data["mode"] = "fast"
        changes = []
        for _, pending in sorted(self.changes.items()):
            entry = pending.record.as_json()
            entry["received_s"] = {str(u): s for u, s in sorted(pending.received_s.items())}
            entry["leader_sent_s"] = pending.leader_sent_s
            changes.append(entry)
        packets = self.medium.stats.log.columns()
        packets["time_s"] = packets["time_s"] - self.sim_zero
        return FastRun(
            run_json=data,
            result=result,
            formation=formation,
            profile=self.profile,
            times=times,
            positions=positions,
            hops=hops,
            checks=checks,
            tracking_error_m=tracking,
            packets=packets,
            speed_changes=changes,
            takeoff_s=takeoffs,
            landed_s=landings,
        )


def fly_fast(plan: MissionPlan, options: FastOptions | None = None) -> FastRun:
    """Fly `plan` in the fast in-process mode (see the module docstring)."""
    if not plan.valid:
        raise ValueError(f"no valid path: {plan.reason}")
    return _FastMission(plan, options or FastOptions()).run()
