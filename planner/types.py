"""The planner's value types: the problem it is given (`PathProblem`) and its answer
(`PathPlan`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.formation import ParkingRows, parking_rows
from planner.obstacles import Obstacles
from planner.validity import PathViolations

__all__ = ["METHODS", "PathPlan", "PathProblem", "within_gap"]

METHODS = ("exact", "penalty")


def within_gap(length: float, lower_bound: float, gap_tolerance: float) -> bool:
    """Whether a path of `length` with a proven `lower_bound` on the shortest valid path is
    proven within the relative `gap_tolerance` (never with a tolerance of 0)."""
    return gap_tolerance > 0.0 and length - lower_bound <= gap_tolerance * length


@dataclass(frozen=True, eq=False)
class PathProblem:
    """A planning problem: A, B, parking angles theta_A, theta_B (degrees, counter-clockwise
    from A->B), rho_c, rho_R, obstacles, parking mode ("segment" or the paper's "ray"), fleet
    size (None = the minimum of eq. 28, grown with the path), method and caps.

    `gap_tolerance` (relative, >= 0) ends the certification once the path is proven at most
    that fraction longer than the shortest valid path (a proven lower bound within it); 0
    certifies exactly.

    A leg of a route (`planner.route`) sets `start_tail`, the polyline flown before it from
    its start back to A and along Delta_A, which replaces the start row (theta_A must then be
    the direction of its first piece), and `open_goal` (no row beyond B, no arrival angle)."""

    start: np.ndarray
    goal: np.ndarray
    start_angle_deg: float
    goal_angle_deg: float
    safety_margin: float
    radio_range: float
    obstacles: Obstacles
    parking: str = "segment"
    fleet_size: int | None = None
    method: str = "exact"
    max_expansions: int = 2_000_000
    max_penalty_iterations: int = 50
    gap_tolerance: float = 0.0
    start_tail: np.ndarray | None = None
    open_goal: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", np.asarray(self.start, float).reshape(2))
        object.__setattr__(self, "goal", np.asarray(self.goal, float).reshape(2))
        if self.start_tail is not None:
            tail = np.asarray(self.start_tail, float).reshape(-1, 2)
            if len(tail) < 2 or np.any(np.abs(tail[0] - self.start) > 1e-6):
                raise ValueError("start_tail must be a polyline (M >= 2) beginning at the start")
            object.__setattr__(self, "start_tail", tail)
        if self.parking not in ("segment", "ray"):
            raise ValueError(f"parking must be 'segment' or 'ray', not {self.parking!r}")
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, not {self.method!r}")
        if not 0.0 <= self.gap_tolerance < 1.0:
            raise ValueError(f"gap_tolerance must be in [0, 1), not {self.gap_tolerance}")
        if self.fleet_size is not None and self.fleet_size < 1:
            raise ValueError(f"fleet_size must be >= 1, not {self.fleet_size}")

    def rows(self, fleet_size: int) -> ParkingRows:
        """The rows the path must respect for `fleet_size` UAVs (docs/design.md 3.2; a leg's start
        tail and open goal, docs/design.md 7)."""
        rows = parking_rows(
            self.start,
            self.goal,
            self.start_angle_deg,
            self.goal_angle_deg,
            fleet_size,
            self.safety_margin,
            self.parking,
        )
        if self.start_tail is None and not self.open_goal:
            return rows
        start_row = rows.start_row if self.start_tail is None else self.start_tail
        goal_row = np.array([self.goal, self.goal]) if self.open_goal else rows.goal_row
        return ParkingRows(
            start_row=start_row,
            goal_row=goal_row,
            start_direction=rows.start_direction,
            goal_direction=rows.goal_direction,
            open_goal=self.open_goal,
        )


@dataclass(frozen=True, eq=False)
class PathPlan:
    """The planner's answer. `reason` (one sentence) says why when `valid` is False; `path`
    is then empty. `rows` are the parking rows for `fleet_size`. `iterations` counts search
    rounds of the final graph (1 = the first walk was valid, 2 = the repair search ran;
    penalty method: rounds of the loop); `level` names that graph ("taut", "full" or
    "penalty"); `repairs` counts repaired walks. `certified` is True when the length is
    proven minimal over the full graph of definition 5 (exact method; False when a check was
    skipped on a large map or the repair search hit its label limit). `node_count` counts
    graph nodes, `edges_examined` the node pairs considered, `edge_count` the edges found
    valid against the obstacles (`candidate_edges`, for plots), `expansions` the states taken
    off the queues; `fleet_rounds` the fleet sizes tried. `lower_bound_m` is a proven lower
    bound on the shortest valid path (equal to `length_m` when certified; at least the
    straight line A-B); `stopped` says the caller's progress callback stopped the search (the
    path is then the best found so far); `gap_tolerance` is the problem's (a path proven
    within it of the shortest ends the certification, not certified)."""

    valid: bool
    reason: str | None
    path: np.ndarray
    length_m: float
    fleet_size: int
    min_fleet_size: int
    rows: ParkingRows
    iterations: int
    expansions: int
    node_count: int
    edges_examined: int
    candidate_edges: np.ndarray
    violations: PathViolations | None = None
    certified: bool = False
    level: str = ""
    repairs: int = 0
    fleet_rounds: int = 1
    edge_count: int = 0
    lower_bound_m: float = math.nan
    stopped: bool = False
    gap_tolerance: float = 0.0

    @property
    def within_gap(self) -> bool:
        """Not certified, but proven within `gap_tolerance` of the shortest (`within_gap`)."""
        return within_gap(self.length_m, self.lower_bound_m, self.gap_tolerance)
