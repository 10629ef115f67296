"""Interop with the real third-party tools a user points at `vehicles sim`: MAVSDK-Python 4.1.0
(its native MAVSDK library) and MAVProxy 1.8.75 (driven through its command prompt). Each test
starts a real `vehicles sim` process on loopback UDP; the tool talks to it as the vehicle's
peer, and a passive observer (the vehicle's `--out` address; it sends nothing) checks what the
vehicle really did: mode, arming, altitude, position, MISSION_ITEM_REACHED, STATUSTEXT.

Everything waits on observable state with deadlines, never on sleeps. Both tools count their
timeouts in wall-clock time and the vehicles run `SPEEDUP` times faster (lower on a busy
machine); MAVProxy, system 255 like the fleetline ground station, sends its heartbeat once a
second of wall clock, i.e. every SPEEDUP simulated seconds, so its vehicle's GCS failsafe
timeout is raised (the failsafe is not what is tested here).
"""

from __future__ import annotations

import math
import queue
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.modes import COPTER_MODE
from tests.flying import flight_speedup
from vehicles.testing import VehicleProcess, free_udp_ports

pytestmark = pytest.mark.slow

SPEEDUP = flight_speedup(8.0)
GUIDED, AUTO, LAND, STABILIZE = (COPTER_MODE[m] for m in ("GUIDED", "AUTO", "LAND", "STABILIZE"))
HOME = (45.7640, 4.8357, 170.0)  # vehicles sim's default --home
DEG_PER_M_NORTH = 1.0 / 111_200.0
DEG_PER_M_EAST = DEG_PER_M_NORTH / math.cos(math.radians(HOME[0]))
PARAMETER_COUNT = 19  # vehicles/autopilot/parameters.py


