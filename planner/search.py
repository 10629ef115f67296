"""Path search (paper sec. IV-B4, Algorithm 1, eqs. 42-47; docs/design.md 3.3), the fleet-size
iteration of finite parking rows (docs/design.md 3.2) and the diagnosis when no valid path exists.

`method="exact"` (default):
1. A* with a Euclidean heuristic over *directed edges* (state = the last edge). A transition
   is allowed only if the bend is at most 90 degrees; the first and last edges keep within 90
   degrees of the parking directions (definition 5), and a walk never bends at both ends of
   an edge shorter than 2 rho_c (but at A: the segments either side of it would come within
   2 rho_c, condition 5). The first walk reaching B is the shortest meeting conditions
   (1)-(4) of definition 4 and that part of (5). Each edge is relaxed once, from the cheapest
   state that allows it (the state after a transition is the new edge alone, or a short
   edge entered with a bend), so the search costs about as much as a Dijkstra over edges.
2. If that walk still breaks condition (5) or repeats a point (definition 1), a label search
   enumerates partial walks in order of length (at most `_LABELS_PER_STATE` per directed
   edge), extending one only if the simplified path stays valid: the next-shortest walks of
   docs/design.md 3.3, invalid prefixes pruned. It returns the shortest valid path, or proves there
   is none when no edge ran out of labels.
3. This runs first on the taut graph (`planner.graph`). Its answer is certified shortest when
   its length equals the shortest walk that keeps the parking rows and angles (no other
   constraint binds); otherwise the
   full graph of definition 5 is searched for a shorter valid path, bounded by the taut
   length (small maps). If the taut graph holds no valid path, the full graph is searched;
   before that, A and B lying in different parts of the free space ends it at once.
4. Large maps search ellipses |Av| + |vB| < L with complete candidate sets first, L growing
   (`_Planner._ellipse_search`; the first in the taut graph, grown ones in the full graph,
   whose path needs no further proof), then radius-limited graphs. When the first ellipse holds no
   valid path, a walk search from B back to A proves B walled in when it lies in a dead end
   that no walk leaves (`_Planner._pocket`; A's too when the radius-limited graphs run dry).

`method="penalty"`: the paper's loop, done properly: Dijkstra (A*) over nodes, then weights of
offending edges grow by (violations they take part in) x (mean edge weight), eq. 46 counting
the bends over 90 degrees and proximity between non-adjacent segments only (docs/design.md 3.3
errata); at most `max_penalty_iterations` rounds, on the full graph without pruning.

Everything is capped by `max_expansions` (states taken off a queue, over every round, graph
and fleet size); the planner has no clock.
"""

from __future__ import annotations

import collections
import heapq
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import shapely

from planner.formation import (
    ANGLE_TOLERANCE,
    DISTANCE_TOLERANCE,
    ParkingRows,
    min_fleet_size,
)
from planner.graph import (
    GOAL,
    START,
    EdgeCache,
    Nodes,
    Occlusion,
    RowGeometry,
    graph_nodes,
    parking_angles_ok,
    segments_clear_of_rows,
    wraps_corner,
)
from planner.numbers import plural
from planner.types import PathPlan, PathProblem, within_gap
from planner.validity import (
    PathViolations,
    Refusal,
    check_path,
    check_rows,
    precheck,
    precheck_issue,
)

__all__ = [
    "Refusal",
    "SearchProgress",
    "check_path",
    "check_rows",
    "plan_path",
    "precheck",
    "precheck_issue",
]

#: Graphs with more candidate targets than 4x this use radius queries (docs/design.md: scale): the
#: taut graph (used first) and the full graph (the fallback, with more but flatter nodes).
LOCAL_CANDIDATES = 250
LOCAL_CANDIDATES_FULL = 150
#: Repair search: partial walks kept per directed edge (docs/design.md 3.3, next-shortest walks).
_LABELS_PER_STATE = 8
#: The repair search runs the heuristic's reverse search on once it has taken this many
#: labels per node the reverse search has settled (`GoalDistance.extend`).
_LABELS_PER_SETTLED = 4
#: At most this many fleet-size rounds (N only grows; rows lengthen each round).
MAX_FLEET_ROUNDS = 12
#: Weight of the heuristic in the quick repair search (weighted A*), which finds a valid
#: path fast for the exact repair search to be bounded by (and to return if stopped).
QUICK_REPAIR_WEIGHT = 1.2
#: Large maps: the first ellipse searched with complete candidate sets is |Av| + |vB| <
#: ELLIPSE_START x |AB|; it grows by ELLIPSE_GROWTH while it holds no valid path.
ELLIPSE_START = 1.15
ELLIPSE_GROWTH = 1.2
#: The caller's progress callback is asked whether to stop every this many expansions: at
#: each, since one expansion may compute a batch of edges that costs a second on a map of
#: large polygons (a 64-expansion interval let a 5 s time limit run to 9.6 s).
_POLL_EVERY = 1
#: Large maps whose first ellipse held no valid path: the search from B for a pocket round
#: it (`_Planner._pocket`) gives up once it has computed the out-edges of this many
#: nodes, or expanded this many states.
END_NODES = 24
END_EXPANSIONS = 1000
#: Certification: at most this many nodes in the ellipse |Av| + |vB| < L of the path found
#: (L its length) get complete candidate sets (every pair examined) to prove it shortest.
CERTIFY_NODES = 12000


# ---------------------------------------------------------------------------------------
# Row-dependent edge filter
# ---------------------------------------------------------------------------------------


class _RowFilter:
    """The parking-row and parking-angle part of definition 5 for one set of rows, applied to
    a cache's edges in bulk as the cache grows (one vectorised call per batch of edges).

    `backward`: for a search from B back to A (`_Planner._pocket`), where the cache's
    edge v->w stands for the path's segment w->v (edges are symmetric): each edge passes
    when the segment it stands for does."""

    def __init__(
        self, problem: PathProblem, rows: ParkingRows, nodes: Nodes, backward: bool = False
    ) -> None:
        self.problem = problem
        self.rows = rows
        self.geometry = RowGeometry.of(rows)
        self.nodes = nodes
        self.backward = backward
        self._masks: dict[tuple, np.ndarray] = {}
        self._reversed: _RowFilter | None = None
        self._heuristics: dict[int, GoalDistance] = {}

    def reversed(self) -> _RowFilter:
        """The same rows for edges standing for their segment the other way round."""
        if self._reversed is None:
            self._reversed = _RowFilter(self.problem, self.rows, self.nodes, not self.backward)
        return self._reversed

    def heuristic(self, cache: EdgeCache, budget: _Budget) -> GoalDistance:
        """`GoalDistance` over the edges these rows let through (computed once per cache)."""
        key = id(cache)
        if key not in self._heuristics:
            self._heuristics[key] = GoalDistance(cache, budget, self)
        return self._heuristics[key]

    def mask(
        self,
        cache: EdgeCache,
        v: int,
        departure: bool = True,
        arrival: bool = True,
        row_tests: bool = True,
    ) -> np.ndarray:
        """Which of v's out-edges pass the row tests and the departure/arrival angle tests
        (each can be switched off, for the diagnosis). A read-only view."""
        lo, hi = cache.edges(v)
        key = (id(cache), departure, arrival, row_tests)
        ok = self._masks.get(key, np.zeros(0, bool))
        if len(ok) < cache.size:
            ok = np.concatenate([ok, self._compute(cache, len(ok), key[1:])])
            self._masks[key] = ok
        return ok[lo:hi]

    def _compute(self, cache: EdgeCache, first: int, flags: tuple[bool, bool, bool]) -> np.ndarray:
        departure, arrival, row_tests = flags
        src = cache.src[first : cache.size]
        dst = cache.dst[first : cache.size]
        direction = cache.direction[first : cache.size]
        if self.backward:  # the path's segment runs dst -> src
            src, dst, direction = dst, src, -direction
        pts = self.nodes.points
        from_start = src == START
        to_goal = dst == GOAL
        ok = np.ones(len(src), bool)
        if row_tests:
            ok &= segments_clear_of_rows(
                pts[src], pts[dst], from_start, to_goal, self.geometry, self.problem.safety_margin
            )
        if departure or arrival:
            ok &= parking_angles_ok(
                direction,
                from_start & departure,
                to_goal & arrival & (not self.rows.open_goal),
                self.rows.start_direction,
                self.rows.goal_direction,
            )
        return ok


