"""Graph nodes (paper sec. IV-B1, eqs. 39-40; docs/design.md 3.1) and lazily built edges (def. 5;
docs/design.md 3.2).

Nodes: A, B; for each obstacle segment C_i D_i four points rho_c beyond each end along the
segment and rho_c to either side (eq. 39, with the erratum: the D rows use D_i); A+-, B+- at
rho_c sqrt(2) from A and B perpendicular to the parking rows (eq. 40). Nodes closer than the
distance tolerance are merged, nodes inside an obstacle's margin dropped.

Edges are never built for all node pairs. `EdgeCache` computes the out-edges of a node the
first time the search needs them, for the whole spatial tile around it at once, as arrays of
pairs: candidate targets (all, or on large maps a radius query completed per octant so open
areas are still crossed, plus B always), tangency (taut graph), collinear pruning, exact
angular-shadow culling by the obstacles nearest to either end (numpy), and only then the
exact clearance test through the prepared obstacle union (`Obstacles.segments_within`). Only
the obstacle part of definition 5 is cached; the parking-row part depends on the fleet size
and is applied by the search.

Two graphs share this code:
* the *full* graph of definition 5 (every node, every clear pair);
* the *taut* graph, used first: only nodes a shortest path can bend at (a node on the flat
  margin of its own obstacle's side cannot be a bend of a taut path), and only edges that are
  tangent at both ends to the mitre corner the node goes round (an edge into the corner's
  cone, or straight away from it, is never part of a locally shortest path). The search adds
  the matching transition rule (a bend wraps round the node's corner, `wraps_corner`).
Both drop an edge v->w that passes exactly through another candidate x of v: v->x then x->w
is the same line, with valid edges whenever v->w is valid (the returned path is simplified).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import shapely

from planner.formation import ANGLE_TOLERANCE, DISTANCE_TOLERANCE, SQRT2, row_direction
from planner.obstacles import ragged

if TYPE_CHECKING:
    from planner.obstacles import CoreGrid, Obstacles
    from planner.types import PathProblem

START = 0  #: index of A in `Nodes`
GOAL = 1  #: index of B in `Nodes`
KIND_START, KIND_GOAL, KIND_ROW, KIND_OBSTACLE = 0, 1, 2, 3

#: Candidate pairs per batch when out-edges are computed tile by tile.
_BATCH_PAIRS = 6000
#: Nearest obstacles of a source node whose angular shadows cull candidate targets.
_OCCLUDERS = 12
#: Footprints closer than this (m) merge into one occluder (`Obstacles.merged`): touching,
#: up to the rounding of coordinates. Merging all whose margins overlap hid more on a
#: synthetic terraced district (23 s instead of 38 s) but cost real districts 10-40 %: a
#: node in a merged block's concave bay loses that block as an occluder.
_TOUCHING = 1.0
#: Octant completion: each node gets at least this many candidate targets per octant.
_OCTANT_MIN = 2
#: ... and at most this many within the candidate radius (the nearest ones).
_OCTANT_MAX = 48
#: Complete candidate sets over more targets than this go through each node's sector reach
#: (`EdgeCache._visible_pairs`): its view cut into _SECTORS equal sectors, each seen only as
#: far as the nearest obstacle that spans it whole.
_SECTOR_REACH_TARGETS = 1500
_SECTORS = 32
#: ... for every member at once when a search has spread over this share of them.
_SPREAD = 1.0 / 16.0
#: Collinear pruning (`EdgeCache._drop_collinear`) stops after this many pairs if it
#: dropped less than this share of them.
COLLINEAR_TRIAL = 50_000
COLLINEAR_SHARE = 0.01


@dataclass(frozen=True, eq=False)
class Nodes:
    """Graph nodes (docs/design.md 3.1). Index 0 is A, 1 is B.

    `anchor` is the obstacle corner (segment end) a node goes round and `cone` the directions
    of the two mitre-rectangle edges that meet at the node (they span the obstacle side);
    `prunable` says a node has exactly one such corner, so the taut rules apply; `flat` marks a
    node on the margin of a side of its own obstacle (never a bend of a taut path).
    """

    points: np.ndarray  # (n, 2)
    kind: np.ndarray  # (n,) KIND_*
    anchor: np.ndarray  # (n, 2), nan when none
    cone: np.ndarray  # (n, 2, 2)
    prunable: np.ndarray  # (n,) bool
    flat: np.ndarray  # (n,) bool

    def __len__(self) -> int:
        return len(self.points)


def graph_nodes(problem: PathProblem) -> Nodes:
    """Nodes of sec. IV-B1: A, B, A+-, B+- (eq. 40), four per segment end (eq. 39), merged
    when closer than `DISTANCE_TOLERANCE`, dropped inside an obstacle's margin."""
    rho = problem.safety_margin
    obstacles = problem.obstacles
    start, goal = problem.start, problem.goal
    ab = math.atan2(*(goal - start)[::-1])
    offsets = np.radians(
        [
            problem.start_angle_deg - 90.0,  # A+
            problem.start_angle_deg + 90.0,  # A-
            problem.goal_angle_deg + 90.0,  # B+
            problem.goal_angle_deg - 90.0,  # B-
        ]
    )
    row_pts = np.array([start, start, goal, goal]) + rho * SQRT2 * np.column_stack(
        [np.cos(ab + offsets), np.sin(ab + offsets)]
    )
    if problem.start_tail is not None:
        # A leg's start (docs/design.md 7): the route behind it is a wall kept 2 rho_c away, so it
        # gets nodes as a segment end does (eq. 39 with 2 rho_c: beyond it at +-45 degrees)
        # and beside it (a turn of 90 degrees, so that a leg can turn back in open space).
        e0 = row_direction(start, goal, problem.start_angle_deg)
        normal = np.array([-e0[1], e0[0]])
        turns = 2.0 * rho * np.array([normal, -normal, e0 + normal, e0 - normal])
        row_pts = np.vstack([start + turns, row_pts[2:]])
    base_pts = np.vstack([start, goal, row_pts])
    base_kind = np.array([KIND_START, KIND_GOAL] + [KIND_ROW] * len(row_pts))
    base = len(base_pts)

    segs = obstacles.segments
    c, d = segs[:, 0], segs[:, 1]
    vec = d - c
    length = np.hypot(vec[:, 0], vec[:, 1])
    u = np.where(length[:, None] > DISTANCE_TOLERANCE, vec, [1.0, 0.0])
    u = u / np.hypot(u[:, 0], u[:, 1])[:, None]
    n = np.column_stack([u[:, 1], -u[:, 0]])  # right-hand normal
    pts, anchors, cones = [], [], []
    for side in (1.0, -1.0):  # eq. 39: C+-, D+- (D rows use D_i: docs/design.md 3.1 erratum)
        pts += [c - rho * u + side * rho * n, d + rho * u + side * rho * n]
        anchors += [c, d]
        cones += [np.stack([u, -side * n], axis=1), np.stack([-u, -side * n], axis=1)]
    obs_pts = np.concatenate(pts) if len(segs) else np.zeros((0, 2))
    obs_anchor = np.concatenate(anchors) if len(segs) else np.zeros((0, 2))
    obs_cone = np.concatenate(cones) if len(segs) else np.zeros((0, 2, 2))
    obs_owner = np.tile(obstacles.segment_owner, 4)

    # Nodes inside an obstacle's margin go first (one vectorised test on the prepared union;
    # merged nodes lie within the tolerance of each other, so go or stay together).
    inside = obstacles.points_within(obs_pts, rho - DISTANCE_TOLERANCE)
    obs_pts, obs_anchor, obs_cone = obs_pts[~inside], obs_anchor[~inside], obs_cone[~inside]
    obs_owner = obs_owner[~inside]
    all_pts = np.vstack([base_pts, obs_pts])
    kind = np.concatenate([base_kind, np.full(len(obs_pts), KIND_OBSTACLE)])
    anchor = np.vstack([np.full((base, 2), np.nan), obs_anchor])
    cone = np.concatenate([np.zeros((base, 2, 2)), obs_cone])

    # Flat: the node lies on the margin of its own obstacle (a side next to its corner).
    flat = np.zeros(len(all_pts), bool)
    if len(obs_pts):
        flat[base:] = obstacles.near_own(obs_pts, obs_owner, rho + DISTANCE_TOLERANCE)

    label = _merge_labels(all_pts)
    rep = label == np.arange(len(all_pts))
    # A merged node keeps the taut rules only if every member has the same corner and cone.
    # (The cone is an unordered pair of directions: a corner's two sides list it in turn.)
    same_cone = np.all(np.abs(cone - cone[label]).reshape(-1, 4) <= ANGLE_TOLERANCE, axis=1)
    swapped = np.all(np.abs(cone[:, ::-1] - cone[label]).reshape(-1, 4) <= ANGLE_TOLERANCE, axis=1)
    same = (
        (kind == KIND_OBSTACLE)
        & (kind[label] == KIND_OBSTACLE)
        & np.all(np.abs(anchor - anchor[label]) <= DISTANCE_TOLERANCE, axis=1)
        & (same_cone | swapped)
    )
    prunable = np.ones(len(all_pts), bool)
    np.logical_and.at(prunable, label, same)
    flat_any = np.zeros(len(all_pts), bool)
    np.logical_or.at(flat_any, label, flat)

    # Obstacle nodes within the margin are gone already; row nodes are tested here.
    keep = rep.copy()
    keep[2:base] &= obstacles.distance_to_points(base_pts[2:]) >= rho - DISTANCE_TOLERANCE
    idx = np.flatnonzero(keep)
    return Nodes(
        points=all_pts[idx],
        kind=kind[idx],
        anchor=anchor[idx],
        cone=cone[idx],
        prunable=prunable[idx] & (kind[idx] == KIND_OBSTACLE),
        flat=flat_any[idx],
    )


