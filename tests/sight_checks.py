"""Line of sight checked independently of `planner.sight` (plain shapely, one chord at a time,
and networkx): the oracles of the line-of-sight tests."""

from __future__ import annotations

import numpy as np
import shapely


def shapely_blocked(polygons, walls, start, end, margin: float) -> bool:
    line = shapely.LineString([start, end])
    shapes = [shapely.Polygon(p) for p in polygons] + [shapely.LineString(w) for w in walls]
    return any(line.distance(shape) <= margin for shape in shapes)


def brute_connected(xy: np.ndarray, stations: np.ndarray, polygons, walls, radio: float) -> bool:
    """Every UAV reaches a station by hops within `radio` whose chords meet no obstacle:
    networkx over plain shapely tests, one chord at a time."""
    import networkx as nx

    nodes = [("uav", i, p) for i, p in enumerate(xy)] + [
        ("bs", k, p) for k, p in enumerate(stations)
    ]
    graph = nx.Graph()
    graph.add_nodes_from(range(len(nodes)))
    for a in range(len(nodes)):
        for b in range(a + 1, len(nodes)):
            if nodes[a][0] == nodes[b][0] == "bs":
                continue
            pa, pb = nodes[a][2], nodes[b][2]
            if np.hypot(*(pa - pb)) <= radio and not shapely_blocked(polygons, walls, pa, pb, 0.0):
                graph.add_edge(a, b)
    base = [k for k, n in enumerate(nodes) if n[0] == "bs"]
    reached = set().union(*(nx.node_connected_component(graph, k) for k in base))
    return all(i in reached for i in range(len(xy)))
