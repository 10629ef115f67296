"""Fake PX4 (SITL SIH, quad-X, main of Aug 2025) built from the P1/P2 transcripts of
`tests/sitl/`, as seen on its offboard/API link (MAVLink mode "onboard").

What it reproduces (times from the first HEARTBEAT at speedup 1; `tests/sitl/README.md`):

* Boot: GPS fix and local position before the first HEARTBEAT (29 / AUTO.LOITER / UNINIT),
  HOME_POSITION +1.0 s (then every 2 s), GLOBAL_POSITION_INT +1.6 s, armable (SYS_STATUS
  pre-arm bit, STANDBY) +3.1 s. STATUSTEXT is held back until the logger runs (+1.4 s); EVENTs
  are not. It streams its telemetry without being asked.
* MAV_CMD_DO_SET_MODE: two COMMAND_ACKs, the first always ACCEPTED, the second the verdict a few
  ms later. While disarmed OFFBOARD is accepted without a setpoint stream (base_mode 1, UNINIT,
  pre-arm bit false) and arming then fails: TEMPORARILY_REJECTED, EVENT, STATUSTEXT severity 2 in
  two chunks `Arming denied: Resolve system health failures firs` + `t\\t`. Armed without a
  stream: second ACK TEMPORARILY_REJECTED, `Switching to Offboard is currently not available\\t`.
  Unknown main mode: two ACCEPTED, nothing changes; unknown AUTO sub-mode: `Unsupported auto
  mode\\t`. SET_MODE: one ACK (command 176).
* Setpoints (SET_POSITION_TARGET_GLOBAL_INT / _LOCAL_NED) are the offboard signal; with none for
  COM_OF_LOSS_T (1 s, wall clock) while armed in OFFBOARD: `Failsafe activated\\t` + EVENT, POSCTL
  (209 / 0x00030000 / CRITICAL), holding position, until the next mode command.
* MAV_CMD_NAV_TAKEOFF: AUTO.TAKEOFF (also while disarmed), climbs to param7 AMSL armed, then
  AUTO.LOITER. MAV_CMD_NAV_LAND: `Landing at current position\\t`, AUTO.LAND, the gimbal
  COMMAND_LONGs PX4 sends to itself, `Landing detected\\t`; it stays armed until disarmed; after
  disarming it returns to the mode it was in before landing (P1: OFFBOARD, P2: Hold).
* Every STATUSTEXT ends in `\\t` and comes with an EVENT (id 410), which pymavlink 2.4.50 cannot
  decode: a ground station gets BAD_DATA for it. Home carries GPS noise (seeded, about a metre).
* Unknown command: UNSUPPORTED.

Extrapolated (not in the transcripts): DISARM in flight is TEMPORARILY_REJECTED; a known
SET_MODE mode is applied with the DO_SET_MODE rules, its single ACK carrying the verdict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fleetwire.modes import PX4_AUTO_SUB_MODE, PX4_MAIN_MODE, px4_custom_mode
from tests.fakes.common import (
    ACCEPTED,
    ARMED_FLAG,
    IGNORE_POSITION,
    IGNORE_VELOCITY,
    PREARM_CHECK,
    TEMPORARILY_REJECTED,
    UNSUPPORTED,
    ExtraMessage,
    FakeAutopilot,
    Home,
    ParameterSet,
    command_ack,
    enu_to_global,
    global_position_int,
    global_to_enu,
    gps_raw_int,
    local_position_ned,
    mavlink,
    position_target_local_ned,
    setpoint_enu,
    text,
)

#: HEARTBEAT custom_mode of a PX4 main mode and sub-mode.
px4_mode = px4_custom_mode
# PX4's main modes and AUTO sub-modes (pymavlink's numbers).
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD, MAIN_STABILIZED = (
    PX4_MAIN_MODE[name]
    for name in ("MANUAL", "ALTCTL", "POSCTL", "AUTO", "ACRO", "OFFBOARD", "STABILIZED")
)
SUB_TAKEOFF, SUB_LOITER, SUB_MISSION, SUB_RTL, SUB_LAND = (
    PX4_AUTO_SUB_MODE[name] for name in ("TAKEOFF", "LOITER", "MISSION", "RTL", "LAND")
)
AUTO_LOITER = px4_mode(MAIN_AUTO, SUB_LOITER)  # 0x03040000
AUTO_TAKEOFF = px4_mode(MAIN_AUTO, SUB_TAKEOFF)  # 0x02040000
AUTO_LAND = px4_mode(MAIN_AUTO, SUB_LAND)  # 0x06040000
OFFBOARD = px4_mode(MAIN_OFFBOARD)  # 0x00060000
POSCTL = px4_mode(MAIN_POSCTL)  # 0x00030000
_AUTO_SUBS = frozenset({2, 3, 4, 5, 6, 7, 8, 9})
_MAIN_MODES = frozenset({1, 2, 3, 4, 5, 6, 7, 8})

#: Where PX4's SITL boots by default (P1 home, without its GPS noise).
SITL_HOME = Home(47.397742, 8.545594, 488.0)

# SYS_STATUS bitmasks recorded in P1 (present, enabled, health without the pre-arm bit).
_SENSORS_BOOT = (0x0, 0x0, 0x321C83F)
_SENSORS_HOME = (0x300400F, 0x301400F, 0x320883F)
_SENSORS_READY = (0x300402F, 0x301402F, 0x320C83F)

# EVENT (id, log_levels, arguments) as recorded in P1/P2.
_EV_LOGGER = (17980399, 102, [234, 7, 11, 22, 8, 41, 24])
_EV_CHECKS_BOOT = [
    (27825120, 136, [0, 0, 0, 18, 1, 128, 0, 0, 0, 128, 59, 1, 128, 128, 59, 1, 128]),
    (30612409, 51, [124, 0, 126, 0, 17]),
    (26788467, 51, [56, 0, 0, 0, 24]),
    (17154777, 102, [8, 0, 0, 0, 20]),
    (19865031, 51, [0, 64, 0, 0, 20]),
    (17231145, 68, [255, 255, 255, 255, 7]),
    (23579003, 102, [255, 255, 255, 255, 12]),
    (18691879, 136, [0, 2, 12, 2, 56]),
]
_EV_CHECKS_READY = [  # position valid, no offboard signal
    (27825120, 136, [0, 0, 0, 16, 0, 128, 0, 0, 0, 176, 59, 127, 128, 176, 59, 127, 128]),
    (17154777, 102, [8, 0, 0, 0, 20]),
    (19865031, 51, [0, 64, 0, 0, 20]),
    (17231145, 68, [255, 255, 255, 255, 7]),
    (18691879, 136, [0, 10, 28, 2, 56]),
]
_EV_CHECKS_SIGNAL = [  # offboard signal present
    (27825120, 136, [0, 0, 0, 0, 0, 128, 0, 0, 0, 176, 123, 127, 128, 176, 123, 127, 128]),
    (17154777, 102, [8, 0, 0, 0, 20]),
    (17231145, 68, [255, 255, 255, 255, 7]),
    (18691879, 136, [0, 10, 28, 2, 56]),
]
_EV_ARM_DENIED = (16910493, 98, [])
_EV_ARMED = (26266355, 102, [4])
_EV_DISARMED = (32794487, 102, [4])
_EV_TAKEOFF_DETECTED = (21054825, 102, [])
_EV_FAILSAFE = (31382480, 66, [0, 0, 6, 0, 2])
_EV_LANDING = (20099806, 102, [])
_EV_LANDED = (26622124, 102, [])
_EV_UNSUPPORTED_AUTO = (19869445, 51, [])
_EV_MODE_NOT_AVAILABLE = (27280279, 98, [0, 0, 6, 0, 7])

ARM_DENIED_TEXT = "Arming denied: Resolve system health failures first\t"
OFFBOARD_NOT_AVAILABLE_TEXT = "Switching to Offboard is currently not available\t"
FAILSAFE_TEXT = "Failsafe activated\t"


@dataclass(frozen=True)
class Px4Timeline:
    """Seconds after the first HEARTBEAT at speedup 1 (P1 and P2 agree within 0.1 s)."""

    home: float = 1.02  # first HOME_POSITION
    logger: float = 1.41  # STATUSTEXT held back until then
    global_position: float = 1.63  # first GLOBAL_POSITION_INT
    armable: float = 3.05  # HEARTBEAT STANDBY, pre-arm bit
    heartbeat_period: float = 1.018  # P1: 1.468, 4.523, ... 75.81


@dataclass(frozen=True)
class Px4Params:
    """Parameters that shape what a GCS sees (PX4 defaults, SIH behaviour of P1)."""

    com_of_loss_t: float = 1.0  # COM_OF_LOSS_T (s, wall clock: never compressed)
    xy_vel_max: float = 12.0  # MPC_XY_VEL_MAX
    z_vel_max_up: float = 3.0  # MPC_Z_VEL_MAX_UP
    z_vel_max_dn: float = 1.5  # MPC_Z_VEL_MAX_DN
    land_speed: float = (
        0.87  # mean AUTO.LAND descent, AMSL (P1: 20.8 m in 24 s, P2: 14.3 m in 16.5 s)
    )
    takeoff_alt_default: float = 2.5  # MIS_TAKEOFF_ALT
    spool_up: float = 1.8  # arming -> lifting (P1 11.84 -> ~13.6)
    landing_detect: float = (
        3.7  # touchdown -> `Landing detected` (P1 70.3 -> 74.7, P2 48.4 -> 52.0)
    )
    mode_ack_delay: float = 0.008  # first -> second DO_SET_MODE ack (P1/P2: 0-12 ms)
    gps_noise_m: float = 0.7  # standard deviation of the GPS offset per axis (m)


#: PX4's parameters as a ground station reads them: the count and encoding recorded in P2
#: (905 parameters, integers copied bytewise: CAL_BARO0_ID 6620172 arrives as 9.28e-39); the
#: limits of its offboard position control at the firmware's defaults (not read in P1/P2).
PX4_PARAMETERS = ParameterSet(
    count=905,
    bytewise=True,
    values={
        "MPC_XY_VEL_MAX": (12.0, mavlink.MAV_PARAM_TYPE_REAL32),  # m/s
        "MPC_ACC_HOR_MAX": (5.0, mavlink.MAV_PARAM_TYPE_REAL32),  # m/s^2
        "MPC_ACC_HOR": (3.0, mavlink.MAV_PARAM_TYPE_REAL32),
        "MPC_Z_VEL_MAX_UP": (3.0, mavlink.MAV_PARAM_TYPE_REAL32),
        "MPC_TILTMAX_AIR": (45.0, mavlink.MAV_PARAM_TYPE_REAL32),  # degrees
        "CAL_BARO0_ID": (6620172.0, mavlink.MAV_PARAM_TYPE_INT32),  # P2
    },
)


class Px4Model(FakeAutopilot):
    """The state machine of one PX4 SITL instance as a ground station sees it."""

    parameter_set = PX4_PARAMETERS

    def __init__(
        self,
        home: Home = SITL_HOME,
        *,
        system_id: int = 1,
        speedup: float = 1.0,
        seed: int = 1,
        timeline: Px4Timeline = Px4Timeline(),
        params: Px4Params = Px4Params(),
        initial_mode: int = AUTO_LOITER,
        ignored_modes: frozenset[int] = frozenset(),
    ) -> None:
        """`initial_mode`: the mode it is in when the GCS connects (AUTO.LOITER after boot;
        OFFBOARD after a flight that ended like P1). `ignored_modes`: custom modes it answers
        with two ACCEPTED and does not enter, as P2 4.58 shows for an unknown main mode."""
        super().__init__(system_id=system_id, speedup=speedup)
        self.boot_spot = home
        self.timeline = timeline
        self.params = params
        rng = np.random.default_rng(seed)
        self.gps_offset = np.clip(rng.normal(0.0, params.gps_noise_m, 3), -2.0, 2.0)
        self.home: Home | None = None
        self.mode = initial_mode
        self.intended_mode = initial_mode
        self.ignored_modes = ignored_modes
        self.mode_after_disarm = initial_mode
        self.armed = False
        self.failsafe = False
        self._started = False
        self._next_heartbeat = 0.0
        self._next_home = timeline.home
        self._events_sequence = 65526
        self._text_id = 0
        self._held_texts: list = []
        self._booted_checks = False
        self._armable_seen = False
        self._last_setpoint: float | None = None
        self._signal = False
        self._target = np.zeros(3)
        self._feed_forward = np.zeros(3)
        self._armed_at = 0.0
        self._takeoff_alt_amsl: float | None = None
        self._touchdown_at: float | None = None
        self._landing_announced = False
        self._gimbal: list[tuple[float, int]] = []

    # --- state ----------------------------------------------------------------------------------

    def position_valid(self, now: float) -> bool:
        return self._after(now, self.timeline.armable)

    def signal(self, now: float) -> bool:
        """Offboard signal: a setpoint within COM_OF_LOSS_T (wall clock)."""
        return self._last_setpoint is not None and (
            now - self._last_setpoint <= self.params.com_of_loss_t
        )

    def armable(self, now: float) -> bool:
        """The pre-arm bit: position, offboard signal in OFFBOARD, no failsafe (P1 44.49)."""
        if not self.position_valid(now) or self.failsafe:
            return False
        return self.mode != OFFBOARD or self.signal(now)

    def reported_enu(self) -> np.ndarray:
        """Where the GPS says the vehicle is (true position + the GPS offset)."""
        return self.body.position + self.gps_offset

    # --- outputs helpers ------------------------------------------------------------------------

    def _event(self, now: float, spec) -> ExtraMessage:
        ident, levels, args = spec
        self._events_sequence = (self._events_sequence + 1) & 0xFFFF
        return ExtraMessage(
            "EVENT",
            id=ident,
            event_time_boot_ms=int(now * self.speedup * 1000) & 0xFFFFFFFF,
            sequence=self._events_sequence,
            log_levels=levels,
            arguments=list(args) + [0] * (40 - len(args)),
        )

    def _texts(self, severity: int, message: str) -> list:
        """STATUSTEXT chunks of 50 characters sharing one id (PX4 splits long texts)."""
        self._text_id = (self._text_id + 1) & 0xFFFF
        chunks = [message[i : i + 50] for i in range(0, len(message), 50)]
        return [text(severity, c, ident=self._text_id, chunk_seq=i) for i, c in enumerate(chunks)]

    def _say(self, now: float, severity: int, message: str, event=None, *, ack=None) -> None:
        """A STATUSTEXT (held back before the logger runs) with its EVENT; an ACK after."""
        if event is not None:
            self.outbox.send(now, self._event(now, event))
        if ack is not None:
            self.outbox.send(now, ack)
        chunks = self._texts(severity, message)
        if self._after(now, self.timeline.logger):
            self.outbox.send(now, *chunks)
        else:
            self._held_texts.extend(chunks)

    def _ack(self, msg, result: int, now: float):
        return command_ack(msg.command, result, *self._gcs)

    # --- inputs ---------------------------------------------------------------------------------

    def _mode_message(self, msg, now: float) -> None:
        main = (int(msg.custom_mode) >> 16) & 0xFF
        sub = (int(msg.custom_mode) >> 24) & 0xFF
        verdict = self._change_mode(main, sub, now)
        ack = command_ack(mavlink.MAV_CMD_DO_SET_MODE, verdict, *self._gcs)
        self.commands.append((now, mavlink.MAV_CMD_DO_SET_MODE, verdict))
        self.outbox.send(now, ack)

    def _command(self, msg, now: float) -> None:
        cmd = int(msg.command)
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if msg.param1 >= 0.5:
                self._arm(msg, now)
            else:
                self._disarm(msg, now)
            return
        if cmd == mavlink.MAV_CMD_DO_SET_MODE:
            self.outbox.send(now, self._ack(msg, ACCEPTED, now))
            if not int(msg.param1) & 1:
                verdict = ACCEPTED
            else:
                verdict = self._change_mode(int(msg.param2), int(msg.param3), now, ack_of=msg)
            self.commands.append((now, cmd, verdict))
            if verdict == ACCEPTED:
                self.outbox.send(now + self.params.mode_ack_delay, self._ack(msg, ACCEPTED, now))
            return
        if cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            self.commands.append((now, cmd, ACCEPTED))
            self.outbox.send(now, self._ack(msg, ACCEPTED, now))
            alt = msg.param7
            home_alt = self.home.alt if self.home else self.boot_spot.alt
            self._takeoff_alt_amsl = (
                float(alt) if math.isfinite(alt) else home_alt + self.params.takeoff_alt_default
            )
            self._set_mode(AUTO_TAKEOFF, intended=True)
            if self.armed:
                self._start_takeoff(now)
            return
        if cmd == mavlink.MAV_CMD_NAV_LAND:
            self.commands.append((now, cmd, ACCEPTED))
            self._say(now, 6, "Landing at current position\t", _EV_LANDING,
                      ack=self._ack(msg, ACCEPTED, now))  # fmt: skip
            self.mode_after_disarm = self.intended_mode
            self.failsafe = False
            self._set_mode(AUTO_LAND, intended=True)
            self._landing_announced = False
            gap = 0.5 / self.speedup
            self._gimbal = [
                (now + 0.012, 0),
                (now + gap, 1),
                (now + 2 * gap, 2),
                (now + 3 * gap, 3),
            ]
            return
        if cmd == mavlink.MAV_CMD_REQUEST_MESSAGE:
            reply = self._requested(int(msg.param1), now)
            result = ACCEPTED if reply is not None else mavlink.MAV_RESULT_FAILED
            self.commands.append((now, cmd, result))
            if reply is not None:
                self.outbox.send(now, reply)
            self.outbox.send(now, self._ack(msg, result, now))
            return
        if cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            self.streams.intervals[int(msg.param1)] = float(msg.param2)
        elif cmd != mavlink.MAV_CMD_DO_CHANGE_SPEED:
            self.commands.append((now, cmd, UNSUPPORTED))
            self.outbox.send(now, self._ack(msg, UNSUPPORTED, now))
            return
        self.commands.append((now, cmd, ACCEPTED))
        self.outbox.send(now, self._ack(msg, ACCEPTED, now))

    def _requested(self, message_id: int, now: float):
        if message_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            custom = [0, 0, 0, 147, 131, 85, 10, 167]
            return mavlink.MAVLink_autopilot_version_message(
                59647, 255, 255, 101854463, 1, custom, custom, [0] * 8, 0, 0,
                5283920058631409231, uid2=[0] * 18,
            )  # fmt: skip
        if message_id == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
            return self._home_position(now)
        return self._stream_message(message_id, now)

    def _change_mode(self, main: int, sub: int, now: float, ack_of=None) -> int:
        """Apply a mode request; return the verdict. A refusal is reported here (second ACK
        first, then its STATUSTEXT and EVENT, in the same millisecond as P2 shows)."""

        def refuse(message: str, event) -> int:
            ack = self._ack(ack_of, TEMPORARILY_REJECTED, now) if ack_of is not None else None
            self._say(now, 2, message, event, ack=ack)
            return TEMPORARILY_REJECTED

        if main not in _MAIN_MODES:
            return ACCEPTED  # P2 4.58: two ACCEPTED, nothing changes
        if main == MAIN_AUTO:
            if sub not in _AUTO_SUBS:
                return refuse("Unsupported auto mode\t", _EV_UNSUPPORTED_AUTO)
            mode = px4_mode(MAIN_AUTO, sub)
        elif main == MAIN_OFFBOARD:
            if self.armed and not self.signal(now):
                return refuse(OFFBOARD_NOT_AVAILABLE_TEXT, _EV_MODE_NOT_AVAILABLE)
            mode = OFFBOARD
        else:
            mode = px4_mode(main)
        if mode in self.ignored_modes:
            return ACCEPTED  # like P2 4.58: two ACCEPTED, nothing changes
        self.failsafe = False
        if mode == AUTO_LAND:
            self.mode_after_disarm = self.intended_mode
            self._landing_announced = False
        if mode == AUTO_TAKEOFF:
            home_alt = self.home.alt if self.home else self.boot_spot.alt
            self._takeoff_alt_amsl = home_alt + self.params.takeoff_alt_default
            if self.armed:
                self._start_takeoff(now)
        if mode in (POSCTL, AUTO_LOITER) or main in (MAIN_MANUAL, MAIN_ALTCTL, MAIN_STABILIZED):
            self._hold()
        self._set_mode(mode, intended=True)
        return ACCEPTED

    def land_by_itself(self, now: float) -> None:
        """AUTO.LAND decided by the vehicle (e.g. a low-battery failsafe)."""
        self.mode_after_disarm = self.intended_mode
        self.failsafe = False
        self._landing_announced = False
        self._set_mode(AUTO_LAND, intended=False)

    def _set_mode(self, mode: int, *, intended: bool) -> None:
        self.mode = mode
        if intended:
            self.intended_mode = mode

    def _hold(self) -> None:
        self._target = self.body.position.copy()
        self._feed_forward = np.zeros(3)

    def _arm(self, msg, now: float) -> None:
        if self.armed:
            self.commands.append((now, msg.command, ACCEPTED))
            self.outbox.send(now, self._ack(msg, ACCEPTED, now))
            return
        if not self.armable(now):
            self.commands.append((now, msg.command, TEMPORARILY_REJECTED))
            self.outbox.send(now, self._event(now, _EV_ARM_DENIED))
            self._say(now, 2, ARM_DENIED_TEXT, ack=self._ack(msg, TEMPORARILY_REJECTED, now))
            return
        self.commands.append((now, msg.command, ACCEPTED))
        self.armed = True
        self._armed_at = now
        self._set_home(now)
        self._say(now, 6, "Armed by external command\t", _EV_ARMED)
        self.outbox.send(now, self._ack(msg, ACCEPTED, now))
        if self.mode == AUTO_TAKEOFF:
            self._start_takeoff(now)
        elif self.mode != OFFBOARD:
            self._hold()

    def _disarm(self, msg, now: float) -> None:
        if self.armed and self.flying():
            self.commands.append((now, msg.command, TEMPORARILY_REJECTED))
            self.outbox.send(now, self._ack(msg, TEMPORARILY_REJECTED, now))
            return
        self.commands.append((now, msg.command, ACCEPTED))
        self.outbox.send(now, self._ack(msg, ACCEPTED, now))
        if self.armed:
            self._say(now, 6, "Disarmed by external command\t", _EV_DISARMED)
            self.armed = False
            self.failsafe = False
            self._set_mode(self.mode_after_disarm, intended=True)

    def _setpoint(self, msg, now: float) -> None:
        mask = int(msg.type_mask)
        home_alt = self.home.alt if self.home else self.boot_spot.alt
        decoded = setpoint_enu(msg, self.boot_spot, home_alt)
        if decoded is None:
            return
        reported, velocity = decoded
        position = reported - self.gps_offset
        if not np.all(np.isfinite(position)) or not np.all(np.isfinite(velocity)):
            return
        self._last_setpoint = now
        if self.mode != OFFBOARD:
            return
        if not mask & IGNORE_POSITION:
            self._target = position
        self._feed_forward = velocity if not mask & IGNORE_VELOCITY else np.zeros(3)

    def _start_takeoff(self, now: float) -> None:
        assert self._takeoff_alt_amsl is not None
        up = self._takeoff_alt_amsl - self.boot_spot.alt - self.gps_offset[2]
        self._target = np.array([*self.body.position[:2], up])
        self._feed_forward = np.zeros(3)

    def _set_home(self, now: float) -> None:
        lat, lon, alt = enu_to_global(self.boot_spot, self.reported_enu())
        self.home = Home(lat, lon, alt)

    # --- time passing ---------------------------------------------------------------------------

    def tick(self, now: float) -> None:
        if not self._started:
            self._started = True
            self.outbox.send(
                now,
                ExtraMessage("CURRENT_EVENT_SEQUENCE", sequence=self._events_sequence, flags=1),
                self._event(now, _EV_LOGGER),
            )
        dt = self._elapsed(now)
        self._boot(now)
        self._offboard(now)
        self._fly(now, dt)
        for due, confirmation in [g for g in self._gimbal if g[0] <= now]:
            self._gimbal.remove((due, confirmation))
            self._send_gimbal(now, confirmation)
        if now >= self._next_heartbeat:
            period = self.timeline.heartbeat_period / self.speedup
            self._next_heartbeat = max(self._next_heartbeat + period, now)
            self.outbox.send(now, self._heartbeat(now))
        if self.home is not None and now >= self._next_home:
            self._next_home = max(self._next_home + 2.04 / self.speedup, now)
            self.outbox.send(now, self._home_position(now))
        self._streams(now)

    def _boot(self, now: float) -> None:
        t = self.timeline
        if not self._booted_checks and self._after(now, t.home):
            self._booted_checks = True
            self._set_home(now)
            self._next_home = now
            self.outbox.send(now, *(self._event(now, e) for e in _EV_CHECKS_BOOT))
            lat, lon, alt = (int(round(v * s)) for v, s in zip(
                (self.boot_spot.lat, self.boot_spot.lon, self.boot_spot.alt), (1e7, 1e7, 1e3),
                strict=True))  # fmt: skip
            self.outbox.send(
                now,
                mavlink.MAVLink_gps_global_origin_message(
                    lat, lon, alt, int(now * self.speedup * 1e6)
                ),
            )
        if self._held_texts and self._after(now, t.logger):
            self.outbox.send(now, *self._held_texts)
            self._held_texts = []
        if not self._armable_seen and self.position_valid(now):
            self._armable_seen = True
            self.outbox.send(now, *(self._event(now, e) for e in _EV_CHECKS_READY))

    def _offboard(self, now: float) -> None:
        signal = self.signal(now)
        if signal == self._signal:
            return
        self._signal = signal
        if not self.position_valid(now):
            return
        checks = _EV_CHECKS_SIGNAL if signal else _EV_CHECKS_READY
        self.outbox.send(now, *(self._event(now, e) for e in checks))
        if not signal and self.armed and self.mode == OFFBOARD:
            # Offboard loss (P1 44.32): fall back to position control, holding position.
            self.failsafe = True
            self._set_mode(POSCTL, intended=False)
            self._hold()
            self._say(now + 0.009, 2, FAILSAFE_TEXT, _EV_FAILSAFE)

    def _fly(self, now: float, dt: float) -> None:
        p = self.params
        s = self.speedup
        if not self.armed:
            self.body.velocity = np.zeros(3)
            return
        if self.mode == AUTO_LAND:
            target = np.array([*self.body.position[:2], -1.0])
            self.body.step(dt * s, target, np.zeros(3), 0.0, 0.0, p.land_speed)
            if self.flying():
                self.landed_state = mavlink.MAV_LANDED_STATE_LANDING
            if self.body.position[2] <= 0.0:
                if self._touchdown_at is None:
                    self._touchdown_at = now
                if not self._landing_announced and now - self._touchdown_at >= (
                    p.landing_detect / s
                ):
                    self._landing_announced = True
                    self.landed_state = mavlink.MAV_LANDED_STATE_ON_GROUND
                    self._say(now, 6, "Landing detected\t", _EV_LANDED)
            return
        self._touchdown_at = None
        if now - self._armed_at < p.spool_up / s:
            return
        if self.mode == AUTO_TAKEOFF and self.flying():
            if self.body.position[2] >= self._target[2] - 0.1:
                self._set_mode(AUTO_LOITER, intended=True)
        self.body.step(
            dt * s, self._target.copy(), self._feed_forward.copy(), p.xy_vel_max,
            p.z_vel_max_up, p.z_vel_max_dn,
        )  # fmt: skip
        if not self.flying() and self.body.position[2] > 0.5:
            self.landed_state = mavlink.MAV_LANDED_STATE_IN_AIR
            self._say(now, 6, "Takeoff detected\t", _EV_TAKEOFF_DETECTED)

    def _send_gimbal(self, now: float, confirmation: int) -> None:
        # P1 46.28: PX4 asks its own gimbal manager (target 1/0) for control and a neutral pose.
        nan = float("nan")
        configure = mavlink.MAVLink_command_long_message(
            self.system_id, 0, 1001, confirmation, 1.0, 1.0, -1.0, -1.0, 0.0, 0.0, 0.0
        )
        if confirmation == 0:
            pitch_yaw = mavlink.MAVLink_command_long_message(
                self.system_id, 0, 1000, 0, nan, nan, nan, nan, 2.0, 0.0, 0.0
            )
            release = mavlink.MAVLink_command_long_message(
                self.system_id, 0, 1001, 0, -3.0, -3.0, -1.0, -1.0, 0.0, 0.0, 0.0
            )
            self.outbox.send(now, configure, pitch_yaw, release)
        else:
            self.outbox.send(now, configure)

    # --- outputs --------------------------------------------------------------------------------

    def _base_and_status(self, now: float) -> tuple[int, int]:
        main = (self.mode >> 16) & 0xFF
        if main == MAIN_AUTO:
            base = 1 | 4 | 8 | 16
        elif main == MAIN_OFFBOARD:
            # The stabilize flag follows the last offboard control mode: none before the first
            # setpoint (P1 6.57: base 1), kept after the stream stops (P1 75.8: base 17).
            base = 1 | (16 if self._last_setpoint is not None else 0)
        else:  # POSCTL and the manual modes
            base = 1 | 16 | 64
        if self.armed:
            base |= ARMED_FLAG
            status = mavlink.MAV_STATE_CRITICAL if self.failsafe else mavlink.MAV_STATE_ACTIVE
        elif self.armable(now):
            status = mavlink.MAV_STATE_STANDBY
        else:
            status = mavlink.MAV_STATE_UNINIT
        return base, status

    def _heartbeat(self, now: float):
        base, status = self._base_and_status(now)
        return mavlink.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base, self.mode, status, 3
        )

    def _home_position(self, now: float):
        if self.home is None:
            return None
        h = self.home
        local = global_to_enu(self.boot_spot, h.lat, h.lon, h.alt)
        return mavlink.MAVLink_home_position_message(
            int(round(h.lat * 1e7)), int(round(h.lon * 1e7)), int(round(h.alt * 1000)),
            local[1], local[0], -local[2], [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
            time_usec=int(now * self.speedup * 1e6),
        )  # fmt: skip

    _DEFAULT_RATES_HZ = {
        mavlink.MAVLINK_MSG_ID_SYS_STATUS: 5.0,
        mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: 5.0,
        mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0,
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
        mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 10.0,
        mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 10.0,
        mavlink.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT: 10.0,
    }

    def _streams(self, now: float) -> None:
        # These stream unasked; an interval set for another message changes nothing.
        self.streams.send_due(
            now, self._DEFAULT_RATES_HZ, self.speedup, self._stream_message, self.outbox
        )

    def _stream_message(self, message_id: int, now: float):
        m = mavlink
        t_ms = int(now * self.speedup * 1000) & 0xFFFFFFFF
        pos = self.reported_enu()
        vel = self.body.velocity
        if message_id == m.MAVLINK_MSG_ID_SYS_STATUS:
            if self.position_valid(now):
                present, enabled, health = _SENSORS_READY
            elif self._after(now, self.timeline.home):
                present, enabled, health = _SENSORS_HOME
            else:
                present, enabled, health = _SENSORS_BOOT
            if self.armable(now):
                health |= PREARM_CHECK
            return m.MAVLink_sys_status_message(
                present, enabled, health, 0, 16200, -1, 100, 0, 0, 0, 0, 0, 0
            )
        if message_id == m.MAVLINK_MSG_ID_GPS_RAW_INT:
            usec = int(now * self.speedup * 1e6)
            return gps_raw_int(self.boot_spot, pos, vel, usec, fix_type=3, eph=70, epv=100)
        if message_id == m.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            return m.MAVLink_extended_sys_state_message(0, self.landed_state)
        if message_id == m.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            if not self._after(now, self.timeline.global_position) or self.home is None:
                return None
            return global_position_int(self.boot_spot, pos, vel, t_ms, self.home.alt)
        if message_id == m.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            return local_position_ned(pos, vel, t_ms)
        if message_id == m.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED:
            if not self.armed:
                mask = 63
            elif self.mode == POSCTL:
                mask = 31
            else:
                mask = 0
            target = self._target + self.gps_offset
            return position_target_local_ned(target, self._feed_forward, mask, t_ms)
        if message_id == m.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT:
            if not self.armed or (self.mode >> 16) & 0xFF != MAIN_AUTO:
                return None
            lat, lon, alt = enu_to_global(self.boot_spot, self._target + self.gps_offset)
            return m.MAVLink_position_target_global_int_message(
                t_ms, 5, 0, int(round(lat * 1e7)), int(round(lon * 1e7)), alt,
                0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            )  # fmt: skip
        return None
