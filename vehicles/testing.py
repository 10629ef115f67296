"""A minimal ground-station side for tests and benchmarks of the simulated vehicles.

Starts ``python -m vehicles sim`` as a real subprocess on free UDP ports, talks to a vehicle
with pymavlink's ``mavutil`` exactly as a GCS would (system 255, component 190, heartbeats at
1 Hz of simulated time), waits on conditions with deadlines (never on sleeps), and generates a
moving-average-smoothed reference along a polyline (docs/design.md 3.5) with velocity
and acceleration feed-forward. Not used by the simulation itself.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.messages import GCS_COMPONENT_ID as GCS_COMPONENT
from fleetwire.messages import GCS_SYSTEM_ID as GCS_SYSTEM
from fleetwire.messages import MASK_POSITION_VELOCITY as MASK_POS_VEL
from fleetwire.messages import MASK_POSITION_VELOCITY_ACCELERATION as MASK_POS_VEL_ACC
from vehicles.ports import free_udp_ports  # re-exported: tests and benches pick ports here

REPO_ROOT = Path(__file__).resolve().parent.parent
CLOCK_WINDOW_S = 1.0


class VehicleProcess:
    """``python -m vehicles sim --count N --base-port P ...`` as a subprocess (context manager)."""

    def __init__(
        self,
        count: int = 1,
        speedup: float = 1.0,
        args: Sequence[str] = (),
        base_port: int | None = None,
    ) -> None:
        self.count = count
        self.speedup = speedup
        self.base_port = free_udp_ports(count) if base_port is None else base_port
        self.command = [
            sys.executable,
            "-m",
            "vehicles",
            "sim",
            "--count",
            str(count),
            "--base-port",
            str(self.base_port),
            "--speedup",
            repr(speedup),
            *args,
        ]
        self._stderr = tempfile.TemporaryFile(mode="w+")
        self.process = subprocess.Popen(
            self.command,
            cwd=REPO_ROOT,
            stdout=subprocess.DEVNULL,
            stderr=self._stderr,
            env=_child_env(),
        )

    def port(self, k: int = 0) -> int:
        return self.base_port + k

    def pid(self) -> int:
        return self.process.pid

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 10.0) -> tuple[int, str]:
        """Send ``sig`` (unless it already exited), wait for the exit; (exit status, stderr)."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
        try:
            code = self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            code = self.process.wait()
        self._stderr.seek(0)
        text = self._stderr.read()
        self._stderr.close()
        return code, text

    def __enter__(self) -> VehicleProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        if not self._stderr.closed:
            self.stop()


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO_ROOT), env.get("PYTHONPATH", "")]))
    return env


@dataclass(frozen=True)
class Text:
    """A STATUSTEXT as received: wall time, estimated vehicle time, severity, text."""

    wall_s: float
    vehicle_s: float
    severity: int
    text: str


