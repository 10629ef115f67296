"""Obstacles as arrays of segments C_i D_i (paper sec. III), with solid polygons.

Rectangles and polygons are solid: a point inside is inside, however far from the edges.
Segments are walls. All queries are vectorised through shapely 2 and an STRtree.
"""

from __future__ import annotations

from dataclasses import dataclass, field

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

    def _nearest(self, geoms: np.ndarray) -> np.ndarray:
        """Distance from each geometry to its nearest obstacle, in input order."""
        (inputs, _), dist = self._tree.query_nearest(geoms, return_distance=True, all_matches=False)
        out = np.empty(len(geoms))
        out[inputs] = dist
        return out