# ---------------------------------------------------------------------------------------
# Searches
# ---------------------------------------------------------------------------------------


@dataclass
class _Budget:
    """The expansion cap, and the caller's stop request (`poll`, asked every `poll_every`
    expansions: True stops every search at once)."""

    limit: int
    used: int = 0
    floor: float = 0.0  # the current search's lower bound (f of its last state)
    #: Whether `floor` bounds every valid path (the certification's search over complete
    #: candidate sets); a search of the taut or a radius-limited graph bounds only its walks.
    proving: bool = False
    best: float = math.inf  # length of the shortest valid path found so far
    poll: Callable[[int], bool] | None = None
    poll_every: int | None = None  # (None: `_POLL_EVERY`)
    stopped: bool = False
    _next_poll: int = 0

    @property
    def spent(self) -> bool:
        if self.stopped or self.used >= self.limit:
            return True
        if self.poll is not None and self.used >= self._next_poll:
            self._next_poll = self.used + (self.poll_every or _POLL_EVERY)
            self.stopped = bool(self.poll(self.used))
        return self.stopped


@dataclass(frozen=True)
class SearchProgress:
    """What a running plan tells its `progress` callback: states expanded so far, the
    shortest valid path found so far (nan before the first) and the best proven lower bound
    on the shortest valid path (m)."""

    expansions: int
    best_length_m: float
    lower_bound_m: float


class GoalDistance:
    """The search heuristic: a lower bound on each node's distance to B over the cache's
    edges that pass the row filter `rows` (parking rows and angles, conditions 2-3), the
    bend rule and condition 5 ignored: a relaxation, so it never overestimates a valid walk.
    Without `rows`, every edge passes (the unconstrained distance). Keeping the rows and
    angles bounds routes that must come round to B's row much better (Vienna 3.7 km route
    3: 4,867 m at A instead of 4,505 m, for a valid path of 5,293 m, and half the walk
    search's expansions). An A* runs backwards from B towards A (key: distance to B
    plus the straight line to A); every node it settled has its exact distance, every other
    one max(straight line to B, K - straight line to A) with K the last key settled, which
    no path from it can beat (its key is at least K). The values are consistent (they never
    drop by more than an edge's length along an edge), so a search may relax each edge once.

    It first runs until it settles A, at the relaxed length L (`values`), or, in an
    ellipse cache, until its keys reach the ellipse's size (A is then left at that bound,
    no shorter path exists: an ellipse searched in vain costs less); `extend`
    runs it on to a larger K, so the repair search, whose labels mostly lie on routes a few
    metres longer than L, gets their exact distances (with only the straight-line bound,
    every node near the line from A looks as good as the best route). Edges are symmetric
    (clearance and tangency are tested at both ends), so a node's out-edges are its
    in-edges, each tested by the row filter the other way round (`_RowFilter.reversed`); A
    is no target and no way through (a valid walk never comes back to it), so
    its own out-edges are read once. With complete candidate sets, once nothing is left to
    settle, every node not settled is out of B's reach: its value is infinite (A's too, in
    an ellipse round a dead end), and the searches drop it. Settled nodes count against
    `max_expansions`."""

    def __init__(self, cache: EdgeCache, budget: _Budget, rows: _RowFilter | None = None) -> None:
        self.cache = cache
        self._into = None if rows is None else rows.reversed()  # which in-edges pass
        pts = cache.nodes.points
        self._to_goal = np.hypot(*(pts - pts[GOAL]).T)
        self._to_start = np.hypot(*(pts - pts[START]).T)
        self._dist = np.full(len(pts), math.inf)
        self._settled = np.zeros(len(pts), bool)
        lo, hi = cache.edges(START)
        leave = slice(lo, hi) if rows is None else lo + np.flatnonzero(rows.mask(cache, START))
        self._from_start = dict(
            zip(cache.dst[leave].tolist(), cache.length[leave].tolist(), strict=True)
        )
        self._dist[GOAL] = 0.0
        self._heap = [(float(self._to_start[GOAL]), GOAL)]
        self.reach = float(self._to_start[GOAL])  # every unsettled node: dist + to_start >= it
        self.values = self._to_goal
        self._count = 0
        # In an ellipse |Av| + |vB| < L no path of L or more matters (`EdgeCache.within`).
        self.extend(math.inf if cache.within is None else _at_most(cache.within), budget)

    @property
    def open(self) -> bool:
        """Whether `extend` can settle more nodes."""
        return bool(self._heap)

    @property
    def settled(self) -> int:
        """How many nodes have their exact distance."""
        return self._count

    def extend(self, key: float, budget: _Budget) -> None:
        """Settle every node whose key is below `key` (stopping once A is settled on the
        first call), then refresh `values`."""
        dist, settled, to_start = self._dist, self._settled, self._to_start
        cache, heap = self.cache, self._heap
        first = not settled[START]
        while heap and heap[0][0] < key and not budget.spent:
            value, w = heapq.heappop(heap)
            if settled[w]:
                continue
            settled[w] = True
            self._count += 1
            self.reach = value
            if w == START:
                if first:
                    break
                continue
            budget.used += 1
            d = float(dist[w])
            step = self._from_start.get(w)
            if step is not None and d + step < dist[START]:
                dist[START] = d + step
                heapq.heappush(heap, (d + step, START))
            lo, hi = cache.edges(w)
            edge = (
                slice(lo, hi)
                if self._into is None
                else lo + np.flatnonzero(self._into.mask(cache, w))
            )
            v = cache.dst[edge]
            nd = d + cache.length[edge]
            better = (nd < dist[v]) & ~settled[v]
            v, nd = v[better], nd[better]
            dist[v] = nd
            for node, item in zip(v.tolist(), (nd + to_start[v]).tolist(), strict=True):
                heapq.heappush(heap, (item, node))
        if heap:  # no node left has a key below the queue's least
            self.reach = max(self.reach, heap[0][0])
        elif cache.radius is None:
            # Every node that reaches B is settled: the others reach it in no way (with
            # complete candidate sets the edges are symmetric, so the search from B saw them
            # all). A dead end in an ellipse: A then says so, instead of its last key.
            self.reach = math.inf
        self.values = np.where(settled, dist, np.maximum(self._to_goal, self.reach - to_start))


def goal_distance(cache: EdgeCache, budget: _Budget, rows: _RowFilter | None = None) -> np.ndarray:
    """The cache's `GoalDistance` values, up to settling A (see `heuristic_of`)."""
    return heuristic_of(cache, budget, rows).values


def heuristic_of(cache: EdgeCache, budget: _Budget, rows: _RowFilter | None = None) -> GoalDistance:
    """The searches' heuristic over `cache` for `rows`, computed once per cache and row
    filter (`_RowFilter.heuristic`); without rows (every edge passes: the tests' yardstick)
    a new one at each call."""
    return GoalDistance(cache, budget) if rows is None else rows.heuristic(cache, budget)


