"""The relief policy of a stations mission (docs/design.md 7): whether a UAV may be relieved
now, which UAV its battery sends home, and when the relieved UAV lands.

A relief sends one UAV home alone from its station (`planner.relief`: it climbs above the
chain, the UAVs of its gap close up, it flies home above the route and lands on the last free
slot of the start row). It is asked by the operator (`gcs relieve N`) or by a battery below
`stations.relieve_below_pct`; one at a time, only while every UAV holds its station, never
while the fleet is landing, returning or frozen, nor while a UAV is not flying the formation. The relieved UAV lands once it is above its
slot, or `landing_settle_s` after its planned arrival.

This module decides from what the core hands it (`ReliefState`, each UAV's battery); the core
plans the relief with its `Roster` and applies it (formation, records, events). Pure: no
clocks, sockets or files.
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: The share of a_max a relieved UAV and the UAVs closing its gap plan their motions with.
RELIEF_ACCELERATION_SHARE = 0.5
#: How each source of a relief is said in the events.
RELIEF_SOURCES = {"operator": "the operator", "battery": "its battery is low"}


@dataclass(frozen=True)
class ReliefState:
    """What the policy reads of the flight when a relief is asked: the fleet's size, why it is
    landing (None: it is not), whether it returns home already, the UAVs relieved already
    (0-based), the relief in progress (0-based UAV and its planned arrival home; None: none),
    whether every UAV holds its station, what froze the formation (None: nothing), and the UAVs
    not flying the formation (0-based -> why)."""

    size: int
    landing: str | None
    returning: bool
    relieved: frozenset[int]
    active: tuple[int, float] | None
    holding: bool
    frozen_by: str | None
    unavailable: dict[int, str] = field(default_factory=dict)


def refusal(uav: int | None, state: ReliefState) -> str | None:
    """Why UAV `uav` (1-based) cannot be relieved now; None: it can."""
    if uav is None or not 1 <= uav <= state.size:
        return f"there is no UAV {uav} (the fleet has UAVs 1 to {state.size})"
    if state.landing is not None:
        return f"the fleet is landing ({state.landing})"
    if state.returning:
        return "the fleet is returning home already"
    if uav - 1 in state.relieved:
        return f"UAV {uav} was relieved already"
    if state.active is not None:
        other, home_s = state.active
        return (
            f"UAV {other + 1} is being relieved (home at about t={home_s:.2f} s): one relief "
            "at a time"
        )
    if not state.holding:
        return "a UAV is relieved from its station: wait until every UAV holds its station"
    if state.frozen_by is not None:
        return f"the formation is frozen ({state.frozen_by})"
    if state.unavailable:
        index, why = next(iter(state.unavailable.items()))
        return f"UAV {index + 1} is not flying the formation ({why})"
    return None


@dataclass
class BatteryWatch:
    """Which UAV on station its battery sends home: the first below `threshold_pct` (%) not
    yet acted on; each UAV is acted on once, relieved or refused."""

    threshold_pct: float | None
    noted: set[int] = field(default_factory=set)

    def due(self, levels: list[float | None], relieved: frozenset[int]) -> int | None:
        """The UAV (0-based) to relieve for its battery now, marked acted on; None: none."""
        if self.threshold_pct is None:
            return None
        for index, level in enumerate(levels):
            if level is None or level >= self.threshold_pct or index in self.noted:
                continue
            if index in relieved:
                continue
            self.noted.add(index)
            return index
        return None


def lands_now(
    t: float, home_s: float, slot_offset_m: float, tolerance_m: float, settle_s: float
) -> bool:
    """The relieved UAV is told to land: past its planned arrival home and above its slot
    (within `tolerance_m`), or `settle_s` after the arrival wherever it is."""
    return t >= home_s and (slot_offset_m <= tolerance_m or t >= home_s + settle_s)