class GroundStation:
    """One GCS link to one simulated vehicle (``udpout`` to its port), driven by polling."""

    def __init__(
        self, port: int, speedup: float = 1.0, sysid: int = GCS_SYSTEM, target: int = 1
    ) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=sysid, source_component=GCS_COMPONENT
        )
        self.speedup = speedup
        self.target = target
        self.send_heartbeats = True
        self.latest: dict[str, Any] = {}
        self.texts: list[Text] = []
        self.acks: list[Any] = []
        self.received: list[Any] = []  # every message, when record_all
        self.record_all = False
        self.listeners: list[Callable[[Any], None]] = []
        self.tick_time_s = (
            0.0  # time_boot_ms of the latest time-stamped message (SIM_STATE has none)
        )
        self._last_heartbeat_wall = 0.0
        self._clock_offsets: deque[tuple[float, float]] = deque()  # (wall s, vehicle s - K wall s)

    @property
    def mav(self) -> mavlink.MAVLink:
        return self.conn.mav

    def close(self) -> None:
        self.conn.close()

    # -- clock -------------------------------------------------------------------------
    def vehicle_time(self) -> float:
        """The vehicle's simulated time now, from its time-stamped telemetry.

        Each ``time_boot_ms`` gives an offset between the vehicle's clock and ``speedup`` x
        the wall clock; delivery delays only make it smaller, so the largest offset of the
        last second is the best estimate (a delay of 1 ms would cost ``speedup`` ms).
        """
        if not self._clock_offsets:
            raise RuntimeError("no time-stamped telemetry yet")
        return self.speedup * time.monotonic() + max(offset for _, offset in self._clock_offsets)

    def _clock_sample(self, vehicle_s: float, wall_s: float) -> None:
        offsets = self._clock_offsets
        offsets.append((wall_s, vehicle_s - self.speedup * wall_s))
        while offsets[0][0] < wall_s - CLOCK_WINDOW_S:
            offsets.popleft()

    # -- receiving ---------------------------------------------------------------------
    def poll(self, wait_s: float = 0.0) -> None:
        """Handle every waiting message (waiting up to ``wait_s`` for the first one)."""
        self._heartbeat()
        if wait_s > 0:
            self.conn.select(wait_s)
        while True:
            message = self.conn.recv_msg()
            if message is None:
                return
            self._handle(message)

    def _handle(self, message: Any) -> None:
        kind = message.get_type()
        if kind == "BAD_DATA" or message.get_srcSystem() != self.target:
            return
        now = time.monotonic()
        boot_ms = getattr(message, "time_boot_ms", None)
        if boot_ms is not None:
            self._clock_sample(boot_ms / 1000.0, now)
            self.tick_time_s = boot_ms / 1000.0
        self.latest[kind] = message
        if kind == "STATUSTEXT":
            vehicle_s = self.vehicle_time() if self._clock_offsets else 0.0
            self.texts.append(Text(now, vehicle_s, message.severity, _decode(message.text)))
        elif kind == "COMMAND_ACK":
            self.acks.append(message)
        if self.record_all:
            self.received.append(message)
        for listener in self.listeners:
            listener(message)

    def _heartbeat(self) -> None:
        if not self.send_heartbeats:
            return
        now = time.monotonic()
        period = 1.0 / self.speedup if "HEARTBEAT" in self.latest else 0.1
        if now - self._last_heartbeat_wall >= period:
            self._last_heartbeat_wall = now
            if self._clock_offsets:
                self.heartbeat_sent_at = self.vehicle_time()
            self.mav.heartbeat_send(
                mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE
            )

    def wait_for(self, predicate: Callable[[], Any], timeout_s: float, what: str) -> Any:
        """Poll until ``predicate()`` is truthy (returned) or ``timeout_s`` wall seconds pass."""
        deadline = time.monotonic() + timeout_s
        while True:
            result = predicate()
            if result:
                return result
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
            self.poll(0.005)

    def run_for(self, vehicle_s: float, timeout_s: float = 60.0) -> None:
        """Keep polling (and heart-beating) for ``vehicle_s`` seconds of vehicle time."""
        end = self.vehicle_time() + vehicle_s
        self.wait_for(
            lambda: self.vehicle_time() >= end, timeout_s, f"{vehicle_s} s of vehicle time"
        )

    def connect(self, timeout_s: float = 10.0) -> Any:
        """Heart-beat until the vehicle answers with its own HEARTBEAT and telemetry."""
        self.wait_for(
            lambda: "HEARTBEAT" in self.latest and self._clock_offsets, timeout_s, "the vehicle"
        )
        return self.latest["HEARTBEAT"]

    # -- commands ----------------------------------------------------------------------
    def command(self, command: int, *params: float, timeout_s: float = 5.0) -> Any:
        """COMMAND_LONG (params 1..7) and wait for its COMMAND_ACK."""
        values = list(params) + [0.0] * (7 - len(params))
        start = len(self.acks)
        self.mav.command_long_send(self.target, 1, command, 0, *values)
        return self._wait_ack(command, start, timeout_s)

    def command_int(
        self,
        command: int,
        *params: float,
        frame: int = 0,
        x: int = 0,
        y: int = 0,
        z: float = 0.0,
        timeout_s: float = 5.0,
    ) -> Any:
        """COMMAND_INT (params 1..4, x, y, z) and wait for its COMMAND_ACK."""
        values = list(params) + [0.0] * (4 - len(params))
        start = len(self.acks)
        self.mav.command_int_send(self.target, 1, frame, command, 0, 0, *values, x, y, z)
        return self._wait_ack(command, start, timeout_s)

    def _wait_ack(self, command: int, start: int, timeout_s: float) -> Any:
        def found() -> Any:
            return next((a for a in self.acks[start:] if a.command == command), None)

        return self.wait_for(found, timeout_s, f"COMMAND_ACK of command {command}")

    def set_mode(self, mode: int) -> int:
        return self.command(
            mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode
        ).result

    def arm(self) -> int:
        return self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result

    def heartbeat_is(self, custom_mode: int | None = None, armed: bool | None = None) -> bool:
        beat = self.latest.get("HEARTBEAT")
        if beat is None:
            return False
        if custom_mode is not None and beat.custom_mode != custom_mode:
            return False
        return armed is None or bool(beat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED) == armed

    def wait_armable(self, timeout_s: float = 10.0) -> None:
        def ready() -> bool:
            status = self.latest.get("SYS_STATUS")
            return status is not None and bool(
                status.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
            )

        self.wait_for(ready, timeout_s, "the pre-arm bit of SYS_STATUS")

    def take_off(self, altitude_m: float, timeout_s: float = 30.0) -> None:
        """GUIDED, arm, NAV_TAKEOFF, and wait until IN_AIR near ``altitude_m``."""
        self.wait_armable()
        assert self.set_mode(4) == mavlink.MAV_RESULT_ACCEPTED
        assert self.arm() == mavlink.MAV_RESULT_ACCEPTED
        ack = self.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, altitude_m)
        assert ack.result == mavlink.MAV_RESULT_ACCEPTED
        self.wait_for(
            lambda: (
                self.latest["EXTENDED_SYS_STATE"].landed_state == mavlink.MAV_LANDED_STATE_IN_AIR
                and self.relative_altitude() > altitude_m - 0.6
            ),
            timeout_s,
            f"take-off to {altitude_m} m",
        )

    def relative_altitude(self) -> float:
        return self.latest["GLOBAL_POSITION_INT"].relative_alt / 1000.0

    def text_matching(self, fragment: str, since: int = 0) -> Text | None:
        return next((t for t in self.texts[since:] if fragment in t.text), None)

    def home(self) -> tuple[float, float, float]:
        """Latitude, longitude (deg) and altitude (m) of the vehicle's home."""
        start = len(self.acks)
        self.mav.command_long_send(
            self.target, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0, 242, 0, 0, 0, 0, 0, 0
        )
        self._wait_ack(mavlink.MAV_CMD_REQUEST_MESSAGE, start, 5.0)
        self.latest.pop("HOME_POSITION", None)
        home = self.wait_for(lambda: self.latest.get("HOME_POSITION"), 5.0, "HOME_POSITION")
        return home.latitude * 1e-7, home.longitude * 1e-7, home.altitude / 1000.0

    def send_position_target(
        self,
        home: tuple[float, float, float],
        position_enu: np.ndarray,
        velocity_enu: np.ndarray,
        acceleration_enu: np.ndarray | None = None,
        mask: int | None = None,
    ) -> None:
        """SET_POSITION_TARGET_GLOBAL_INT, relative-altitude frame, from ENU metres about home."""
        lat, lon, _ = pymap3d.enu2geodetic(
            position_enu[0], position_enu[1], 0.0, home[0], home[1], home[2]
        )
        acc = np.zeros(3) if acceleration_enu is None else acceleration_enu
        if mask is None:
            mask = MASK_POS_VEL if acceleration_enu is None else MASK_POS_VEL_ACC
        self.mav.set_position_target_global_int_send(
            int(self.vehicle_time() * 1000) & 0xFFFFFFFF,
            self.target,
            1,
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            mask,
            int(round(float(lat) * 1e7)),
            int(round(float(lon) * 1e7)),
            float(position_enu[2]),
            float(velocity_enu[1]),
            float(velocity_enu[0]),
            -float(velocity_enu[2]),
            float(acc[1]),
            float(acc[0]),
            -float(acc[2]),
            0.0,
            0.0,
        )


