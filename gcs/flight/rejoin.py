"""The link policy: a UAV lost freezes the formation; it moves again only when every such UAV
has rejoined its target, else everyone lands.

A UAV is *unavailable* while its link is lost or it flies its own failsafe (the core's
`_unavailable`: UAV index -> why). Each tick:

* a UAV that holds (its autopilot's own hold) and whose link is back goes back to guided flight
  and starts rejoining; so does every unavailable UAV;
* the first unavailable UAV freezes the formation (speed 0 at the earliest effective time):
  with an operator (the live view) the operator decides what follows (a speed, or `land`);
  without one a deadline of `link_wait_s` starts;
* without an operator, a UAV that lands by itself lands everyone; the formation resumes once no
  UAV is unavailable and every rejoining UAV has flown guided within its tracking allowance of its target
  for `settle_s` (two heartbeats: a mode its autopilot took while cut off is known before the
  formation moves again); at the deadline, any UAV still lost or not back lands everyone.

This module decides (`RejoinPolicy.decide`, pure, on mission time); `gcs.flight.core` applies
its `RejoinDecision` (drivers, freeze, events, landing) in the order the fields are listed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

#: A UAV whose link came back rejoins the formation only after this long (mission s) in
#: guided flight within its tracking allowance: two heartbeats, so a mode its autopilot took
#: while cut off (BRAKE, its own failsafe) is known before the formation moves again. (With
#: none, a formation resumed at the link's return, 0.8 s before that UAV's BRAKE was read,
#: and left it 5.1 m behind.)
REJOIN_SETTLE_S = 2.0


@dataclass(frozen=True)
class RejoinDecision:
    """What the core does this tick, in this order: take `guided` (UAV indices holding with
    their link back) back to guided flight; freeze the formation for the link (`freeze`);
    tell the operator (`ask_operator`); land everyone (`land`: the reason) or resume the
    formation (`resume`)."""

    guided: tuple[int, ...] = ()
    freeze: bool = False
    ask_operator: bool = False
    land: str | None = None
    resume: bool = False


@dataclass
class RejoinPolicy:
    """The link policy's state: who is rejoining, since when each has been back within its
    tolerance, and the deadline (mission s) to be back by, without an operator."""

    link_wait_s: float
    interactive: bool
    settle_s: float = REJOIN_SETTLE_S
    rejoining: set[int] = field(default_factory=set)
    rejoined_since: dict[int, float] = field(default_factory=dict)
    deadline: float | None = None

    def decide(
        self,
        t: float,
        unavailable: Mapping[int, str],
        holding: frozenset[int],
        landing: frozenset[int],
        tracking_now: np.ndarray,
        tolerance_m: float,
        frozen_by: str | None,
    ) -> RejoinDecision:
        """One tick: `unavailable` UAV index -> why; `holding` the UAVs in their autopilot's
        hold whose link is back; `landing` the UAVs landing by themselves; `tracking_now` each
        UAV's tracking error (m), back when within `tolerance_m`; `frozen_by` the cause the
        formation is frozen for, if any."""
        guided = tuple(i for i in unavailable if i in holding)
        self.rejoining.update(unavailable)
        freeze = bool(unavailable) and frozen_by != "link"
        ask = freeze and self.interactive
        if freeze and not self.interactive:
            self.deadline = t + self.link_wait_s
        if not (freeze or frozen_by == "link") or self.interactive:
            self.rejoining.clear()  # the operator decided
            self.rejoined_since.clear()
            return RejoinDecision(guided, freeze, ask)
        landed = [i for i in unavailable if i in landing]
        if landed:
            return RejoinDecision(
                guided, freeze, ask, land=f"UAV {landed[0] + 1} {unavailable[landed[0]]}"
            )
        for i in self.rejoining:
            if i in unavailable or not tracking_now[i] <= tolerance_m:
                self.rejoined_since.pop(i, None)
            else:
                self.rejoined_since.setdefault(i, t)
        away = [
            i for i in self.rejoining if t - self.rejoined_since.get(i, math.inf) < self.settle_s
        ]
        if not unavailable and not away:
            self.rejoining.clear()
            self.rejoined_since.clear()
            self.deadline = None
            return RejoinDecision(guided, freeze, ask, resume=True)
        if self.deadline is not None and t >= self.deadline:
            gone = sorted(set(unavailable) | set(away))
            names = ", ".join(str(i + 1) for i in gone)
            why = unavailable.get(gone[0], "not back within its margin")
            return RejoinDecision(
                guided, freeze, ask, land=f"UAV {names}: {why} for {self.link_wait_s:g} s"
            )
        return RejoinDecision(guided, freeze, ask)

    def operator_decided(self) -> None:
        """An operator's speed change took the formation over: no deadline any more."""
        self.deadline = None
