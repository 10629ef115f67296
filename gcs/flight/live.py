"""The live loop: drives the ground-station core over real links on the wall clock.

ONE loop for the whole fleet, no thread: it waits on every UAV link at once (`selectors`)
until the next tick, hands what arrived to the core, polls the fleet's processes, the operator
socket and the terminal, and ticks the core at the mission's setpoint rate. All flight policy
is in `gcs.flight.core`; this module owns only the sockets and the clock.
"""

from __future__ import annotations

import selectors
import time
from collections.abc import Callable

from gcs.drivers.base import Fleet
from gcs.flight.core import GroundStation
from gcs.flight.lockstep import WorldSync
from gcs.flight.result import RunResult
from gcs.speed import OperatorSocket
from gcs.transport.forward import Forwarder

#: Longest wait for messages while connecting (wall s).
CONNECT_POLL_S = 0.02
#: The live view is redrawn at most this often (wall s).
VIEW_PERIOD_S = 0.2


class LiveLoop:
    """Flies `station` over its drivers' links (see the module docstring)."""

    def __init__(
        self,
        station: GroundStation,
        *,
        fleet: Fleet | None = None,
        operator: OperatorSocket | None = None,
        forwarder: Forwarder | None = None,
        world: WorldSync | None = None,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.station = station
        self.world = world
        self.fleet = fleet
        self.operator = operator
        self.forwarder = forwarder
        self._monotonic = monotonic
        self._last_view = -float("inf")
        self.tick_work: list[float] = []  # wall seconds each flight tick took

    def run(self) -> RunResult:
        """Connect, fly, land; return the result. The caller owns links, fleet and recorder."""
        selector = self._selector()
        try:
            if self._connect(selector):
                self._fly(selector)
        finally:
            selector.close()
        return self.station.result()

    def fly(self, until: Callable[[float], bool] | None = None) -> None:
        """The flight loop alone, on an anchored clock (benchmarks): tick until every UAV has
        landed or `until(wall)` says stop."""
        selector = self._selector()
        try:
            self._fly(selector, until)
        finally:
            selector.close()

    def _selector(self) -> selectors.BaseSelector:
        """select(2) wakes up to the microsecond (epoll and poll round to milliseconds, which is
        a millisecond of setpoint jitter); epoll beyond select's descriptor limit."""
        drivers = self.station.drivers
        if len(drivers) < 500:
            selector = selectors.SelectSelector()
        else:  # pragma: no cover - very large fleets
            selector = selectors.DefaultSelector()
        for index, driver in enumerate(drivers):
            selector.register(driver.link.fileno(), selectors.EVENT_READ, index)
        if self.forwarder is not None:  # the outputs' tools: (None, output index)
            for output, fd in enumerate(self.forwarder.filenos()):
                selector.register(fd, selectors.EVENT_READ, (None, output))
        return selector

    def _connect(self, selector) -> bool:
        station = self.station
        started = self._monotonic()
        while True:
            self._receive(selector, CONNECT_POLL_S)
            now = self._monotonic()
            self._poll_fleet(now)
            self._update_view(now)
            state = station.connect_step(now, started)
            if state is not None:
                return state

    def _fly(self, selector, until: Callable[[float], bool] | None = None) -> None:
        station = self.station
        period = station.tick_period_wall
        next_tick = self._monotonic()
        while True:
            now = self._monotonic()
            self._receive(selector, max(0.0, next_tick - now))
            now = self._monotonic()
            if now < next_tick:
                continue
            self._poll_fleet(now)
            self._poll_operator(now)
            self._sync_world(now)
            station.tick(now)
            if self.world is not None and station.mission_time is not None:
                self.world.ticked(station.mission_time)
                self._sync_world(now)  # the followers may run on to the new tick
            self._update_view(now)
            self.tick_work.append(self._monotonic() - now)
            next_tick += period
            if next_tick < now:  # overrun: do not burst to catch up
                next_tick = now + period
            if station.finished(now) or (until is not None and until(now)):
                return

    def _sync_world(self, now: float) -> None:
        """Lockstep: publish the mission clock to the simulated world, held back for its
        slowest process (`gcs.flight.lockstep`)."""
        if self.world is None:
            return
        for text in self.world.step(now, self.station.clock):
            self.station.note("warning", "world", text, now)

    def _receive(self, selector, timeout: float) -> None:
        ready = selector.select(timeout)
        self._sync_world(self._monotonic())
        drivers = self.station.drivers
        tools = [key.data[1] for key, _ in ready if isinstance(key.data, tuple)]
        if tools:
            links = {driver.spec.system_id: driver.link for driver in drivers}
            for output in tools:
                self.forwarder.poll(output, links)

        def batches():
            for key, _ in ready:
                index = key.data
                if isinstance(index, tuple):
                    continue
                now = self._monotonic()
                yield index, drivers[index].link.receive(now), now

        self.station.receive(self._monotonic(), batches())

    def _poll_fleet(self, now: float) -> None:
        """What the fleet's processes reported (an exit, the radio medium's reports)."""
        if self.fleet is not None:
            reports = getattr(self.fleet, "radio_reports", list)()  # the radio medium's
            self.station.fleet_reports(now, self.fleet.poll(), reports)

    def _poll_operator(self, now: float) -> None:
        """The operator socket (`gcs speed`, `gcs return`, `gcs relieve`) and the lines typed
        in the live view."""
        station = self.station
        if self.operator is not None:
            for request in self.operator.poll():
                if request.command == "return":
                    answer = station.operator_return(request.at, request.error, now)
                elif request.command == "relieve":
                    answer = station.operator_relieve(request.uav, request.error, now)
                else:
                    answer = station.operator_request(request.speed, request.at, request.error, now)
                request.reply(answer)
        for line in station.view.commands():
            station.operator_command(line, now)

    def _update_view(self, now: float) -> None:
        if now - self._last_view >= VIEW_PERIOD_S:
            self._last_view = now
            self.station.view.update(self.station, now)
