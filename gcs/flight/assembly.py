"""One assembly of a flight: the drivers of a plan's formation on their links, and the
ground-station core over them.

The live command (`gcs mission run`), the fast mode (`gcs.sim.fastsim`) and the streaming
benchmark (`bench.bench_gcs`) each open their own links (UDP to simulated or real autopilots,
in-memory ones in the fast mode), recorder and loop; they build what flies here, so that they
fly one core built one way: UAV n (1-based, formation order) is MAVLink system n, has its home
on the n-th start slot and lands on the n-th landing slot (the goal slots, or the start slots
of a stations mission), at the mission's altitude.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

from gcs.drivers.base import Driver, DriverTiming, UavSpec
from gcs.flight.clock import MissionClock
from gcs.flight.core import GroundStation, Recorder, RunOptions, View
from gcs.transport.link import Link


def uav_specs(plan, urls: Sequence[str]) -> list[UavSpec]:
    """What each driver is told of its UAV, one per link URL in formation order."""
    formation, mission = plan.formation, plan.mission
    landing = formation.landing_slots
    return [
        UavSpec(
            uav_id=index + 1,
            system_id=index + 1,
            url=url,
            origin=mission.origin,
            start_slot=formation.start_slots[index],
            goal_slot=landing[index],
            altitude=mission.altitude,
        )
        for index, url in enumerate(urls)
    ]


def assemble(
    plan,
    links: Sequence[Link],
    family: type[Driver],
    timing: DriverTiming,
    clock: MissionClock,
    recorder: Recorder,
    options: RunOptions,
    *,
    view: View | None = None,
    replan: Callable[[float, float], object] | None = None,
    wall: Callable[[], float] = time.monotonic,
) -> GroundStation:
    """The ground station flying `plan` through `links` (one per UAV, formation order) with
    drivers of `family`. A recorder that can fail (`on_error`: a full disk) reports it as an
    event of the run at `wall()` (the loop's time), never stopping the flight."""
    specs = uav_specs(plan, [link.url for link in links])
    drivers = [family(spec, link, timing) for spec, link in zip(specs, links, strict=True)]
    station = GroundStation(plan, drivers, clock, recorder, options, view=view, replan=replan)
    recorder.on_error = lambda text: station.note("error", "recording", text, wall())
    if recorder.error is not None:  # it failed already, describing the mission
        station.note("error", "recording", recorder.error, wall())
    return station
