"""Line of sight between nodes through a city (docs/line-of-sight.md).

A radio link needs the two nodes within range *and* the chord between them clear of the
buildings: at 2.4 GHz a wall costs tens of dB, so a link through a footprint is cut. `Sight`
answers, vectorised over many node pairs, whether each chord is clear:

* in 2-D (`clear`): the chord meets no obstacle (touching counts as meeting: a chord that
  grazes a corner has its Fresnel zone in the wall), and keeps `margin` from every one when
  asked (a margin of rho_c makes the chord between two *targets* stand for every chord between
  UAVs within rho_c of them: such a chord lies within rho_c of the target chord);
* in 3-D (`clear_3d`): a footprint with a known roof height blocks the chord only where the
  chord passes below that height (the chord's height is linear along it, so its lowest point
  over the footprint is where it enters or leaves it); footprints without a height and walls
  block at every height.

Pure: numbers in, booleans out; the obstacles' STRtree and prepared geometry do the geometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from planner.obstacles import Obstacles


@dataclass(frozen=True, eq=False)
class Sight:
    """What blocks radio: `obstacles` (solid polygons and walls), and `heights` (one per
    polygon, metres above the local frame's origin; inf: blocks at every height). Without
    heights every polygon blocks at every height."""

    obstacles: Obstacles
    heights: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.heights is not None:
            heights = np.asarray(self.heights, float).reshape(-1)
            if len(heights) != len(self.obstacles.polygons):
                raise ValueError("Sight: one height per polygon")
            object.__setattr__(self, "heights", heights)

    def clear(self, starts: np.ndarray, ends: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether each chord starts[i] -> ends[i] ((..., 2), horizontal) meets no obstacle
        and keeps more than `margin` from every one (`margin` 0: touching blocks)."""
        starts = np.asarray(starts, float)
        ends = np.asarray(ends, float)
        segments = np.stack([starts[..., :2], ends[..., :2]], axis=-2)
        if len(self.obstacles) == 0:
            return np.ones(segments.shape[:-2], bool)
        return ~self.obstacles.segments_within(segments, margin)

    def clear_3d(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """Whether each chord starts[i] -> ends[i] ((n, 3): x, y, height) passes no obstacle
        below its height: a polygon with a finite height blocks the chord only where the
        chord runs below that height over it; walls and polygons without one block it."""
        starts = np.asarray(starts, float).reshape(-1, 3)
        ends = np.asarray(ends, float).reshape(-1, 3)
        clear = np.ones(len(starts), bool)
        if len(starts) == 0 or len(self.obstacles) == 0:
            return clear
        lines = shapely.linestrings(np.stack([starts[:, :2], ends[:, :2]], axis=1))
        chord, obstacle = self.obstacles.pairs_within(lines, 0.0)
        polygons = len(self.obstacles.polygons)
        roof = np.full(len(obstacle), np.inf)
        if self.heights is not None:
            is_polygon = obstacle < polygons
            roof[is_polygon] = self.heights[obstacle[is_polygon]]
        tall = ~np.isfinite(roof)
        clear[chord[tall]] = False
        low = np.flatnonzero(~tall & clear[chord])
        if len(low) == 0:
            return clear
        chord, obstacle, roof = chord[low], obstacle[low], roof[low]
        # the chord's lowest point over the footprint is where it crosses the outline or an
        # end of it inside (its height is linear): line-line crossings, robust where an
        # intersection with an invalid outline is not
        geometries = self.obstacles.geometries[obstacle]
        crossings = shapely.intersection(lines[chord], shapely.boundary(geometries))
        xy, owner = shapely.get_coordinates(crossings, return_index=True)
        for end in (starts, ends):
            inside = shapely.intersects_xy(geometries, end[chord, 0], end[chord, 1])
            xy = np.concatenate([xy, end[chord[inside], :2]])
            owner = np.concatenate([owner, np.flatnonzero(inside)])
        a, b = starts[chord[owner]], ends[chord[owner]]
        along = b[:, :2] - a[:, :2]
        length2 = np.einsum("ij,ij->i", along, along)
        fraction = np.where(
            length2 > 0.0,
            np.einsum("ij,ij->i", xy - a[:, :2], along) / np.where(length2 > 0, length2, 1.0),
            0.0,
        ).clip(0.0, 1.0)
        height = a[:, 2] + fraction * (b[:, 2] - a[:, 2])
        lowest = np.full(len(chord), np.inf)
        np.minimum.at(lowest, owner, height)
        clear[chord[lowest < roof]] = False
        return clear


#: Arc-length step (m) of the samples `chord_reach` tests along a path.
REACH_STEP_M = 1.0


def chord_reach(
    polyline: np.ndarray, sight: Sight, limit: float, step: float = REACH_STEP_M
) -> float:
    """The path's line-of-sight reach: the largest d <= `limit` such that every chord between
    two points of `polyline` ((K, 2), followed along its arcs) at most d apart along it is
    clear (the rigid formation's spacing under line of sight, docs/line-of-sight.md).

    Sampled, and sound: points are taken every `step` of arc length and every pair of them at
    most G steps apart is tested with a margin of step / 2. Any chord between two points at
    most (G - 1) step apart lies within step / 2 of a tested one (each end is within step / 2
    of a sample, and a chord is convex in its ends), so it is clear when the tested one keeps
    that margin: the reach returned is (G - 1) step for the largest G whose pairs all keep
    it (the first gap with a blocked pair, less one).

    A pair whose two samples lie on one straight piece of the polyline is not tested when
    that piece keeps the margin: its chord is part of the piece. Only pairs round a bend are
    (on planned paths, whose pieces keep rho_c from every building, most pairs are not)."""
    samples = _PathSamples.of(polyline, sight, step)
    most = int(np.ceil(limit / step)) + 1
    for gap in range(1, min(most, len(samples.grid) - 1) + 1):
        test = np.flatnonzero(samples.tested(gap))
        if len(test) and not np.all(samples.clear(test, gap)):
            return max((gap - 2) * step, 0.0)
    return float(limit)


def clear_gaps(
    polyline: np.ndarray, sight: Sight, limit: float, step: float = REACH_STEP_M
) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's line of sight back along `polyline`: its samples' arc lengths (every
    `step`, and the end) and, per sample j, the number G_j of gaps g = 1 .. G_j for which the
    pair (j - g, j) keeps the margin step / 2 (as `chord_reach` tests them, up to `limit`
    of arc); G_j = j when every sample behind j is seen. A point x behind a point y sees it
    when their nearest samples i <= j have j - i <= G_j (the chord is within step / 2 of
    the tested one): the elastic formation's links (`planner.elastic`)."""
    samples = _PathSamples.of(polyline, sight, step)
    count = len(samples.grid)
    most = min(int(np.ceil(limit / step)) + 1, count - 1)
    gaps = np.arange(count)  # seen back to the start until a blocked pair says otherwise
    open_ = np.ones(count, bool)
    for low in range(1, most + 1, _GAP_BLOCK):  # a block of gaps per call: fewer, bigger calls
        block = np.arange(low, min(low + _GAP_BLOCK, most + 1))
        ends = np.flatnonzero(open_[low:]) + low
        if len(ends) == 0:
            break
        end, gap = (a.ravel() for a in np.meshgrid(ends, block, indexing="ij"))
        keep = end - gap >= 0
        end, gap = end[keep], gap[keep]
        keep = samples.piece_pair_tested(end - gap, end)
        end, gap = end[keep], gap[keep]
        blocked = ~samples.sight.clear(
            samples.points[end - gap], samples.points[end], samples.margin
        )
        first = np.full(count, most + 1)
        np.minimum.at(first, end[blocked], gap[blocked])
        newly = first <= most
        gaps[newly] = first[newly] - 1
        open_[newly] = False
    seen_limit = open_ & (gaps > most)
    gaps[seen_limit] = most
    return samples.grid, gaps


#: `clear_gaps` tests this many gaps per call.
_GAP_BLOCK = 16


@dataclass(frozen=True, eq=False)
class _PathSamples:
    """A polyline sampled every `step` of arc length (`grid`, `points`), with what it takes to
    test pairs of samples `gap` apart at the margin step / 2."""

    grid: np.ndarray
    points: np.ndarray
    piece: np.ndarray  # the straight piece of each sample
    piece_clear: np.ndarray  # whether that piece keeps the margin
    sight: Sight
    margin: float

    @classmethod
    def of(cls, polyline: np.ndarray, sight: Sight, step: float) -> _PathSamples:
        points = _straight_runs(np.asarray(polyline, float).reshape(-1, 2))
        pieces = np.diff(points, axis=0)
        lengths = np.hypot(pieces[:, 0], pieces[:, 1])
        arcs = np.concatenate([[0.0], np.cumsum(lengths)])
        grid = np.append(np.arange(0.0, arcs[-1], step), arcs[-1])
        samples = np.column_stack(
            [np.interp(grid, arcs, points[:, 0]), np.interp(grid, arcs, points[:, 1])]
        )
        margin = step / 2.0
        piece_clear = sight.clear(points[:-1], points[1:], margin)
        last = max(len(pieces) - 1, 0)
        piece = np.clip(np.searchsorted(arcs, grid, side="right") - 1, 0, last)
        return cls(grid, samples, piece, piece_clear, sight, margin)

    def tested(self, gap: int) -> np.ndarray:
        """(len - gap,) bool: whether the pair (i, i + gap) needs a test (`piece_pair_tested`)."""
        return self.piece_pair_tested(
            np.arange(len(self.grid) - gap), np.arange(gap, len(self.grid))
        )

    def piece_pair_tested(self, first: np.ndarray, second: np.ndarray) -> np.ndarray:
        """Whether each pair of samples needs a test; a pair on one straight piece that itself
        keeps the margin does not (its chord is part of it)."""
        piece = self.piece
        return ~((piece[first] == piece[second]) & self.piece_clear[piece[second]])

    def clear(self, first: np.ndarray, gap: int) -> np.ndarray:
        """Whether the chords from samples `first` to `first + gap` keep the margin."""
        return self.sight.clear(self.points[first], self.points[first + gap], self.margin)


def _straight_runs(points: np.ndarray) -> np.ndarray:
    """`points` without the vertices where the polyline goes straight on (and repeated ones):
    the same curve, in as few straight pieces as it has."""
    if len(points) < 2:
        return points
    keep = np.ones(len(points), bool)
    pieces = np.diff(points, axis=0)
    lengths = np.hypot(pieces[:, 0], pieces[:, 1])
    keep[1:][lengths <= 0.0] = False  # repeated points
    points, pieces = points[keep], pieces[lengths > 0.0]
    if len(points) < 3:
        return points
    lengths = np.hypot(pieces[:, 0], pieces[:, 1])
    unit = pieces / lengths[:, None]
    cross = unit[:-1, 0] * unit[1:, 1] - unit[:-1, 1] * unit[1:, 0]
    dot = np.einsum("ij,ij->i", unit[:-1], unit[1:])
    straight = (np.abs(cross) < 1e-9) & (dot > 0)
    return points[np.concatenate([[True], ~straight, [True]])]


def sight_json(obstacles: Obstacles) -> dict:
    """What blocks radio as plain JSON data (the buildings file the ground station writes for
    the radio medium process, `sight_from_json` reads it): `{"polygons": [[[x, y], ...], ...],
    "walls": [[[x, y], [x, y]], ...]}`, local metres."""
    return {
        "polygons": [np.asarray(p, float).tolist() for p in obstacles.polygons],
        "walls": np.asarray(obstacles.walls, float).tolist(),
    }


def sight_from_json(data) -> Sight:
    """`Sight` of `sight_json`'s data; `ValueError` naming what is wrong."""
    if not isinstance(data, dict) or set(data) != {"polygons", "walls"}:
        raise ValueError('expected an object with "polygons" and "walls"')
    try:
        polygons = [np.asarray(p, float).reshape(-1, 2) for p in data["polygons"]]
        walls = np.asarray(data["walls"], float).reshape(-1, 2, 2)
    except (TypeError, ValueError):
        raise ValueError("expected lists of [x, y] points in metres") from None
    if any(len(p) < 3 for p in polygons):
        raise ValueError("expected polygons of at least 3 points")
    if not all(np.isfinite(p).all() for p in polygons) or not np.isfinite(walls).all():
        raise ValueError("expected finite coordinates")
    return Sight(Obstacles(polygons=tuple(polygons), walls=walls))
