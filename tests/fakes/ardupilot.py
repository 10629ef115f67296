"""Fake ArduCopter (V4.7.0-dev SITL) built from the A1/A2 transcripts of `tests/sitl/`.

What it reproduces (times from the first HEARTBEAT at speedup 1; `tests/sitl/README.md`):

* Boot: HEARTBEAT 89/0/BOOT, `ArduPilot Ready` at +1.44 s (a mode set during boot is reset to
  STABILIZE then), STABILIZE disarmed 81/0/STANDBY; GPS fix +9.2 s; EKF origin +19.0 s
  (unsolicited GPS_GLOBAL_ORIGIN + HOME_POSITION); pre-arm bit (STABILIZE) +22.7 s; position
  estimate (`EKF3 IMU0 is using GPS`, LOCAL_POSITION_NED) +40.6 s. Pre-arm checks run at 1 Hz.
* Streams nothing but HEARTBEAT until asked with MAV_CMD_SET_MESSAGE_INTERVAL (every id is
  ACCEPTED; POSITION_TARGET_GLOBAL_INT is never sent, POSITION_TARGET_LOCAL_NED only in GUIDED).
* SET_MODE is never acknowledged (an unknown mode: STATUSTEXT `No such mode N`);
  MAV_CMD_DO_SET_MODE is (FAILED + the same text for an unknown mode). GUIDED is accepted
  without a position estimate. A mode change sends a HEARTBEAT at once.
* Arming refusals: FAILED, STATUSTEXT severity 2 just before the ACK: `Arm: System not
  initialised` (booting), `Arm: Accels inconsistent` (before the pre-arm checks pass), `Arm: Need
  Position Estimate` (GUIDED without a position estimate); periodic `PreArm: Need Position
  Estimate` while failing in GUIDED. Accepted: `Arming motors`, HOME_POSITION re-sent.
* NAV_TAKEOFF: FAILED while disarmed (no text); armed in GUIDED: ~3 s spool-up, climb at
  WPNAV_SPEED_UP (landed_state 3, then 2 at the target altitude, status ACTIVE once lifting).
* Setpoints: silently ignored outside GUIDED or on the ground; in GUIDED, position targets
  never time out; velocity-only targets stop after GUID_TIMEOUT (3 s).
* LAND: descends (LAND_SPEED_HIGH above 10 m, LAND_SPEED below), landed_state 4, touchdown,
  landed_state 1 after 1.6 s, auto-disarm (`Disarming motors`, 89/9/3) after 2.1 s.
* Unknown command: UNSUPPORTED. DISARM while disarmed: ACCEPTED.

Extrapolated (not in the transcripts, from ArduCopter's documented defaults): auto-disarm
DISARM_DELAY 10 s after arming without taking off; DISARM refused (FAILED) while flying;
arming refused in LAND (`Arm: Mode not armable`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fleetwire.modes import COPTER_MODE
from tests.fakes.common import (
    ACCEPTED,
    ARMED_FLAG,
    FAILED,
    IGNORE_POSITION,
    IGNORE_VELOCITY,
    PREARM_CHECK,
    UNSUPPORTED,
    FakeAutopilot,
    Home,
    ParameterSet,
    command_ack,
    enu_to_global,
    global_position_int,
    gps_raw_int,
    local_position_ned,
    mavlink,
    position_target_local_ned,
    setpoint_enu,
    text,
)

# Copter mode numbers (custom_mode), pymavlink's.
STABILIZE, GUIDED, LAND = COPTER_MODE["STABILIZE"], COPTER_MODE["GUIDED"], COPTER_MODE["LAND"]
#: Every Copter mode number of 4.7 (anything else: `No such mode N`): the firmware's, which is
#: not pymavlink's table (that has 8, 10 and 29 too).
KNOWN_MODES = frozenset({0, 1, 2, 3, 4, 5, 6, 7, 9, 11, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22,
                         23, 24, 25, 26, 27, 28})  # fmt: skip
#: Modes whose base_mode carries MAV_MODE_FLAG_GUIDED_ENABLED (seen: GUIDED, LAND).
_GUIDED_FLAG_MODES = frozenset(COPTER_MODE[name] for name in (
    "AUTO", "GUIDED", "LOITER", "RTL", "LAND", "POSHOLD", "BRAKE", "SMART_RTL", "AUTOROTATE",
    "AUTO_RTL"))  # fmt: skip
#: Modes that need a position estimate to arm.
_POSITION_MODES = frozenset(COPTER_MODE[name] for name in (
    "AUTO", "GUIDED", "LOITER", "RTL", "POSHOLD", "BRAKE", "SMART_RTL"))  # fmt: skip

# HEARTBEAT base_mode pieces: CUSTOM_MODE_ENABLED | STABILIZE_ENABLED | MANUAL_INPUT_ENABLED.
_BASE = 1 | 16 | 64
_GUIDED_ENABLED = 8

# SYS_STATUS bitmasks recorded in A1 (present, enabled, health).
_SENSORS_BOOT = (0x5371FC0F, 0x53419C0F, 0x47519C0F)
_SENSORS_GPS = (0x5371FC2F, 0x53419C2F, 0x47519C2F)
_AHRS_BIT = 0x00200000
_POSITION_CONTROL_BITS = 0x6000  # z/altitude and x/y position control, GUIDED

#: ArduPilot SITL's default home as HOME_POSITION reported it (A1).
SITL_HOME = Home(-35.363261, 149.1652299, 584.09)

# EKF_STATUS_REPORT flags recorded in A1.
EKF_UNINITIALISED, EKF_NO_FLAGS, EKF_ATTITUDE_ONLY, EKF_USING_GPS = 1024, 0, 167, 831


@dataclass(frozen=True)
class ArduCopterTimeline:
    """Seconds after the first HEARTBEAT at speedup 1 (A1, both runs agree within 0.1 s)."""

    ready: float = 1.436  # `ArduPilot Ready`
    ekf_reporting: float = 4.67  # EKF flags 1024 -> 0
    ekf_attitude: float = 5.16  # flags 167
    gps_detected: float = 8.81  # `GPS 1: detected u-blox`
    gps_fix: float = 9.17
    ekf_origin: float = 19.0
    ahrs: float = 21.67
    prearm_ok: float = 22.6
    position_estimate: float = 40.6
    prearm_phase: float = 0.66  # pre-arm checks run at 1 Hz on this phase
    report_phase: float = 1.436  # periodic PreArm text on this phase


@dataclass(frozen=True)
class ArduCopterParams:
    """Parameters that shape what a GCS sees (ArduCopter defaults)."""

    wpnav_speed: float = 10.0  # WPNAV_SPEED 1000 cm/s
    wpnav_speed_up: float = 2.5  # WPNAV_SPEED_UP 250 cm/s
    wpnav_speed_dn: float = 1.5  # WPNAV_SPEED_DN 150 cm/s
    land_speed: float = 0.5  # LAND_SPEED 50 cm/s
    land_speed_high: float = 1.5  # LAND_SPEED_HIGH 0 = WPNAV_SPEED_DN
    land_alt_low: float = 10.0  # LAND_ALT_LOW 1000 cm
    guid_timeout: float = 3.0  # GUID_TIMEOUT (s, velocity/acceleration targets only)
    disarm_delay: float = 10.0  # DISARM_DELAY (s)
    spool_up: float = 2.9  # takeoff command -> lifting (A1: 42.95 -> 45.9)
    landed_detect: float = 1.6  # touchdown -> landed_state ON_GROUND (A1: 105.5 -> 107.1)
    land_disarm: float = 2.1  # touchdown -> auto-disarm in LAND (A1: 105.5 -> 107.6)


#: ArduCopter's parameters as a ground station reads them: the count and encoding recorded in
#: A1 (1349 parameters, integers cast to float: COMPASS_DEV_ID 97539.0 INT32); the limits of
#: its GUIDED position controller at the firmware's defaults (not read in the transcripts).
ARDUCOPTER_PARAMETERS = ParameterSet(
    count=1349,
    bytewise=False,
    values={
        "WPNAV_SPEED": (1000.0, mavlink.MAV_PARAM_TYPE_REAL32),  # cm/s
        "WPNAV_ACCEL": (250.0, mavlink.MAV_PARAM_TYPE_REAL32),  # cm/s^2
        "WPNAV_SPEED_UP": (250.0, mavlink.MAV_PARAM_TYPE_REAL32),
        "WPNAV_SPEED_DN": (150.0, mavlink.MAV_PARAM_TYPE_REAL32),
        "ANGLE_MAX": (3000.0, mavlink.MAV_PARAM_TYPE_INT16),  # centidegrees
        "COMPASS_DEV_ID": (97539.0, mavlink.MAV_PARAM_TYPE_INT32),  # A1
    },
)


class ArduCopterModel(FakeAutopilot):
    """The state machine of one ArduCopter SITL instance as a ground station sees it."""

    parameter_set = ARDUCOPTER_PARAMETERS

    def __init__(
        self,
        home: Home = SITL_HOME,
        *,
        system_id: int = 1,
        speedup: float = 1.0,
        timeline: ArduCopterTimeline = ArduCopterTimeline(),
        params: ArduCopterParams = ArduCopterParams(),
        known_modes: frozenset[int] = KNOWN_MODES,
        extra_arm_refusals: int = 0,
        refusal_text_delay_s: float = 0.0,
        info_text_with_refusals: str | None = None,
        lost_takeoffs: int = 0,
    ) -> None:
        """`known_modes`: the modes this firmware was built with (others: `No such mode`).
        `extra_arm_refusals`: the next N arming attempts in GUIDED fail as in A1 at 28.66
        (`Arm: Need Position Estimate`) even with a position, to exercise a driver's retry.
        `refusal_text_delay_s`: the `Arm: ...` / `No such mode N` text of a refusing ACK goes
        out this long (wall seconds) after the ACK; 0: just before it, as recorded (1 ms).
        `info_text_with_refusals`: an INFO text sent with every refusing ACK, just before it
        (as `EKF3 IMU0 is using GPS` (A1 41.52) can be near an ARM): never the reason.
        `lost_takeoffs`: the next N NAV_TAKEOFF commands never arrive (a lossy link), so the
        vehicle stays on the ground and disarms after DISARM_DELAY."""
        super().__init__(system_id=system_id, speedup=speedup)
        self.boot_home = home
        self.home = home
        self.timeline = timeline
        self.params = params
        self.known_modes = known_modes
        self.extra_arm_refusals = extra_arm_refusals
        self.refusal_text_delay_s = refusal_text_delay_s
        self.info_text_with_refusals = info_text_with_refusals
        self.lost_takeoffs = lost_takeoffs
        self.mode = STABILIZE
        self.armed = False
        self._started = False
        self._next_heartbeat = 0.0
        self._ready_done = False
        self._origin_sent = False
        self._gps_text_sent = False
        self._prearm_bit = False
        self._next_prearm_check = timeline.prearm_phase
        self._next_report = timeline.report_phase
        self._last_prearm_report: float | None = None
        self._gps_used = False
        self._takeoff_at: float | None = None  # when the climb starts (after spool-up)
        self._takeoff_alt = 0.0
        self._armed_at = 0.0
        self._touchdown_at: float | None = None
        self._target = np.zeros(3)
        self._feed_forward = np.zeros(3)
        self._velocity_only_until: float | None = None
        self._target_mask = 3079  # POSITION_TARGET_LOCAL_NED echo: GUIDED idle

    # --- timeline helpers (internal processes are compressed by `speedup`) --------------------

    @property
    def booting(self) -> bool:
        return not self._ready_done

    def position_estimate(self, now: float) -> bool:
        return self._after(now, self.timeline.position_estimate)

    # --- inputs ---------------------------------------------------------------------------------

    def _mode_message(self, msg, now: float) -> None:
        if msg.custom_mode in self.known_modes:
            self._set_mode(int(msg.custom_mode), now)
        else:
            self.outbox.send(now, text(4, f"No such mode {msg.custom_mode}"))

    def _ack(self, msg, result: int, now: float):
        self.commands.append((now, int(msg.command), result))
        return command_ack(msg.command, result, *self._gcs)

    def _command(self, msg, now: float) -> None:
        cmd = int(msg.command)
        p1, p2 = msg.param1, msg.param2
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if p1 >= 0.5:
                self._arm(msg, now)
            elif not self.armed or not self.flying() or p2 == 21196:
                self._disarm(now, announce=self.armed)
                self.outbox.send(now, self._ack(msg, ACCEPTED, now))
            else:
                self.outbox.send(now, self._ack(msg, FAILED, now))
        elif cmd == mavlink.MAV_CMD_DO_SET_MODE:
            mode = int(p2)
            if int(p1) & 1 and mode in self.known_modes:
                self.outbox.send(now, self._ack(msg, ACCEPTED, now))
                self._set_mode(mode, now)
            else:
                self._refuse(msg, text(4, f"No such mode {mode}"), now, text_first=False)
        elif cmd == mavlink.MAV_CMD_NAV_TAKEOFF and self.lost_takeoffs > 0:
            self.lost_takeoffs -= 1  # lost on the way: no effect, no ACK
        elif cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            ok = self.armed and self.mode == GUIDED and not self.flying() and msg.param7 > 0
            if ok:
                self._takeoff_alt = float(msg.param7)
                self._takeoff_at = now + self.params.spool_up / self.speedup
                self._target = np.array([*self.body.position[:2], self._takeoff_alt])
                self._feed_forward = np.zeros(3)
                self._velocity_only_until = None
                self._target_mask = 3576
            self.outbox.send(now, self._ack(msg, ACCEPTED if ok else FAILED, now))
        elif cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            self.streams.intervals[int(p1)] = float(p2)
            self.outbox.send(now, self._ack(msg, ACCEPTED, now))
        elif cmd == mavlink.MAV_CMD_REQUEST_MESSAGE:
            reply = self._requested(int(p1), now)
            if reply is None:
                self.outbox.send(now, self._ack(msg, FAILED, now))
            else:
                self.outbox.send(now, self._ack(msg, ACCEPTED, now), *reply)
        elif cmd == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            self.outbox.send(now, self._ack(msg, ACCEPTED, now))
        elif cmd == mavlink.MAV_CMD_NAV_LAND:
            self.outbox.send(now, self._ack(msg, ACCEPTED, now))
            self._set_mode(LAND, now)
        else:
            self.outbox.send(now, self._ack(msg, UNSUPPORTED, now))

    def _requested(self, message_id: int, now: float) -> list | None:
        """What MAV_CMD_REQUEST_MESSAGE sends after its ACK ([]: nothing); None: refused."""
        if message_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return [mavlink.MAVLink_autopilot_version_message(
                64495, 67567616, 0, 0, 0, list(b"90700977"), [0] * 8, [0] * 8, 0, 0, 0,
                uid2=[0] * 18,
            )]  # fmt: skip
        if message_id == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
            # Before the EKF origin, ArduPilot accepts the request and sends nothing.
            return [self._home_position(now)] if self._origin_sent else []
        message = self._stream_message(message_id, now)
        return None if message is None else [message]

    def _refuse(self, msg, reason, now: float, *, text_first: bool) -> None:
        """ACK FAILED with its reason in the same millisecond, the text first (A1 0.942: `Arm:`
        1 ms before the ACK) or not (A2 10.005: `No such mode`), or `refusal_text_delay_s`
        after the ACK."""
        ack = self._ack(msg, FAILED, now)
        info = [text(6, self.info_text_with_refusals)] if self.info_text_with_refusals else []
        if self.refusal_text_delay_s > 0:
            self.outbox.send(now, *info, ack)
            self.outbox.send(now + self.refusal_text_delay_s, reason)
        elif text_first:
            self.outbox.send(now, reason, *info, ack)
        else:
            self.outbox.send(now, *info, ack, reason)

    def _arm_refusal(self, now: float) -> str | None:
        if self.booting:
            return "Arm: System not initialised"
        if not self._after(now, self.timeline.prearm_ok):
            return "Arm: Accels inconsistent"
        if self.mode == LAND:
            return "Arm: Mode not armable"
        if self.mode in _POSITION_MODES and not self.position_estimate(now):
            return "Arm: Need Position Estimate"
        if self.extra_arm_refusals > 0 and self.mode in _POSITION_MODES:
            self.extra_arm_refusals -= 1
            return "Arm: Need Position Estimate"
        return None

    def _arm(self, msg, now: float) -> None:
        if self.armed:
            self.outbox.send(now, self._ack(msg, ACCEPTED, now))
            return
        refusal = self._arm_refusal(now)
        if refusal is not None:
            self._refuse(msg, text(2, refusal), now, text_first=True)
            return
        self.armed = True
        self._armed_at = now
        self.home = Home(*enu_to_global(self.boot_home, self.body.position))
        self.outbox.send(
            now, self._ack(msg, ACCEPTED, now), self._home_position(now), text(6, "Arming motors")
        )

    def _disarm(self, now: float, *, announce: bool) -> None:
        was_armed = self.armed
        self.armed = False
        self._takeoff_at = None
        self._touchdown_at = None
        if was_armed and announce:
            self.outbox.send(now, text(6, "Disarming motors"))

    def _set_mode(self, mode: int, now: float) -> None:
        previous = self.mode
        self.mode = mode
        if mode != GUIDED:
            self._velocity_only_until = None
        if mode == GUIDED:
            self._target = self.body.position.copy()
            self._feed_forward = np.zeros(3)
            self._target_mask = 3079 if not self.flying() else 3576
        # The heartbeat sent on a mode change carries the guided flag of either mode (A1, A2).
        flag = _GUIDED_ENABLED if (previous in _GUIDED_FLAG_MODES or mode in _GUIDED_FLAG_MODES
                                   or self.booting) else 0  # fmt: skip
        self.outbox.send(now, self._heartbeat(guided_flag=flag))

    def change_mode_by_itself(self, mode: int, now: float) -> None:
        """A mode change the vehicle decides (GCS or battery failsafe, RC switch)."""
        self._set_mode(mode, now)

    def _setpoint(self, msg, now: float) -> None:
        # Outside GUIDED, disarmed or on the ground: silently ignored (A2 24.70-30.7).
        if self.mode != GUIDED or not self.armed or not self.flying():
            return
        mask = int(msg.type_mask)
        decoded = setpoint_enu(msg, self.boot_home, self.home.alt)
        if decoded is None:
            return
        position, velocity = decoded
        use_position = not mask & IGNORE_POSITION
        use_velocity = not mask & IGNORE_VELOCITY
        if not (use_position or use_velocity):
            return
        self._takeoff_at = None  # a new target ends a takeoff
        if self.landed_state == mavlink.MAV_LANDED_STATE_TAKEOFF:
            self.landed_state = mavlink.MAV_LANDED_STATE_IN_AIR
        if use_position:
            self._target = position
            self._velocity_only_until = None
        else:
            self._velocity_only_until = now + self.params.guid_timeout
        self._feed_forward = velocity if use_velocity else np.zeros(3)
        self._target_mask = 3072

    # --- time passing ---------------------------------------------------------------------------

    def tick(self, now: float) -> None:
        """Advance to `now`: boot timeline, pre-arm checks, flight, periodic messages."""
        if not self._started:
            self._started = True
            self.outbox.send(now, text(6, "Calibrating barometer"))
        dt = self._elapsed(now)
        self._boot(now)
        self._prearm(now)
        self._fly(now, dt)
        if now >= self._next_heartbeat:  # 1 Hz, on a fixed phase
            self._next_heartbeat = max(self._next_heartbeat + 1.0 / self.speedup, now)
            self.outbox.send(now, self._heartbeat())
        self._streams(now)

    def _boot(self, now: float) -> None:
        t = self.timeline
        if not self._ready_done and self._after(now, t.ready):
            self._ready_done = True
            self.outbox.send(now, text(6, "ArduPilot Ready"))
            if self.mode != STABILIZE:  # a mode chosen during boot does not survive (A2)
                self._set_mode(STABILIZE, now)
        if not self._gps_text_sent and self._after(now, t.gps_detected):
            self._gps_text_sent = True
            self.outbox.send(now, text(6, "GPS 1: detected u-blox"))
        if not self._origin_sent and self._after(now, t.ekf_origin):
            self._origin_sent = True
            lat, lon, alt = (int(round(self.home.lat * 1e7)), int(round(self.home.lon * 1e7)),
                             int(round(self.home.alt * 1000)))  # fmt: skip
            usec = int(now * self.speedup * 1e6)
            self.outbox.send(
                now,
                mavlink.MAVLink_gps_global_origin_message(lat, lon, alt, time_usec=usec),
                self._home_position(now),
                text(6, "EKF3 IMU0 origin set"),
            )
        if not self._gps_used and self.position_estimate(now):
            self._gps_used = True
            self.outbox.send(now, text(6, "EKF3 IMU0 is using GPS"))

    def _prearm_passes(self, now: float) -> bool:
        if self.booting or not self._after(now, self.timeline.prearm_ok):
            return False
        # The position check passes one check after `EKF3 IMU0 is using GPS` (A1 41.52 -> 42.59).
        settled = self._after(now, self.timeline.position_estimate + 0.5)
        return not (self.mode in _POSITION_MODES and not settled)

    def _prearm(self, now: float) -> None:
        # Checks run at 1 Hz and set the SYS_STATUS bit; a failing position check (GUIDED) is
        # reported on the next report slot, then every 30 s (A1 26.36; A2 35.36, 2 s later).
        scaled = now * self.speedup
        while scaled >= self._next_prearm_check:
            self._next_prearm_check += 1.0
            self._prearm_bit = self._prearm_passes(now)
        while scaled >= self._next_report:
            self._next_report += 1.0
            failing = (
                not self._prearm_bit and not self.booting
                and self._after(now, self.timeline.prearm_ok)
                and self.mode in _POSITION_MODES and not self.position_estimate(now)
            )  # fmt: skip
            if not failing:
                self._last_prearm_report = None
            elif self._last_prearm_report is None or now - self._last_prearm_report >= 30.0 / (
                self.speedup
            ):
                self._last_prearm_report = now
                self.outbox.send(now, text(2, "PreArm: Need Position Estimate"))

    def _fly(self, now: float, dt: float) -> None:  # noqa: C901 (over 15 branches: to split)
        p = self.params
        s = self.speedup
        if self.armed and not self.flying():  # auto-disarm on the ground
            if self.mode == LAND:
                if self._touchdown_at is None:
                    self._touchdown_at = now
                if now - self._touchdown_at >= p.land_disarm / s:
                    self._disarm(now, announce=True)
            elif self._takeoff_at is None and now - self._armed_at >= p.disarm_delay / s:
                self._disarm(now, announce=True)
        if self.armed and self._takeoff_at is not None and now >= self._takeoff_at:
            if not self.flying():
                self.landed_state = mavlink.MAV_LANDED_STATE_TAKEOFF
        if not self.armed or not self.flying():
            self.body.velocity = np.zeros(3)
            return
        if self.mode == LAND:
            self._takeoff_at = None
            alt = self.body.position[2]
            speed = p.land_speed_high if alt > p.land_alt_low else p.land_speed
            target = np.array([*self.body.position[:2], -1.0])
            self.body.step(dt * s, target, np.zeros(3), 0.0, 0.0, speed)
            if self.body.position[2] <= 0.0 and self._touchdown_at is None:
                self._touchdown_at = now
            if self._touchdown_at is not None and now - self._touchdown_at >= p.landed_detect / s:
                self.landed_state = mavlink.MAV_LANDED_STATE_ON_GROUND
            else:
                self.landed_state = mavlink.MAV_LANDED_STATE_LANDING
            return
        if self.mode != GUIDED:  # other modes: hold where it is
            self.body.step(dt * s, self.body.position.copy(), np.zeros(3), 0.0, 0.0, 0.0)
            return
        target, feed_forward = self._target, self._feed_forward
        if self._velocity_only_until is not None:
            if now >= self._velocity_only_until:  # GUID_TIMEOUT: stop
                self._velocity_only_until = None
                self._target = self.body.position.copy()
                self._feed_forward = np.zeros(3)
                target, feed_forward = self._target, self._feed_forward
            else:
                target = self.body.position + feed_forward * dt * s
        self.body.step(
            dt * s, target, feed_forward.copy(), p.wpnav_speed, p.wpnav_speed_up,
            p.wpnav_speed_dn,
        )  # fmt: skip
        if self.landed_state == mavlink.MAV_LANDED_STATE_TAKEOFF:
            if self.body.position[2] >= self._takeoff_alt - 0.1:
                self.landed_state = mavlink.MAV_LANDED_STATE_IN_AIR
                self._takeoff_at = None

    # --- outputs --------------------------------------------------------------------------------

    def _heartbeat(self, guided_flag: int | None = None):
        if guided_flag is None:
            in_boot_flag = self.booting or (self.mode in _GUIDED_FLAG_MODES)
            guided_flag = _GUIDED_ENABLED if in_boot_flag else 0
        base = _BASE | guided_flag | (ARMED_FLAG if self.armed else 0)
        if self.booting:
            status = mavlink.MAV_STATE_BOOT
        elif self.armed and self.flying():
            status = mavlink.MAV_STATE_ACTIVE
        else:
            status = mavlink.MAV_STATE_STANDBY
        return mavlink.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, base, self.mode,
            status, 3,
        )  # fmt: skip

    def _home_position(self, now: float):
        h = self.home
        return mavlink.MAVLink_home_position_message(
            int(round(h.lat * 1e7)), int(round(h.lon * 1e7)), int(round(h.alt * 1000)),
            0.0, 0.0, 0.0, [float("nan")] * 4, 0.0, 0.0, 0.0, time_usec=int(now * self.speedup * 1e6),
        )  # fmt: skip

    def _streams(self, now: float) -> None:
        # Nothing streams until asked; an interval of 0 asks for 1 Hz.
        requested = dict.fromkeys(self.streams.intervals, 1.0)
        self.streams.send_due(now, requested, self.speedup, self._stream_message, self.outbox)

    def _stream_message(self, message_id: int, now: float):
        m = mavlink
        t_ms = int(now * self.speedup * 1000) & 0xFFFFFFFF
        pos = self.body.position
        vel = self.body.velocity
        if message_id == m.MAVLINK_MSG_ID_SYS_STATUS:
            return self._sys_status(now)
        if message_id == m.MAVLINK_MSG_ID_HOME_POSITION:
            return self._home_position(now) if self._origin_sent else None
        if message_id == m.MAVLINK_MSG_ID_GPS_RAW_INT:
            if not self._after(now, self.timeline.gps_fix):
                return m.MAVLink_gps_raw_int_message(0, 0, 0, 0, 0, 65535, 65535, 0, 0, 0)
            usec = int(now * self.speedup * 1e6)
            return gps_raw_int(self.boot_home, pos, vel, usec, fix_type=6, eph=121, epv=200)
        if message_id == m.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            if not self._after(now, self.timeline.gps_fix):
                return m.MAVLink_global_position_int_message(t_ms, 0, 0, 0, 0, 0, 0, 0, 0)
            return global_position_int(self.boot_home, pos, vel, t_ms, self.home.alt)
        if message_id == m.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            if not self.position_estimate(now):
                return None
            return local_position_ned(pos, vel, t_ms)
        if message_id == m.MAVLINK_MSG_ID_EKF_STATUS_REPORT:
            return m.MAVLink_ekf_status_report_message(
                self._ekf_flags(now), 0.0, 0.0, 0.0, 0.0, 0.0
            )
        if message_id == m.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            return m.MAVLink_extended_sys_state_message(m.MAV_VTOL_STATE_MC, self.landed_state)
        if message_id == m.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED:
            if self.mode != GUIDED:
                return None
            return position_target_local_ned(
                self._target, self._feed_forward, self._target_mask, t_ms
            )
        return None  # e.g. POSITION_TARGET_GLOBAL_INT: accepted, never sent (A1)

    def _ekf_flags(self, now: float) -> int:
        t = self.timeline
        if self.position_estimate(now):
            return EKF_USING_GPS
        if self._after(now, t.ekf_attitude):
            return EKF_ATTITUDE_ONLY
        if self._after(now, t.ekf_reporting):
            return EKF_NO_FLAGS
        return EKF_UNINITIALISED

    def _sys_status(self, now: float):
        present, enabled, health = (
            _SENSORS_GPS if self._after(now, self.timeline.gps_fix) else _SENSORS_BOOT
        )
        if self._after(now, self.timeline.ahrs):
            enabled |= _AHRS_BIT
            health |= _AHRS_BIT
        if self.mode == GUIDED:
            enabled |= _POSITION_CONTROL_BITS
            health |= _POSITION_CONTROL_BITS
        if self._prearm_bit:
            health |= PREARM_CHECK
        return mavlink.MAVLink_sys_status_message(
            present, enabled, health, 0, 12600, 0, 100, 0, 0, 0, 0, 0, 0
        )