def _goes_straight(d_in: np.ndarray, dirs: np.ndarray, bend: np.ndarray) -> np.ndarray:
    """Which unit directions `dirs` (their dot products with `d_in`: `bend`) carry on
    straight from the unit direction `d_in`, so the segment grows instead of bending."""
    cross = d_in[0] * dirs[:, 1] - d_in[1] * dirs[:, 0]
    return (np.abs(cross) <= ANGLE_TOLERANCE) & (bend > 0)


def _apart(problem: PathProblem) -> float:
    """Condition (5): non-adjacent segments closer than this break it (2 rho_c, less the
    tolerance of a length comparison)."""
    return 2.0 * problem.safety_margin - DISTANCE_TOLERANCE


def _walk_search(  # noqa: C901 (over 15 branches: to split)
    cache: EdgeCache,
    rows: _RowFilter,
    budget: _Budget,
    bound: float = math.inf,
    short_limit: float = 0.0,
    backward: bool = False,
    straight_line: bool = False,
) -> tuple[list[int] | None, str]:
    """A* over directed edges; returns (edge numbers of the shortest walk A..B meeting
    conditions (1)-(4), "found") or (None, "exhausted" | "exhausted-short" | "cap" |
    "bound"); "bound" when no such walk is shorter than `bound`, "exhausted-short" when
    there is none but the short-edge rule below refused some bend on the way.

    `backward` (with a backward `rows`): the walk B..A, each of its edges standing for the
    path's segment the other way round (the rules are symmetric). `straight_line` (implied
    by `backward`): guided by the straight line to the far end, not `GoalDistance`. Both
    serve to prove that no walk leaves an end (`_Planner._pocket`).

    With `short_limit` (2 rho_c), also the part of condition (5) that two edges decide: a
    walk that bends at both ends of an edge shorter than that, neither end A, has a segment
    whose neighbours come closer than its length (they meet its ends), so it is not valid.
    A short edge entered with a bend is then a state of its own (it may only go on
    straight); entered straight (or from A) it is the edge's ordinary state. In narrow
    streets most first walks broke (5) only this way, and the repair search cost seconds."""
    nodes = cache.nodes
    source, target = (GOAL, START) if backward else (START, GOAL)
    if backward or straight_line:
        heuristic = np.hypot(*(nodes.points - nodes.points[target]).T)
    else:
        heuristic = goal_distance(cache, budget, rows)
    heap: list[tuple[float, float, int, float, int]] = []
    # states: 2 e (edge e), 2 e + 1 (short edge e entered with a bend)
    pred: dict[int, int] = {}
    remaining: dict[int, np.ndarray] = {}
    left: dict[int, int] = {}  # out-edges of a node not relaxed yet
    bent_pushed: set[int] = set()
    floor = -math.sin(ANGLE_TOLERANCE)
    tick = 0
    pruned = False  # whether the short-edge rule refused a bend the others allowed

    def expand(v: int, state_in: int, g: float) -> None:
        nonlocal tick, pruned
        lo, hi = cache.edges(v)
        rem = remaining.get(v)
        if rem is None:
            rem = rows.mask(cache, v).copy()
            remaining[v] = rem
            left[v] = int(np.count_nonzero(rem))
        if left[v] == 0:
            return
        edge_in = state_in >> 1
        straight = None
        if state_in < 0:
            allowed = rem
        else:
            d_in = cache.direction[edge_in]
            dirs = cache.direction[lo:hi]
            bend = dirs @ d_in
            allowed = rem & (bend >= floor)
            if cache.taut and nodes.prunable[v]:
                allowed &= wraps_corner(
                    d_in, dirs, cache.side_at_dst[edge_in], cache.side_at_src[lo:hi]
                )
            if short_limit > 0.0:
                straight = _goes_straight(d_in, dirs, bend)
                if state_in & 1:  # a short edge entered with a bend goes on straight
                    pruned |= bool(np.any(allowed & ~straight))
                    allowed = allowed & straight
        local = np.flatnonzero(allowed)
        if len(local) == 0:
            return
        edge = lo + local
        state = 2 * edge
        if straight is not None:
            bent_short = ~straight[local] & (cache.length[edge] < short_limit)
            state[bent_short] += 1
            # the ordinary state of a short edge entered with a bend stays to be relaxed
            consumed = local[~bent_short]
        else:
            consumed = local
        rem[consumed] = False
        left[v] -= len(consumed)
        cost = g + cache.length[edge] + cache.penalty[edge]
        target = cache.dst[edge]
        score = cost + heuristic[target]
        for s_out, w, c, f in zip(
            state.tolist(), target.tolist(), cost.tolist(), score.tolist(), strict=True
        ):
            if left.get(w, 1) == 0 or f == math.inf:
                continue  # every out-edge of w is relaxed from a cheaper state, or B is out of reach
            if s_out & 1:
                if s_out in bent_pushed:
                    continue
                bent_pushed.add(s_out)
            pred[s_out] = state_in
            tick += 1
            heapq.heappush(heap, (f, -c, tick, c, s_out))

    budget.used += 1
    expand(source, -1, 0.0)
    while heap:
        f, _, _, g, state = heapq.heappop(heap)
        budget.floor = max(budget.floor, f)
        if f >= bound:
            return None, "bound"
        w = int(cache.dst[state >> 1])
        if w == target:
            walk = [state]
            while pred[walk[-1]] >= 0:
                walk.append(pred[walk[-1]])
            return [s >> 1 for s in walk[::-1]], "found"
        if left.get(w, 1) == 0:
            continue
        if budget.spent:
            return None, "cap"
        budget.used += 1
        expand(w, state, g)
    return None, "exhausted-short" if pruned else "exhausted"