class Observer:
    """What the vehicle sends to its `--out` address: the latest message of each type, every
    STATUSTEXT and MISSION_ITEM_REACHED (it never sends, so it never becomes the peer)."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=201)
        self.latest: dict[str, Any] = {}
        self.texts: list[str] = []
        self.reached: list[int] = []

    def poll(self, wait_s: float = 0.0) -> None:
        if wait_s > 0:
            self.conn.select(wait_s)
        while (message := self.conn.recv_msg()) is not None:
            kind = message.get_type()
            if kind == "BAD_DATA" or message.get_srcSystem() != 1:
                continue
            self.latest[kind] = message
            if kind == "STATUSTEXT":
                self.texts.append(message.text)
            elif kind == "MISSION_ITEM_REACHED":
                self.reached.append(message.seq)

    def wait_for(self, condition: Callable[[], Any], timeout_s: float, what: str) -> Any:
        """Poll until `condition()` is true (returns it) or `timeout_s` of wall clock passes."""
        deadline = time.monotonic() + timeout_s
        while True:
            self.poll(0.01)
            result = condition()
            if result:
                return result
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")

    def heartbeat(self, custom_mode: int | None = None, armed: bool | None = None) -> bool:
        beat = self.latest.get("HEARTBEAT")
        if beat is None:
            return False
        is_armed = bool(beat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        return (custom_mode is None or beat.custom_mode == custom_mode) and (
            armed is None or is_armed == armed
        )

    def altitude(self) -> float:
        return self.latest["GLOBAL_POSITION_INT"].relative_alt / 1000.0

    def north_east(self) -> tuple[float, float]:
        position = self.latest["GLOBAL_POSITION_INT"]
        return (
            (position.lat * 1e-7 - HOME[0]) / DEG_PER_M_NORTH,
            (position.lon * 1e-7 - HOME[1]) / DEG_PER_M_EAST,
        )

    def close(self) -> None:
        self.conn.close()


@pytest.fixture
def vehicle(request):
    """A `vehicles sim` process (no noise) and an observer of everything it sends."""
    port = free_udp_ports(1)
    args = ["--no-noise", "--seed", "5", "--out", f"udpout:127.0.0.1:{port}"]
    args += list(getattr(request, "param", ()))
    with VehicleProcess(count=1, speedup=SPEEDUP, args=args) as process:
        observer = Observer(port)
        observer.wait_for(lambda: "SYS_STATUS" in observer.latest, 20.0, "the vehicle's telemetry")
        yield process, observer
        observer.close()
        code, stderr = process.stop()
        print(stderr)
        assert code == 0, stderr


def seconds(simulated_s: float) -> float:
    """Wall-clock deadline for `simulated_s` of flight, with a margin for a busy machine."""
    return 5.0 + 3.0 * simulated_s / SPEEDUP


# ---------------------------------------------------------------------- MAVSDK -------------
class Mavsdk:
    """MAVSDK (the native library in the `mavsdk` wheel) connected to one vehicle, its plugins
    created on demand; `close` destroys it."""

    def __init__(self, port: int) -> None:
        import mavsdk  # the `mavsdk` wheel: requirements.lock (make installs it)

        self.mavsdk = mavsdk.Mavsdk(
            mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.GROUND_STATION)
        )
        self.mavsdk.add_any_connection(f"udpout://127.0.0.1:{port}")
        self.system = self.mavsdk.first_autopilot(20.0)
        assert self.system is not None, "MAVSDK found no autopilot"

    def plugin(self, name: str):
        module = __import__(f"mavsdk.plugins.{name}", fromlist=["x"])
        cls = getattr(module, "".join(part.title() for part in name.split("_")))
        return cls(self.system)

    def close(self) -> None:
        self.mavsdk.destroy()


def test_mavsdk_arms_takes_off_goes_to_flies_offboard_and_lands(vehicle):
    process, observer = vehicle
    tool = Mavsdk(process.port())
    try:
        from mavsdk.plugins.offboard import PositionNedYaw, VelocityNedYaw

        telemetry, action, offboard = (tool.plugin(n) for n in ("telemetry", "action", "offboard"))
        param = tool.plugin("param")
        observer.wait_for(lambda: telemetry.health().is_armable, 20.0, "MAVSDK: armable")
        # the parameter list (PARAM_REQUEST_LIST; no FTP)
        params = param.get_all_params()
        names = {p.name: p.value for p in [*params.int_params, *params.float_params]}
        assert len(names) == PARAMETER_COUNT and names["WPNAV_SPEED"] == pytest.approx(1500.0)
        # arm where it boots (STABILIZE), then takeoff (MAVSDK switches to GUIDED itself)
        observer.wait_for(lambda: observer.heartbeat(STABILIZE, armed=False), 5.0, "STABILIZE")
        action.set_takeoff_altitude(5.0)
        action.arm()
        observer.wait_for(lambda: observer.heartbeat(STABILIZE, armed=True), 10.0, "armed")
        action.takeoff()
        observer.wait_for(lambda: observer.altitude() > 4.5, seconds(5.0), "5 m")
        assert observer.heartbeat(custom_mode=GUIDED, armed=True)
        # goto_location: GUIDED + MAV_CMD_DO_REPOSITION (AMSL)
        home = telemetry.home()
        target = (home.latitude_deg + 20 * DEG_PER_M_NORTH, home.longitude_deg)
        action.goto_location(*target, home.absolute_altitude_m + 7.0, float("nan"))
        observer.wait_for(
            lambda: abs(observer.north_east()[0] - 20.0) < 1.0 and abs(observer.altitude() - 7) < 1,
            seconds(8.0),
            "goto_location 20 m north at 7 m",
        )
        # offboard: a position in LOCAL_NED (it holds it: no timeout), then a velocity
        offboard.set_position_ned(PositionNedYaw(0.0, 15.0, -6.0, 0.0))
        offboard.start()
        observer.wait_for(
            lambda: math.dist(observer.north_east(), (0.0, 15.0)) < 1.0,
            seconds(10.0),
            "offboard position 15 m east",
        )
        offboard.set_velocity_ned(VelocityNedYaw(0.0, -3.0, 0.0, 0.0))
        observer.wait_for(
            lambda: observer.latest["GLOBAL_POSITION_INT"].vy < -250,
            seconds(2.0),
            "offboard velocity 3 m/s west",
        )
        offboard.stop()  # MAVSDK: Hold (BRAKE on ArduCopter)
        observer.wait_for(lambda: observer.heartbeat(COPTER_MODE["BRAKE"]), 10.0, "BRAKE")
        # land where it is: LAND, touch-down, automatic disarm
        action.land()
        observer.wait_for(lambda: observer.heartbeat(LAND), 10.0, "LAND")
        observer.wait_for(
            lambda: observer.heartbeat(armed=False), seconds(20.0), "landed, disarmed"
        )
        assert "Disarming motors" in observer.texts and observer.altitude() < 0.3
    finally:
        tool.close()


def test_mavsdk_returns_to_launch_and_cannot_arm_again_in_brake(vehicle):
    """return_to_launch: RTL climbs to RTL_ALT, comes home, lands, disarms. MAVSDK's arm() from
    RTL (or LAND, AUTO) first asks for Hold, which is BRAKE on ArduCopter, where ArduCopter does
    not arm: refused with `Arm: Mode not armable`, as a real ArduCopter refuses it."""
    process, observer = vehicle
    tool = Mavsdk(process.port())
    try:
        telemetry, action = tool.plugin("telemetry"), tool.plugin("action")
        observer.wait_for(lambda: telemetry.health().is_armable, 20.0, "MAVSDK: armable")
        action.set_takeoff_altitude(5.0)
        action.arm()
        action.takeoff()
        observer.wait_for(lambda: observer.altitude() > 4.5, seconds(5.0), "5 m")
        home = telemetry.home()
        target = (home.latitude_deg, home.longitude_deg + 20 * DEG_PER_M_EAST)
        action.goto_location(*target, home.absolute_altitude_m + 5.0, float("nan"))
        observer.wait_for(
            lambda: abs(observer.north_east()[1] - 20.0) < 1.0, seconds(8.0), "20 m east"
        )
        action.return_to_launch()
        observer.wait_for(lambda: observer.heartbeat(COPTER_MODE["RTL"]), 10.0, "RTL")
        observer.wait_for(lambda: observer.altitude() > 14.5, seconds(6.0), "RTL_ALT (15 m)")
        observer.wait_for(lambda: observer.heartbeat(armed=False), seconds(60.0), "RTL landed")
        assert math.hypot(*observer.north_east()) < 1.5 and observer.altitude() < 0.3
        with pytest.raises(Exception, match="FAILED"):
            action.arm()
        assert observer.wait_for(
            lambda: "Arm: Mode not armable" in observer.texts, 5.0, "the arming refusal"
        )
    finally:
        tool.close()


def test_mavsdk_uploads_a_mission_and_flies_it_in_auto(vehicle):
    process, observer = vehicle
    tool = Mavsdk(process.port())
    try:
        from mavsdk.plugins.mission import MissionItem, MissionPlan
        from mavsdk.plugins.mission_raw import MissionItem as RawItem

        telemetry, action = tool.plugin("telemetry"), tool.plugin("action")
        mission, raw = tool.plugin("mission"), tool.plugin("mission_raw")
        observer.wait_for(lambda: telemetry.health().is_armable, 20.0, "MAVSDK: armable")
        lat, lon = HOME[0], HOME[1]
        # The Mission plugin puts its take-off at item 0, which ArduCopter takes as home: AUTO
        # is refused on the ground as ArduCopter refuses it.
        nan = float("nan")
        takeoff, none = MissionItem.VehicleAction.TAKEOFF, MissionItem.VehicleAction.NONE
        plan = MissionPlan(
            [
                MissionItem(lat, lon, 10.0, nan, False, nan, nan,
                            MissionItem.CameraAction.NONE, 0.0, nan, nan, nan, nan, vehicle_action)
                for vehicle_action in (takeoff, none)
            ]
        )  # fmt: skip
        mission.upload_mission(plan)
        action.arm()
        with pytest.raises(Exception, match="UNKNOWN|DENIED|FAILED"):
            mission.start_mission()
        observer.wait_for(
            lambda: "Auto: Missing Takeoff Cmd" in observer.texts, 5.0, "the AUTO refusal"
        )

        # MissionRaw, item 0 = home: take-off, two waypoints, land
        def item(seq, command, north=None, east=0.0, alt=0.0, frame=3):
            x = round((lat + north * DEG_PER_M_NORTH) * 1e7) if north is not None else 0
            y = round((lon + east * DEG_PER_M_EAST) * 1e7) if north is not None else 0
            return RawItem(seq, frame, command, int(seq == 0), 1, 0.0, 0.0, 0.0, 0.0, x, y, alt, 0)

        items = [
            item(0, 16, 0.0, 0.0, HOME[2], frame=0),
            item(1, 22, alt=5.0),
            item(2, 16, 25.0, 0.0, 5.0),
            item(3, 16, 25.0, 25.0, 5.0),
            item(4, 21, 0.0, 25.0),
        ]
        raw.upload_mission(items)
        observer.wait_for(
            lambda: observer.texts[-1:] == ["Flight plan received"], 5.0, "the flight plan"
        )
        down = raw.download_mission()
        assert [(i.seq, i.command) for i in down] == [(i.seq, i.command) for i in items]
        assert (down[0].x, down[0].y, down[0].z) == (items[0].x, items[0].y, HOME[2])  # home
        action.arm()
        raw.start_mission()  # MAVSDK: AUTO, then MAV_CMD_MISSION_START (auto-arms)
        observer.wait_for(lambda: observer.heartbeat(AUTO), 10.0, "AUTO")
        observer.wait_for(lambda: observer.heartbeat(armed=False), seconds(40.0), "the mission end")
        assert observer.reached == [1, 2, 3, 4]
        observer.wait_for(raw.is_mission_finished, 5.0, "MAVSDK: the mission finished")
        assert math.dist(observer.north_east(), (0.0, 25.0)) < 2.5 and observer.altitude() < 0.3
        for text in ("Mission: 1 Takeoff", "Reached command #2", "Mission: 4 Land"):
            assert text in observer.texts
    finally:
        tool.close()


# ---------------------------------------------------------------------- MAVProxy -----------
class MavProxy:
    """`mavproxy.py --master=udpout:...` driven through its command prompt (stdin), its output
    read line by line."""

    def __init__(self, port: int, state_dir: Path) -> None:
        script = Path(sys.executable).parent / "mavproxy.py"  # requirements-interop.lock
        self.process = subprocess.Popen(
            [sys.executable, "-u", str(script), f"--master=udpout:127.0.0.1:{port}",
             f"--state-basedir={state_dir}"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            bufsize=1, cwd=state_dir,
        )  # fmt: skip
        self.lines: list[str] = []
        self._queue: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self._queue.put(line.rstrip())

    def output(self) -> list[str]:
        while not self._queue.empty():
            self.lines.append(self._queue.get_nowait())
        return self.lines

    def send(self, command: str) -> int:
        """Type `command`; the number of output lines before it (to search after)."""
        start = len(self.output())
        self.process.stdin.write(command + "\n")
        self.process.stdin.flush()
        return start

    def printed(self, pattern: str, start: int = 0) -> str | None:
        return next((ln for ln in self.output()[start:] if re.search(pattern, ln)), None)

    def close(self) -> None:
        if self.process.poll() is None:
            self.send("exit")
            self.process.stdin.close()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


@pytest.mark.parametrize("vehicle", [("--gcs-timeout", "120")], indirect=True)
def test_mavproxy_flies_guided_lands_and_runs_a_mission_file(vehicle, tmp_path):
    process, observer = vehicle
    lat, lon, alt = HOME
    mission = tmp_path / "mission.txt"  # QGC WPL 110: home, take-off, 2 waypoints, land
    mission.write_text(
        "QGC WPL 110\n"
        f"0\t1\t0\t16\t0\t0\t0\t0\t{lat:.7f}\t{lon:.7f}\t{alt}\t1\n"
        "1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t5\t1\n"
        f"2\t0\t3\t16\t0\t0\t0\t0\t{lat + 25 * DEG_PER_M_NORTH:.7f}\t{lon:.7f}\t5\t1\n"
        f"3\t0\t3\t16\t0\t0\t0\t0\t{lat + 25 * DEG_PER_M_NORTH:.7f}\t"
        f"{lon + 25 * DEG_PER_M_EAST:.7f}\t5\t1\n"
        "4\t0\t3\t21\t0\t0\t0\t0\t0\t0\t0\t1\n"
    )
    tool = MavProxy(process.port(), tmp_path)
    try:
        # connect: the parameters come over PARAM_REQUEST_LIST once FTP is refused (no FTP
        # timeout), and the geofence is present, not enabled, never breached
        observer.wait_for(lambda: tool.printed(r"online system 1"), 20.0, "MAVProxy online")
        received = observer.wait_for(
            lambda: tool.printed(r"Received \d+ parameters"), 10.0, "the parameter download"
        )
        assert received.endswith(f"Received {PARAMETER_COUNT} parameters")
        start = tool.send("param show WPNAV_SPEED")
        observer.wait_for(lambda: tool.printed(r"WPNAV_SPEED\s+1500", start), 5.0, "WPNAV_SPEED")
        assert tool.printed("fence present") and not tool.printed("fence breach")
        # GUIDED, arm, take-off, a position target (held: no timeout), LAND
        tool.send("mode guided")
        observer.wait_for(lambda: observer.heartbeat(GUIDED), 10.0, "GUIDED")
        tool.send("arm throttle")
        observer.wait_for(lambda: observer.heartbeat(GUIDED, armed=True), 10.0, "armed")
        tool.send("takeoff 5")
        observer.wait_for(lambda: observer.altitude() > 4.5, seconds(5.0), "5 m")
        tool.send("position 20 0 -2")  # BODY_NED: 20 m ahead (north), 2 m up
        observer.wait_for(
            lambda: (
                math.dist(observer.north_east(), (20.0, 0.0)) < 0.5
                and abs(observer.altitude() - 7.0) < 0.5
            ),
            seconds(10.0),
            "the position target 20 m north, 7 m up",
        )
        start = tool.send("velocity 0 3 0")  # BODY_NED: 3 m/s right (east), for GUID_TIMEOUT
        observer.wait_for(
            lambda: observer.latest["GLOBAL_POSITION_INT"].vy > 250, seconds(2.0), "velocity east"
        )
        observer.wait_for(
            lambda: "Guided: no setpoint for 1 s, holding" in observer.texts,
            seconds(3.0),
            "the velocity target's timeout",
        )
        tool.send("mode land")
        observer.wait_for(lambda: observer.heartbeat(LAND), 10.0, "LAND")
        observer.wait_for(lambda: observer.heartbeat(armed=False), seconds(20.0), "landed")
        start = tool.send("arm throttle")  # in LAND: refused as ArduCopter refuses it
        observer.wait_for(
            lambda: tool.printed("Arm: Mode not armable", start), 5.0, "the arming refusal"
        )
        # wp load, mode auto: on the ground AUTO waits for MISSION_START (throttle at zero)
        tool.send("mode guided")
        tool.send("arm throttle")
        observer.wait_for(lambda: observer.heartbeat(GUIDED, armed=True), 10.0, "armed again")
        start = tool.send(f"wp load {mission}")
        observer.wait_for(
            lambda: tool.printed(r"MISSION_ACK: TYPE_MISSION: ACCEPTED", start), 10.0, "wp load"
        )
        tool.send("mode auto")
        observer.wait_for(lambda: observer.heartbeat(AUTO), 10.0, "AUTO")
        tool.send("long MISSION_START")
        observer.wait_for(lambda: observer.heartbeat(armed=False), seconds(40.0), "mission end")
        assert observer.reached == [1, 2, 3, 4]
        assert math.dist(observer.north_east(), (25.0, 25.0)) < 2.5
        observer.wait_for(lambda: tool.printed(r"waypoint 4"), 5.0, "MAVProxy: waypoint 4")
        start = tool.send("wp list")
        observer.wait_for(lambda: tool.printed(r"Saved 5 waypoints", start), 10.0, "wp list")
    finally:
        tool.close()
