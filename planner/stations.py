"""Monitoring stations (use case 1, paper sec. III-C1; docs/design.md 7): the order in which the
fleet visits the points, and where along the route A -> P_1 -> ... -> P_m each UAV stops.

Stations are distances along the route from A (docs/design.md 7, "Stations"): s_1 > s_2 > ... > s_N,
consecutive ones at least dS_c and at most dS_r apart, dS_c <= s_N <= dS_r (the chain reaches
the base station at A), every point exactly on one station, N the fewest UAVs allowing this.
Distances carry the `DISTANCE_TOLERANCE` of docs/design.md 3.2.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from fleetline.errors import FleetlineError
from planner.formation import DISTANCE_TOLERANCE, collision_spacing, radio_spacing
from planner.numbers import digits_against, fmt_against, plural

__all__ = [
    "StationError",
    "StationLayout",
    "route_length",
    "station_layout",
    "visit_order",
    "visit_orders",
]

#: Largest number of points whose route `visit_order` finds exactly (docs/design.md 7).
EXACT_POINTS = 8
#: Seed of the annealing for more points: equal inputs give equal routes.
TSP_SEED = 0


def route_length(start: np.ndarray, points: np.ndarray, order: np.ndarray) -> float:
    """Length of the open polyline A -> points[order[0]] -> points[order[1]] -> ..."""
    start = np.asarray(start, float)
    points = np.asarray(points, float).reshape(-1, start.size)
    path = np.vstack([start[None], points[np.asarray(order, int)]])
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def visit_order(start: np.ndarray, points: np.ndarray, order: str = "tsp") -> np.ndarray:
    """Indices into `points` in visiting order (docs/design.md 7, "Order").

    "given": the list's order. "tsp": the shortest open route from A through every point
    (ending anywhere, straight-line distances): exact for m <= EXACT_POINTS (every permutation,
    vectorised); beyond, networkx's simulated annealing (fixed seed) started from the
    nearest-neighbour route, then 2-opt, so never longer than the nearest-neighbour route.
    """
    start = np.asarray(start, float)
    points = np.asarray(points, float).reshape(-1, start.size)
    m = len(points)
    if order == "given" or (order == "tsp" and m <= 1):
        return np.arange(m)
    if order != "tsp":
        raise ValueError(f"order must be 'tsp' or 'given', not {order!r}")
    dist = _distances(start, points)
    if m <= EXACT_POINTS:
        return _shortest_orders(dist, 1)[0]
    return _two_opt(dist, _annealed(dist, _nearest_neighbour(dist))) - 1


def _distances(start: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance matrix of node 0 = A and node i + 1 = points[i]."""
    nodes = np.vstack([start[None], points])
    return np.linalg.norm(nodes[:, None] - nodes[None], axis=2)


def _shortest_orders(dist: np.ndarray, count: int) -> np.ndarray:
    """The `count` shortest open routes from node 0 through every other node, every
    permutation scored at once (vectorised), shortest first, ties in permutation order; as
    indices into the points (node - 1)."""
    perms = np.array(list(itertools.permutations(range(1, len(dist)))))
    cost = dist[0, perms[:, 0]] + dist[perms[:, :-1], perms[:, 1:]].sum(axis=1)
    return perms[np.argsort(cost, kind="stable")[:count]] - 1


def visit_orders(
    start: np.ndarray, points: np.ndarray, order: str = "tsp", count: int = 1
) -> list[np.ndarray]:
    """`visit_order` first, then (tsp, m <= EXACT_POINTS) the next shortest open routes, at
    most `count` in all, shortest first (ties in permutation order)."""
    start = np.asarray(start, float)
    points = np.asarray(points, float).reshape(-1, start.size)
    m = len(points)
    if order != "tsp" or m <= 1 or m > EXACT_POINTS or count <= 1:
        return [visit_order(start, points, order)]
    return list(_shortest_orders(_distances(start, points), count))