def _label_search(  # noqa: C901 (over 15 branches: to split)
    problem: PathProblem,
    cache: EdgeCache,
    rows: _RowFilter,
    budget: _Budget,
    bound: float = math.inf,
    weight: float = 1.0,
) -> tuple[np.ndarray | None, str]:
    """Repair of conditions (5) and definition 1: enumerate partial walks in order of
    f = g + h (labels), up to `_LABELS_PER_STATE` per directed edge, extending a label only
    if the simplified path stays valid. The new (or grown) straight segment must keep 2 rho_c
    from every earlier segment but its predecessor; (1)-(4) hold by construction. The first
    label to reach B is the shortest valid path unless some edge ran out of labels
    (status "found" or "found-capped"); otherwise (None, "exhausted" | "capped" | "cap")."""
    nodes = cache.nodes
    pts = nodes.points
    goal = heuristic_of(cache, budget, rows)
    heuristic = goal.values
    relaxed = float(heuristic[START])  # the walk's length with the bend rule ignored
    pops = 0  # labels taken since the heuristic last ran on
    limit = _apart(problem)
    floor = -math.sin(ANGLE_TOLERANCE)
    # label fields: edge, g, open segment start (node), closed segments (linked tuples)
    lab_edge: list[int] = []
    lab_g: list[float] = []
    lab_open: list[int] = []
    lab_closed: list[tuple | None] = []
    heap: list[tuple[float, float, int]] = []
    settled: dict[int, int] = {}
    saturated = False

    # the closed segments of a linked tuple as arrays (start points, end points, bounding
    # boxes), built from its parent's when first needed (the parent's are there by then)
    closed_arrays: dict[int, tuple[np.ndarray, ...]] = {}

    def push(edge: np.ndarray, g: np.ndarray, open_start: np.ndarray, closed) -> None:
        first = len(lab_edge)
        lab_edge.extend(edge.tolist())
        lab_g.extend(g.tolist())
        lab_open.extend(open_start.tolist())
        lab_closed.extend([closed] * len(edge))
        f = g + weight * heuristic[cache.dst[edge]]
        for k, (fk, gk) in enumerate(zip(f.tolist(), g.tolist(), strict=True)):
            if fk < math.inf:  # (B out of reach from there)
                heapq.heappush(heap, (fk, -gk, first + k))

    def segments_of(closed) -> tuple[np.ndarray, ...]:
        key = id(closed)
        if key not in closed_arrays:
            a, b = pts[closed[0]][None, :], pts[closed[1]][None, :]
            row = (a, b, np.minimum(a, b), np.maximum(a, b))
            if closed[2] is not None:  # newest first
                parent = segments_of(closed[2])
                row = tuple(np.vstack([r, p]) for r, p in zip(row, parent, strict=True))
            closed_arrays[key] = row
        return closed_arrays[key]

    lo, hi = cache.edges(START)
    first = lo + np.flatnonzero(rows.mask(cache, START))
    budget.used += 1
    push(first, cache.length[first], np.full(len(first), START), None)
    while heap:
        f, _, label = heapq.heappop(heap)
        if weight == 1.0:
            pops += 1
            ripe = pops >= _LABELS_PER_SETTLED * goal.settled
            if f >= goal.reach and ripe and goal.open and not budget.spent:
                # The labels left lie beyond the exact part of the heuristic, and the labels
                # taken so far outnumber its settled nodes (a settled node may cost a tile of
                # edges, a label little): run it on, the window past L doubling each time,
                # then take the labels in their new order.
                window = max(2.0 * (f - relaxed), 2.0 * limit)
                goal.extend(relaxed + window, budget)
                heuristic = goal.values
                pops = 0
            fresh = lab_g[label] + float(heuristic[cache.dst[lab_edge[label]]])
            if fresh > f + DISTANCE_TOLERANCE:
                heapq.heappush(heap, (fresh, -lab_g[label], label))
                continue
        if not saturated and weight == 1.0:  # a dropped label may hide a path as short as f
            budget.floor = max(budget.floor, f)
        if f >= bound and weight == 1.0:
            return None, "bound"
        e = lab_edge[label]
        v = int(cache.dst[e])
        if lab_g[label] + float(heuristic[v]) >= bound:
            continue  # (weighted search) cannot beat the bound
        if v == GOAL:
            path = pts[[lab_open[label], GOAL]]
            if lab_closed[label] is not None:  # the closed segments' starts, oldest first
                path = np.vstack([segments_of(lab_closed[label])[0][::-1], path])
            return path, "found-capped" if saturated else "found"
        done = settled.get(e, 0)
        if done >= _LABELS_PER_STATE:
            saturated = True
            continue
        settled[e] = done + 1
        if budget.spent:
            return None, "cap"
        budget.used += 1
        lo, hi = cache.edges(v)
        if hi == lo:
            continue
        d_in = cache.direction[e]
        dirs = cache.direction[lo:hi]
        bend = dirs @ d_in
        allowed = rows.mask(cache, v) & (bend >= floor)
        if cache.taut and nodes.prunable[v]:
            allowed &= wraps_corner(d_in, dirs, cache.side_at_dst[e], cache.side_at_src[lo:hi])
        local = np.flatnonzero(allowed)
        if len(local) == 0:
            continue
        edge = lo + local
        straight = _goes_straight(d_in, dirs[local], bend[local])
        start = lab_open[label]
        seg_start = np.where(straight, start, v)
        closed = lab_closed[label]
        ok = np.ones(len(local), bool)
        if closed is not None:
            near = _segments_near(pts[seg_start], pts[cache.dst[edge]], segments_of(closed), limit)
            near[straight, 0] = False  # a grown segment is adjacent to the last closed one
            ok = ~near.any(axis=1)
        g = lab_g[label] + cache.length[edge]
        if np.any(ok & straight):
            pick = ok & straight
            push(edge[pick], g[pick], seg_start[pick], closed)
        if np.any(ok & ~straight):
            pick = ok & ~straight
            push(edge[pick], g[pick], seg_start[pick], (start, v, closed))
    return None, "capped" if saturated else "exhausted"


def _segments_near(
    starts: np.ndarray, ends: np.ndarray, old: tuple[np.ndarray, ...], limit: float
) -> np.ndarray:
    """(k, m): whether new segment i comes closer than `limit` to old segment j (`old`:
    start points, end points, and their boxes' low and high corners). Bounding boxes farther
    apart than `limit` settle most pairs; shapely measures the others."""
    old_starts, old_ends, old_low, old_high = old
    low, high = np.minimum(starts, ends), np.maximum(starts, ends)
    gap = np.maximum(old_low[None, :, :] - high[:, None, :], low[:, None, :] - old_high[None, :, :])
    gap = np.maximum(gap, 0.0)
    near = np.hypot(gap[..., 0], gap[..., 1]) < limit
    i, j = np.nonzero(near)
    if len(i):
        new = shapely.linestrings(np.stack([starts[i], ends[i]], axis=1))
        old = shapely.linestrings(np.stack([old_starts[j], old_ends[j]], axis=1))
        near[i, j] = shapely.distance(new, old) < limit
    return near


def _node_search(
    cache: EdgeCache, rows: _RowFilter, budget: _Budget, **relax: bool
) -> tuple[list[int] | None, str]:
    """A* over nodes (Dijkstra with the Euclidean heuristic): the paper's penalty loop, and
    (with the row filter relaxed) the unconstrained shortest path."""
    pts = cache.nodes.points
    heuristic = np.hypot(*(pts - pts[GOAL]).T)
    best = {START: 0.0}
    pred: dict[int, int] = {START: -1}
    done: set[int] = set()
    heap = [(float(heuristic[START]), 0, 0.0, START)]
    tick = 0
    while heap:
        _, _, g, v = heapq.heappop(heap)
        if v in done:
            continue
        if v == GOAL:
            walk = []
            while pred[v] >= 0:
                walk.append(pred[v])
                v = int(cache.src[pred[v]])
            return walk[::-1], "found"
        done.add(v)
        if budget.spent:
            return None, "cap"
        budget.used += 1
        lo, hi = cache.edges(v)
        if hi == lo:
            continue
        local = np.flatnonzero(rows.mask(cache, v, **relax))
        edge = lo + local
        cost = g + cache.length[edge] + cache.penalty[edge]
        for e, w, c in zip(edge.tolist(), cache.dst[edge].tolist(), cost.tolist(), strict=True):
            if w in done or c >= best.get(w, math.inf):
                continue
            best[w] = c
            pred[w] = e
            tick += 1
            heapq.heappush(heap, (c + float(heuristic[w]), tick, c, w))
    return None, "exhausted"