def _decode(text: Any) -> str:
    if isinstance(text, bytes | bytearray):
        return text.split(b"\x00", 1)[0].decode("ascii", "replace")
    return str(text)


def local_of(
    home: tuple[float, float, float], lat_deg: float, lon_deg: float, alt_m: float
) -> np.ndarray:
    """Geodetic -> ENU metres about ``home``."""
    return np.array(pymap3d.geodetic2enu(lat_deg, lon_deg, alt_m, *home), dtype=float)


class SmoothedPath:
    """A polyline flown at constant speed, smoothed by a moving average of width ``window_s``.

    ``sample(t)`` returns the smoothed position, its velocity and acceleration (the
    feed-forward a GCS sends, docs/design.md 3.5); before t = 0 and after the end it rests at the
    first and last point.
    """

    def __init__(
        self, points: np.ndarray, speed_mps: float, window_s: float, step_s: float = 0.005
    ) -> None:
        points = np.asarray(points, dtype=float)
        lengths = np.linalg.norm(np.diff(points, axis=0), axis=1)
        cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
        self.duration_s = float(cumulative[-1] / speed_mps)
        self.window_s = window_s
        margin = window_s
        self._t = np.arange(-margin, self.duration_s + margin + step_s, step_s)
        s = np.clip(self._t, 0.0, self.duration_s) * speed_mps
        raw = np.stack(
            [np.interp(s, cumulative, points[:, k]) for k in range(points.shape[1])], axis=1
        )
        half = int(round(window_s / 2 / step_s))
        n = len(raw)
        integral = np.concatenate([np.zeros((1, raw.shape[1])), np.cumsum(raw, axis=0)])
        index = np.arange(n)
        lo, hi = np.clip(index - half, 0, n - 1), np.clip(index + half, 0, n - 1)
        self._position = (integral[hi + 1] - integral[lo]) / (hi - lo + 1)[:, None]
        self._velocity = (raw[hi] - raw[lo]) / window_s
        raw_velocity = np.gradient(raw, step_s, axis=0)
        self._acceleration = (raw_velocity[hi] - raw_velocity[lo]) / window_s
        self.points = points

    def sample(self, t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.clip(np.asarray(t, dtype=float), self._t[0], self._t[-1])

        def at(values: np.ndarray) -> np.ndarray:
            return np.stack(
                [np.interp(t, self._t, values[:, k]) for k in range(values.shape[1])], axis=-1
            )

        return at(self._position), at(self._velocity), at(self._acceleration)