def _nearest_neighbour(dist: np.ndarray) -> np.ndarray:
    """Open route from node 0, always to the nearest unvisited node (lowest index on ties)."""
    route, free = [0], np.ones(len(dist), bool)
    free[0] = False
    for _ in range(len(dist) - 1):
        route.append(int(np.argmin(np.where(free, dist[route[-1]], np.inf))))
        free[route[-1]] = False
    return np.array(route[1:])


def _annealed(dist: np.ndarray, route: np.ndarray) -> np.ndarray:
    """networkx's simulated annealing on the open route from node 0, as a closed tour.

    A dummy node D is 0 from every node, and every edge at A costs BIG more (D-A excepted):
    a tour pays BIG once iff A's neighbours are D and one point, which makes it an open route
    from A plus BIG; with BIG above any open route, every other tour costs more. Annealing
    keeps its best tour and starts from `route`, so the result is never longer. (Not through
    `traveling_salesman_problem`: it replaces weights by shortest paths, which would pass D.)
    """
    import networkx as nx  # here: only routes of more than EXACT_POINTS points need it

    n = len(dist)
    dummy, big = n, 1.0 + n * float(dist.max())
    graph = nx.complete_graph(n + 1)
    for u, v in graph.edges:
        w = 0.0 if dummy in (u, v) else float(dist[u, v]) + (big if 0 in (u, v) else 0.0)
        graph.edges[u, v]["weight"] = w
    init = [0, *map(int, route), dummy, 0]
    tour = nx.approximation.simulated_annealing_tsp(graph, init, source=0, seed=TSP_SEED)[:-1]
    if tour[1] == dummy:  # the route runs the other way round the tour
        tour = [0, *tour[:0:-1]]
    return np.array(tour[1:-1])


def _two_opt(dist: np.ndarray, route: np.ndarray) -> np.ndarray:
    """Best-improvement 2-opt on an open route from node 0 (deterministic): reverse the
    stretch route[i..j] while some reversal shortens the route by more than the tolerance."""
    m = len(route)
    # Padded with a free end E (0 from every node): the route is 0 -> route -> E.
    free_end = np.zeros((len(dist) + 1, len(dist) + 1))
    free_end[:-1, :-1] = dist
    i, j = np.triu_indices(m, 1)  # reverse route[i..j], 0 <= i < j < m
    while True:
        q = np.concatenate([[0], route, [len(dist)]])  # q[k + 1] is route[k]
        gain = (
            free_end[q[i], q[j + 1]]
            + free_end[q[i + 1], q[j + 2]]
            - free_end[q[i], q[i + 1]]
            - free_end[q[j + 1], q[j + 2]]
        )
        best = int(np.argmin(gain))
        if gain[best] >= -DISTANCE_TOLERANCE:
            return route
        route = np.concatenate(
            [route[: i[best]], route[i[best] : j[best] + 1][::-1], route[j[best] + 1 :]]
        )


class StationError(FleetlineError, ValueError):
    """No stations fit the gap before point `point` (0-based, in visiting order)."""

    def __init__(self, point: int, message: str) -> None:
        super().__init__(message)
        self.point = point


@dataclass(frozen=True, eq=False)
class StationLayout:
    """Stations of UAVs 1..N (docs/design.md 7): `stations[n - 1]` is s_n, metres along the route,
    decreasing; `holders[i]` is the UAV (1-based) holding point i (visiting order);
    `relays[n - 1]` is True when UAV n holds no point."""

    stations: np.ndarray  # (N,) float
    holders: np.ndarray  # (m,) int
    fleet_size: int
    relays: np.ndarray  # (N,) bool
    minimum: int = 0  # the fewest UAVs these points need (N when no more were asked for)

    def __post_init__(self) -> None:
        if not self.minimum:
            object.__setattr__(self, "minimum", self.fleet_size)


