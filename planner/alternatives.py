"""What would be accepted instead of refused parking rows (eqs. 14-15) or a refused A or B.

Numbers in, numbers out (no files, no clock). For a `PathProblem` that `precheck_issue`
refuses for its rows, `suggest` finds the nearest accepted theta_A (theta_B kept), the nearest
accepted theta_B (theta_A kept) and, when neither alone is accepted, the nearest accepted pair;
with a radius, also the nearest start point (or goal point, when B is refused) whose margin and
rows are accepted. Rows are sized for the fleet size the refusal was made for (docs/design.md 3.2).

The angle search goes outward from the requested angle both ways, 1 degree at a time over
the whole turn (every candidate row built and tested at once against the obstacles' STRtree),
then every 0.1 degree no farther out than the nearest whole degree found: the answer is the
accepted angle of least |delta| on the 0.1-degree grid (ties go counter-clockwise), unless
the accepted angles fit between two whole degrees. The chosen answer is confirmed with
`precheck_issue` itself, so a suggestion is never one the planner would refuse.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely

from planner.formation import DISTANCE_TOLERANCE, min_fleet_size, parking_rows
from planner.validity import Refusal, precheck_issue

if TYPE_CHECKING:
    from planner.types import PathProblem

__all__ = [
    "AngleSuggestion",
    "PointSuggestion",
    "Suggestions",
    "suggest",
]

#: Steps of the outward angle search (coarse, then fine), degrees.
COARSE_STEP_DEG = 1.0
FINE_STEP_DEG = 0.1
#: How far either way the angle search turns, degrees.
SEARCH_SPAN_DEG = 180.0
#: Candidate start points: rings every RING_STEP_M metres, a point every RING_ANGLE_STEP_DEG.
RING_STEP_M = 1.0
RING_ANGLE_STEP_DEG = 10.0
#: Candidate points are snapped to this grid (m), so the printed point is the tested one.
POINT_GRID_M = 0.1

#: Refusal subjects this module can answer (planner.validity.Refusal).
ROW_SUBJECTS = ("start_row", "goal_row", "rows")
PLACEMENT_SUBJECTS = ("start", "goal")

_FINE_PER_DEG = round(1.0 / FINE_STEP_DEG)  # fine steps in a degree (angles are integers / 10)
_COARSE = round(COARSE_STEP_DEG * _FINE_PER_DEG)  # fine steps in a coarse step
_SPAN = round(SEARCH_SPAN_DEG * _FINE_PER_DEG)  # fine steps in the span
_CONFIRMATIONS = 32  # candidates confirmed with precheck_issue before giving up


@dataclass(frozen=True)
class AngleSuggestion:
    """An accepted parking angle: `which` is "theta_A" or "theta_B"; `angle_deg` the angle
    (counter-clockwise from A->B, in (-180, 180]); `delta_deg` its turn from the requested
    angle, in [-180, 180]."""

    which: str
    angle_deg: float
    delta_deg: float

    def as_json(self) -> dict[str, Any]:
        return {"which": self.which, "angle_deg": self.angle_deg, "delta_deg": self.delta_deg}


@dataclass(frozen=True)
class PointSuggestion:
    """An accepted A (`which` "start") or B ("goal") at (x, y), `distance_m` from the requested
    one, with the rows at the requested angles."""

    which: str
    x: float
    y: float
    distance_m: float

    def as_json(self) -> dict[str, Any]:
        return {
            "which": self.which,
            "x": self.x,
            "y": self.y,
            "distance_m": self.distance_m,
        }


@dataclass(frozen=True)
class Suggestions:
    """What `suggest` found for `refusal` (None when nothing was refused; angles answer the
    row refusals, points also A or B in a margin) with rows for `fleet_size` UAVs.

    `angles`: the nearest accepted theta_A alone and theta_B alone (either may be missing);
    `pair`: the nearest accepted (theta_A, theta_B) when neither alone is accepted, nearest
    by |delta_A| + |delta_B|; `points`: the nearest accepted point within `near_m` (empty
    when none, or no radius was given). `span_deg` is how far either way angles were tried.
    """

    refusal: Refusal | None
    fleet_size: int
    angles: tuple[AngleSuggestion, ...] = ()
    pair: tuple[AngleSuggestion, AngleSuggestion] | None = None
    points: tuple[PointSuggestion, ...] = ()
    near_m: float | None = None
    span_deg: float = SEARCH_SPAN_DEG

    @property
    def found(self) -> bool:
        """True when anything accepted was found."""
        return bool(self.angles or self.pair or self.points)

    def as_json(self) -> list[dict[str, Any]]:
        """Angles (alone, then the pair's two, each with `"pair": true`) then points."""
        out = [a.as_json() for a in self.angles]
        out += [{**a.as_json(), "pair": True} for a in self.pair or ()]
        return out + [p.as_json() for p in self.points]

    def describe(self) -> str | None:
        """One clause for a refusal message: `accepted instead: theta_A = 35 deg (+35), or
        theta_B = -20 deg (-20), or start at (x, y), 6.2 m from A`, or what was searched in
        vain; None when nothing was refused or searched."""
        if self.refusal is None:
            return None
        parts = [
            f"{a.which} = {_deg(a.angle_deg)} deg ({_deg(a.delta_deg, '+')})" for a in self.angles
        ]
        if self.pair:
            a, b = self.pair
            parts.append(
                f"theta_A = {_deg(a.angle_deg)} deg ({_deg(a.delta_deg, '+')}) with "
                f"theta_B = {_deg(b.angle_deg)} deg ({_deg(b.delta_deg, '+')})"
            )
        for p in self.points:
            verb, name = ("start", "A") if p.which == "start" else ("end", "B")
            parts.append(f"{verb} at ({p.x:.1f}, {p.y:.1f}), {p.distance_m:.1f} m from {name}")
        if parts:
            return "accepted instead: " + ", or ".join(parts)
        missed = []
        if self.refusal.subject in ROW_SUBJECTS:
            missed.append(
                f"no theta_A, theta_B or pair of them within {self.span_deg:g} degrees of the "
                f"requested ones gives accepted rows for {self.fleet_size} UAVs"
            )
        if self.near_m:
            which = "goal" if self.refusal.subject == "goal" else "start"
            missed.append(
                f"no {which} point within {self.near_m:g} m does with the requested angles"
            )
        return "; ".join(missed) or None


def suggest(
    problem: PathProblem, fleet_size: int | None = None, near_m: float | None = None
) -> Suggestions:
    """The nearest accepted alternatives for `problem` as refused by `precheck_issue` with
    `fleet_size` UAVs (default: the size `precheck_issue` uses); start points (goal points
    when B is refused) within `near_m` metres when given."""
    size = _fleet_size(problem, fleet_size)
    refusal = precheck_issue(problem, size)
    empty = Suggestions(refusal, size, near_m=near_m)
    placement = refusal is not None and refusal.subject in PLACEMENT_SUBJECTS
    if refusal is None or not (refusal.subject in ROW_SUBJECTS or placement):
        return empty
    if placement and refusal.obstacle is None:  # A equal to B: no point to suggest
        return empty
    angles: tuple[AngleSuggestion, ...] = ()
    pair = None
    if refusal.subject in ROW_SUBJECTS:
        angles, pair = _AngleSearch(problem, size).run()
    points: tuple[PointSuggestion, ...] = ()
    if near_m is not None and near_m > 0:
        which = "goal" if refusal.subject == "goal" else "start"
        point = _nearest_point(problem, size, which, float(near_m))
        points = (point,) if point else ()
    return replace(empty, angles=angles, pair=pair, points=points)


# --- angles ------------------------------------------------------------------------------------


class _AngleSearch:
    """Row tests on a grid of angle offsets (integers in tenths of a degree, within the
    span), cached per row and offset."""

    def __init__(self, problem: PathProblem, size: int) -> None:
        self.problem = problem
        self.size = size
        self.length = _row_length(problem, size)
        ab = problem.goal - problem.start
        self.heading = math.atan2(ab[1], ab[0])
        self.clear: dict[str, dict[int, bool]] = {"A": {}, "B": {}}

    def run(self) -> tuple[tuple[AngleSuggestion, ...], tuple | None]:
        singles = tuple(s for s in (self.single("A"), self.single("B")) if s is not None)
        return singles, (None if singles else self.pair())

    # rows at offsets (tenths of a degree) from the requested angles
    def rows(self, which: str, offsets: np.ndarray) -> np.ndarray:
        base = self.problem.start_angle_deg if which == "A" else self.problem.goal_angle_deg
        theta = self.heading + np.radians(base + offsets / _FINE_PER_DEG)
        u = np.column_stack([np.cos(theta), np.sin(theta)])
        if which == "A":
            root, tip = self.problem.start, self.problem.start - self.length * u
        else:
            root, tip = self.problem.goal, self.problem.goal + self.length * u
        return np.stack([np.broadcast_to(root, tip.shape), tip], axis=1)

    def clear_of_obstacles(self, which: str, offsets: np.ndarray) -> np.ndarray:
        """Eq. 14 for the row `which` at each offset (cached)."""
        cache = self.clear[which]
        todo = np.array([o for o in np.unique(offsets) if int(o) not in cache], dtype=np.int64)
        if len(todo):
            ok = _rows_clear(self.problem, self.rows(which, todo))
            cache.update(zip(todo.tolist(), ok.tolist(), strict=True))
        return np.array([cache[int(o)] for o in offsets], dtype=bool)

    def apart(self, off_a: np.ndarray, off_b: np.ndarray) -> np.ndarray:
        """Eq. 15 for each pair of offsets (equal-length arrays)."""
        rows_a, rows_b = self.rows("A", off_a), self.rows("B", off_b)
        gap = _segment_distance(rows_a[:, 0], rows_a[:, 1], rows_b[:, 0], rows_b[:, 1])
        return gap >= 2.0 * self.problem.safety_margin - DISTANCE_TOLERANCE

    def accepted(self, off_a: np.ndarray, off_b: np.ndarray) -> np.ndarray:
        ok = self.clear_of_obstacles("A", off_a)
        ok[ok] = self.clear_of_obstacles("B", off_b[ok])
        ok[ok] = self.apart(off_a[ok], off_b[ok])
        return ok

    def single(self, which: str) -> AngleSuggestion | None:
        """The nearest accepted angle for one row, the other kept: the nearest on the
        1-degree grid, then every 0.1 degree no farther out (exact on the 0.1-degree grid
        unless no whole degree is accepted at all)."""
        other = "B" if which == "A" else "A"
        if not self.clear_of_obstacles(other, np.zeros(1, np.int64))[0]:
            return None  # the other row is refused as it is
        found = self._first(which, _outward(_SPAN, _COARSE))
        if found is None:
            return None
        fine = _outward(abs(found), 1)
        best = self._first(which, fine, confirm=True)
        if best is None:  # the confirmation disagreed: try the rest
            best = self._first(which, _outward(_SPAN, 1)[len(fine) :], confirm=True)
        return None if best is None else self._suggestion(which, best)

    def _first(self, which: str, offsets: np.ndarray, confirm: bool = False) -> int | None:
        zeros = np.zeros_like(offsets)
        pairs = (offsets, zeros) if which == "A" else (zeros, offsets)
        hits = offsets[self.accepted(*pairs)]
        if not confirm:
            return int(hits[0]) if len(hits) else None
        for offset in hits[:_CONFIRMATIONS]:
            pair = (int(offset), 0) if which == "A" else (0, int(offset))
            if self.confirmed(*pair):
                return int(offset)
        return None

    def pair(self) -> tuple[AngleSuggestion, AngleSuggestion] | None:
        """The nearest accepted pair by |delta_A| + |delta_B|: on the 1-degree grid, then on
        the 0.1-degree grid at costs from 2 degrees below the coarse one to 2 above."""
        coarse = _outward(_SPAN, _COARSE)
        ok_a = coarse[self.clear_of_obstacles("A", coarse)]
        ok_b = coarse[self.clear_of_obstacles("B", coarse)]
        if not len(ok_a) or not len(ok_b):
            return None
        grid_a, grid_b = (g.ravel() for g in np.meshgrid(ok_a, ok_b, indexing="ij"))
        good = self.apart(grid_a, grid_b)
        if not good.any():
            return None
        cost = np.abs(grid_a[good]) + np.abs(grid_b[good])
        top = int(cost.min())
        for low, high in ((max(0, top - 2 * _COARSE), top), (top + 1, top + 2 * _COARSE)):
            found = self._pair_between(low, high)
            if found is not None:
                return self._suggestion("A", found[0]), self._suggestion("B", found[1])
        return None

    def _pair_between(self, low: int, high: int) -> tuple[int, int] | None:
        """The accepted pair of least cost in [low, high] (fine steps), confirmed."""
        for cost in range(low, high + 1):
            off_a = np.arange(-cost, cost + 1)
            off_a = off_a[np.abs(off_a) <= _SPAN]
            rest = cost - np.abs(off_a)
            off_a = np.concatenate([off_a, off_a[rest > 0]])
            off_b = np.concatenate([rest, -rest[rest > 0]])
            keep = (np.abs(off_b) <= _SPAN) & (off_a > -_SPAN) & (off_b > -_SPAN)
            off_a, off_b = off_a[keep], off_b[keep]
            if not len(off_a):
                continue
            order = np.lexsort((-off_b, -off_a, np.abs(off_a) + np.abs(off_b)))
            off_a, off_b = off_a[order], off_b[order]
            ok = self.accepted(off_a, off_b)
            for a, b in list(zip(off_a[ok], off_b[ok], strict=True))[:_CONFIRMATIONS]:
                if self.confirmed(int(a), int(b)):
                    return int(a), int(b)
        return None

    def confirmed(self, off_a: int, off_b: int) -> bool:
        """The planner's own check (precheck_issue) at these offsets."""
        p = self.problem
        moved = replace(
            p,
            start_angle_deg=p.start_angle_deg + off_a / _FINE_PER_DEG,
            goal_angle_deg=p.goal_angle_deg + off_b / _FINE_PER_DEG,
        )
        return precheck_issue(moved, self.size) is None

    def _suggestion(self, which: str, offset: int) -> AngleSuggestion:
        base = self.problem.start_angle_deg if which == "A" else self.problem.goal_angle_deg
        return AngleSuggestion(
            which=f"theta_{which}",
            angle_deg=_wrap(base + offset / _FINE_PER_DEG),
            delta_deg=offset / _FINE_PER_DEG,
        )


def _outward(bound: int, step: int) -> np.ndarray:
    """Offsets 0, +s, -s, +2s, -2s, ... with |offset| <= bound and offset > -SPAN (a full
    turn either way is the same angle)."""
    k = np.arange(0, bound // step + 1) * step
    out = np.column_stack([k, -k]).ravel()[1:]
    return out[out > -_SPAN]


def _deg(value: float, sign: str = "") -> str:
    """Degrees with the digits the search used (no trailing zeros), e.g. `35`, `-20.5`."""
    return f"{value:{sign}.6f}".rstrip("0").rstrip(".")


def _wrap(angle_deg: float) -> float:
    """An angle in (-180, 180], rounded to the fine grid's precision (no -0.0)."""
    wrapped = -((-angle_deg + 180.0) % 360.0 - 180.0)
    return round(wrapped, 9) + 0.0


# --- points ------------------------------------------------------------------------------------


def _nearest_point(
    problem: PathProblem,
    size: int,
    which: str,
    radius: float,
) -> PointSuggestion | None:
    """The nearest point within `radius` of A (or B) whose margin and rows at the requested
    angles are accepted (the rows turn with the direction A->B); candidates on rings every
    RING_STEP_M, RING_ANGLE_STEP_DEG apart, snapped to POINT_GRID_M. (A suggested angle is
    accepted at A itself, so a moved point is only worth naming with the requested angles.)"""
    origin = problem.start if which == "start" else problem.goal
    other = problem.goal if which == "start" else problem.start
    rho = problem.safety_margin
    radii = np.arange(RING_STEP_M, radius + 1e-9, RING_STEP_M)
    if not len(radii):
        radii = np.array([radius])
    turns = np.radians(np.arange(0.0, 360.0, RING_ANGLE_STEP_DEG))
    ring = np.column_stack([np.cos(turns), np.sin(turns)])
    points = origin + (radii[:, None, None] * ring[None]).reshape(-1, 2)
    points = np.round(points / POINT_GRID_M) * POINT_GRID_M
    dist = np.hypot(*(points - origin).T)
    order = np.argsort(dist, kind="stable")
    points, dist = points[order], dist[order]
    keep = (dist <= radius + 1e-9) & (dist > 0.0)
    keep &= np.hypot(*(points - other).T) > DISTANCE_TOLERANCE
    keep &= problem.obstacles.distance_to_points(points) >= rho - DISTANCE_TOLERANCE
    points, dist = points[keep], dist[keep]
    if not len(points):
        return None
    length = _row_length(problem, size)
    starts = points if which == "start" else np.broadcast_to(problem.start, points.shape)
    goals = points if which == "goal" else np.broadcast_to(problem.goal, points.shape)
    heading = np.arctan2(*(goals - starts).T[::-1])
    theta_a, theta_b = problem.start_angle_deg, problem.goal_angle_deg
    row_a = np.stack([starts, starts - length * _units(heading + math.radians(theta_a))], 1)
    row_b = np.stack([goals, goals + length * _units(heading + math.radians(theta_b))], 1)
    ok = _rows_clear(problem, row_a) & _rows_clear(problem, row_b)
    gap = _segment_distance(row_a[:, 0], row_a[:, 1], row_b[:, 0], row_b[:, 1])
    ok &= gap >= 2.0 * rho - DISTANCE_TOLERANCE
    for k in np.flatnonzero(ok)[:_CONFIRMATIONS]:
        moved = replace(
            problem,
            start=points[k] if which == "start" else problem.start,
            goal=points[k] if which == "goal" else problem.goal,
        )
        if precheck_issue(moved, size) is None:
            x, y = (round(float(v), 6) + 0.0 for v in points[k])
            return PointSuggestion(which, x, y, float(dist[k]))
    return None


# --- geometry ----------------------------------------------------------------------------------


def _fleet_size(problem: PathProblem, fleet_size: int | None) -> int:
    """The N `precheck_issue` sizes the rows for."""
    if fleet_size:
        return int(fleet_size)
    if problem.fleet_size:
        return int(problem.fleet_size)
    straight = float(np.hypot(*(problem.goal - problem.start)))
    try:
        return min_fleet_size(straight, problem.safety_margin, problem.radio_range)
    except ValueError:
        return 1


def _row_length(problem: PathProblem, size: int) -> float:
    """Length of either row for `size` UAVs (formation.parking_rows)."""
    rows = parking_rows(
        problem.start, problem.goal, 0.0, 0.0, size, problem.safety_margin, problem.parking
    )
    return float(np.hypot(*(rows.start_row[1] - rows.start_row[0])))


def _units(angle: np.ndarray) -> np.ndarray:
    return np.column_stack([np.cos(angle), np.sin(angle)])


def _rows_clear(problem: PathProblem, rows: np.ndarray) -> np.ndarray:
    """Eq. 14 for each row (n, 2, 2), from its root rows[:, 0]: no obstacle within rho_c.

    One vectorised STRtree dwithin query. A long row's envelope covers much of the map, so
    each row is first cut where it leaves the obstacles' bounding box (grown by rho_c) and
    then into pieces about as long as a few obstacles are apart; `confirmed` then asks the
    planner's own nearest-distance test."""
    clear = np.ones(len(rows), bool)
    obstacles = problem.obstacles
    if len(obstacles) == 0 or len(rows) == 0:
        return clear
    limit = problem.safety_margin - DISTANCE_TOLERANCE
    x0, y0, x1, y1 = shapely.total_bounds(obstacles.geometries)
    root, tip = rows[:, 0], rows[:, 1]
    length = np.hypot(*(tip - root).T)
    corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]])
    reach = np.hypot(*(corners[None] - root[:, None]).transpose(2, 0, 1)).max(axis=1)
    cut = np.minimum(length, reach + problem.safety_margin + 1.0)
    spacing = math.sqrt(max((x1 - x0) * (y1 - y0), 1.0) / len(obstacles))
    piece = max(2.5 * spacing, 4.0 * problem.safety_margin)
    count = np.maximum(1, np.ceil(cut / piece)).astype(np.int64)
    step = cut / count
    direction = (tip - root) / np.where(length > 0, length, 1.0)[:, None]
    # Pieces nearest the roots first, then twice as many, ...: most blocked rows are
    # blocked near their roots and drop out before their far pieces are built.
    done = 0
    window = 2
    while True:
        rows_left = np.flatnonzero(clear & (count > done))
        if not len(rows_left):
            return clear
        take = np.minimum(count[rows_left] - done, window)
        owner = np.repeat(rows_left, take)
        first = np.concatenate([[0], np.cumsum(take)[:-1]])
        index = done + np.arange(len(owner)) - np.repeat(first, take)
        near = root[owner] + (index * step[owner])[:, None] * direction[owner]
        far = root[owner] + ((index + 1) * step[owner])[:, None] * direction[owner]
        pieces = shapely.linestrings(np.stack([near, far], axis=1))
        hit, _ = obstacles.tree.query(pieces, predicate="dwithin", distance=limit)
        clear[owner[hit]] = False
        done += window
        window *= 2


def _segment_distance(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray):
    """Distance between segments a0a1 and b0b1, row by row ((n, 2) arrays); 0 when they cross."""

    def to_segment(p, s0, s1):
        d = s1 - s0
        dd = np.einsum("ij,ij->i", d, d)
        t = np.einsum("ij,ij->i", p - s0, d) / np.where(dd > 0, dd, 1.0)
        t = np.clip(t, 0.0, 1.0)
        return np.hypot(*(p - (s0 + t[:, None] * d)).T)

    def orient(p, q, r):
        return np.sign(
            (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])
        )

    dist = np.minimum.reduce(
        [
            to_segment(a0, b0, b1),
            to_segment(a1, b0, b1),
            to_segment(b0, a0, a1),
            to_segment(b1, a0, a1),
        ]
    )
    crossing = (orient(a0, a1, b0) * orient(a0, a1, b1) < 0) & (
        orient(b0, b1, a0) * orient(b0, b1, a1) < 0
    )
    return np.where(crossing, 0.0, dist)
