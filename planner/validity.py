"""Definition 4 (valid path, conditions (1)-(5), eqs. 34-38) and the row conditions (eqs. 14-15).

Every comparison carries the explicit tolerances of docs/design.md 3.2: distances may fall short by
`DISTANCE_TOLERANCE` (1e-6 m), angles may exceed 90 degrees by `ANGLE_TOLERANCE` (1e-9 rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import shapely

from planner.formation import (
    ANGLE_TOLERANCE,
    DISTANCE_TOLERANCE,
    ParkingRows,
    min_fleet_size,
    min_radio_range,
)
from planner.numbers import fmt_against

if TYPE_CHECKING:
    from planner.types import PathProblem


def _empty(cols: int) -> np.ndarray:
    return np.zeros((0, cols))


@dataclass(frozen=True, eq=False)
class PathViolations:
    """What a path breaks in definition 4, condition by condition; `ok` when nothing.

    Rows of the arrays: `obstacle` [segment k, obstacle index, distance] (1);
    `start_row`/`goal_row` [segment k, distance] (2); `bends` [vertex k, bend degrees] (4);
    `proximity` [segment k, segment k', distance] for |k - k'| > 1 (5). Segments and vertices
    are 0-based (segment k joins path[k] and path[k+1]). `structure` lists breaches of
    definition 1 (ends not at A and B, repeated points, fewer than two points).
    `safety_margin` (rho_c) is the limit the distances broke: `describe` prints them with the
    digits that tell them from it.
    """

    structure: tuple[str, ...] = ()
    obstacle: np.ndarray = field(default_factory=lambda: _empty(3))
    start_row: np.ndarray = field(default_factory=lambda: _empty(2))
    goal_row: np.ndarray = field(default_factory=lambda: _empty(2))
    departure_angle_deg: float | None = None  # set when (3) fails at A
    arrival_angle_deg: float | None = None  # set when (3) fails at B
    bends: np.ndarray = field(default_factory=lambda: _empty(2))
    proximity: np.ndarray = field(default_factory=lambda: _empty(3))
    safety_margin: float = math.nan

    @property
    def ok(self) -> bool:
        return not (
            self.structure
            or len(self.obstacle)
            or len(self.start_row)
            or len(self.goal_row)
            or self.departure_angle_deg is not None
            or self.arrival_angle_deg is not None
            or len(self.bends)
            or len(self.proximity)
        )

    def describe(self) -> str | None:
        """One sentence naming the first breach, or None when the path is valid."""
        rho = self.safety_margin
        if self.structure:
            return self.structure[0]
        if len(self.obstacle):
            k, i, d = self.obstacle[0]
            return (
                f"segment {int(k)} passes {fmt_against(d, rho)} m from obstacle {int(i)} "
                "(condition 1)"
            )
        if len(self.start_row):
            k, d = self.start_row[0]
            return (
                f"segment {int(k)} passes {fmt_against(d, 2 * rho)} m from the parking row at A "
                "(condition 2)"
            )
        if len(self.goal_row):
            k, d = self.goal_row[0]
            return (
                f"segment {int(k)} passes {fmt_against(d, 2 * rho)} m from the parking row at B "
                "(condition 2)"
            )
        if self.departure_angle_deg is not None:
            return (
                f"the first segment turns {fmt_against(self.departure_angle_deg, 90, 4)} degrees "
                "from the start row direction (condition 3)"
            )
        if self.arrival_angle_deg is not None:
            return (
                f"the last segment turns {fmt_against(self.arrival_angle_deg, 90, 4)} degrees "
                "from the goal row direction (condition 3)"
            )
        if len(self.bends):
            k, a = self.bends[0]
            return f"the path bends {fmt_against(a, 90, 4)} degrees at point {int(k)} (condition 4)"
        if len(self.proximity):
            k, j, d = self.proximity[0]
            return (
                f"segments {int(k)} and {int(j)} come {fmt_against(d, 2 * rho)} m apart "
                "(condition 5)"
            )
        return None


def _angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unsigned angle (radians) between rows of a and b."""
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    dot = np.sum(a * b, axis=-1)
    return np.arctan2(np.abs(cross), dot)


def check_path(path: np.ndarray, problem: PathProblem, rows: ParkingRows) -> PathViolations:
    """Conditions (1)-(5) of definition 4 (eqs. 34-38) for `path` (K, 2), A..B, with the
    docs/design.md 3.2 erratum on (2) (the Delta_A test skips the first segment, Delta_B the
    last)."""
    path = np.asarray(path, float).reshape(-1, 2)
    rho = problem.safety_margin
    structure: list[str] = []
    if len(path) < 2:
        return PathViolations(structure=("a path needs at least two points, A and B",))
    if np.any(np.abs(path[0] - problem.start) > DISTANCE_TOLERANCE):
        structure.append("the path does not start at A")
    if np.any(np.abs(path[-1] - problem.goal) > DISTANCE_TOLERANCE):
        structure.append("the path does not end at B")
    repeated = _repeated_points(path)
    if len(repeated):
        structure.append(
            f"point {int(repeated[0, 1])} repeats point {int(repeated[0, 0])} (definition 1)"
        )
    segs = np.stack([path[:-1], path[1:]], axis=1)
    vec = segs[:, 1] - segs[:, 0]
    if np.any(np.hypot(vec[:, 0], vec[:, 1]) <= DISTANCE_TOLERANCE):
        return PathViolations(structure=tuple(structure) or ("the path has a zero-length segment",))
    lines = shapely.linestrings(segs)
    count = len(segs)

    # (1) eq. 34: every segment at least rho_c from every obstacle (solids are solid).
    # (Nearest-distance queries: GEOS's dwithin predicate skips degenerate obstacles.)
    obstacle = _empty(3)
    obstacles = problem.obstacles
    if len(obstacles):
        (seg_i, obs_i), dist = obstacles.tree.query_nearest(
            lines, return_distance=True, all_matches=False
        )
        close = dist < rho - DISTANCE_TOLERANCE
        obstacle = np.column_stack([seg_i[close], obs_i[close], dist[close]]).astype(float)

    # (2) eq. 35 with the erratum.
    limit = 2.0 * rho - DISTANCE_TOLERANCE
    # A leg's start row is the route behind it: its first segment keeps 2 rho_c from the
    # tail beyond the previous segment (condition 5 across legs, docs/design.md 7).
    start_row = _row_breaches(lines, shapely.LineString(rows.start_row), limit, range(1, count))
    if rows.start_rest is not None:
        first = _row_breaches(lines, shapely.LineString(rows.start_rest), limit, range(1))
        start_row = np.concatenate([first, start_row])
    goal_row = _empty(2)
    if not rows.open_goal:
        goal_row = _row_breaches(lines, shapely.LineString(rows.goal_row), limit, range(count - 1))

    # (3) eq. 36: first and last segments within 90 degrees of the parking directions.
    right = math.pi / 2.0 + ANGLE_TOLERANCE
    departure = float(_angle_between(vec[0], rows.start_direction))
    arrival = 0.0 if rows.open_goal else float(_angle_between(vec[-1], rows.goal_direction))

    # (4) eq. 37: every bend at most 90 degrees.
    bend = _angle_between(vec[:-1], vec[1:])
    sharp = np.flatnonzero(bend > right)
    bends = np.column_stack([sharp + 1, np.degrees(bend[sharp])]).astype(float)

    # (5) eq. 38: non-consecutive segments at least 2 rho_c apart.
    i, j = np.triu_indices(count, k=2)
    dist = shapely.distance(lines[i], lines[j])
    close = dist < limit
    proximity = np.column_stack([i[close], j[close], dist[close]]).astype(float)

    return PathViolations(
        structure=tuple(structure),
        obstacle=obstacle,
        start_row=start_row,
        goal_row=goal_row,
        departure_angle_deg=math.degrees(departure) if departure > right else None,
        arrival_angle_deg=math.degrees(arrival) if arrival > right else None,
        bends=bends,
        proximity=proximity,
        safety_margin=rho,
    )


def _repeated_points(path: np.ndarray) -> np.ndarray:
    """Pairs [k, k'] (k < k') of points closer than the tolerance (definition 1)."""
    tree = shapely.STRtree(shapely.points(path))
    i, j = tree.query(shapely.points(path), predicate="dwithin", distance=DISTANCE_TOLERANCE)
    keep = i < j
    return np.column_stack([i[keep], j[keep]])


def _row_breaches(lines: np.ndarray, row: shapely.Geometry, limit: float, which) -> np.ndarray:
    idx = np.fromiter(which, np.int64)
    if len(idx) == 0:
        return _empty(2)
    dist = shapely.distance(lines[idx], row)
    bad = dist < limit
    return np.column_stack([idx[bad], dist[bad]]).astype(float)


@dataclass(frozen=True, eq=False)
class Refusal:
    """Why a problem cannot be planned, found before any search (`precheck_issue`).

    `subject` names the input at fault: "inputs" (not finite), "safety_margin",
    "radio_range" (eq. 9), "goal" (A equal to B, or B in an obstacle or its margin), "start",
    "start_row" / "goal_row" (eq. 14), "rows" (eq. 15). `obstacle` is the index into
    `Obstacles.geometries` involved (polygons first, then walls), `distance` the distance
    found (m), `message` one sentence.
    """

    subject: str
    message: str
    obstacle: int | None = None
    distance: float | None = None


def check_rows(problem: PathProblem, rows: ParkingRows) -> str | None:
    """Eqs. 14-15: each parking row at least rho_c from every obstacle, the two rows at least
    2 rho_c apart. Returns the reason (one sentence) or None."""
    refusal = row_refusal(problem, rows)
    return refusal.message if refusal else None


def row_refusal(problem: PathProblem, rows: ParkingRows) -> Refusal | None:
    """Eqs. 14-15 as a `Refusal` naming the row (and obstacle) at fault, or None."""
    rho = problem.safety_margin
    obstacles = problem.obstacles
    named = [("start_row", "behind A", rows.start_row)]
    if not rows.open_goal:
        named.append(("goal_row", "beyond B", rows.goal_row))
    for subject, where, row in named:
        if len(obstacles) == 0:
            break
        # (Nearest-distance query: GEOS's dwithin predicate skips degenerate obstacles.)
        (_, nearest), dist = obstacles.tree.query_nearest(
            shapely.linestrings(row[None]), return_distance=True, all_matches=False
        )
        if dist[0] < rho - DISTANCE_TOLERANCE:
            length = float(np.hypot(*(row[1] - row[0])))
            d = float(dist[0])
            message = (
                f"the parking row {where} ({length:.4g} m) comes {fmt_against(d, rho)} m from "
                f"obstacle {int(nearest[0])}; it must stay at least rho_c = "
                f"{fmt_against(rho, d, 6)} m away (eq. 14)"
            )
            return Refusal(subject, message, int(nearest[0]), float(dist[0]))
    if rows.open_goal:
        return None
    gap = float(
        shapely.distance(shapely.LineString(rows.start_row), shapely.LineString(rows.goal_row))
    )
    if gap < 2.0 * rho - DISTANCE_TOLERANCE:
        message = (
            f"the parking rows behind A and beyond B are {fmt_against(gap, 2 * rho)} m apart; "
            f"they must be at least 2 rho_c = {fmt_against(2 * rho, gap, 6)} m apart (eq. 15)"
        )
        return Refusal("rows", message, None, gap)
    return None


def _endpoint_refusal(problem: PathProblem, point: np.ndarray, subject: str) -> Refusal | None:
    """Why A or B cannot be used: inside a solid obstacle or within rho_c of one."""
    obstacles = problem.obstacles
    if len(obstacles) == 0:
        return None
    rho = problem.safety_margin
    (_, nearest), dist = obstacles.tree.query_nearest(
        shapely.points(point.reshape(1, 2)), return_distance=True, all_matches=False
    )
    dist, nearest = float(dist[0]), int(nearest[0])
    name = "A" if subject == "start" else "B"
    where = f"{name} ({point[0]:g}, {point[1]:g})"
    if dist <= 0.0 and obstacles.geometries[nearest].geom_type == "Polygon":
        return Refusal(subject, f"{where} lies inside obstacle {nearest}", nearest, dist)
    if dist < rho - DISTANCE_TOLERANCE:
        message = (
            f"{where} is {fmt_against(dist, rho)} m from obstacle {nearest}, inside its safety "
            f"margin rho_c = {fmt_against(rho, dist, 6)} m"
        )
        return Refusal(subject, message, nearest, dist)
    return None


def precheck_issue(problem: PathProblem, fleet_size: int | None = None) -> Refusal | None:
    """Why a problem cannot be planned before any search, or None: values not finite,
    rho_c <= 0, rho_R below eq. 9, A equal to B, A or B inside an obstacle or its margin,
    rows breaking eqs. 14-15 (for `fleet_size` UAVs; default the problem's, else the
    straight-line minimum of eq. 28)."""
    rho, radio = problem.safety_margin, problem.radio_range
    values = np.concatenate([problem.start, problem.goal, [rho, radio]])
    if not np.all(np.isfinite(values)):
        return Refusal("inputs", "A, B, rho_c and rho_R must be finite numbers")
    if rho <= 0:
        return Refusal("safety_margin", f"the safety margin rho_c must be > 0, got {rho:g}")
    needed = min_radio_range(rho)
    if radio < needed - DISTANCE_TOLERANCE:
        message = (
            f"the radio range rho_R = {fmt_against(radio, needed, 6)} m is below "
            f"2(1+sqrt 2) rho_c = {fmt_against(needed, radio, 4)} m (eq. 9)"
        )
        return Refusal("radio_range", message)
    straight = float(np.hypot(*(problem.goal - problem.start)))
    if straight <= DISTANCE_TOLERANCE:
        return Refusal("goal", "A and B coincide", None, straight)
    for point, subject in ((problem.start, "start"), (problem.goal, "goal")):
        refusal = _endpoint_refusal(problem, point, subject)
        if refusal:
            return refusal
    size = fleet_size or problem.fleet_size or min_fleet_size(straight, rho, radio)
    return row_refusal(problem, problem.rows(size))


def precheck(problem: PathProblem, fleet_size: int | None = None) -> str | None:
    """`precheck_issue` as one sentence (or None)."""
    refusal = precheck_issue(problem, fleet_size)
    return refusal.message if refusal else None