def _walk_points(cache: EdgeCache, walk: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Points of a walk with straight-through vertices removed, and for each walk edge the
    index of the simplified segment it belongs to."""
    pts = cache.nodes.points
    idx = np.concatenate([[START], cache.dst[np.asarray(walk)]])
    raw = pts[idx]
    vec = np.diff(raw, axis=0)
    cross = vec[:-1, 0] * vec[1:, 1] - vec[:-1, 1] * vec[1:, 0]
    dot = np.sum(vec[:-1] * vec[1:], axis=1)
    scale = np.hypot(*vec[:-1].T) * np.hypot(*vec[1:].T)
    straight = (np.abs(cross) <= ANGLE_TOLERANCE * scale) & (dot > 0)
    keep = np.concatenate([[True], ~straight, [True]])
    segment_of_edge = np.cumsum(keep[:-1]) - 1
    return raw[keep], segment_of_edge


def _offences(violations: PathViolations, segments: int) -> np.ndarray:
    """Eq. 46 with the docs/design.md 3.3 errata, per segment: non-adjacent segments closer than
    2 rho_c, plus adjacent bends over 90 degrees; anything else also counts once."""
    count = np.zeros(segments)
    if len(violations.proximity):
        pair = violations.proximity[:, :2].astype(np.int64)
        np.add.at(count, pair[:, 0], 1.0)
        np.add.at(count, pair[:, 1], 1.0)
    if len(violations.bends):
        vertex = violations.bends[:, 0].astype(np.int64)
        np.add.at(count, vertex - 1, 1.0)
        np.add.at(count, vertex, 1.0)
    for rows_ in (violations.obstacle, violations.start_row, violations.goal_row):
        if len(rows_):
            np.add.at(count, rows_[:, 0].astype(np.int64), 1.0)
    if violations.departure_angle_deg is not None:
        count[0] += 1.0
    if violations.arrival_angle_deg is not None:
        count[-1] += 1.0
    if violations.structure and not count.any():
        count += 1.0
    return count


@dataclass
class _LevelResult:
    path: np.ndarray | None
    rounds: int
    repairs: int
    # "found", "exhausted" (no walk at all), "repair" (walks, none valid), "repair-capped"
    # (none valid within the label limit), "cap" (max_expansions)
    status: str
    violations: PathViolations | None = None
    certified: bool = False
    lower_bound: float = 0.0  # proven lower bound on the shortest valid path (m)
    reason: str | None = None  # why there is no valid path, when that is proven already


def _exact_level(
    problem: PathProblem,
    cache: EdgeCache,
    rows: _RowFilter,
    budget: _Budget,
    bound: float = math.inf,
    explain: bool = False,
) -> _LevelResult:
    """Shortest walk meeting (1)-(4); if it breaks (5) or repeats a point, the label search
    for the shortest valid path (docs/design.md 3.3). With `bound`, only paths shorter than it.
    When the walk search's short-edge rule left no walk, there is no valid path either
    ("exhausted"); with `explain` (the search whose failure is diagnosed) the walks without
    that rule are searched too, so that the reason names condition (5) when it is the one."""
    limit = _apart(problem)
    walk, status = _walk_search(cache, rows, budget, bound, short_limit=limit)
    if status == "exhausted-short":
        if explain:
            walk, status = _walk_search(cache, rows, budget, bound)
        else:
            status = "exhausted"
    if walk is None:
        return _LevelResult(None, 1, 0, status)
    path, _ = _walk_points(cache, walk)
    first = check_path(path, problem, rows.rows)
    if first.ok:
        return _LevelResult(path, 1, 0, "found", first)
    # A quick repair first (weighted A*: greedy towards B), so a stopped search still has a
    # valid path; then the exact repair, bounded by it.
    quick, _ = _label_search(problem, cache, rows, budget, bound, weight=QUICK_REPAIR_WEIGHT)
    if quick is not None:
        bound = min(bound, _length(quick) - DISTANCE_TOLERANCE)
        budget.best = min(budget.best, _length(quick))
    path, status = _label_search(problem, cache, rows, budget, bound)
    if path is None and quick is not None:
        # the exact search proved nothing shorter (bound, exhausted) or was cut (cap, capped)
        path = quick
        status = "found" if status in ("bound", "exhausted") else "found-capped"
    if path is None:
        status = {"cap": "cap", "capped": "repair-capped", "bound": "bound"}.get(status, "repair")
        return _LevelResult(None, 2, 1, status, first)
    final = check_path(path, problem, rows.rows)
    if not final.ok:  # cannot happen: the label search keeps (1)-(5); never return it
        return _LevelResult(None, 2, 1, "repair", final)
    return _LevelResult(path, 2, 1, "found" if status == "found" else "found-capped", final)


def _at_most(bound: float) -> float:
    """`bound` with the tolerance of a length comparison (relative 1e-12, plus 1e-9 m)."""
    return bound * (1.0 + 1e-12) + DISTANCE_TOLERANCE


def _length(path: np.ndarray) -> float:
    return float(np.sum(np.hypot(*np.diff(path, axis=0).T)))


def _penalty_loop(
    problem: PathProblem, cache: EdgeCache, rows: _RowFilter, budget: _Budget
) -> _LevelResult:
    """The paper's Algorithm 1 (done as a real Dijkstra): search, check definition 4,
    raise the weight of each offending edge by I(P, e) x W (eqs. 43, 46, 47), search again;
    at most `max_penalty_iterations` rounds."""
    cache.penalty[: cache.size] = 0.0
    mean_weight = None
    last = None
    for round_ in range(1, problem.max_penalty_iterations + 1):
        walk, status = _node_search(cache, rows, budget)
        if walk is None:
            if round_ == 1 or status == "cap":
                return _LevelResult(None, round_, round_ - 1, status, last)
            return _LevelResult(None, round_, round_ - 1, "repair", last)
        path, segment_of_edge = _walk_points(cache, walk)
        violations = check_path(path, problem, rows.rows)
        if violations.ok:
            return _LevelResult(path, round_, round_ - 1, "found", violations)
        last = violations
        if mean_weight is None:
            mean_weight = float(np.mean(cache.length[: cache.size]))  # W, eq. 43
        offences = _offences(violations, len(path) - 1)
        cache.penalty[np.asarray(walk)] += offences[segment_of_edge] * mean_weight
        if budget.spent:
            return _LevelResult(None, round_, round_, "cap", last)
    count = problem.max_penalty_iterations
    return _LevelResult(None, count, count, "repair", last)


# ---------------------------------------------------------------------------------------
# Diagnosis
# ---------------------------------------------------------------------------------------


def _reaches_goal(cache: EdgeCache, filters: _RowFilter, budget: _Budget, **relax: bool) -> bool:
    """Whether B can be reached from A over edges, ignoring the bend rule (a breadth-first
    search over nodes); keyword flags switch parts of the row filter off."""
    return bool(_reachable(cache, filters, budget, START, GOAL, **relax)[0][GOAL])


def _walled_in(
    cache: EdgeCache, filters: _RowFilter, budget: _Budget, source: int, **relax: bool
) -> bool:
    """Whether the nodes reachable from `source` (A, or B with a backward filter) over
    edges, ignoring the bend rule, were all found before the budget ran out, without the
    other end among them."""
    target = START + GOAL - source
    seen, finished = _reachable(cache, filters, budget, source, target, **relax)
    return finished and not seen[target]


def _reachable(
    cache: EdgeCache, filters: _RowFilter, budget: _Budget, source: int, target: int, **relax
) -> tuple[np.ndarray, bool]:
    """The nodes a breadth-first search from `source` reached (over edges, ignoring the
    bend rule) before it reached `target`, ran out of nodes or of budget; and whether it
    ran out of nodes (every node reachable is among them)."""
    seen = np.zeros(len(cache.nodes), bool)
    seen[source] = True
    queue = collections.deque([source])
    while queue and not seen[target]:
        if budget.spent:
            return seen, False
        budget.used += 1
        v = queue.popleft()
        lo, hi = cache.edges(v)
        dst = cache.dst[lo:hi][filters.mask(cache, v, **relax)]
        dst = dst[~seen[dst]]
        seen[dst] = True
        queue.extend(dst.tolist())
    return seen, not queue


def _diagnose(problem: PathProblem, cache: EdgeCache, rows: _RowFilter, budget: _Budget) -> str:
    """Why the full graph holds no valid path (called after its search failed): relax one
    constraint at a time and name the one that makes B reachable."""
    if not rows.mask(cache, START, departure=False).any():
        return (
            "no straight segment leaves A clear of the obstacles by rho_c and of the row "
            "beyond B by 2 rho_c: A is boxed in"
        )
    if _reaches_goal(cache, rows, budget):
        return _explain(problem, "bends")
    departure = _reaches_goal(cache, rows, budget, departure=False)
    arrival = _reaches_goal(cache, rows, budget, arrival=False)
    if budget.spent:
        return _cap_reason(problem, budget)
    if departure or arrival:
        return _explain(problem, "departure" if departure else "arrival")
    if _reaches_goal(cache, rows, budget, departure=False, arrival=False):
        return _explain(problem, "both")
    if _reaches_goal(cache, rows, budget, departure=False, arrival=False, row_tests=False):
        return _explain(problem, "rows")
    if budget.spent:
        return _cap_reason(problem, budget)
    return _explain(problem, "unreachable")


def _explain(problem: PathProblem, culprit: str) -> str:
    """The reason no valid path exists, for the constraint found to rule them all out:
    "bends", "departure", "arrival", "both" (the angles at both ends), "rows" or
    "unreachable" (the obstacles alone)."""
    theta_a, theta_b = problem.start_angle_deg, problem.goal_angle_deg
    leg = problem.start_tail is not None  # a leg of a route (planner.route, docs/design.md 7)
    if culprit == "bends":
        return (
            "every route from A to B needs a bend sharper than 90 degrees (condition 4 of "
            "definition 4), for example to turn round where no obstacle corner allows it"
        )
    if culprit == "departure" and leg:
        return (
            "every way on turns more than 90 degrees from the segment the route arrives on "
            "(condition 4 at the point)"
        )
    if culprit == "departure":
        return (
            "every route needs a sharp bend at departure: the first segment of every route "
            f"turns more than 90 degrees from the start row direction (theta_A = {theta_a:g} deg)"
        )
    if culprit == "arrival":
        return (
            "every route needs a sharp bend at arrival: the last segment of every route turns "
            f"more than 90 degrees from the goal row direction (theta_B = {theta_b:g} deg)"
        )
    if culprit == "both":
        return (
            "every route needs sharp bends at both departure and arrival (more than 90 "
            f"degrees from the row directions, theta_A = {theta_a:g} deg, "
            f"theta_B = {theta_b:g} deg)"
        )
    if culprit == "rows" and leg:
        return (
            "every way there comes within 2 rho_c of the route flown before it or of the "
            "parking row at A (condition 5 across legs)"
        )
    if culprit == "rows":
        return (
            "the parking rows cut every route: no path keeps 2 rho_c from the row behind A "
            "and the row beyond B (eq. 35); change theta_A/theta_B or the fleet size"
        )
    return (
        "B is unreachable from A: the obstacles with their rho_c margins leave no corridor "
        "between them"
    )


#: Appended to a reason found on radius-limited graphs: they lack the longer edges, so
#: running dry proves nothing (`_Planner._pocket` proves the common case, an end in a pocket).
_RADIUS_LIMITED = (
    "(so the graph limited to each node's neighbourhood shows, on a map too large to examine "
    "every pair of nodes: not proven)"
)

_SEPARATED = (
    "B is unreachable from A: the obstacles with their rho_c margins wall one of them in "
    "(A and B lie in different parts of the free space)"
)


def _cap_reason(problem: PathProblem, budget: _Budget | None = None) -> str:
    if budget is not None and budget.stopped:
        return (
            f"the search was stopped (time limit) after {budget.used} expansions without "
            "finding a valid path"
        )
    return (
        f"the search stopped at its cap of {problem.max_expansions} expansions "
        "(max_expansions) without finding a valid path"
    )


# ---------------------------------------------------------------------------------------
# Planner
# ---------------------------------------------------------------------------------------


class _Planner:
    """Holds the nodes and edge caches of one problem across fleet-size rounds."""

    def __init__(
        self, problem: PathProblem, progress: Callable[[SearchProgress], bool] | None = None
    ) -> None:
        self.problem = problem
        self.straight = float(np.hypot(*(problem.goal - problem.start)))
        poll = None
        if progress is not None:

            def poll(used: int) -> bool:
                best = self.budget.best
                bound = self.straight
                if self.budget.proving:
                    bound = max(bound, self.budget.floor)
                bound = min(bound, best)
                return progress(SearchProgress(used, best if best < math.inf else math.nan, bound))

        self.budget = _Budget(problem.max_expansions, poll=poll)
        self.nodes = graph_nodes(problem)
        self.occlusion = Occlusion(self.nodes, problem.obstacles, problem.safety_margin)
        self._caches: dict[str, EdgeCache] = {}
        self._retired: list[EdgeCache] = []

    def cache(self, level: str) -> EdgeCache:
        if level not in self._caches:
            self._caches[level] = EdgeCache(
                self.problem,
                self.nodes,
                taut=level == "taut",
                prune_collinear=level != "penalty",
                local_candidates={"taut": LOCAL_CANDIDATES, "full": LOCAL_CANDIDATES_FULL}.get(
                    level
                ),
                occlusion=self.occlusion,
                to_start=level == "to-start",
            )
        return self._caches[level]

    @property
    def all_caches(self) -> list[EdgeCache]:
        """Every cache of this problem, the ellipses outgrown included (their work counts)."""
        return [*self._caches.values(), *self._retired]

    @property
    def edges_examined(self) -> int:
        return sum(c.examined for c in self.all_caches)

    @property
    def candidate_edges(self) -> np.ndarray:
        found = [c.computed_edges() for c in self.all_caches]
        return np.concatenate(found) if found else np.zeros((0, 2, 2))

    def solve(self, rows: ParkingRows) -> tuple[_LevelResult, str, str | None]:
        """(result, level, reason) for one set of rows."""
        rows_filter = _RowFilter(self.problem, rows, self.nodes)
        if self.problem.method == "penalty":
            result = _penalty_loop(self.problem, self.cache("penalty"), rows_filter, self.budget)
            if result.path is not None:
                return result, "penalty", None
            return result, "penalty", self._why(result, rows_filter, "penalty")
        found = self._ellipse_search(rows_filter) if self.cache("taut").radius else None
        if found is not None:
            result, level = found
            if result.path is None or result.certified:  # B in a pocket (`_pocket`), or proven
                return result, level, result.reason
            return self._certify(result, rows_filter, level)
        taut = _exact_level(self.problem, self.cache("taut"), rows_filter, self.budget)
        if taut.path is not None:
            return self._certify(taut, rows_filter, "taut")
        problem = self.problem
        if taut.status == "exhausted" and problem.obstacles.separated(
            problem.start, problem.goal, problem.safety_margin - DISTANCE_TOLERANCE
        ):
            return taut, "full", _SEPARATED
        radius_limited = self.cache("full").radius is not None
        if taut.status == "exhausted" and radius_limited:
            reason = self._pocket(rows, GOAL, self.cache("taut"))
            if reason is not None:
                return taut, "full", reason
        if taut.status != "cap":
            full = _exact_level(
                self.problem, self.cache("full"), rows_filter, self.budget, explain=True
            )
            if full.path is not None:
                return self._from_full_graph(full, complete=not radius_limited), "full", None
            taut = full
        if radius_limited and taut.status != "cap":
            # the radius-limited graphs ran dry, which proves nothing: A in a pocket?
            reason = self._pocket(rows, START)
            if reason is not None:
                return taut, "full", reason
        reason = self._why(taut, rows_filter, "full")
        if radius_limited and not self.budget.spent:
            reason += f" {_RADIUS_LIMITED}"
        return taut, "full", reason

    def _ellipse_search(self, rows: _RowFilter) -> tuple[_LevelResult, str] | None:
        """On a map too large for complete candidate sets: the graph with every pair
        examined inside the ellipse |Av| + |vB| < L, searched for a valid path shorter than
        L, L from `ELLIPSE_START` x |AB| growing by `ELLIPSE_GROWTH` until one is found. None
        when the ellipse outgrows `CERTIFY_NODES` nodes (or the budget is spent): the
        radius-limited taut graph is searched instead.

        The first ellipse is searched in the taut graph: a path as short as the straight
        line needs no proof, and any other is then proven over the full graph inside its own
        ellipse (`_certify`). Where the taut graph has no valid path there although a route
        shorter than L exists (the shortest walk keeping the rows and angles, bends
        ignored), the radius-limited full graph is searched with the same bound: the taut
        graph bends only where a path wraps a corner, and a parking row or angle may need a
        bend it does not have (a Vienna street: no taut walk at all, 47 s spent growing the
        ellipse and exhausting the taut graph before the full graph's 0.6 s search found the
        path). After that first ellipse searched in vain, B may be proven walled in
        (`_pocket`): the result then has no path, and its reason.

        A grown ellipse is searched in the full graph of definition 5 at once: a path longer
        than 1.15 |AB| would need that proof anyway, and the one search costs less than the
        taut graph's followed by the full graph's (Vienna 3.7 km route 2: 5.5 -> 4.4 s). Its
        path, the shortest valid one shorter than L when the search ran to the end, comes
        back certified."""
        length = self.straight * ELLIPSE_START
        taut = True
        while not self.budget.spent:
            cache = self.certify_cache(length, taut=taut)
            if cache is None:
                return None
            result = _exact_level(self.problem, cache, rows, self.budget, length)
            if result.path is not None and taut:
                return result, "taut"
            if result.path is not None:
                self.budget.best = min(self.budget.best, _length(result.path))
                return self._from_full_graph(result, complete=True), "full"
            if result.status == "cap":
                return None
            if taut:
                # Routes shorter than L over the taut graph, bends ignored (the full graph
                # may have shorter ones: this only decides where to look).
                free = self._relaxed_length(cache, rows)
                if free < length:  # routes shorter than L exist, none valid in the taut graph
                    full = _exact_level(self.problem, self.cache("full"), rows, self.budget, length)
                    if full.path is not None:
                        return full, "full"
                    if full.status in ("cap", "exhausted"):
                        return None  # no walk at all in the full graph: growing L cannot help
                reason = self._pocket(rows.rows, GOAL, cache)
                if reason is not None:
                    return _LevelResult(None, 1, 0, "exhausted", reason=reason), "full"
            taut = False
            length *= ELLIPSE_GROWTH
        return None

    def _from_full_graph(self, result: _LevelResult, complete: bool) -> _LevelResult:
        """`result`, a path the full graph of definition 5 gave, certified when that graph
        had complete candidate sets (every path the search bounds is in it) and the search
        ran to the end; its lower bound otherwise the straight line."""
        result.certified = complete and result.status == "found"
        result.lower_bound = _length(result.path) if result.certified else self.straight
        return result

    def _pocket(self, rows: ParkingRows, end: int, gate: EdgeCache | None = None) -> str | None:
        """Where B (`end` GOAL) or A lies in a pocket that no walk meeting conditions (1)-(4)
        leaves (a dead end whose way out needs a sharp bend, say), a large map's ellipses
        grow in vain and the radius-limited graphs searched next prove nothing when they run
        dry, after minutes (a Vienna street: stopped at 60 s). This proves in seconds that no
        valid path exists: the walk search from that end (from B back to A, each edge
        standing for the path's segment the other way round; the rules are symmetric) over
        complete candidate sets runs out of edges within its budget (`_end_budget`).
        Returns the reason, naming the rule that closes the pocket: the breadth-first search
        from that end, bends ignored, finds every node it can reach unless that rule is
        relaxed too. None when there is no such proof.

        B's pocket is looked for after the first ellipse searched in vain, and when the taut
        graph has no walk at all but the full graph would be radius-limited; A's when the
        radius-limited graphs ran dry. The graph just searched (`gate`), whose edges round
        the end are mostly computed already, is tried first: where the walks get away there,
        the end is taken to be in no pocket."""
        backward = end == GOAL
        filters = _RowFilter(self.problem, rows, self.nodes, backward=backward)
        cache = self.cache("to-start")
        for graph in (gate, cache) if gate is not None else (cache,):
            budget = self._end_budget(graph)
            _, status = _walk_search(
                graph,
                filters,
                budget,
                short_limit=_apart(self.problem),
                backward=backward,
                straight_line=True,
            )
            self.budget.used += budget.used
            if status not in ("exhausted", "exhausted-short"):
                return None
        angle = "arrival" if backward else "departure"
        tests = (
            ("bends", {}),
            (angle, {angle: False}),
            ("rows", {angle: False, "row_tests": False}),
        )
        for culprit, relax in tests:
            budget = self._end_budget(cache)
            walled_in = _walled_in(cache, filters, budget, end, **relax)
            self.budget.used += budget.used
            if not walled_in:
                return _explain(self.problem, culprit)
        return _explain(self.problem, "unreachable")

    def _end_budget(self, cache: EdgeCache) -> _Budget:
        """A budget for a search from an end (`_pocket`), spent once `cache` has
        computed the out-edges of `END_NODES` more nodes, after `END_EXPANSIONS`
        expansions, or with the plan's: it passes the stop request on (the caller adds its
        expansions to the plan's)."""
        plan, cap = self.budget, cache.computed + END_NODES

        def poll(used: int) -> bool:
            if plan.poll is not None and not plan.stopped:
                plan.stopped = bool(plan.poll(plan.used + used))
            return plan.stopped or cache.computed >= cap

        return _Budget(min(END_EXPANSIONS, max(plan.limit - plan.used, 0)), poll=poll, poll_every=1)

    def certify_cache(self, length: float, taut: bool = False) -> EdgeCache | None:
        """The full graph of definition 5 (or the taut graph) inside the ellipse
        |Av| + |vB| < `length` (no shorter path leaves it), with complete candidate sets; None
        when the ellipse holds more than `CERTIFY_NODES` nodes."""
        pts = self.nodes.points
        detour = np.hypot(*(pts - pts[START]).T) + np.hypot(*(pts - pts[GOAL]).T)
        if np.count_nonzero(detour < length + DISTANCE_TOLERANCE) > CERTIFY_NODES:
            return None
        key = "certify-taut" if taut else "certify"
        if key in self._caches:  # kept alive: row filters key their masks by id(cache)
            self._retired.append(self._caches[key])
        self._caches[key] = EdgeCache(
            self.problem,
            self.nodes,
            taut=taut,
            prune_collinear=True,
            within=length,
            occlusion=self.occlusion,
        )
        return self._caches[key]

    def _relaxed_length(self, cache: EdgeCache, rows: _RowFilter) -> float:
        """The shortest walk A -> B over the cache's edges that `rows` let through, the bend
        rule and condition 5 ignored: the heuristic's value at A, a lower bound on every
        valid path in that graph."""
        return float(goal_distance(cache, self.budget, rows)[START])

    def _certify(
        self, taut: _LevelResult, rows: _RowFilter, level: str
    ) -> tuple[_LevelResult, str, None]:
        """Prove the path found shortest, or find a shorter one (`level`: the graph it came
        from, taut or, when the taut graph had none, full; "the taut path" below). As short
        as the straight line, it is. The full graph of definition 5 inside the ellipse of the
        taut length L (`certify_cache`, complete candidate sets) holds every path shorter than
        L. A valid path as short as the shortest walk there that keeps the rows and parking
        angles (the heuristic's value at A, bends and condition 5 ignored) is the shortest:
        no valid path can beat it. Otherwise that graph is searched for a valid path shorter
        than L: the one found is certified if the search was exhaustive or it meets that
        value, and if there is none the taut path is. A search cut short (cap or stop request) leaves the best proven
        lower bound: that value, or the last f the bounded search reached.

        The taut graph's own unconstrained length is no such bound: the full graph's
        shortest path can bend at nodes the taut graph leaves out or may not bend at (a
        node between two footprints, on the margin of one; random maps: up to 29 m shorter),
        so it is never used to certify."""
        length = _length(taut.path)
        self.budget.best = min(self.budget.best, length)
        taut.lower_bound = self.straight
        gap = self.problem.gap_tolerance
        if length <= _at_most(self.straight):
            taut.certified = True
            return taut, level, None
        if self.budget.spent or within_gap(length, taut.lower_bound, gap):
            return taut, level, None
        full_cache = self.certify_cache(length)
        if full_cache is None:
            return taut, level, None
        free = self._relaxed_length(full_cache, rows)
        taut.lower_bound = max(self.straight, min(free, length))
        if length <= _at_most(free):
            taut.certified = True
            taut.lower_bound = length
            return taut, level, None
        if self.budget.spent or within_gap(length, taut.lower_bound, gap):
            return taut, level, None
        self.budget.floor, self.budget.proving = 0.0, True
        # Only a path shorter by more than the gap tolerance would matter.
        sought = length * (1.0 - gap) - DISTANCE_TOLERANCE
        full = _exact_level(self.problem, full_cache, rows, self.budget, sought)
        self.budget.proving = False
        floor = max(taut.lower_bound, min(self.budget.floor, length))
        if full.path is not None:
            found = _length(full.path)
            full.certified = full.status == "found" or found <= _at_most(free)
            full.lower_bound = found if full.certified else min(floor, found)
            return full, "full", None
        exhaustive = full.status in ("bound", "exhausted", "repair")
        taut.certified = exhaustive and gap == 0.0
        if taut.certified:
            taut.lower_bound = length
        else:
            taut.lower_bound = max(floor, min(sought, length)) if exhaustive else floor
        return taut, level, None

    def _why(self, result: _LevelResult, rows: _RowFilter, level: str) -> str:
        if result.status == "cap" or self.budget.spent:
            return _cap_reason(self.problem, self.budget)
        what = result.violations.describe() if result.violations else None
        if result.status == "repair" and level == "penalty":
            return (
                f"the paper's penalty loop found no valid path in {result.rounds} rounds "
                f"(max_penalty_iterations; last try: {what})"
            )
        if result.status == "repair":
            return (
                "no valid path exists: every route meeting conditions (1)-(4) of definition 4 "
                f"comes back within 2 rho_c of itself (condition 5; the shortest: {what})"
            )
        if result.status == "repair-capped":
            return (
                "no valid path found: the routes meeting conditions (1)-(4) of definition 4 "
                f"come back within 2 rho_c of themselves (condition 5; the shortest: {what}), "
                f"and the repair search kept {_LABELS_PER_STATE} partial routes per edge"
            )
        return _diagnose(self.problem, self.cache(level), rows, self.budget)


def _rows(problem: PathProblem, fleet_size: int) -> ParkingRows:
    return problem.rows(fleet_size)


def plan_path(
    problem: PathProblem, progress: Callable[[SearchProgress], bool] | None = None
) -> PathPlan:
    """Plan a valid path (definition 4) from A to B, or say why there is none.

    `progress`, when given, is called at every expansion with a `SearchProgress`;
    returning True stops the search: the plan is then the shortest valid path found so far
    (`stopped`, not certified) or, with none found yet, invalid. The planner has no clock:
    a time limit is the caller's `progress`.

    With finite rows ("segment"), N starts at the straight-line bound (or the given fleet
    size), and the path is planned again while it needs more UAVs than the rows were sized
    for (N only grows, docs/design.md 3.2). `fleet_size` is the N the rows are sized for (at least
    the requested size), `min_fleet_size` eq. 28 for the path found.
    """
    rho, radio = problem.safety_margin, problem.radio_range
    straight = float(np.hypot(*(problem.goal - problem.start)))
    reason = precheck(problem)
    try:
        lower = min_fleet_size(straight, rho, radio)
    except ValueError:
        lower = 1
    size = max(problem.fleet_size or 1, lower)
    if reason is not None:
        return _invalid(problem, reason, size, lower, _rows(problem, size))
    planner = _Planner(problem, progress)
    for fleet_round in range(1, MAX_FLEET_ROUNDS + 1):
        rows = _rows(problem, size)
        reason = check_rows(problem, rows)
        if reason is not None:
            uavs = plural(size, "UAV")
            reason = f"the path needs {uavs} (eq. 28), and with {uavs} {reason}"
            return _invalid(problem, reason, size, lower, rows, planner, fleet_round)
        result, level, reason = planner.solve(rows)
        if result.path is None:
            if fleet_round > 1 and problem.parking == "segment":
                reason = (
                    f"{reason} (with the parking rows sized for the {plural(size, 'UAV')} that the "
                    "shorter routes need, eq. 28)"
                )
            return _invalid(problem, reason, size, lower, rows, planner, fleet_round, result)
        length = _length(result.path)
        need = min_fleet_size(length, rho, radio)
        if need > size and problem.parking == "segment":
            # Longer rows only remove edges: if this path is still valid with rows for
            # `need` UAVs, it is still the shortest, and no new search is needed.
            grown = _rows(problem, need)
            if check_rows(problem, grown) is None and check_path(result.path, problem, grown).ok:
                size, rows = need, grown
        if need <= size or problem.parking == "ray":
            return PathPlan(
                valid=True,
                reason=None,
                path=result.path,
                length_m=length,
                fleet_size=max(size, need),
                min_fleet_size=need,
                rows=rows if need <= size else _rows(problem, need),
                iterations=result.rounds,
                expansions=planner.budget.used,
                node_count=len(planner.nodes),
                edges_examined=planner.edges_examined,
                candidate_edges=planner.candidate_edges,
                violations=result.violations,
                certified=result.certified,
                level=level,
                repairs=result.repairs,
                fleet_rounds=fleet_round,
                edge_count=sum(c.size for c in planner.all_caches),
                lower_bound_m=length if result.certified else min(result.lower_bound, length),
                stopped=planner.budget.stopped,
                gap_tolerance=problem.gap_tolerance,
            )
        size = need
    return _invalid(
        problem,
        f"the fleet size kept growing with the path for {MAX_FLEET_ROUNDS} rounds",
        size,
        lower,
        _rows(problem, size),
        planner,
        MAX_FLEET_ROUNDS,
    )


def _invalid(
    problem: PathProblem,
    reason: str,
    size: int,
    lower: int,
    rows: ParkingRows,
    planner: _Planner | None = None,
    fleet_round: int = 1,
    result: _LevelResult | None = None,
) -> PathPlan:
    return PathPlan(
        valid=False,
        reason=reason,
        path=np.zeros((0, 2)),
        length_m=math.nan,
        fleet_size=size,
        min_fleet_size=lower,
        rows=rows,
        iterations=result.rounds if result else 0,
        expansions=planner.budget.used if planner else 0,
        node_count=len(planner.nodes) if planner else 0,
        edges_examined=planner.edges_examined if planner else 0,
        candidate_edges=planner.candidate_edges if planner else np.zeros((0, 2, 2)),
        violations=result.violations if result else None,
        level="",
        repairs=result.repairs if result else 0,
        fleet_rounds=fleet_round,
        stopped=planner.budget.stopped if planner else False,
    )
