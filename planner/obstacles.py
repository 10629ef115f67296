"""Obstacles as arrays of segments C_i D_i (paper sec. III), with solid polygons.

Rectangles and polygons are solid: a point inside is inside, however far from the edges.
Segments are walls. All queries are vectorised through shapely 2 and an STRtree.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import shapely


@dataclass(frozen=True, eq=False)
class Obstacles:
    """Solid polygons (each an (k, 2) ring, not closed) and free wall segments (W, 2, 2)."""

    polygons: tuple[np.ndarray, ...] = ()
    walls: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))

    def __post_init__(self) -> None:
        polygons = tuple(np.asarray(p, float).reshape(-1, 2) for p in self.polygons)
        walls = np.asarray(self.walls, float).reshape(-1, 2, 2)
        object.__setattr__(self, "polygons", polygons)
        object.__setattr__(self, "walls", walls)
        geoms = [shapely.Polygon(p) for p in polygons] + list(shapely.linestrings(walls))
        object.__setattr__(self, "_geometries", np.array(geoms, dtype=object))
        object.__setattr__(self, "_tree", shapely.STRtree(self._geometries))

    @property
    def segments(self) -> np.ndarray:
        """Every obstacle segment C_i D_i: polygon edges then walls, shape (M, 2, 2)."""
        edges = [np.stack([p, np.roll(p, -1, axis=0)], axis=1) for p in self.polygons]
        return np.concatenate(edges + [self.walls], axis=0) if edges else self.walls.copy()

    @property
    def geometries(self) -> np.ndarray:
        """The obstacles as shapely geometries (polygons first, then walls)."""
        return self._geometries

    @property
    def tree(self) -> shapely.STRtree:
        """STRtree over `geometries`."""
        return self._tree

    def __len__(self) -> int:
        return len(self._geometries)

    def distance_to_points(self, points: np.ndarray) -> np.ndarray:
        """Distance from each point (..., 2) to the nearest obstacle; 0 inside a solid one.

        Infinite when there are no obstacles.
        """
        points = np.asarray(points, float)
        flat = points.reshape(-1, 2)
        if len(self) == 0:
            return np.full(points.shape[:-1], np.inf)
        return self._nearest(shapely.points(flat)).reshape(points.shape[:-1])

    def distance_to_segments(self, segments: np.ndarray) -> np.ndarray:
        """Distance from each segment (..., 2, 2) to the nearest obstacle (0 if it enters one)."""
        segments = np.asarray(segments, float)
        flat = segments.reshape(-1, 2, 2)
        if len(self) == 0:
            return np.full(segments.shape[:-2], np.inf)
        return self._nearest(shapely.linestrings(flat)).reshape(segments.shape[:-2])

    @property
    def segment_owner(self) -> np.ndarray:
        """Index into `geometries` of the obstacle each row of `segments` belongs to, (M,)."""
        counts = [len(p) for p in self.polygons] + [1] * len(self.walls)
        return np.repeat(np.arange(len(counts)), counts).astype(np.intp)

    @cached_property
    def _prepared_union(self) -> tuple[shapely.Geometry, ...]:
        """The obstacles as a few prepared geometries (GEOS indexes them once, so each later
        query costs about a microsecond per segment): the union of the solids (made valid),
        the walls as one multi-line, and zero-length walls as points (GEOS's prepared
        predicates skip a degenerate line)."""
        parts = []
        if self.polygons:
            polygons = self._geometries[: len(self.polygons)]
            solids = shapely.union_all(shapely.make_valid(polygons))
            parts.append(solids)
        if len(self.walls):
            length = np.hypot(*(self.walls[:, 1] - self.walls[:, 0]).T)
            proper = length > 0.0
            if proper.any():
                parts.append(shapely.multilinestrings(self.walls[proper]))
            if not proper.all():
                parts.append(shapely.multipoints(self.walls[~proper, 0]))
        for part in parts:
            shapely.prepare(part)
        return tuple(parts)

    def segments_within(self, segments: np.ndarray, distance: float) -> np.ndarray:
        """True for each segment (..., 2, 2) that comes within `distance` (inclusive) of an
        obstacle, or enters a solid one. Vectorised over a prepared union of the obstacles:
        segments that cross an obstacle are found by a cheap intersection test first, the
        exact distance test runs only on the others."""
        segments = np.asarray(segments, float)
        flat = segments.reshape(-1, 2, 2)
        hit = np.zeros(len(flat), bool)
        if len(flat) == 0 or len(self) == 0:
            return hit.reshape(segments.shape[:-2])
        lines = shapely.linestrings(flat)
        for geom in self._prepared_union:
            rest = np.flatnonzero(~hit)
            crossing = shapely.intersects(geom, lines[rest])
            hit[rest[crossing]] = True
            rest = rest[~crossing]
            hit[rest] = shapely.dwithin(geom, lines[rest], distance)
        return hit.reshape(segments.shape[:-2])

    def points_within(self, points: np.ndarray, distance: float) -> np.ndarray:
        """True for each point (..., 2) within `distance` (inclusive) of an obstacle or
        inside a solid one; one vectorised STRtree query (for points it beats the prepared
        union, which wins for long segments)."""
        points = np.asarray(points, float)
        flat = points.reshape(-1, 2)
        hit = np.zeros(len(flat), bool)
        if len(flat) == 0 or len(self) == 0:
            return hit.reshape(points.shape[:-1])
        near, _ = self._tree.query(shapely.points(flat), predicate="dwithin", distance=distance)
        hit[near] = True
        return hit.reshape(points.shape[:-1])

    @cached_property
    def vertices(self) -> tuple[np.ndarray, np.ndarray]:
        """Vertices of every obstacle, flat: (points (P, 2), offsets (G + 1,)); obstacle g
        owns points[offsets[g]:offsets[g + 1]] (polygons first, then walls, as in
        `geometries`). Memory grows with the vertex count, not with the largest obstacle."""
        rings = list(self.polygons) + list(self.walls)
        if not rings:
            return np.zeros((0, 2)), np.zeros(1, np.intp)
        sizes = np.array([len(r) for r in rings], np.intp)
        return np.concatenate(rings), np.concatenate([[0], np.cumsum(sizes)])

    @cached_property
    def hulls(self) -> np.ndarray:
        """Convex hull of each obstacle (shapely geometries, prepared)."""
        hulls = shapely.convex_hull(self._geometries)
        shapely.prepare(hulls)
        return hulls

    def separated(self, first: np.ndarray, second: np.ndarray, margin: float) -> bool:
        """True when no curve from `first` to `second` keeps `margin` from every obstacle:
        the points lie in different connected parts of the free space. Conservative: the
        margins are polygons inscribed in the round ones, so True is a proof."""
        if len(self) == 0:
            return False
        grown = shapely.union_all(shapely.buffer(self._geometries, margin, quad_segs=4))
        pts = shapely.points(np.array([first, second], float).reshape(2, 2))
        if np.any(shapely.contains(grown, pts)):
            return False  # a point inside a margin: not this test's business
        holes = [shapely.Polygon(r) for r in shapely.get_rings(shapely.get_parts(grown))]
        holes = [h for h in holes if h.is_valid]
        if not holes:
            return False
        inside = shapely.contains(np.array(holes, dtype=object)[:, None], pts[None, :])
        return bool(np.any(inside[:, 0] != inside[:, 1]))

    def _nearest(self, geoms: np.ndarray) -> np.ndarray:
        """Distance from each geometry to its nearest obstacle, in input order."""
        (inputs, _), dist = self._tree.query_nearest(geoms, return_distance=True, all_matches=False)
        out = np.empty(len(geoms))
        out[inputs] = dist
        return out
