"""A driver and a fake autopilot on real UDP sockets, and the scheduler loop between them.

`Flight` plays the runtime's part for one UAV: it waits on the link's socket, feeds what
arrives to the driver (`on_message`), steps it, and streams setpoints at 10 Hz while the driver
wants them, from a `Route` (position and velocity in the mission's local frame at a time).
"""

from __future__ import annotations

import selectors
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from gcs.drivers import driver_class
from gcs.drivers.base import Driver, DriverEvent, DriverTiming, UavSpec
from gcs.geodesy import Origin, enu_to_geodetic
from gcs.transport.link import Link
from tests.fakes.common import FakeEndpoint, Home
from vehicles.ports import free_udp_ports

#: (position (3,), velocity (3,)) in the local ENU frame at mission time t (vehicle-time seconds
#: since the route began, the wall clock times the speedup), velocities in vehicle-time m/s.
Route = Callable[[float], tuple[np.ndarray, np.ndarray]]


def hover(point: np.ndarray) -> Route:
    """Stay at `point` (x, y, altitude above the origin)."""
    point = np.asarray(point, float)
    return lambda t: (point, np.zeros(3))


def leg(start: np.ndarray, velocity: np.ndarray, duration: float) -> Route:
    """From `start`, move at `velocity` for `duration` s, then stay."""
    start, velocity = np.asarray(start, float), np.asarray(velocity, float)

    def route(t: float) -> tuple[np.ndarray, np.ndarray]:
        if t >= duration:
            return start + velocity * duration, np.zeros(3)
        return start + velocity * t, velocity

    return route


def home_of(origin: Origin, slot: tuple[float, float], up: float = 0.0) -> Home:
    """The WGS84 home of a vehicle parked on `slot` (local x, y), `up` m above the origin."""
    lat, lon, alt = enu_to_geodetic(slot[0], slot[1], up, origin)
    return Home(float(lat), float(lon), float(alt))


@dataclass
class Flight:
    """One driver flying one fake autopilot (see the module docstring)."""

    driver: Driver
    fake: FakeEndpoint
    link: Link
    route: Route | None = None
    setpoint_rate_hz: float = 10.0
    stream_paused: bool = False
    events: list[DriverEvent] = field(default_factory=list)  # drained from the driver
    _route_t0: float | None = None

    @classmethod
    def start(
        cls,
        backend: str,
        model,
        *,
        origin: Origin,
        slot: tuple[float, float] = (0.0, 0.0),
        altitude: float = 20.0,
        speedup: float = 1.0,
    ) -> Flight:
        """Start the fake (ArduPilot: listening, PX4: pushing to our port) and the driver."""
        if backend == "px4":
            port = free_udp_ports()
            link = Link(f"udpin:127.0.0.1:{port}", model.system_id)
            fake = FakeEndpoint(model, f"udpout:127.0.0.1:{port}")
        else:
            fake = FakeEndpoint(model, "udpin:127.0.0.1:0")
            link = Link(f"udpout:127.0.0.1:{fake.port}", model.system_id)
        spec = UavSpec(
            uav_id=1,
            system_id=model.system_id,
            url=link.url,
            origin=origin,
            start_slot=np.asarray(slot, float),
            goal_slot=np.asarray(slot, float),
            altitude=altitude,
        )
        driver = driver_class(backend)(spec, link, DriverTiming(speedup=speedup))
        fake.start()
        # As the runtime does: the mission's 10 Hz in vehicle time.
        return cls(driver, fake, link, setpoint_rate_hz=10.0 * speedup)

    def follow(self, route: Route) -> None:
        """Stream `route` from now on (its time starts at the next setpoint sent)."""
        self.route = route
        self._route_t0 = None

    def close(self) -> None:
        self.fake.stop()
        self.link.close()

    def __enter__(self) -> Flight:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def run_until(self, done: Callable[[], bool], timeout: float) -> bool:
        """Run the loop until `done()` or `timeout` wall seconds; return `done()`."""
        self.events.extend(self.driver.drain_events())
        selector = selectors.DefaultSelector()
        selector.register(self.link.fileno(), selectors.EVENT_READ)
        deadline = time.monotonic() + timeout
        period = 1.0 / self.setpoint_rate_hz
        next_setpoint = time.monotonic()
        try:
            while True:
                now = time.monotonic()
                if done():
                    return True
                if now >= deadline:
                    return False
                selector.select(min(0.01, max(0.0, next_setpoint - now)))
                now = time.monotonic()
                for message in self.link.receive(now):
                    self.driver.on_message(message, now)
                self.driver.step(now)
                self.events.extend(self.driver.drain_events())
                wants = self.driver.wants_setpoints and self.route is not None
                if not wants or self.stream_paused:
                    continue
                if now >= next_setpoint:
                    next_setpoint = max(next_setpoint + period, now)
                    if self._route_t0 is None:
                        self._route_t0 = now
                    mission_time = (now - self._route_t0) * self.driver.timing.speedup
                    position, velocity = self.route(mission_time)
                    self.driver.send_setpoint(position, velocity, None, 0.0, now)
        finally:
            selector.close()

    def texts(self, kind: str) -> list[str]:
        """The texts of the driver's events of one kind, in order."""
        return [e.text for e in self.events if e.kind == kind]


@dataclass
class SinkDriver:
    """A driver whose link leads to a loopback socket nobody reads (for transcript replays:
    what it sends has no effect, the recording answers)."""

    driver: Driver
    sink: socket.socket
    sent: list  # (time, message) the driver sent

    @classmethod
    def start(cls, backend: str, system_id: int, origin: Origin, slot, altitude: float):
        sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sink.bind(("127.0.0.1", 0))
        sent: list = []

        def capture(direction: str, raw: bytes, message, now: float) -> None:
            if direction == "tx":
                sent.append((now, message))

        link = Link(f"udpout:127.0.0.1:{sink.getsockname()[1]}", system_id, capture=capture)
        spec = UavSpec(1, system_id, link.url, origin, np.asarray(slot, float),
                       np.asarray(slot, float), altitude)  # fmt: skip
        return cls(driver_class(backend)(spec, link, DriverTiming()), sink, sent)

    def __enter__(self) -> SinkDriver:
        return self

    def commands(self, command: int) -> list[tuple[float, object]]:
        """The COMMAND_LONG/INT of one kind the driver sent, with their times."""
        return [
            (t, m) for t, m in self.sent
            if m.get_type() in ("COMMAND_LONG", "COMMAND_INT") and m.command == command
        ]  # fmt: skip

    def __exit__(self, *exc) -> None:
        self.driver.link.close()
        self.sink.close()
