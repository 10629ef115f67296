"""The take-off and landing schedule: when each UAV takes off and lands, and when a UAV late
to take off freezes the formation.

Each tick, for each UAV (not relieved; the fleet not landing):

* a UAV whose formation returns before it left its start slot (a stations mission) *stays*:
  it lands where it is, once;
* a UAV takes off once mission time reaches its departure (Phi(L_0,n)) less the take-off lead
  (arming, climb, margin);
* a UAV not yet up (ready, arming, taking off) whose departure falls within the horizon (the
  speed-change lead plus two ticks) is *late*: the formation freezes until none is ("takeoff"),
  and resumes then. A UAV the formation froze for stays late until it is up: the freeze itself
  moves every departure not yet reached to infinity, and reading that as "no longer late" made
  the formation resume and freeze again every tick (seen in CI with 30 % loss: ten speed
  changes in 0.4 s);
* a UAV following its target lands once the formation has been still at its arrival for half a
  smoothing window plus `STILL_BEFORE_LANDING_S`, when it is within the landing tolerance of its
  arrival slot, or at the latest after the settle time (where it is). A stations fleet lands
  only once it returns.

This module decides (`Schedule.decide`, pure, on mission time); `gcs.flight.core` applies its
`ScheduleDecision` (drivers, events, freeze and resume).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

#: A UAV is told to land only once its reference has been still this long (mission s): if the
#: LAND request is lost, the setpoints the vehicle keeps extrapolating carry no braking
#: feed-forward (extrapolated for 1 s, a braking one would fly it back along the path).
STILL_BEFORE_LANDING_S = 0.5


@dataclass(frozen=True)
class UavProgress:
    """What the schedule reads of one UAV: relieved (flies its own relief), stays on its slot
    (the return came first), its driver's state, and whether take-off and landing were sent."""

    relieved: bool
    stays: bool
    not_up: bool  # ready, arming or taking off
    following: bool
    takeoff_sent: bool
    land_sent: bool


@dataclass(frozen=True)
class ScheduleDecision:
    """UAV indices to tell to stay (land on the slot they are on), to take off and to land
    this tick; `late` the UAV ids (1-based) late to take off."""

    stay: tuple[int, ...] = ()
    takeoff: tuple[int, ...] = ()
    land: tuple[int, ...] = ()
    late: tuple[int, ...] = ()


@dataclass(frozen=True)
class Schedule:
    """The schedule's settings: the take-off lead (mission s), the landing tolerance (m) and
    the longest wait for it (mission s), and whether the fleet lands (no stations, or
    returning)."""

    takeoff_lead_s: float
    landing_tolerance_m: float
    landing_settle_s: float

    def decide(
        self,
        t: float,
        uavs: Sequence[UavProgress],
        departures: np.ndarray,
        arrivals: np.ndarray,
        horizon: float,
        window_s: float,
        lands: bool,
        slot_offset: Callable[[int], float],
        frozen_for: frozenset[int] = frozenset(),
    ) -> ScheduleDecision:
        """One tick at mission time `t`: `departures`, `arrivals` (N,) the mission times of
        each UAV's departure and arrival (inf: never); `horizon` how far ahead a departure
        makes a UAV not yet up late; `slot_offset(i)` UAV i's distance to its arrival slot
        (m), asked only when it matters; `frozen_for` the UAVs (indices) the formation is frozen
        for, late while they are not up."""
        stay, takeoff, land, late = [], [], [], []
        for index, uav in enumerate(uavs):
            if uav.relieved:
                continue
            if uav.stays:
                if not uav.land_sent:
                    stay.append(index)
                continue
            if not uav.takeoff_sent and t >= departures[index] - self.takeoff_lead_s:
                takeoff.append(index)
            if uav.not_up and (departures[index] <= horizon or index in frozen_for):
                late.append(index + 1)
            still = arrivals[index] + window_s / 2
            if (
                lands
                and uav.following
                and not uav.land_sent
                and t >= still + STILL_BEFORE_LANDING_S
                and (
                    slot_offset(index) <= self.landing_tolerance_m
                    or t >= still + self.landing_settle_s
                )
            ):
                land.append(index)
        return ScheduleDecision(tuple(stay), tuple(takeoff), tuple(land), tuple(late))
