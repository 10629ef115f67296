"""A line-of-sight mission flown end to end (real `gcs`, `vehicles` and radio medium processes
over loopback UDP), the medium cutting every link whose chord meets an obstacle
(`radio.buildings: true`, its buildings file written by the ground station): the small
mission's line-of-sight formation (its corners taken wider) completes, every sample of the medium connected,
every sample of the ground station connected by line of sight."""

from __future__ import annotations

import json

import pytest

from tests.flying import Flight, flight_speedup, mission_file

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


def test_a_line_of_sight_mission_flies_connected_through_a_medium_that_knows_buildings(
    tmp_path,
):
    mission = mission_file(
        tmp_path,
        connectivity={"rule": "line_of_sight"},
        radio={"enabled": True, "buildings": True},
    )
    flight = Flight(
        ["mission", "run", str(mission), "--speedup", str(flight_speedup(5)),
         "--vehicles-per-process", "5", "--json"],
        tmp_path,
    )  # fmt: skip
    try:
        code, out, err = flight.finish(timeout=280)
    finally:
        flight.kill()
    run = json.loads(out)
    assert code == 0, err[-3000:]
    assert run["completed"] is True
    assert run["radio"]["connected_fraction"] == 1.0
    assert run["los_connected_fraction"] == 1.0
    assert run["max_tracking_error_m"] < 5.0
