"""Time on station in a stations mission (docs/design.md 7): how long each UAV held its point,
the fleet's connectivity while every UAV held, and the tick every UAV is first on station.

A UAV is *on its station* while its virtual target holds there and its reported position is
within rho_c of it; the fleet *holds* from the outbound distance S_out until the first UAV
leaves for home again (2 M - S_out once the return was asked at formation distance M). The
core hands the watch, each tick, the targets, the positions it has and the formation distance,
and turns what it says into the run's events and result (`PointHeld`, `StationsResult`). Pure:
no clocks, sockets or files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from planner.formation import DISTANCE_TOLERANCE


@dataclass
class StationWatch:
    """The stations' tallies of one flight (see the module docstring)."""

    size: int
    safety_margin: float
    #: per UAV (formation order), mission seconds on its station
    on_station_s: np.ndarray = field(init=False)
    #: every UAV holds its station now (until the return)
    holding: bool = False
    #: every UAV has been on station at least once (the event was said)
    reached: bool = False
    held_samples: int = 0
    held_connected: int = 0
    last_tick: float | None = None

    def __post_init__(self) -> None:
        self.on_station_s = np.zeros(self.size)

    def update(
        self,
        t: float,
        slots: np.ndarray,
        targets: np.ndarray,
        positions: np.ndarray,
        distance: float,
        outbound: float,
        return_distance: float | None,
        connected: bool | None,
    ) -> bool:
        """One tick at mission time `t`: `slots` (N, 2) the stations, `targets` (N, 2) the
        virtual targets, `positions` (N, 2) the reported positions (NaN: none, or the link
        lost), `distance` the formation distance, `outbound` S_out, `return_distance` M, the
        formation distance the return was asked at (None: no return yet), `connected` the
        connectivity sample of this tick (None: none taken). True the first tick every UAV
        is on station."""
        dt = 0.0 if self.last_tick is None else max(t - self.last_tick, 0.0)
        self.last_tick = t
        held = np.hypot(*(targets - slots).T) <= DISTANCE_TOLERANCE
        with np.errstate(invalid="ignore"):
            near = np.hypot(*(positions - slots).T) <= self.safety_margin
        self.on_station_s += dt * (held & near)
        leaves = math.inf if return_distance is None else 2 * return_distance - outbound
        self.holding = outbound - DISTANCE_TOLERANCE <= distance <= leaves + DISTANCE_TOLERANCE
        if self.holding and connected is not None:
            self.held_samples += 1
            self.held_connected += int(connected)
        if self.holding and not self.reached:
            self.reached = True
            return True
        return False

    @property
    def held_connected_fraction(self) -> float | None:
        """The share of the connectivity samples taken while every UAV held that found the
        fleet connected (None: none taken)."""
        return self.held_connected / self.held_samples if self.held_samples else None
