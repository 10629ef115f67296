"""The :class:`Autopilot` facade: the state of one vehicle's autopilot, the routing of each
received message to its protocol module, the control tick (:meth:`Autopilot.update`), and the
telemetry, built from one frozen :class:`~vehicles.autopilot.status.AutopilotStatus` per tick.

The protocol modules are functions of the autopilot: :mod:`~vehicles.autopilot.modes` (modes,
arming, ground state, landing), :mod:`~vehicles.autopilot.failsafes` (setpoint timeout, GCS
failsafe), :mod:`~vehicles.autopilot.commands` (COMMAND_LONG / COMMAND_INT),
:mod:`~vehicles.autopilot.setpoints` (SET_POSITION_TARGET_*), :mod:`~vehicles.autopilot.speed`
(speed changes, mission clock, leader requests), :mod:`~vehicles.autopilot.parameters`,
:mod:`~vehicles.autopilot.missions` (the mission protocol), :mod:`~vehicles.autopilot.auto`
(AUTO flying the mission) and :mod:`~vehicles.autopilot.ftp` (MAVFTP refused at once).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.geodesy import Origin
from fleetwire.messages import clock_slipped_text
from vehicles import telemetry
from vehicles.autopilot import (
    auto,
    commands,
    failsafes,
    ftp,
    missions,
    modes,
    parameters,
    setpoints,
    speed,
)
from vehicles.autopilot.config import AutopilotConfig
from vehicles.autopilot.status import AutopilotStatus, BatteryState, battery_of
from vehicles.autopilot.types import AUTOPILOT_COMPONENT, Guided, Mode, Stamp
from vehicles.dynamics import FleetDynamics
from vehicles.fleet_speed import LeaderRequest, LeaderSchedule, MissionClock, SpeedBook
from vehicles.telemetry import BUILDERS, FleetSnapshot, TelemetrySchedule

log = logging.getLogger(__name__)

#: Sent once the boot is over (with the STATUSTEXT "ArduPilot Ready").
_BOOT_MESSAGES = (mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, mavlink.MAVLINK_MSG_ID_HOME_POSITION)
_ATTITUDE = mavlink.MAVLINK_MSG_ID_ATTITUDE


def _on_timesync(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    """TIMESYNC request (tc1 = 0): answer with the simulated time in ns."""
    if msg.tc1 == 0:
        ap.send(mavlink.MAVLink_timesync_message(int(stamp.sim_s * 1e9), msg.ts1))


#: The module function that handles each message type (for this system, or broadcast).
_HANDLERS: dict[str, Callable[[Autopilot, mavlink.MAVLink_message, Stamp], None]] = {
    "SET_MODE": modes.on_set_mode,
    "COMMAND_LONG": commands.on_command_long,
    "COMMAND_INT": commands.on_command_int,
    "COMMAND_ACK": speed.on_command_ack,
    "SET_POSITION_TARGET_LOCAL_NED": setpoints.on_position_target_local,
    "SET_POSITION_TARGET_GLOBAL_INT": setpoints.on_position_target_global,
    "NAMED_VALUE_INT": speed.on_named_value_int,
    "TIMESYNC": _on_timesync,
    "PARAM_REQUEST_LIST": parameters.on_param_request_list,
    "PARAM_REQUEST_READ": parameters.on_param_request_read,
    "PARAM_SET": parameters.on_param_set,
    "MISSION_REQUEST_LIST": missions.on_mission_request_list,
    "MISSION_REQUEST_INT": missions.on_mission_request_int,
    "MISSION_REQUEST": missions.on_mission_request,
    "MISSION_COUNT": missions.on_mission_count,
    "MISSION_CLEAR_ALL": missions.on_mission_clear_all,
    "MISSION_ITEM_INT": missions.on_mission_item,
    "MISSION_ITEM": missions.on_mission_item,
    "FILE_TRANSFER_PROTOCOL": ftp.on_file_transfer_protocol,
}


class Autopilot:
    """One vehicle's MAVLink behaviour: modes, arming, commands, setpoints, failsafes, telemetry.

    It owns the state its protocol modules share (the attributes set in ``__init__``), routes
    each message to them (:meth:`handle`), advances them at the control rate (:meth:`update`)
    and queues what it sends in ``outbox``.
    """

    def __init__(
        self,
        *,
        sysid: int,
        index: int,
        count: int,
        config: AutopilotConfig,
        dynamics: FleetDynamics,
        origin: Origin,
        leader_requests: tuple[LeaderRequest, ...] = (),
    ) -> None:
        self.sysid = sysid
        self.index = index
        self.count = count
        self.config = config
        self.dynamics = dynamics
        self.origin = origin
        self.leader_requests = leader_requests
        self.outbox: list[mavlink.MAVLink_message] = []
        self.comm_errors = 0
        # the stored mission survives a reboot (missions.py); AUTO's progress in it does not
        self.mission: tuple[missions.MissionItem, ...] = ()
        self.mission_item_warned = False
        self.mission_request_warned = False
        self._refusal_last: dict[str, float] = {}
        self._boot(0.0)

    def _boot(self, now_s: float) -> None:
        """The state of an autopilot that boots at simulated time ``now_s``: STABILIZE,
        disarmed, on the ground, home and EKF origin where it stands, default telemetry."""
        config, dynamics, index = self.config, self.dynamics, self.index
        self.booted_at_s = now_s
        self.mode = Mode.STABILIZE
        self.armed = False
        self.auto_armed = False  # AUTO may take off (Copter::update_auto_armed)
        self.landed = True
        self.guided = Guided.IDLE
        self.ekf_origin_enu = dynamics.position[index].copy()
        self.home_enu = dynamics.position[index].copy()
        self.mission_clock = MissionClock()
        self.speeds = SpeedBook()
        self.leader = LeaderSchedule(
            self.leader_requests, config.leader_retry_s, config.leader_max_tries
        )
        self.telemetry = TelemetrySchedule(
            config.telemetry.intervals(), phase=telemetry.phase_of(index, self.count)
        )
        # failsafes
        self.gcs_failsafe: str | None = None  # None, "hold" or "land"
        self.gcs_last: Stamp | None = None  # the last message from the GCS (once it is known)
        self.gcs_failsafe_since: Stamp | None = None
        self.last_setpoint: Stamp | None = None
        self.setpoint_timed_out = False
        # ground state, take-off and RTL
        self.grounded_since: float | None = None
        self.landed_since: float | None = None
        self.takeoff_target_z = 0.0
        self.takeoff_started_s = 0.0
        self.rtl_phase = ""  # "climb", "return", "land"
        # the mission: an upload in progress (missions.py), AUTO's progress (auto.py)
        self.mission_upload: missions.Upload | None = None
        self.mission_nav = 0  # the navigation item AUTO is at (0: none)
        self.mission_running = False
        self.mission_complete = False
        self.auto_waiting = False  # AUTO was selected: start or resume at the next tick
        self.auto_phase = ""  # "takeoff_wait", "takeoff", "wp", "land_approach", "land", "rtl"
        self.auto_target: np.ndarray | None = None
        self.nav_speed_mps = config.waypoint_speed_mps
        self.wp_arrived_s: float | None = None
        # output
        self._booted_announced = False
        self._reported_attitude: tuple[float, float, float, float] | None = None
        dynamics.motors_on[index] = False
        modes.idle_on_ground(self)

    def reboot(self, stamp: Stamp) -> None:
        """MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN (disarmed): boot again from ``stamp``; the mission
        and the parameters stay, the rest starts afresh (the link keeps its peer)."""
        log.info("sysid %d: rebooting", self.sysid)
        self._boot(stamp.sim_s)

    # ------------------------------------------------------------------ state ----------
    def booting(self, stamp: Stamp) -> bool:
        return stamp.sim_s - self.booted_at_s < self.config.boot_time_s

    def airborne(self) -> bool:
        return self.armed and not self.landed

    def battery(self) -> BatteryState:
        return battery_of(self.dynamics, self.index)

    def status(self, stamp: Stamp) -> AutopilotStatus:
        """The frozen status the telemetry builders read at ``stamp``."""
        i = self.index
        dynamics = self.dynamics
        return AutopilotStatus(
            sysid=self.sysid,
            index=i,
            booting=stamp.sim_s - self.booted_at_s < self.config.boot_time_s,  # self.booting()
            mode=self.mode,
            guided=self.guided,
            rtl_phase=self.rtl_phase,
            auto_phase=self.auto_phase,
            armed=self.armed,
            landed=self.landed,
            gcs_failsafe=self.gcs_failsafe is not None,
            comm_errors=self.comm_errors,
            airframe=dynamics.config.airframe,
            energy_used_j=float(dynamics.energy_used_j[i]),
            power_w=float(dynamics.power_w[i]),
            battery_capacity_mah=float(dynamics.battery_capacity_mah[i]),
            home_enu=tuple(self.home_enu.tolist()),
            ekf_origin_enu=tuple(self.ekf_origin_enu.tolist()),
            fleet_speed_mps=self.speeds.fleet_speed(stamp.sim_s, self.mission_clock),
            mission_time_s=self.mission_clock.now(stamp.sim_s),
            reported_attitude=self._reported_attitude,
            mission_count=len(self.mission),
            mission_nav=self.mission_nav,
            mission_running=self.mission_running,
            mission_complete=self.mission_complete,
        )

    # ------------------------------------------------------------------ output ---------
    def send(self, message: mavlink.MAVLink_message) -> None:
        self.outbox.append(message)

    def status_text(self, severity: int, text: str) -> None:
        log.info("sysid %d: %s", self.sysid, text)
        self.send(
            mavlink.MAVLink_statustext_message(severity, text[:50].encode("ascii", "replace"))
        )

    def refuse(self, key: str, text: str, stamp: Stamp) -> None:
        """A rate-limited STATUSTEXT for refusals that can arrive at stream rate."""
        last = self._refusal_last.get(key)
        if last is None or stamp.sim_s - last >= self.config.refusal_text_interval_s:
            self._refusal_last[key] = stamp.sim_s
            self.status_text(mavlink.MAV_SEVERITY_WARNING, text)

    def emit(self, msg_id: int, snapshot: FleetSnapshot, stamp: Stamp) -> bool:
        """Build and queue message ``msg_id`` now; False if it cannot be produced."""
        if msg_id not in BUILDERS:
            return False
        self.emit_due((msg_id,), snapshot, stamp)
        return True

    def emit_due(
        self, msg_ids: list[int] | tuple[int, ...], snapshot: FleetSnapshot, stamp: Stamp
    ) -> None:
        """Build and queue the messages ``msg_ids`` (the telemetry due now) from one status."""
        if not msg_ids:
            return
        status = self.status(stamp)
        outbox = self.outbox
        for msg_id in msg_ids:
            builder = BUILDERS.get(msg_id)
            if builder is None:
                continue
            message = builder(status, snapshot, stamp)
            if message is not None:
                outbox.append(message)
            if msg_id == _ATTITUDE:  # its rates are differences between the attitudes reported
                self._reported_attitude = (stamp.sim_s, *snapshot.attitude(self.index))

    # ------------------------------------------------------------------ tick -----------
    def tick(self, stamp: Stamp, snapshot: FleetSnapshot) -> None:
        """Advance the state machine to ``stamp`` and queue the telemetry that is due."""
        self.update(stamp)
        self.emit_due(self.telemetry.due(stamp.sim_s), snapshot, stamp)

    def update(self, stamp: Stamp) -> None:
        """Advance the state machine (boot, ground contact, modes, failsafes, leader) to ``stamp``."""
        if not self._booted_announced and not self.booting(stamp):
            self._booted_announced = True
            self.status_text(mavlink.MAV_SEVERITY_INFO, "ArduPilot Ready")
            self.emit_due(_BOOT_MESSAGES, FleetSnapshot(self.dynamics, self.origin), stamp)
        modes.update_ground_state(self, stamp)
        if self.mode == Mode.AUTO:
            auto.update(self, stamp)
        elif self.armed and not self.landed:
            modes.update_mode(self, stamp)
            failsafes.update_setpoint_timeout(self, stamp)
        if self.mission_upload is not None:
            missions.update(self, stamp)
        failsafes.update_gcs_failsafe(self, stamp)
        if self.leader.active():
            speed.update_leader(self, stamp)

    def land_before_stopping(self, stamp: Stamp) -> None:
        """The process is asked to stop while this vehicle flies: land first (LAND, as the GCS
        failsafe would), so that stopping the process never drops a UAV from the sky."""
        if self.airborne() and self.mode != Mode.LAND:
            modes.set_mode(self, Mode.LAND, stamp)
            self.status_text(mavlink.MAV_SEVERITY_CRITICAL, "Sim: stopping: landing first")

    def clock_slipped(self, seconds: float, stamp: Stamp) -> None:
        """The simulation could not keep up and its clock slipped (the sim rate-limits this)."""
        self.status_text(mavlink.MAV_SEVERITY_WARNING, clock_slipped_text(seconds))

    # ------------------------------------------------------------------ input ----------
    def handle(self, message: mavlink.MAVLink_message, stamp: Stamp) -> None:
        """React to one decoded message (already known to be valid MAVLink)."""
        source = message.get_srcSystem()
        kind = message.get_type()
        if source == self.config.failsafe.gcs_system and (
            self.gcs_last is not None or kind == "HEARTBEAT"
        ):
            failsafes.gcs_alive(self, stamp)
        handler = _HANDLERS.get(kind)
        if handler is None:
            return
        if source == self.sysid:
            return  # our own echo
        target = getattr(message, "target_system", 0)
        if target not in (0, self.sysid):
            return
        component = getattr(message, "target_component", 0)
        if component not in (0, AUTOPILOT_COMPONENT):
            return
        handler(self, message, stamp)
