"""Obstacles as arrays of segments C_i D_i (paper sec. III), with solid polygons.

Rectangles and polygons are solid: a point inside is inside, however far from the edges.
Segments are walls. All queries are vectorised through shapely 2 and an STRtree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import shapely


@dataclass(frozen=True, eq=False)
class Obstacles:
    """Solid polygons (each an (k, 2) ring, not closed) and free wall segments (W, 2, 2)."""

    polygons: tuple[np.ndarray, ...] = ()
    walls: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))

    #: `segments_within` builds the prepared union once this many segments were tested, or
    #: at once on obstacles of at most `UNION_VERTICES` vertices (it then costs milliseconds).
    UNION_AFTER = 200_000
    UNION_VERTICES = 2_000
    #: Polygons of more vertices than this are queried through their edges (an STRtree of
    #: segments) and a prepared polygon for what lies inside, so that a query costs the
    #: logarithm of the polygon's size, not its size (`_Large`): node building and clearance
    #: tests stay near-linear in a polygon's vertices (a 10,000-vertex polygon: 4.4 s to
    #: 0.1 s for its nodes). Footprints and drawn obstacles are smaller and keep one entry.
    LARGE_POLYGON = 64

    def __post_init__(self) -> None:
        object.__setattr__(self, "_tested", [0])  # segments tested so far (a counter)
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
        if self._wall_points is not None:
            parts.append(self._wall_points)
        for part in parts:
            shapely.prepare(part)
        return tuple(parts)

    @cached_property
    def _wall_points(self) -> shapely.Geometry | None:
        """Zero-length walls as one prepared multi-point (GEOS's predicates skip a degenerate
        line), or None."""
        length = np.hypot(*(self.walls[:, 1] - self.walls[:, 0]).T)
        if np.all(length > 0.0):
            return None
        points = shapely.multipoints(self.walls[length <= 0.0, 0])
        shapely.prepare(points)
        return points

    def segments_within(self, segments: np.ndarray, distance: float) -> np.ndarray:
        """True for each segment (..., 2, 2) that comes within `distance` (inclusive) of an
        obstacle, or enters a solid one. Vectorised over a prepared union of the obstacles:
        segments that cross an obstacle are found by a cheap intersection test first, the
        exact distance test runs only on the others. The union of a city of footprints costs
        half a second to seconds to build (over `UNION_VERTICES` vertices), and the STRtree
        answers about as fast per segment (Bet Shemesh, 5,419 footprints: 4.3 us against
        5.9 us; the union wins on segments hundreds of metres long across sparse obstacles,
        200 random buildings: 2.3 us against 9.3 us): there the first `UNION_AFTER` segments
        query the STRtree, so a plan that tests fewer never builds the union."""
        segments = np.asarray(segments, float)
        flat = segments.reshape(-1, 2, 2)
        hit = np.zeros(len(flat), bool)
        if len(flat) == 0 or len(self) == 0:
            return hit.reshape(segments.shape[:-2])
        lines = shapely.linestrings(flat)
        self._tested[0] += len(flat)
        if (
            self._tested[0] <= self.UNION_AFTER
            and "_prepared_union" not in self.__dict__
            and len(self.vertices[0]) > self.UNION_VERTICES
        ):
            near, _ = self.pairs_within(lines, distance)
            hit[near] = True  # (a solid is an area: a segment inside it is at distance 0)
            if self._wall_points is not None:  # GEOS skips a degenerate line: as points
                hit |= shapely.dwithin(self._wall_points, lines, distance)
            return hit.reshape(segments.shape[:-2])
        for geom in self._prepared_union:
            rest = np.flatnonzero(~hit)
            crossing = shapely.intersects(geom, lines[rest])
            hit[rest[crossing]] = True
            rest = rest[~crossing]
            hit[rest] = shapely.dwithin(geom, lines[rest], distance)
        return hit.reshape(segments.shape[:-2])

    def core_grid(self, bounds: tuple[float, float, float, float], distance: float) -> CoreGrid:
        """A `CoreGrid` over `bounds` (xmin, ymin, xmax, ymax): the cells every point of which
        lies within `distance` of an obstacle."""
        return CoreGrid.of(self, bounds, distance)

    def points_within(self, points: np.ndarray, distance: float) -> np.ndarray:
        """True for each point (..., 2) within `distance` (inclusive) of an obstacle or
        inside a solid one; one vectorised STRtree query (for points it beats the prepared
        union, which wins for long segments)."""
        points = np.asarray(points, float)
        flat = points.reshape(-1, 2)
        hit = np.zeros(len(flat), bool)
        if len(flat) == 0 or len(self) == 0:
            return hit.reshape(points.shape[:-1])
        near, _ = self.pairs_within(shapely.points(flat), distance)
        hit[near] = True
        return hit.reshape(points.shape[:-1])

    def pairs_within(self, geoms: np.ndarray, distance: float) -> tuple[np.ndarray, np.ndarray]:
        """Every (input, obstacle) pair of `geoms` (points or lines) and indices into
        `geometries` where the input comes within `distance` (inclusive) of the obstacle or
        lies inside a solid one, as an STRtree `dwithin` query."""
        large = self._large
        if large is None:
            return self._tree.query(geoms, predicate="dwithin", distance=distance)
        first, second = large.small_tree.query(geoms, predicate="dwithin", distance=distance)
        near_first, near_second = large.near(geoms, distance)
        return (
            np.concatenate([first, near_first]),
            np.concatenate([large.small[second], large.large[near_second]]),
        )

    def near_own(self, points: np.ndarray, owner: np.ndarray, distance: float) -> np.ndarray:
        """True where points[i] (n, 2) lies within `distance` (inclusive) of obstacle
        owner[i] (an index into `geometries`)."""
        where = shapely.points(np.asarray(points, float).reshape(-1, 2))
        large = self._large
        if large is None:
            return shapely.distance(where, self._geometries[owner]) <= distance
        near = np.zeros(len(where), bool)
        slot = large.slot_of(owner)
        rest = np.flatnonzero(slot < 0)
        near[rest] = shapely.distance(where[rest], self._geometries[owner[rest]]) <= distance
        big = np.flatnonzero(slot >= 0)
        near[big] = shapely.dwithin(large.prepared[slot[big]], where[big], distance)
        return near

    @cached_property
    def _large(self) -> _Large | None:
        """The queries' split of the obstacles when a polygon has more than `LARGE_POLYGON`
        vertices, else None (every query uses the one STRtree)."""
        sizes = np.array([len(p) for p in self.polygons], np.intp)
        if not np.any(sizes > self.LARGE_POLYGON):
            return None
        is_large = np.zeros(len(self._geometries), bool)
        is_large[: len(sizes)] = sizes > self.LARGE_POLYGON
        return _Large.of(self._geometries, is_large, self.polygons)

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

    def merged(self, gap: float) -> Obstacles:
        """The obstacles with every group of polygons less than `gap` apart (touching, in
        practice: terraced houses, a block's buildings) grown by `gap` / 2 and merged into one
        solid polygon (its outer ring; holes filled): the occluders of `graph.Occlusion`.
        The growth is polygonal, inscribed in the round one, so a segment that meets a
        merged polygon comes within `gap` / 2 of an obstacle. A row of terraced houses is
        one occluder that hides everything behind it, where each house alone spans too
        narrow an angle to hide anything. Walls and polygons apart are kept as they are."""
        solids = self._geometries[: len(self.polygons)]
        first, second = self._tree.query(solids, predicate="dwithin", distance=gap)
        touching = np.unique(first[(first != second) & (second < len(solids))])  # no walls
        if len(touching) == 0:
            return self
        grown = shapely.buffer(solids[touching], gap / 2.0, quad_segs=1)
        merged = shapely.get_parts(shapely.union_all(grown))
        rings = [shapely.get_coordinates(r)[:-1] for r in shapely.get_exterior_ring(merged)]
        alone = np.setdiff1d(np.arange(len(self.polygons)), touching)
        return Obstacles(polygons=[self.polygons[k] for k in alone] + rings, walls=self.walls)

    def _nearest(self, geoms: np.ndarray) -> np.ndarray:
        """Distance from each geometry to its nearest obstacle, in input order."""
        large = self._large
        if large is None:
            return _nearest_in(self._tree, geoms)
        out = np.minimum(_nearest_in(large.small_tree, geoms), _nearest_in(large.edge_tree, geoms))
        out[large.inside(geoms)] = 0.0
        return out


def _nearest_in(tree: shapely.STRtree, geoms: np.ndarray) -> np.ndarray:
    """Distance from each geometry to its nearest one in `tree` (inf for an empty tree)."""
    out = np.full(len(geoms), np.inf)
    if len(tree):
        (inputs, _), dist = tree.query_nearest(geoms, return_distance=True, all_matches=False)
        out[inputs] = dist
    return out


@dataclass(frozen=True, eq=False)
class _Large:
    """The obstacles split for queries (`Obstacles.LARGE_POLYGON`): `small_tree` over the
    others (`small`: their indices into the geometries); the large polygons (`large`: their
    indices) prepared (GEOS indexes their edges: a distance or containment test is then
    logarithmic) in `large_tree`, and their edges as lines in `edge_tree` for nearest
    distances (`edge_owner`: each edge's polygon), which preparing does not speed up."""

    small: np.ndarray
    small_tree: shapely.STRtree
    large: np.ndarray
    prepared: np.ndarray
    large_tree: shapely.STRtree
    edge_owner: np.ndarray
    edge_tree: shapely.STRtree

    @classmethod
    def of(cls, geometries: np.ndarray, is_large: np.ndarray, polygons) -> _Large:
        large = np.flatnonzero(is_large)
        small = np.flatnonzero(~is_large)
        rings = [np.asarray(polygons[k]) for k in large]
        edges = np.concatenate([np.stack([r, np.roll(r, -1, axis=0)], axis=1) for r in rings])
        # copies: preparing leaves `geometries` as they are
        prepared = np.array([shapely.Polygon(r) for r in rings], dtype=object)
        shapely.prepare(prepared)
        return cls(
            small=small,
            small_tree=shapely.STRtree(geometries[small]),
            large=large,
            prepared=prepared,
            large_tree=shapely.STRtree(prepared),
            edge_owner=np.repeat(large, [len(r) for r in rings]),
            edge_tree=shapely.STRtree(shapely.linestrings(edges)),
        )

    def slot_of(self, index: np.ndarray) -> np.ndarray:
        """Position in `large` of each obstacle index, -1 for a small one."""
        slot = np.full(int(max(self.large.max(), np.max(index, initial=0))) + 1, -1, np.intp)
        slot[self.large] = np.arange(len(self.large))
        return slot[index]

    def near(self, geoms: np.ndarray, distance: float) -> tuple[np.ndarray, np.ndarray]:
        """(input, position in `large`) pairs where the input comes within `distance` of the
        large polygon or lies inside it: bounding boxes grown by `distance` first, then
        the prepared test."""
        bounds = shapely.bounds(geoms) + np.array([-distance, -distance, distance, distance])
        first, second = self.large_tree.query(shapely.box(*bounds.T))
        keep = shapely.intersects(self.prepared[second], geoms[first])  # cheaper: first
        rest = np.flatnonzero(~keep)
        keep[rest] = shapely.dwithin(self.prepared[second[rest]], geoms[first[rest]], distance)
        return first[keep], second[keep]

    def inside(self, geoms: np.ndarray) -> np.ndarray:
        """Which inputs meet a large polygon (are at distance 0 from it)."""
        first, second = self.large_tree.query(geoms)  # bounding boxes
        hit = np.zeros(len(geoms), bool)
        hit[first[shapely.intersects(self.prepared[second], geoms[first])]] = True
        return hit


@dataclass(frozen=True, eq=False)
class CoreGrid:
    """Square cells of side `cell` from `origin`; `core[i, j]` (i along x) is True when every
    point of cell (i, j) lies within the grid's distance of an obstacle. A segment with a
    point in such a cell certainly comes that close: `blocks` is a cheap, sound culling
    before the exact clearance test (it may miss a blocked segment, never clears one)."""

    origin: np.ndarray
    cell: float
    core: np.ndarray

    #: Cell side c as a fraction of the distance d, and the sample spacings along a segment
    #: (in cell sides) of the passes of `blocks`. Every point within d - 2 x (c / sqrt 2) =
    #: 0.58 d of an obstacle lies in a core cell, so a segment through an obstacle crosses a
    #: run of core cells at least 1.15 d = 3.8 c long, which the last spacing does not step
    #: over (with cells enlarged by `MAX_CELLS`, some are missed: still sound).
    CELL_PER_DISTANCE = 0.3
    SPACINGS = (64.0, 16.0, 3.0)
    #: At most this many cells: larger boxes get larger cells (fewer of them are core).
    MAX_CELLS = 4_000_000
    #: At most this many samples per segment and pass (longer segments are sampled more
    #: sparsely: the exact test decides them).
    MAX_SAMPLES = 64

    @classmethod
    def of(cls, obstacles: Obstacles, bounds, distance: float) -> CoreGrid:
        x0, y0, x1, y1 = (float(b) for b in bounds)
        area = max((x1 - x0) * (y1 - y0), 1.0)
        cell = max(cls.CELL_PER_DISTANCE * distance, math.sqrt(area / cls.MAX_CELLS))
        shape = (max(1, math.ceil((x1 - x0) / cell)), max(1, math.ceil((y1 - y0) / cell)))
        origin = np.array([x0, y0])
        core = np.zeros(shape, bool)
        # A cell's centre within distance - half its diagonal: the whole cell within distance.
        # Round buffers are drawn inside their circles, so a centre inside one is that close.
        inner = distance - cell * math.sqrt(0.5)
        box = shapely.box(x0 - distance, y0 - distance, x1 + distance, y1 + distance)
        near = obstacles.tree.query(box)
        if len(near) and inner > 0:
            grown = shapely.buffer(obstacles.geometries[near], inner, quad_segs=4)
            core = _cell_centres_inside(grown, origin, cell, shape)
        return cls(origin, cell, core)

    def covers(self, bounds) -> bool:
        """Whether the grid spans the box `bounds` (xmin, ymin, xmax, ymax)."""
        x0, y0 = self.origin
        x1, y1 = self.origin + self.cell * np.array(self.core.shape)
        return x0 <= bounds[0] and y0 <= bounds[1] and bounds[2] <= x1 and bounds[3] <= y1

    def blocks(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """True for segments starts[k] -> ends[k] with a sampled point in a core cell: sparse
        points first, then denser ones on the segments left (`SPACINGS`, at most
        `MAX_SAMPLES` per segment and pass; `_CHUNK` samples at a time)."""
        hit = np.zeros(len(starts), bool)
        length = np.hypot(*(ends - starts).T)
        for spacing in self.cell * np.asarray(self.SPACINGS):
            rest = np.flatnonzero(~hit)
            if len(rest) == 0:
                break
            count = np.ceil(length[rest] / spacing).astype(np.int64).clip(1, self.MAX_SAMPLES)
            ends_at = np.cumsum(count)
            cuts = np.searchsorted(ends_at, np.arange(self._CHUNK, ends_at[-1], self._CHUNK))
            for part in np.split(np.arange(len(rest)), cuts):
                rows = rest[part]
                hit[rows] = self._sampled_core(starts[rows], ends[rows], count[part])
        return hit

    #: Samples handled at once by `blocks` (bounds its memory).
    _CHUNK = 1 << 18

    def _sampled_core(self, starts: np.ndarray, ends: np.ndarray, count: np.ndarray) -> np.ndarray:
        """Whether one of `count[k]` evenly spread points of segment k lies in a core cell."""
        owner, step = ragged(count)
        t = (step + 0.5) / count[owner]
        a = starts[owner]
        at = a + (ends[owner] - a) * t[:, None]
        cell = np.floor((at - self.origin) / self.cell).astype(np.int64)
        inside = np.all((cell >= 0) & (cell < self.core.shape), axis=1)
        sample = np.zeros(len(owner), bool)
        sample[inside] = self.core[cell[inside, 0], cell[inside, 1]]
        found = np.zeros(len(starts), bool)
        found[owner[sample]] = True
        return found


def _cell_centres_inside(
    area: shapely.Geometry | np.ndarray, origin: np.ndarray, cell: float, shape
) -> np.ndarray:
    """(nx, ny) bool: which cell centres lie inside `area`, polygons with holes that may
    overlap (an array of them, or one geometry), by a scanline fill: each row of centres
    crosses each ring's edges (half-open in y); the crossings of one ring in one row pair
    up, [x_1, x_2), [x_3, x_4), ..., and count +1 over an outer ring's spans, -1 over a
    hole's. A centre is inside where the count is positive, so no union is needed."""
    parts = shapely.get_parts(area)
    rings, polygon = shapely.get_rings(parts, return_index=True)
    hole = np.ones(len(rings), bool)
    hole[np.searchsorted(polygon, np.arange(len(parts)))] = False  # each polygon's first
    coords, ring = shapely.get_coordinates(rings, return_index=True)
    same = ring[:-1] == ring[1:]
    a, b, ring = coords[:-1][same], coords[1:][same], ring[:-1][same]
    ys = origin[1] + cell * (np.arange(shape[1]) + 0.5)
    low, high = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    first = np.searchsorted(ys, low, side="left")  # rows with low <= y < high
    last = np.searchsorted(ys, high, side="left")
    edge, step = ragged(last - first)
    row = first[edge] + step
    a, b, y, ring = a[edge], b[edge], ys[row], ring[edge]
    x = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    order = np.lexsort((x, row, ring))
    row, x, ring = row[order], x[order], ring[order]
    column = np.ceil((x - origin[0]) / cell - 0.5).astype(np.int64).clip(0, shape[0])
    group = ring.astype(np.int64) * shape[1] + row
    opens = (np.arange(len(row)) - np.searchsorted(group, group, side="left")) % 2 == 0
    sign = np.where(hole[ring], -1, 1)
    change = np.zeros((shape[1], shape[0] + 1), np.int32)
    np.add.at(change, (row, column), np.where(opens, sign, -sign))
    return (np.cumsum(change, axis=1, dtype=np.int32)[:, : shape[0]] > 0).T


def ragged(count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For groups of `count[k]` items laid end to end: each item's group and its rank in it
    (`ragged([2, 0, 3])` is ([0, 0, 2, 2, 2], [0, 1, 0, 1, 2]))."""
    owner = np.repeat(np.arange(len(count)), count)
    return owner, np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)
