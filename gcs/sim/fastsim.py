"""The fast in-process mode: a planned mission flown in lockstep, as fast as the CPU allows.

The ground station is THE ground-station core (`gcs.flight.core.GroundStation`) with the simulated
backend's drivers (`gcs.drivers.sim.SimDriver`), exactly as `gcs mission run` flies it; only the
loop around it differs. Instead of sockets and the wall clock: the same vehicles as the networked
simulation (`vehicles.lockstep`: the dynamics and the ArduCopter-like autopilots of `vehicles sim`),
the same radio medium model (`medium.medium.MediumModel`: unit-disk graph on the true positions,
per-hop latency, jitter and loss, ground users and UAV data), in-memory links
(`gcs.transport.link.MemoryLink`), and simulated time as the loop's clock. Every MAVLink message
goes through the medium: a packet with no path is dropped, the others arrive after their hops'
delay.

Differences from a networked run: no recording unless asked (`FastOptions.log`; the run
JSON's `log` is null without one, and the MAVLink topics are never written), no signing, and
the vehicles skip the telemetry streams the core does not read (attitude, BATTERY_STATUS,
VFR_HUD, local position; the battery level comes with SYS_STATUS). Nobody is there to ask a stations mission's fleet home: without `return.at`
or a `dwell_s` on every point, it returns as soon as every UAV is on station
(`RunOptions.return_when_on_station`). The result is the run JSON of docs/outputs.md plus the
time series the paper's figures need, sampled from the true state of the simulation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.drivers.base import DriverTiming
from gcs.drivers.sim import SimDriver
from gcs.flight.answers import OperatorAnswer
from gcs.flight.assembly import assemble
from gcs.flight.clock import MissionClock
from gcs.flight.core import NullRecorder, RunOptions
from gcs.flight.records import run_json_radio
from gcs.flight.result import RunResult
from gcs.planning import MissionPlan, plan_json
from gcs.sim.medium_process import buildings_sight
from gcs.summary import run_json
from gcs.transport.link import MemoryLink
from medium.ground_users import DEFAULT_PACKET_BYTES, GroundUser
from medium.medium import MediumModel
from medium.radio import DelayLine, RadioConfig
from planner.guarantees import GuaranteeSamples, check_positions
from planner.kinematics import LineFormation, SpeedProfile
from vehicles.autopilot import AutopilotConfig
from vehicles.dynamics import Airframe, Disturbances, DynamicsConfig
from vehicles.fleet_speed import LeaderRequest
from vehicles.lockstep import QUIET_STREAMS, LockstepConfig, LockstepFleet

#: Streams the vehicles skip in the fast mode: what the core does not read.
FAST_QUIET_STREAMS = tuple(
    set(QUIET_STREAMS)
    - {
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,  # the drivers' telemetry
        mavlink.MAVLINK_MSG_ID_SIM_STATE,  # the core's true positions
        mavlink.MAVLINK_MSG_ID_SYS_STATUS,  # pre-arm checks, battery level
        mavlink.MAVLINK_MSG_ID_HOME_POSITION,  # the home check before arming
    }
    | {mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED}
)


@dataclass(frozen=True)
class Faults:
    """Faults and operator actions injected into a fast run, at times on the vehicles' clock
    counted from mission time 0 (a stalled ground station holds its mission clock back; this
    clock runs on)."""

    #: (from, to): the ground station does not run (a stopped or starved process); what the
    #: vehicles send meanwhile waits in its socket buffer, as over UDP
    gcs_stalls: tuple[tuple[float, float], ...] = ()
    #: the stalls stop the ground station after it read its links and before its tick: it
    #: wakes up in the tick, the backlog still unread (else it wakes up reading it)
    gcs_stalls_before_tick: bool = False
    #: (UAV id, from, to): every packet to and from that UAV is lost (out of range, jammed)
    link_cuts: tuple[tuple[int, float, float], ...] = ()
    #: (UAV id, from, to): what the ground station sends that UAV is lost, what it sends still
    #: arrives (a UAV starved of setpoints: it stops following, its link stays alive)
    setpoint_cuts: tuple[tuple[int, float, float], ...] = ()
    #: (UAV id, from, to, seconds): what that UAV sends and receives from `from` to `to` is
    #: that much later, in order (a late vehicle process); UAV id 0: every UAV (the radio
    #: medium late)
    late: tuple[tuple[int, float, float, float], ...] = ()
    #: (when, speed, effective time or None): `gcs speed` requests of the operator
    operator_requests: tuple[tuple[float, float, float | None], ...] = ()
    #: (when, effective time or None): `gcs return` requests of the operator
    operator_returns: tuple[tuple[float, float | None], ...] = ()
    #: (when, UAV id): `gcs relieve` requests of the operator
    operator_reliefs: tuple[tuple[float, int], ...] = ()
    #: (when, line): lines the operator types in the live view ("5 @120", "return", ...)
    typed: tuple[tuple[float, str], ...] = ()
    #: when the operator presses Ctrl-C
    interrupts: tuple[float, ...] = ()
    #: the probability that a packet between the ground station and a UAV is lost, each way,
    #: drawn from a generator seeded with `link_loss_seed` (a lossy network, as the proxy of
    #: the live fault tests)
    link_loss: float = 0.0
    link_loss_seed: int = 0

    def stalled(self, t: float) -> bool:
        return any(start <= t < end for start, end in self.gcs_stalls)

    def cut(self, uav: int, t: float) -> bool:
        return any(u == uav and start <= t < end for u, start, end in self.link_cuts)

    def setpoints_cut(self, uav: int, t: float) -> bool:
        return any(u == uav and start <= t < end for u, start, end in self.setpoint_cuts)

    def lateness(self, uav: int, t: float) -> float:
        """Seconds what UAV `uav` sends or receives at `t` is late (`late`)."""
        return sum(s for u, start, end, s in self.late if u in (0, uav) and start <= t < end)


@dataclass(frozen=True)
class FastOptions:
    """How to fly in the fast mode."""

    fleet_size: int | None = None  # None: the plan's; fewer breaks the guarantee (tests)
    uav_data_bps: float | None = 800.0  # each UAV also sends data (paper sec. VI-A); None: no
    packet_bytes: int = DEFAULT_PACKET_BYTES
    sample_period_s: float = 0.1  # metrics and connectivity samples (mission s)
    link_wait_s: float = RunOptions.link_wait_s  # as `gcs mission run --link-wait`
    takeoff_lead_s: float | None = None  # as `gcs mission run --takeoff-lead`
    time_limit_s: float | None = None  # mission s; None: twice the planned duration + 300 s
    faults: Faults = field(default_factory=Faults)
    #: an MCAP file to record the flight to, as `gcs mission run --log` (no MAVLink topics;
    #: log time is simulated time, from the Unix epoch); slower: every sample is written
    log: Path | None = None


@dataclass(frozen=True, eq=False)
class FastRun:
    """What a fast run produced: the run JSON and the time series behind the figures.

    `times` (T,) mission seconds of the samples; `positions` (T, N, 3) true; `hops` (T, N)
    from the medium (-1: no path); `checks` the planner's sampled guarantee metrics;
    `tracking_error_m` (T, N) |true - V_n(t)|; `formation` the formation flown (a stations
    mission's with its way home once it returned); `packets` the medium's packet log (time in
    mission s; `kind` indexes `medium.radio_stats.KINDS`); `speed_changes` each change with
    the mission time each UAV received it (`received_s`) and, for a leader's request, the time
    the leader sent it (`leader_sent_s`); `takeoff_s` and `landed_s` (N,) mission times (NaN:
    never); `operator_answers` the typed answers (`gcs.flight.answers`) to `Faults.operator_requests`, `operator_returns`
    and `operator_reliefs`, in the order asked; `stalls` the core's stall records;
    `battery_remaining_pct` (N,) the last battery level (%, SYS_STATUS) each UAV reported
    (NaN: none).
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
    operator_answers: list[OperatorAnswer] = field(default_factory=list)
    stalls: list = field(default_factory=list)  # the core's `Stall` records
    battery_remaining_pct: np.ndarray = field(default_factory=lambda: np.empty(0))


def with_fleet_size(plan: MissionPlan, fleet_size: int) -> MissionPlan:
    """The plan flown by `fleet_size` UAVs on the same path (a fleet smaller than eq. 28's
    minimum breaks the connectivity guarantee: tests use it to show a disconnection). A
    stations plan is flown only by its own fleet, one UAV per station (ValueError otherwise)."""
    formation = plan.formation
    if formation.stations is not None:
        if fleet_size != formation.fleet_size:
            raise ValueError(
                f"a stations plan is flown by its {formation.fleet_size} UAVs, one per "
                f"station, not {fleet_size}"
            )
        return plan
    return replace(plan, formation=replace(formation, fleet_size=fleet_size))


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
    """The medium of `mission`: its radio range and `radio:` section, seeded by `sim.seed`.
    With `radio.model: calibrated`, the table of `radio.calibration` (None: the shipped one);
    the load level follows the medium's data sources (every UAV's data and every ground
    user's: `medium.medium.offered_data_bps`)."""
    from medium.calibration import DEFAULT_CALIBRATION, load_calibration

    radio = mission.radio
    calibrated = radio.model == "calibrated"
    return RadioConfig(
        range_m=mission.radio_range,
        hop_latency_s=radio.hop_latency_ms / 1000.0,
        jitter_s=radio.jitter_ms / 1000.0,
        loss=radio.loss,
        seed=mission.sim.seed,
        model=radio.model,
        calibration=load_calibration(radio.calibration or DEFAULT_CALIBRATION)
        if calibrated
        else None,
        sight=buildings_sight(mission),
    )


def base_stations(mission) -> np.ndarray:
    """A, B (when the mission has one) and the extra base stations, (k, 2)."""
    return mission.base_station_points


class _LockstepMission:
    """The lockstep loop around the ground-station core (see the module docstring)."""

    def __init__(self, plan: MissionPlan, options: FastOptions) -> None:
        if options.fleet_size is not None:
            plan = with_fleet_size(plan, options.fleet_size)
        mission = plan.mission
        self.plan, self.mission, self.options = plan, mission, options
        self.formation = formation = plan.formation
        size = formation.fleet_size
        self.size = size
        leaders: dict[int, list[LeaderRequest]] = {}
        for change in plan.speeds.changes:
            if change.leader is not None:
                leaders.setdefault(change.leader, []).append(LeaderRequest(change.at, change.speed))
        starts = np.column_stack([formation.start_slots, np.zeros(size)])
        origin = mission.origin
        self.fleet = LockstepFleet(
            LockstepConfig(
                starts=tuple(map(tuple, starts.tolist())),
                sysids=tuple(range(1, size + 1)),
                origin=origin,
                seed=mission.sim.seed,
                dynamics=mission_dynamics(mission),
                # WPNAV_SPEED (the guided limit the driver reads) at the airframe's max speed
                autopilot=AutopilotConfig(waypoint_speed_mps=mission.vehicle.max_speed),
                leader_requests={uav: tuple(r) for uav, r in leaders.items()},
                quiet_streams=FAST_QUIET_STREAMS,
                battery_mah=mission.sim.battery_capacities(size),
            )
        )
        self.medium = MediumModel(
            radio_config(mission),
            base_stations(mission),
            formation.start_slots,
            ground_users=tuple(GroundUser(u.x, u.y, u.rate_bps) for u in mission.ground_users),
            uav_data_bps=options.uav_data_bps,
            packet_bytes=options.packet_bytes,
            sample_period_s=options.sample_period_s,
            keep_packets=True,
        )
        self.delay = DelayLine()
        self._loss_draws = np.random.default_rng(options.faults.link_loss_seed)
        self._last_due: dict[tuple[int, str], float] = {}  # (UAV, direction): FIFO when late
        # each vehicle's own MAVLink identity, to frame what it sends as its radio would
        self.encoders = [
            mavlink.MAVLink(None, srcSystem=uav, srcComponent=1) for uav in range(1, size + 1)
        ]
        self.links = [MemoryLink(f"memory:{uav}", uav) for uav in range(1, size + 1)]
        self.clock = MissionClock(1.0, monotonic=lambda: 0.0, unix_ns=lambda: 0)
        run_options = RunOptions(
            setpoint_rate_hz=mission.sim.setpoint_rate_hz,
            link_wait_s=options.link_wait_s,
            takeoff_lead_s=options.takeoff_lead_s,
            return_when_on_station=True,  # nobody to ask for it
        )
        self.recorder = NullRecorder() if options.log is None else self._recorder(options.log)
        self.station = assemble(
            plan, self.links, SimDriver, DriverTiming(), self.clock, self.recorder, run_options,
            wall=lambda: self.fleet.sim_s,
        )  # fmt: skip
        planned = plan.duration_s if plan.duration_s and math.isfinite(plan.duration_s) else 600
        if formation.stations is not None:  # out, the hold, and home
            dwells = [point.dwell_s for point in mission.stations]
            planned = 2 * planned + max(max(dwells), mission.return_at or 0.0)
        self.time_limit_s = (
            options.time_limit_s if options.time_limit_s is not None else 2 * planned + 300.0
        )
        self.received_s: dict[int, dict[int, float]] = {}  # change seq -> UAV -> mission s
        self.leader_sent_s: dict[int, list[float]] = {}  # UAV -> its requests, first sent at
        self._leader_seen: set[tuple[int, int]] = set()
        self.sim_zero = math.inf  # simulated s at mission time 0 (before any stall)
        self.operator_answers: list[OperatorAnswer] = []
        self._arrived: dict[int, list] = {}  # what waits in the ground station's buffers
        self._times: list[float] = []
        self._positions: list[np.ndarray] = []
        self._hops: list[np.ndarray] = []
        # sample index -> (V_n as flown, UAVs out of the fleet, one flying home above): the
        # samples taken since a relief (`_sample`)
        self._relieved_samples: dict[int, tuple[np.ndarray, np.ndarray, bool]] = {}

    def _recorder(self, path: Path):
        """A `FlightRecorder` on the simulated clock, the plan described."""
        from gcs.recording.recording import FlightRecorder

        recorder = FlightRecorder(path, self.clock, force=True)
        recorder.describe(self.plan, plan_json(self.plan), 0.0)
        return recorder

    def mission_time(self, sim_s: float) -> float:
        return self.clock.mission_time(sim_s) if self.clock.anchored else -math.inf

    # ------------------------------------------------------------------ the loop
    def run(self) -> FastRun:
        """Fly, and the result; a recording (`FastOptions.log`) is closed whatever happens."""
        try:
            self._fly()
            run = self._finish()
            if self.options.log is not None:
                run.run_json["log"] = str(self.options.log)
                self.recorder.outcome(run.run_json)
            return run
        finally:
            if self.options.log is not None:
                self.recorder.close()

    def _fly(self) -> None:  # noqa: C901 (over 15 branches: to split)
        fleet, station, faults = self.fleet, self.station, self.options.faults
        stalls = bool(faults.gcs_stalls)  # (most runs have none: no test per iteration)
        tick_period = 1.0 / station.options.setpoint_rate_hz
        next_tick = 0.0
        next_sample = 0.0
        connected = False
        operator = sorted(faults.operator_requests)
        returns = sorted(faults.operator_returns, key=lambda request: request[0])
        reliefs = sorted(faults.operator_reliefs)
        typed = sorted(faults.typed)
        interrupts = sorted(faults.interrupts)
        was_stalled = False
        while True:
            sim_s = fleet.sim_s
            self.medium.observe_all(fleet.true_xy(), sim_s)
            self._deliver(sim_s)
            vehicle_t = sim_s - self.sim_zero
            stalled = connected and stalls and faults.stalled(vehicle_t)
            woke_in_tick = was_stalled and not stalled and faults.gcs_stalls_before_tick
            was_stalled = stalled
            if not stalled:
                if not woke_in_tick:
                    station.receive(sim_s, self._batches(sim_s))
                while operator and vehicle_t >= operator[0][0]:
                    _, speed, at = operator.pop(0)
                    self.operator_answers.append(station.operator_request(speed, at, None, sim_s))
                while returns and vehicle_t >= returns[0][0]:
                    _, at = returns.pop(0)
                    self.operator_answers.append(station.operator_return(at, None, sim_s))
                while reliefs and vehicle_t >= reliefs[0][0]:
                    _, uav = reliefs.pop(0)
                    self.operator_answers.append(station.operator_relieve(uav, None, sim_s))
                while typed and vehicle_t >= typed[0][0]:
                    station.operator_command(typed.pop(0)[1], sim_s)
                while interrupts and vehicle_t >= interrupts[0]:
                    interrupts.pop(0)
                    station.interrupt()
                if sim_s >= next_tick - 1e-9:
                    next_tick += tick_period
                    if connected:
                        station.tick(sim_s)
                    else:
                        state = station.connect_step(sim_s, 0.0)
                        if state is False:
                            break
                        if state:
                            connected = True
                            self.sim_zero = self.clock.wall_at(0.0)
                self._send_down(sim_s)
            if connected and not (stalls and faults.stalled(vehicle_t)):  # the GCS records
                if sim_s >= next_sample - 1e-9:
                    self._sample(sim_s)
                    next_sample = sim_s + self.options.sample_period_s
                if station.finished(sim_s) or self.mission_time(sim_s) > self.time_limit_s:
                    break
            self.medium.periodic(sim_s)
            for index, message in fleet.control_tick():
                self._send_up(index, message, sim_s)

    def _deliver(self, sim_s: float) -> None:
        """Deliver what is due: to the vehicles (their answers go up at once), and to the
        ground station's socket buffers (`_arrived`, read by `_batches`)."""
        for due, (direction, index, message, sent) in self.delay.pop_due(sim_s):
            if direction == "down":
                self._on_received_by_uav(index, message, due)
                self.fleet.deliver(index, message, due)
                for k, answer in self.fleet.drain():
                    self._send_up(k, answer, sim_s)
            else:
                self._on_sent_by_uav(index, message, sent)
                self._arrived.setdefault(index, []).append(message)

    def _batches(self, sim_s: float):
        """What waits for the ground station, one batch per UAV link."""
        arrived, self._arrived = self._arrived, {}
        for index, messages in arrived.items():
            yield index, self.links[index].accept(messages, sim_s), sim_s

    def _send_up(self, index: int, message, sim_s: float) -> None:
        encoder = self.encoders[index]
        message.pack(encoder)
        encoder.seq = (encoder.seq + 1) % 256
        _, delay = self.medium.route("uplink", index, sim_s)
        if delay is not None and not self._cut(index, sim_s):
            due = self._due(index, "up", sim_s, delay)
            self.delay.put((index, "up"), due, ("up", index, message, sim_s))

    def _send_down(self, sim_s: float) -> None:
        """What the drivers sent, into the medium."""
        for index, link in enumerate(self.links):
            if not link.outbox:
                continue
            starved = self.options.faults.setpoints_cut(index + 1, sim_s - self.sim_zero)
            for message in link.outbox:
                _, delay = self.medium.route("downlink", index, sim_s)
                if delay is not None and not self._cut(index, sim_s) and not starved:
                    due = self._due(index, "down", sim_s, delay)
                    self.delay.put((index, "down"), due, ("down", index, message, sim_s))
            link.outbox.clear()

    def _cut(self, index: int, sim_s: float) -> bool:
        """The packet sent now to or from UAV `index` is lost (`Faults.link_cuts`, `link_loss`)."""
        faults = self.options.faults
        if faults.link_loss > 0 and self._loss_draws.random() < faults.link_loss:
            return True
        return bool(faults.link_cuts) and faults.cut(index + 1, sim_s - self.sim_zero)

    def _due(self, index: int, direction: str, sim_s: float, delay: float) -> float:
        """When a packet sent now arrives: the medium's delay, plus the lateness of a late
        process or medium (`Faults.late`), never before the one sent before it."""
        faults = self.options.faults
        if not faults.late:
            return sim_s + delay
        due = sim_s + delay + faults.lateness(index + 1, sim_s - self.sim_zero)
        due = max(due, self._last_due.get((index, direction), -math.inf))
        self._last_due[(index, direction)] = due
        return due

    # ------------------------------------------------------------------ speed-change timing
    def _on_received_by_uav(self, index: int, message, due_sim_s: float) -> None:
        """T_dv is measured where it happens: the instant the UAV receives the change."""
        if (
            message.get_type() == "COMMAND_INT"
            and message.command == mavlink.MAV_CMD_DO_CHANGE_SPEED
        ):
            received = self.received_s.setdefault(int(message.y), {})
            received.setdefault(index + 1, self.mission_time(due_sim_s))

    def _on_sent_by_uav(self, index: int, message, sent_sim_s: float) -> None:
        """A leader's request (its own sequence number): when it was first sent."""
        if (
            message.get_type() == "COMMAND_INT"
            and message.command == mavlink.MAV_CMD_DO_CHANGE_SPEED
            and (index, int(message.y)) not in self._leader_seen
        ):
            self._leader_seen.add((index, int(message.y)))
            self.leader_sent_s.setdefault(index + 1, []).append(self.mission_time(sent_sim_s))

    # ------------------------------------------------------------------ samples and result
    def _sample(self, sim_s: float) -> None:
        if self.clock.frozen:
            # a stall being resolved: the mission clock stands at the stall's start while the
            # UAVs flew on (the sample would pair them with V_n there: 9.4 m that never were)
            return
        t = self.mission_time(sim_s)
        self._times.append(t)
        self._positions.append(self.fleet.dynamics.position.copy())
        self._hops.append(self.medium.topology_at(sim_s).hops.copy())
        roster = self.station.roster
        if roster is not None and roster.reshaped:  # a relief: V_n as flown, who is out
            self._relieved_samples[len(self._times) - 1] = (
                self.station.virtual_targets(t),
                self.station.out_of_fleet(),
                roster.active is not None,
            )

    def _relief_checks(self, checks: GuaranteeSamples, positions: np.ndarray) -> GuaranteeSamples:
        """The guarantee checks of the samples taken since a relief: the relieved UAVs that
        landed are out of the fleet; while one flies home above the chain, UAV-UAV distances
        and links are 3-D (`check_positions`)."""
        mission = self.mission
        closest, obstacle = checks.min_uav_uav_m.copy(), checks.min_uav_obstacle_m.copy()
        connected, max_hops = checks.connected.copy(), checks.max_hops.copy()
        hops = checks.hops.copy()
        for k, (_, out, lane) in self._relieved_samples.items():
            keep = ~out
            sample = check_positions(
                positions[k : k + 1, keep, :2],
                mission.obstacles,
                base_stations(mission),
                mission.radio_range,
                positions[k : k + 1, keep, 2] if lane else None,
            )
            closest[k], obstacle[k] = sample.min_uav_uav_m[0], sample.min_uav_obstacle_m[0]
            connected[k], max_hops[k] = sample.connected[0], sample.max_hops[0]
            hops[k] = 0
            hops[k, keep] = sample.hops[0]
        return replace(
            checks,
            min_uav_uav_m=closest,
            min_uav_obstacle_m=obstacle,
            connected=connected,
            max_hops=max_hops,
            hops=hops,
        )

    def _speed_changes(self) -> list[dict]:
        """Each change's record, with when each UAV received it and, for a leader's, when the
        leader sent its request (a leader's requests and its changes match in order)."""
        leader_sent = {uav: list(times) for uav, times in self.leader_sent_s.items()}
        changes = []
        for entry in self.station.speeds.as_json():
            received = self.received_s.get(entry["seq"], {})
            entry["received_s"] = {str(u): s for u, s in sorted(received.items())}
            entry["leader_sent_s"] = None
            if entry["source"].startswith("leader:"):
                sent = leader_sent.get(int(entry["source"].split(":")[1]), [])
                entry["leader_sent_s"] = sent.pop(0) if sent else None
            changes.append(entry)
        return changes

    def _finish(self) -> FastRun:
        mission, station = self.mission, self.station
        formation = station.formation  # a stations mission's with its way home
        times = np.array(self._times)
        positions = np.array(self._positions).reshape(len(times), self.size, 3)
        hops = np.array(self._hops).reshape(len(times), self.size)
        xy = positions[..., :2]
        checks = check_positions(xy, mission.obstacles, base_stations(mission), mission.radio_range)
        roster = station.roster
        if roster is not None and roster.reshaped:
            formation = roster.outbound  # until the first relief; then as sampled
        virtual = formation.positions(station.profile.distance(times))
        if self._relieved_samples:
            checks = self._relief_checks(checks, positions)
            for k, (targets, _, _) in self._relieved_samples.items():
                virtual[k] = targets
        tracking = np.hypot(*np.moveaxis(xy - virtual, -1, 0))
        result = replace(station.result(), radio=run_json_radio(self.medium.stats.summary()))
        data = run_json(result, "", mission.safety_margin)
        data["log"] = None
        data["mode"] = "fast"
        packets = self.medium.stats.log.columns()
        if self.clock.anchored:
            packets["time_s"] = packets["time_s"] - self.clock.wall_at(0.0)

        def mission_times(values) -> np.ndarray:
            return np.array([math.nan if v is None else v for v in values], dtype=float)

        return FastRun(
            run_json=data,
            result=result,
            formation=formation,
            profile=station.profile,
            times=times,
            positions=positions,
            hops=hops,
            checks=checks,
            tracking_error_m=tracking,
            packets=packets,
            speed_changes=self._speed_changes(),
            takeoff_s=mission_times(t.takeoff_time for t in station.tracks),
            landed_s=mission_times(t.landed_time for t in station.tracks),
            operator_answers=self.operator_answers,
            stalls=list(station.stalls),
            battery_remaining_pct=np.array(
                [d.telemetry.battery_remaining_pct for d in station.drivers], dtype=float
            ),
        )


def fly_fast(plan: MissionPlan, options: FastOptions | None = None) -> FastRun:
    """Fly `plan` in the fast in-process mode (see the module docstring)."""
    if not plan.valid:
        raise ValueError(f"no valid path: {plan.reason}")
    return _LockstepMission(plan, options or FastOptions()).run()