def station_layout(
    point_distances: np.ndarray,
    safety_margin: float,
    radio_range: float,
    fleet_size: int | None = None,
) -> StationLayout:
    """Stations for points at `point_distances` along the route (increasing; docs/design.md 7).

    Gap i runs from d_{i-1} to d_i (d_0 = 0, at A) and gets c_i = ceil(g_i / dS_r) stations,
    at least one, evenly spaced and ending on d_i (a tolerance keeps an exact multiple of dS_r
    from rounding up, as in `min_fleet_size`); it is feasible iff c_i dS_c <= g_i.
    N = sum c_i is the minimum: each gap needs at least ceil(g_i / dS_r) stations in
    (d_{i-1}, d_i], its last on d_i, and more stations only make the dS_c floor (c dS_c <= g_i)
    harder to meet; the gaps do not interact, every point being a station.
    Raises StationError naming the first gap that cannot be split.

    A `fleet_size` above that minimum adds relays one at a time to the gap whose spacing
    stays the widest (g_i / (c_i + 1)) while c_i + 1 stations still fit dS_c apart; more
    UAVs than every gap can space so raise ValueError.
    """
    d = np.asarray(point_distances, float).reshape(-1)
    spacing_c = collision_spacing(safety_margin)
    spacing_r = radio_spacing(safety_margin, radio_range)
    if not (safety_margin > 0 and spacing_r > 0):
        raise ValueError("safety_margin must be positive and radio_range above 2 * safety_margin")
    if len(d) == 0 or not np.isfinite(d).all():
        raise ValueError("point_distances must be finite, at least one")
    gaps = np.diff(d, prepend=0.0)
    if (gaps < 0).any():
        raise ValueError("point_distances must increase along the route")
    counts = np.maximum(1, np.ceil((gaps - DISTANCE_TOLERANCE) / spacing_r)).astype(int)
    bad = np.flatnonzero(counts * spacing_c > gaps + DISTANCE_TOLERANCE)
    if len(bad):
        raise StationError(
            int(bad[0]), _gap_message(int(bad[0]), gaps, counts, spacing_c, spacing_r)
        )
    minimum = int(counts.sum())
    if fleet_size is not None and fleet_size > minimum:
        capacity = np.floor((gaps + DISTANCE_TOLERANCE) / spacing_c).astype(int)
        if fleet_size > capacity.sum():
            raise ValueError(
                f"{plural(fleet_size, 'UAV')} cannot all hold stations at least dS_c = "
                f"{spacing_c:.4g} m apart on this route: at most {int(capacity.sum())} can"
            )
        for _ in range(fleet_size - minimum):
            room = np.where(counts < capacity, gaps / (counts + 1), -np.inf)
            counts[int(np.argmax(room))] += 1
    gap_of = np.repeat(np.arange(len(d)), counts)  # ascending stations, by gap
    last = np.cumsum(counts)  # 1 + index of each point's station, ascending
    k = last[gap_of] - np.arange(last[-1]) - 1  # stations before the gap's point: c-1 .. 0
    ascending = d[gap_of] - gaps[gap_of] * k / counts[gap_of]
    fleet = int(last[-1])
    holders = fleet + 1 - last
    relays = np.ones(fleet, bool)
    relays[holders - 1] = False
    return StationLayout(ascending[::-1].copy(), holders, fleet, relays, minimum)


def _gap_message(i: int, gaps: np.ndarray, counts: np.ndarray, dsc: float, dsr: float) -> str:
    """One sentence: why the gap before point i takes no stations."""
    g, c = float(gaps[i]), int(counts[i])
    head = f"point {i} is {{}} m along the route from {f'point {i - 1}' if i else 'A'}"
    if c == 1:
        return (
            head.format(fmt_against(g, dsc))
            + f"; stations must be at least dS_c = {fmt_against(dsc, g)} m apart"
        )
    split, floor = (c - 1) * dsr, c * dsc
    g_text = fmt_against(g, floor, digits_against(g, split))
    times = f"{c - 1} x " if c > 2 else ""
    return head.format(g_text) + (
        f", more than {times}dS_r = {fmt_against(split, g)} m, so it needs"
        f" {plural(c, 'station')}, and {c} stations at least dS_c = {fmt_against(dsc, g / c)} m"
        f" apart need {fmt_against(floor, g)} m"
    )