def _merge_labels(points: np.ndarray) -> np.ndarray:
    """Label of each point = smallest index among the points within the tolerance of it
    (transitively), found by label propagation over STRtree pairs."""
    label = np.arange(len(points))
    if len(points) < 2:
        return label
    tree = shapely.STRtree(shapely.points(points))
    i, j = tree.query(shapely.points(points), predicate="dwithin", distance=DISTANCE_TOLERANCE)
    pair = i != j
    i, j = i[pair], j[pair]
    while len(i):
        new = label.copy()
        np.minimum.at(new, i, label[j])
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    return label


def tangent(nodes: Nodes, index: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """True where the line through node `index` along `direction` (either sense) does not cut
    the mitre corner the node goes round: the direction is not strictly inside the corner's
    cone nor its opposite. Always True for nodes without a single corner."""
    cone = nodes.cone[index]
    dx, dy = direction[:, 0], direction[:, 1]
    along_a = dx * cone[:, 0, 0] + dy * cone[:, 0, 1]
    along_b = dx * cone[:, 1, 0] + dy * cone[:, 1, 1]
    eps = ANGLE_TOLERANCE * np.hypot(dx, dy)
    inside = (along_a > eps) & (along_b > eps)
    opposite = (along_a < -eps) & (along_b < -eps)
    return ~nodes.prunable[index] | ~(inside | opposite)


def corner_side(nodes: Nodes, index: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """Cross product of an edge direction with the vector from node `index` to its corner:
    > 0 when the corner lies to the left of the edge (nan for nodes without a corner)."""
    rel = nodes.anchor[index] - nodes.points[index]
    return unit[:, 0] * rel[:, 1] - unit[:, 1] * rel[:, 0]


def wraps_corner(
    incoming: np.ndarray, outgoing: np.ndarray, side_in: float, side_out: np.ndarray
) -> np.ndarray:
    """Taut transition rule at a node (unit `incoming`, unit `outgoing` (k, 2), corner sides
    of both edges from `corner_side`): straight on, or a bend towards the node's corner with
    the corner on the inner side of both edges."""
    turn = incoming[0] * outgoing[:, 1] - incoming[1] * outgoing[:, 0]
    straight = np.abs(turn) <= ANGLE_TOLERANCE
    if side_in > 0:
        return straight | ((turn > 0) & (side_out > 0))
    if side_in < 0:
        return straight | ((turn < 0) & (side_out < 0))
    return straight


@dataclass(frozen=True, eq=False)
class RowGeometry:
    """A `ParkingRows` as prepared shapely lines for the row tests: `goal` is None with an
    open goal, `start_rest` None for a plain parking row (see `ParkingRows.start_rest`)."""

    start: shapely.Geometry
    goal: shapely.Geometry | None
    start_rest: shapely.Geometry | None

    @classmethod
    def of(cls, rows) -> RowGeometry:
        start = shapely.LineString(rows.start_row)
        goal = None if rows.open_goal else shapely.LineString(rows.goal_row)
        rest = rows.start_rest
        rest = None if rest is None else shapely.LineString(rest)
        for line in (start, goal, rest):
            if line is not None:
                shapely.prepare(line)
        return cls(start, goal, rest)


def segments_clear_of_rows(
    starts: np.ndarray,
    ends: np.ndarray,
    from_start: np.ndarray,
    to_goal: np.ndarray,
    rows: RowGeometry,
    safety_margin: float,
) -> np.ndarray:
    """Def. 5 / eq. 35 with the docs/design.md 3.2 erratum: a segment not starting at A keeps
    2 rho_c from Delta_A, a segment not ending at B keeps 2 rho_c from Delta_B. A leg's
    first segment keeps 2 rho_c from its start tail beyond the first piece (docs/design.md 7)."""
    ok = np.ones(len(starts), bool)
    if len(starts) == 0:
        return ok
    limit = 2.0 * safety_margin - DISTANCE_TOLERANCE
    low, high = np.minimum(starts, ends), np.maximum(starts, ends)
    tests = [(rows.start, ~from_start), (rows.goal, ~to_goal), (rows.start_rest, from_start)]
    for row, applies in tests:
        if row is None:
            continue
        xmin, ymin, xmax, ymax = shapely.bounds(row)
        near = (
            applies
            & (low[:, 0] <= xmax + limit)
            & (high[:, 0] >= xmin - limit)
            & (low[:, 1] <= ymax + limit)
            & (high[:, 1] >= ymin - limit)
        )
        test = np.flatnonzero(near)
        if len(test):
            lines = shapely.linestrings(np.stack([starts[test], ends[test]], axis=1))
            ok[test] &= ~shapely.dwithin(row, lines, limit)
    return ok


def parking_angles_ok(
    directions: np.ndarray,
    from_start: np.ndarray,
    to_goal: np.ndarray,
    start_direction: np.ndarray,
    goal_direction: np.ndarray,
) -> np.ndarray:
    """Def. 5 / eq. 36: a first segment within 90 degrees of e_0, a last one within 90 degrees
    of e_K (angle tolerance 1e-9 rad)."""
    norm = np.hypot(directions[:, 0], directions[:, 1])
    floor = -np.sin(ANGLE_TOLERANCE) * norm
    ok = np.ones(len(directions), bool)
    ok[from_start] &= directions[from_start] @ start_direction >= floor[from_start]
    ok[to_goal] &= directions[to_goal] @ goal_direction >= floor[to_goal]
    return ok


def edge_ok(problem: PathProblem, rows, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Definition 5 for segments starts[k] -> ends[k] (each (k, 2)), vectorised: clear of every
    obstacle by rho_c, of the rows by 2 rho_c (erratum of docs/design.md 3.2) and within 90 degrees
    of the parking directions at A and B. `rows` is a `ParkingRows`."""
    starts = np.asarray(starts, float).reshape(-1, 2)
    ends = np.asarray(ends, float).reshape(-1, 2)
    rho = problem.safety_margin
    from_start = np.all(np.abs(starts - problem.start) <= DISTANCE_TOLERANCE, axis=1)
    to_goal = np.all(np.abs(ends - problem.goal) <= DISTANCE_TOLERANCE, axis=1)
    ok = ~problem.obstacles.segments_within(
        np.stack([starts, ends], axis=1), rho - DISTANCE_TOLERANCE
    )
    ok &= segments_clear_of_rows(starts, ends, from_start, to_goal, RowGeometry.of(rows), rho)
    ok &= parking_angles_ok(
        ends - starts,
        from_start,
        to_goal & (not rows.open_goal),
        rows.start_direction,
        rows.goal_direction,
    )
    ok &= np.hypot(*(ends - starts).T) > DISTANCE_TOLERANCE
    return ok


class Occlusion:
    """What certainly hides what, for one problem's nodes; shared by its edge caches.

    Shadows: per node (rows) and nearest obstacle (columns, `_OCCLUDERS` of them), the
    reference angle, the obstacle's angular span relative to it, and its farthest vertex's
    distance, computed on demand (unused slots never block). A segment from a node whose other
    end lies strictly inside such a span and beyond the farthest vertex crosses the obstacle
    (a connected obstacle whose convex hull does not hold the viewpoint meets every ray
    strictly inside its angular span, within its farthest vertex). Core grids: where a
    segment is certainly within rho_c of an obstacle (`CoreGrid`)."""

    def __init__(self, nodes: Nodes, obstacles: Obstacles, safety_margin: float) -> None:
        self.nodes = nodes
        self.obstacles = obstacles
        self.safety_margin = safety_margin
        # Shadows are cast by touching footprints merged: a block of terraced houses hides
        # what lies behind it (no single house spans a wide enough angle).
        if len(obstacles) > _OCCLUDERS:
            obstacles = obstacles.merged(min(_TOUCHING, safety_margin))
        self.occluders = obstacles
        self._verdicts = _KeyTable()  # pair key -> 1 clear, 0 blocked (`verdicts`)
        self.shadow = np.empty((len(nodes), _OCCLUDERS, 4))
        self.shadow[...] = [0.0, np.inf, -np.inf, np.inf]
        self.done = np.zeros(len(nodes), bool)
        self._grid: CoreGrid | None = None
        self._radius = math.inf  # the nearest occluders are looked for within it
        if len(obstacles) > _OCCLUDERS:
            box = obstacles.vertices[0]
            span = box.max(axis=0) - box.min(axis=0)
            area = max(float(span[0] * span[1]), 1.0)
            self._radius = math.sqrt(4.0 * _OCCLUDERS * area / (math.pi * len(obstacles)))

    def in_shadow(self, node: np.ndarray, angle: np.ndarray, length: np.ndarray) -> np.ndarray:
        """Whether the segment of `length` leaving `node` at `angle` ends in the shadow of
        one of the node's nearest obstacles (`ensure` them first)."""
        shadow = self.shadow[node]  # (k, _OCCLUDERS, 4): ref, low, high, far
        ref, low, high, far = (shadow[..., c] for c in range(4))
        # angle - ref lies in [-2 pi, 3 pi] (`angle` up to 2 pi for the far end): one turn
        # added or taken brings it into [-pi, pi), cheaper than np.mod (3 pi gives pi,
        # which like -pi lies inside no span)
        rel = angle[:, None] - ref
        rel -= (2.0 * math.pi) * (rel >= math.pi)
        rel += (2.0 * math.pi) * (rel < -math.pi)
        inside = rel > low + ANGLE_TOLERANCE
        inside &= rel < high - ANGLE_TOLERANCE
        inside &= length[:, None] > far + DISTANCE_TOLERANCE
        return np.any(inside, axis=1)

    def pair_keys(self, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
        """One key per unordered node pair (the clearance test is symmetric)."""
        return np.minimum(src, dst).astype(np.int64) * len(self.nodes) + np.maximum(src, dst)

    def verdicts(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(known, clear) per pair key: whether an ellipse cache has tested the pair's
        clearance already, and its answer."""
        found = self._verdicts.get(keys)
        return found >= 0, found == 1

    def record(self, keys: np.ndarray, clear: np.ndarray) -> None:
        self._verdicts.put(keys, clear.astype(np.int8))

    def grid(self, bounds: tuple[float, float, float, float]) -> CoreGrid:
        """A core grid covering `bounds` (the last one built when it does)."""
        grid = self._grid
        if grid is None or not grid.covers(bounds):
            margin = self.safety_margin - DISTANCE_TOLERANCE
            self._grid = grid = self.obstacles.core_grid(bounds, margin)
        return grid

    def ensure(self, index: np.ndarray) -> None:
        """Compute the shadows of the nodes `index` not done yet."""
        index = index[~self.done[index]]
        if len(index) == 0:
            return
        self.done[index] = True
        obstacles = self.occluders
        pts = self.nodes.points[index]
        where = shapely.points(pts)
        if math.isinf(self._radius):
            s = np.repeat(np.arange(len(index)), len(obstacles))
            o = np.tile(np.arange(len(obstacles)), len(index))
        else:
            # Dense districts find their nearest obstacles well within the map's mean radius:
            # a quarter of it first, the whole radius for the nodes short of `_OCCLUDERS`.
            s, o = obstacles.tree.query(where, predicate="dwithin", distance=self._radius / 4)
            short = np.flatnonzero(np.bincount(s, minlength=len(index)) < _OCCLUDERS)
            if len(short):
                enough = ~np.isin(s, short)
                s, o = s[enough], o[enough]
                s2, o2 = obstacles.tree.query(
                    where[short], predicate="dwithin", distance=self._radius
                )
                s, o = np.concatenate([s, short[s2]]), np.concatenate([o, o2])
        dist = shapely.distance(where[s], obstacles.geometries[o])
        order = np.lexsort((dist, s))
        s, o = s[order], o[order]
        rank = _rank_in_group(s)
        keep = rank < _OCCLUDERS
        s, o, rank = s[keep], o[keep], rank[keep]
        usable = ~shapely.intersects(obstacles.hulls[o], where[s])
        s, o, rank = s[usable], o[usable], rank[usable]
        if len(s) == 0:
            return
        # One row per (pair, vertex of the pair's obstacle), reduced per pair (ragged).
        flat, offsets = obstacles.vertices
        sizes = offsets[o + 1] - offsets[o]
        first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        pair, rank_in = ragged(sizes)
        vertex = offsets[o][pair] + rank_in
        verts = flat[vertex] - pts[s][pair]
        centre = np.add.reduceat(verts, first, axis=0) / sizes[:, None]
        ref_s = np.arctan2(centre[:, 1], centre[:, 0])
        ang = np.arctan2(verts[:, 1], verts[:, 0]) - ref_s[pair]
        ang = np.mod(ang + math.pi, 2.0 * math.pi) - math.pi
        far = np.maximum.reduceat(np.hypot(verts[:, 0], verts[:, 1]), first)
        self.shadow[index[s], rank] = np.column_stack(
            [ref_s, np.minimum.reduceat(ang, first), np.maximum.reduceat(ang, first), far]
        )


class EdgeCache:
    """Obstacle-clear out-edges of graph nodes, computed on demand per spatial tile.

    `to_start` adds the edges into A, which only a search from B back to A uses.

    `within` keeps only the nodes inside the ellipse |Av| + |vB| < within, and the edges v->w
    with |Av| + |vw| + |wB| < within (or w->v: edges stay symmetric): every path shorter than
    `within` uses only those, so a
    search bounded by `within` loses nothing (and distances to B over them stay exact for
    every node of such a path, so the heuristic stays admissible).

    Edges are numbered in the order they are computed; `src`, `dst`, `length`, `direction`
    (unit) and `penalty` (extra weight, for the repair loops) are indexed by edge number.
    `edges(v)` returns the (lo, hi) range of node v's out-edges.
    """

    def __init__(
        self,
        problem: PathProblem,
        nodes: Nodes,
        *,
        taut: bool,
        prune_collinear: bool,
        local_candidates: int | None = None,
        within: float | None = None,
        occlusion: Occlusion | None = None,
        to_start: bool = False,
    ) -> None:
        self.problem = problem
        self.nodes = nodes
        self.taut = taut
        self.prune_collinear = prune_collinear
        count = len(nodes)
        if taut:
            member = (nodes.kind <= KIND_GOAL) | ((nodes.kind == KIND_OBSTACLE) & ~nodes.flat)
        else:
            member = np.ones(count, bool)
        self.within = within
        if within is not None:
            # Only nodes a path shorter than `within` can visit: |Av| + |vB| < within.
            pts = nodes.points
            self._to_start = np.hypot(*(pts - pts[START]).T)
            self._to_goal = np.hypot(*(pts - pts[GOAL]).T)
            detour = self._to_start + self._to_goal
            member &= (nodes.kind <= KIND_GOAL) | (detour < within + DISTANCE_TOLERANCE)
        self.members = np.flatnonzero(member)
        # A is no target (a valid walk never comes back to it) but for searches from B.
        self.targets = self.members if to_start else self.members[self.members != START]
        self.first = np.full(count, -1, np.int64)
        self.count = np.zeros(count, np.int64)
        self.examined = 0  # candidate pairs examined
        self.computed = 0  # nodes whose out-edges are computed
        self.collinear_tested = 0  # pairs `_drop_collinear` tested, and dropped
        self.collinear_dropped = 0
        self.size = 0
        self.src = np.zeros(0, np.int64)
        self.dst = np.zeros(0, np.int64)
        self.length = np.zeros(0)
        self.direction = np.zeros((0, 2))
        self.penalty = np.zeros(0)
        self.side_at_src = np.zeros(0)  # corner_side of each edge at its source
        self.side_at_dst = np.zeros(0)  # ... and at its destination
        self.radius: float | None = None
        self._grid_bounds: tuple[float, float, float, float] | None = None
        self.occlusion = occlusion or Occlusion(nodes, problem.obstacles, problem.safety_margin)
        pts = nodes.points
        self.uses_sector_reach = False
        span = pts[self.targets].max(axis=0) - pts[self.targets].min(axis=0)
        self._extent = 2.0 * float(np.hypot(*span)) + 1.0
        if local_candidates is not None and len(self.targets) > 4 * local_candidates:
            area = max(float(span[0] * span[1]), 1.0)
            self.radius = math.sqrt(local_candidates * area / (math.pi * len(self.targets)))
            self._target_tree = shapely.STRtree(shapely.points(pts[self.targets]))
        elif len(self.targets) > _SECTOR_REACH_TARGETS and len(problem.obstacles) > _OCCLUDERS:
            self.uses_sector_reach = True
            self._reach_squared = np.full((count, _SECTORS), np.inf)
            self._reach_done = np.zeros(count, bool)
            self._target_xy: np.ndarray | None = None
        # Tiles: a square grid over the members, sized so a batch holds about _BATCH_PAIRS
        # candidate pairs.
        per_node = len(self.targets) if self.radius is None else 1.5 * local_candidates
        tile_nodes = min(max(_BATCH_PAIRS / max(per_node, 1.0), 4.0), 128.0)
        lo = pts[self.members].min(axis=0)
        span = np.maximum(pts[self.members].max(axis=0) - lo, 1.0)
        per_side = max(1, int(math.sqrt(len(self.members) / tile_nodes)))
        cell = np.floor((pts - lo) / span * per_side).clip(0, per_side - 1).astype(np.int64)
        self.tile = np.full(count, -1, np.int64)
        self.tile[self.members] = cell[self.members, 0] * per_side + cell[self.members, 1]

    # -- public -------------------------------------------------------------------------
    def edges(self, v: int) -> tuple[int, int]:
        """(lo, hi): edge numbers of v's out-edges, computing v's tile if needed."""
        if self.first[v] < 0:
            if self.tile[v] < 0:
                return 0, 0
            batch = self.members[(self.tile[self.members] == self.tile[v])]
            self._compute(batch[self.first[batch] < 0])
        lo = int(self.first[v])
        return lo, lo + int(self.count[v])

    def computed_edges(self) -> np.ndarray:
        """Every edge computed so far as segments (E, 2, 2), for plots."""
        pts = self.nodes.points
        return np.stack([pts[self.src[: self.size]], pts[self.dst[: self.size]]], axis=1)

    # -- batch computation --------------------------------------------------------------
    def _candidate_pairs(self, sources: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distinct (source, target) pairs to test: every target for A and B, and for every
        source when the radius is unlimited; otherwise the local pairs, plus B for every
        source (B's own set is complete so that B sees every node that sees it: the
        heuristic's backward search follows B's out-edges)."""
        if self.uses_sector_reach:
            return self._visible_pairs(sources)
        ends = (sources == START) | (sources == GOAL)
        unlimited = sources if self.radius is None else sources[ends]
        src = [np.repeat(unlimited, len(self.targets))]
        dst = [np.tile(self.targets, len(unlimited))]
        local = sources if self.radius is None else sources[~ends]
        if self.radius is not None and len(local):
            s, t = self._local_pairs(local)
            far_goal = np.hypot(*(self.nodes.points[local] - self.nodes.points[GOAL]).T)
            far_goal = local[far_goal > self.radius]  # B not among the radius query's pairs
            src += [s, far_goal]
            dst += [t, np.full(len(far_goal), GOAL)]
        src, dst = np.concatenate(src), np.concatenate(dst)
        keep = src != dst
        return src[keep], dst[keep]

    def _local_pairs(self, sources: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Targets within the radius; then, for each octant (seen from a source) holding
        fewer than _OCTANT_MIN of them, the nearest _OCTANT_MIN targets in that octant at any
        distance (`_wedge_targets`), so open areas are crossed."""
        pts = self.nodes.points
        where = shapely.points(pts[sources])
        i, j = self._target_tree.query(where, predicate="dwithin", distance=self.radius)
        src, dst = sources[i], self.targets[j]
        rel = pts[dst] - pts[src]
        octant = _octant(rel)
        # Dense districts hold many more targets in the radius than the map's mean: keep the
        # nearest `_OCTANT_MAX` per octant (farther ones are mostly hidden behind them).
        if len(i) > _OCTANT_MAX * 8 * len(sources):
            # one sort by (source, octant, distance): distances are below the radius, so
            # this key orders by group first
            group = i * 8 + octant
            order = np.argsort(group * (2.0 * self.radius) + np.hypot(rel[:, 0], rel[:, 1]))
            group = group[order]
            keep = np.sort(order[_rank_in_group(group) < _OCTANT_MAX])
            i, src, dst, octant = i[keep], src[keep], dst[keep], octant[keep]
        have = np.bincount(i * 8 + octant, minlength=8 * len(sources)).reshape(-1, 8)
        row, oct_ = np.nonzero(have < _OCTANT_MIN)
        if len(row) == 0:
            return src, dst
        # Wedges: apex at the source, the octant's two bounding rays; targets inside them
        # beyond the radius are the candidates. First out to 2 radii, then 8, then, for the
        # wedges with fewer than _OCTANT_MIN targets that near, out of the map.
        s_new, t_new = self._wedge_targets(sources[row], oct_)
        return np.concatenate([src, s_new]), np.concatenate([dst, t_new])

    def _wedge_targets(
        self, apex_nodes: np.ndarray, octant: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """For each (node, octant): the nearest _OCTANT_MIN targets in that octant beyond
        the radius (ties broken by target number), looked for within 2 radii first, then 8,
        then at any distance: the STRtree returns every target in a wedge, and most wedges
        find theirs within 2 radii (Bet Shemesh 11 km: 6.6 M targets returned for 4,650
        wedges within 8 radii at once)."""
        pts = self.nodes.points
        s_all, t_all = [], []
        wedge = np.arange(len(apex_nodes))
        out = 1e-9  # rad
        for reach in (2.0 * self.radius, 8.0 * self.radius, self._extent):
            # the octant's rays turned out by `out`: a target on a ray (a grid's, along an
            # axis or a diagonal) lies inside the triangle, not a rounding error outside
            a0 = -math.pi + octant[wedge] * (math.pi / 4.0) - out
            a1 = a0 + math.pi / 4.0 + 2.0 * out
            apex = pts[apex_nodes[wedge]]
            side = reach / math.cos(math.pi / 8.0 + out)  # the triangle holds the sector
            ring = np.stack(
                [
                    apex,
                    apex + side * np.column_stack([np.cos(a0), np.sin(a0)]),
                    apex + side * np.column_stack([np.cos(a1), np.sin(a1)]),
                ],
                axis=1,
            )
            w, k = self._target_tree.query(shapely.polygons(ring), predicate="intersects")
            s_new, t_new = apex_nodes[wedge[w]], self.targets[k]
            d = pts[t_new] - pts[s_new]
            dist = np.hypot(d[:, 0], d[:, 1])
            inside = (_octant(d) == octant[wedge[w]]) & (dist > self.radius) & (dist <= reach)
            w, s_new, t_new, dist = w[inside], s_new[inside], t_new[inside], dist[inside]
            order = np.lexsort((t_new, dist, w))  # ties by target: the same at any reach
            w, s_new, t_new = w[order], s_new[order], t_new[order]
            pick = _rank_in_group(w) < _OCTANT_MIN
            found = np.bincount(w[pick], minlength=len(wedge))
            done = found >= _OCTANT_MIN
            if reach == self._extent:
                done[:] = True
            # a wedge is settled once it holds _OCTANT_MIN within `reach`: nothing beyond
            # is nearer; the others are looked for again, farther
            keep = pick & done[w]
            s_all.append(s_new[keep])
            t_all.append(t_new[keep])
            wedge = wedge[~done]
            if len(wedge) == 0:
                break
        return np.concatenate(s_all), np.concatenate(t_all)

    def _visible_pairs(self, sources: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Complete candidate sets without testing every pair in full: every target that is
        not certainly hidden. Each node's view is cut into `_SECTORS` sectors; a sector that
        one of the node's nearest obstacles spans whole is blocked beyond that obstacle's
        farthest vertex (the shadow argument of `Occlusion`), and in the taut graph a sector
        inside the node's corner cone (or its opposite) holds no tangent edge. A pair is kept
        only if the target lies within the source's reach in its sector and, where the
        target's reach is known, the source within the target's. Reaches are computed for the
        sources, and for every member once a search has spread over `_SPREAD` of them."""
        pts = self.nodes.points
        if np.count_nonzero(self._reach_done[self.members]) >= _SPREAD * len(self.members):
            self._sector_reach(self.members)
        self._sector_reach(sources)
        reach, known = self._reach_squared, self._reach_done
        if self._target_xy is None:
            self._target_xy = np.ascontiguousarray(pts[self.targets].T)
        tx, ty = self._target_xy
        # (sources, targets) arrays by broadcasting, rows in the order of `sources`; squared
        # lengths (no square root over every target)
        dx = tx[None, :] - pts[sources, 0][:, None]
        dy = ty[None, :] - pts[sources, 1][:, None]
        squared = dx * dx
        squared += dy * dy
        sector = np.arctan2(dy, dx)
        sector += math.pi
        sector *= _SECTORS / (2.0 * math.pi)
        # The direction pi (sector _SECTORS) goes to the last sector, whose closed span holds
        # it (`_sector_reach` tests the closed sector), its reverse 0 to the one before 0's.
        sector = np.minimum(sector.astype(np.intp), _SECTORS - 1)
        row, col = np.nonzero(squared <= np.take_along_axis(reach[sources], sector, axis=1))
        src, dst = sources[row], self.targets[col]
        back = (sector[row, col] + _SECTORS // 2) % _SECTORS
        ok = (src != dst) & (~known[dst] | (squared[row, col] <= reach[dst, back]))
        return src[ok], dst[ok]

    def _sector_reach(self, index: np.ndarray) -> None:
        """Fill `_reach_squared` (nodes, `_SECTORS`), the square of how far a node can see
        into each sector (see `_visible_pairs`), for the nodes `index` not done yet. Sector k
        spans the angles [-pi + k w, -pi + (k + 1) w), w = 2 pi / `_SECTORS`; a sector
        counts as covered only when its closed span lies strictly inside a shadow."""
        index = index[~self._reach_done[index]]
        if len(index) == 0:
            return
        self._reach_done[index] = True
        width = 2.0 * math.pi / _SECTORS
        first = -math.pi + width * np.arange(_SECTORS)
        for chunk in np.array_split(index, max(1, len(index) // 2000)):
            self.occlusion.ensure(chunk)
            shadow = self.occlusion.shadow[chunk]  # (k, _OCCLUDERS, 4): ref, low, high, far
            ref, low, high, far = (shadow[..., c, None] for c in range(4))
            rel = np.mod(first - ref + math.pi, 2.0 * math.pi) - math.pi  # (k, occ, sectors)
            covers = (rel > low + ANGLE_TOLERANCE) & (rel + width < high - ANGLE_TOLERANCE)
            reach = np.where(covers, far, np.inf).min(axis=1) + DISTANCE_TOLERANCE
            if self.taut:
                reach = np.where(self._inside_cone(chunk, first, width), 0.0, reach)
            self._reach_squared[chunk] = reach * reach

    def _inside_cone(self, index: np.ndarray, first: np.ndarray, width: float) -> np.ndarray:
        """(k, sectors): sectors whose every direction is strictly inside node `index`'s
        corner cone or its opposite (no edge there is tangent, see `tangent`). The cone's two
        unit directions are 90 degrees apart or less, so a sector is inside when both its
        bounding rays are, with the angle tolerance."""
        cone = self.nodes.cone[index]  # (k, 2, 2)
        out = np.zeros((len(index), len(first)), bool)
        rays = [first + 1e-9, first + width - 1e-9]
        rays = [np.stack([np.cos(a), np.sin(a)], axis=-1) for a in rays]  # (sectors, 2) each
        for sign in (1.0, -1.0):
            inside = np.ones_like(out)
            for ray in rays:
                along = sign * np.einsum("kcj,sj->kcs", cone, ray)
                inside &= np.all(along > 2.0 * ANGLE_TOLERANCE, axis=1)
            out |= inside
        return out & self.nodes.prunable[index, None]

    def _compute(self, sources: np.ndarray) -> None:
        nodes = self.nodes
        pts = nodes.points
        rho = self.problem.safety_margin
        sources = np.sort(sources)
        src, dst = self._candidate_pairs(sources)
        self.examined += len(src)
        self.computed += len(sources)
        d = pts[dst] - pts[src]
        length = np.hypot(d[:, 0], d[:, 1])
        keep = length > DISTANCE_TOLERANCE
        if self.within is not None:  # and only edges such a path can use: |Av|+|vw|+|wB|
            # (either way round: the edges stay symmetric, as the heuristic's search needs)
            ahead = self._to_start[src] + self._to_goal[dst]
            back = self._to_start[dst] + self._to_goal[src]
            keep &= np.minimum(ahead, back) + length < self.within + DISTANCE_TOLERANCE
        if self.taut:  # at the source, then at the far end of the pairs left
            keep[keep] = tangent(nodes, src[keep], d[keep])
            keep[keep] = tangent(nodes, dst[keep], d[keep])
        idx = np.flatnonzero(keep)
        if self.prune_collinear and len(idx):
            idx = self._drop_collinear(idx, src, dst, d, length)
        idx = idx[~self._occluded(src[idx], dst[idx], d[idx], length[idx])]
        if (self.within is not None or self.uses_sector_reach) and len(idx):
            # Long pairs (complete candidate sets; radius-limited pairs are short) go through
            # the core grid first. Ellipse caches overlap (each growth of L, then
            # certification): a pair tested by one is not tested again.
            keys = self.occlusion.pair_keys(src[idx], dst[idx])
            known, clear = self.occlusion.verdicts(keys)
            fresh = idx[~known]
            blocked = self._core_grid().blocks(pts[src[fresh]], pts[dst[fresh]])
            segs = np.stack([pts[src[fresh[~blocked]]], pts[dst[fresh[~blocked]]]], axis=1)
            blocked[~blocked] = self.problem.obstacles.segments_within(
                segs, rho - DISTANCE_TOLERANCE
            )
            self.occlusion.record(keys[~known], ~blocked)
            idx = np.sort(np.concatenate([idx[known & clear], fresh[~blocked]]))
        else:
            if self.radius is not None and len(idx):
                # Pairs much longer than the radius (A's and B's complete sets, wedges
                # across open ground) mostly cross an obstacle: the core grid culls them.
                far = idx[length[idx] > 2.0 * self.radius]
                if len(far):
                    blocked = self._core_grid().blocks(pts[src[far]], pts[dst[far]])
                    idx = np.setdiff1d(idx, far[blocked], assume_unique=True)
            segs = np.stack([pts[src[idx]], pts[dst[idx]]], axis=1)
            idx = idx[~self.problem.obstacles.segments_within(segs, rho - DISTANCE_TOLERANCE)]
        src, dst, d, length = src[idx], dst[idx], d[idx], length[idx]
        order = np.argsort(src, kind="stable")
        src, dst, d, length = src[order], dst[order], d[order], length[order]
        self._append(sources, src, dst, d / length[:, None], length)

    def _drop_collinear(self, idx, src, dst, d, length) -> np.ndarray:
        """`idx` without the pairs `_collinear_shadowed` (before the clearance tests: if
        v->w is clear, so is its part v->x). Grids line nodes up (a third of the pairs go),
        real footprints almost never (1 of 1.8 M pairs on a Vienna route): after the first
        `COLLINEAR_TRIAL` pairs, the test goes on only where it dropped at least
        `COLLINEAR_SHARE` of them."""
        if self.collinear_tested >= COLLINEAR_TRIAL and (
            self.collinear_dropped < COLLINEAR_SHARE * self.collinear_tested
        ):
            return idx
        shadowed = _collinear_shadowed(src[idx], dst[idx], d[idx], length[idx], self.radius)
        self.collinear_tested += len(idx)
        self.collinear_dropped += int(np.count_nonzero(shadowed))
        return idx[~shadowed]

    def _core_grid(self) -> CoreGrid:
        """Where a segment is certainly too close to an obstacle, over the members."""
        if self._grid_bounds is None:
            pts = self.nodes.points[self.members]
            self._grid_bounds = (*pts.min(axis=0), *pts.max(axis=0))
        return self.occlusion.grid(self._grid_bounds)

    def _occluded(
        self, src: np.ndarray, dst: np.ndarray, d: np.ndarray, length: np.ndarray
    ) -> np.ndarray:
        """True for pairs certainly blocked: seen from either end, the other end lies
        strictly inside the angular shadow of one of that end's nearest obstacles, farther
        than all of its vertices (`Occlusion`). Cheap numpy culling before the exact
        clearance test."""
        if len(self.problem.obstacles) == 0 or len(src) == 0:
            return np.zeros(len(src), bool)
        occlusion = self.occlusion
        occlusion.ensure(np.unique(src))
        angle = np.arctan2(d[:, 1], d[:, 0])
        blocked = occlusion.in_shadow(src, angle, length)
        # The far end's shadows only where they are known already (computing them for every
        # target of a tile costs more than the exact test they would spare).
        rest = np.flatnonzero(~blocked & occlusion.done[dst])
        blocked[rest] = occlusion.in_shadow(dst[rest], angle[rest] + math.pi, length[rest])
        return blocked

    def _append(self, sources, src, dst, unit, length) -> None:
        need = self.size + len(src)
        if need > len(self.src):
            cap = max(need, 2 * len(self.src), 1024)
            self.src = _grow(self.src, cap)
            self.dst = _grow(self.dst, cap)
            self.length = _grow(self.length, cap)
            self.direction = _grow(self.direction, cap)
            self.penalty = _grow(self.penalty, cap)
            self.side_at_src = _grow(self.side_at_src, cap)
            self.side_at_dst = _grow(self.side_at_dst, cap)
        sl = slice(self.size, need)
        self.side_at_src[sl] = corner_side(self.nodes, src, unit)
        self.side_at_dst[sl] = corner_side(self.nodes, dst, unit)
        self.src[sl], self.dst[sl], self.length[sl], self.direction[sl] = src, dst, length, unit
        self.penalty[sl] = 0.0
        counts = np.bincount(np.searchsorted(sources, src), minlength=len(sources))
        self.first[sources] = self.size + np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.count[sources] = counts
        self.size = need


class _KeyTable:
    """Non-negative int64 keys -> int8 values, looked up and stored a whole array at a time
    (open addressing, linear probing, at most half full): the clearance verdicts of
    millions of node pairs, where a dict costs a Python call per key."""

    _EMPTY = -1

    def __init__(self) -> None:
        self._keys = np.full(1 << 10, self._EMPTY, np.int64)
        self._values = np.zeros(1 << 10, np.int8)
        self._count = 0

    def get(self, keys: np.ndarray) -> np.ndarray:
        """The value of each key, -1 where it has none."""
        out = np.full(len(keys), -1, np.int8)
        if self._count == 0 or len(keys) == 0:
            return out
        mask = len(self._keys) - 1
        rows, at = np.arange(len(keys)), self._hash(keys) & mask
        while len(rows):
            held = self._keys[at]
            hit = held == keys[rows]
            out[rows[hit]] = self._values[at[hit]]
            going = ~hit & (held != self._EMPTY)
            rows, at = rows[going], (at[going] + 1) & mask
        return out

    def put(self, keys: np.ndarray, values: np.ndarray) -> None:
        """Store values; a key stored before keeps its value (a pair's verdict never
        changes), a key given twice keeps one of them."""
        if 2 * (self._count + len(keys)) > len(self._keys):
            self._grow(self._count + len(keys))
        mask = len(self._keys) - 1
        rows, at = np.arange(len(keys)), self._hash(keys) & mask
        while len(rows):
            held = self._keys[at]
            done = held == keys[rows]
            empty = held == self._EMPTY
            # each key claims the empty slot it reached; where several did, the last
            # write holds it (a key given twice: both hold it) and the others probe on
            slots, claim = at[empty], rows[empty]
            self._keys[slots] = keys[claim]
            won = self._keys[slots] == keys[claim]
            self._values[slots[won]] = values[claim[won]]
            self._count += int(np.count_nonzero(won))
            done[empty] = won
            rows, at = rows[~done], (at[~done] + 1) & mask

    def _grow(self, count: int) -> None:
        used = self._keys != self._EMPTY
        keys, values = self._keys[used], self._values[used]
        size = len(self._keys)
        while 2 * count > size:
            size *= 2
        self._keys = np.full(size, self._EMPTY, np.int64)
        self._values = np.zeros(size, np.int8)
        self._count = 0
        if len(keys):
            self.put(keys, values)

    @staticmethod
    def _hash(keys: np.ndarray) -> np.ndarray:
        """Well spread bits (a multiplicative hash, the high bits brought down)."""
        mixed = keys.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
        return (mixed ^ (mixed >> np.uint64(29))).astype(np.int64) & np.int64(0x7FFFFFFFFFFFFFFF)


def _rank_in_group(group: np.ndarray) -> np.ndarray:
    """Each element's place within its run of equal keys (`group` sorted): 0, 1, 2, ..."""
    return np.arange(len(group)) - np.searchsorted(group, group, side="left")


def _grow(array: np.ndarray, capacity: int) -> np.ndarray:
    out = np.zeros((capacity,) + array.shape[1:], array.dtype)
    out[: len(array)] = array
    return out


def _octant(d: np.ndarray) -> np.ndarray:
    angle = np.arctan2(d[:, 1], d[:, 0])
    return (np.floor((angle + math.pi) / (math.pi / 4.0)).astype(np.int64)) % 8


def _collinear_shadowed(
    src: np.ndarray, dst: np.ndarray, d: np.ndarray, length: np.ndarray, radius: float | None
) -> np.ndarray:
    """True for edges v->w that pass through a nearer target x of v on the same ray (within
    1e-9 m): v->x then x->w is the same line, with valid edges (sub-segments of a clear
    segment, same tangency; x->w is no longer than v->w, so within x's candidate radius).
    Edges from A or into B are never dropped (row exemptions), nor edges longer than the
    candidate radius (they may come from the octant completion, which x does not share)."""
    shadowed = np.zeros(len(src), bool)
    usable = (src != START) & (dst != GOAL)
    if radius is not None:
        usable &= length <= radius
    cand = np.flatnonzero(usable)
    if len(cand) < 2:
        return shadowed
    angle = np.arctan2(d[cand, 1], d[cand, 0])
    order = cand[np.lexsort((length[cand], angle, src[cand]))]
    ang = np.arctan2(d[order, 1], d[order, 0])
    new_group = np.ones(len(order), bool)
    new_group[1:] = (src[order][1:] != src[order][:-1]) | (np.diff(ang) > 1e-11)
    head = order[np.maximum.accumulate(np.where(new_group, np.arange(len(order)), 0))]
    # distance of the group's nearest target x from the line v->w
    offset = np.abs(d[order, 0] * d[head, 1] - d[order, 1] * d[head, 0]) / length[order]
    shadowed[order] = ~new_group & (offset <= 1e-9) & (length[order] > length[head])
    return shadowed
