"""Elastic spacing for line of sight (docs/line-of-sight.md): the UAVs close up where the
path turns a corner and spread out on the straights, with one formation distance S for the
whole fleet.

The rigid line-of-sight formation spaces every UAV by the path's worst chord reach, a few
tens of metres round a corner hugged at rho_c, all the way along the path. The elastic one
keeps eq. 27's spacing dS = dS_r in *formation distance* and maps it to the path through a
warp G (arc length -> formation distance, slope >= 1; `LineFormation.warp`): where G is
steep a UAV flies at v / G', so the ones behind close up on it. A link joins two UAVs dS
apart in formation distance; it is clear when the arc between them is short enough for
their chord to clear the buildings there, whatever the fleet does elsewhere.

The warp is built on the polyline the UAVs fly (start row, path, goal row), sampled every
`step` (`planner.sight.clear_gaps`): sample j sees back G_j samples. A UAV at y (nearest
sample j) has its follower at x with G(y) - G(x) = dS; the link is clear when x's nearest
sample is at least j - G_j, which holds when F_{j-1} - F_{j-G_j} >= dS, F_k = G(s_k)
(G(y) >= F_{j-1} as y is nearer s_j; x >= s_{j-G_j} then). So every sample whose window of
cells (j - G_j, j - 1] is short of dS in formation distance gets the shortfall added to the
last cell of its window that lies on the path (the rows are not warped): that cell becomes a
near-stop, where each UAV waits for the one behind. Going left to right and adding at the
window's right end satisfies each window with the least added (a later window that holds the
cell needs less), so the formation distance, the flight time and the fleet
ceil(G(len) / dS) (eq. 28) stay small. Windows never shorter than dS_c of arc keep
consecutive UAVs at least dS_c apart along the path (theorems 3-5 as in the paper); this is
checked, not assumed.

Pure: numbers in, numbers out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.formation import DISTANCE_TOLERANCE
from planner.sight import REACH_STEP_M, Sight, clear_gaps


@dataclass(frozen=True, eq=False)
class ElasticWarp:
    """The warp of an elastic formation: `knots` (M, 2), arc length from A along the path ->
    formation distance from A (`LineFormation.warp`); `formation_length` G(len(P)); the
    fleet eq. 28 needs with it, ceil(G(len(P)) / spacing)."""

    knots: np.ndarray
    formation_length: float
    spacing: float

    @property
    def fleet_size(self) -> int:
        return max(1, math.ceil(self.formation_length / self.spacing - DISTANCE_TOLERANCE))


def elastic_warp(
    polyline: np.ndarray,
    sight: Sight,
    path_from: float,
    path_to: float,
    spacing: float,
    collision_spacing: float,
    step: float = REACH_STEP_M,
) -> ElasticWarp | None:
    """The warp keeping every link of a formation spaced `spacing` (dS) clear on `polyline`
    (the flown polyline, the path between arc lengths `path_from` (A) and `path_to` (B)), or
    None when no warp of the path can: a sample sees back less than `collision_spacing` of
    arc, or a window short of dS holds no cell of the path (module docstring)."""
    grid, gaps = clear_gaps(polyline, sight, spacing + step, step)
    cells = np.diff(grid)  # cell k = [s_k, s_{k+1}]: the cell before sample k + 1
    on_path = (grid[:-1] >= path_from - DISTANCE_TOLERANCE) & (
        grid[1:] <= path_to + DISTANCE_TOLERANCE
    )
    path_cells = np.flatnonzero(on_path)
    extra = np.zeros(len(cells))
    index = np.arange(len(grid))
    # samples that do not see every sample behind them: their windows are the constraints
    limited = np.flatnonzero(gaps < index)
    shortest = collision_spacing + 2.0 * step  # `_separated` rounds its windows outwards
    if len(limited) and np.any(grid[limited - 1] - grid[limited - gaps[limited]] < shortest):
        return None
    prefix = np.concatenate([[0.0], np.cumsum(cells)])
    for j in limited:
        first, last = j - int(gaps[j]), j - 1  # samples; cells first .. last - 1
        have = prefix[last] - prefix[first] + extra[first:last].sum()
        if have >= spacing - DISTANCE_TOLERANCE:
            continue
        where = np.searchsorted(path_cells, last, side="left") - 1  # last path cell < last
        if where < 0 or path_cells[where] < first:
            return None
        extra[path_cells[where]] += spacing - have
    formation = cells + extra
    if not _separated(grid, formation, spacing, collision_spacing):
        return None
    return ElasticWarp(
        knots=_knots(grid, formation, path_from, path_to),
        formation_length=float(path_to - path_from + extra.sum()),
        spacing=float(spacing),
    )


def _separated(grid: np.ndarray, formation: np.ndarray, spacing: float, minimum: float) -> bool:
    """Whether UAVs `spacing` apart in formation distance stay at least `minimum` apart in
    arc: every arc interval of length `minimum` takes at most `spacing` of formation
    distance. Tested on the windows of samples less than `minimum` + 2 steps apart, each of
    which holds every such interval that starts in its first cell."""
    prefix = np.concatenate([[0.0], np.cumsum(formation)])
    step = float(np.max(np.diff(grid))) if len(grid) > 1 else 0.0
    start = np.searchsorted(grid, grid - minimum - 2.0 * step, side="right")
    within = prefix[np.arange(len(grid))] - prefix[start]
    return bool(np.all(within <= spacing + DISTANCE_TOLERANCE))


def _knots(grid: np.ndarray, formation: np.ndarray, path_from: float, path_to: float):
    """The warp's knots on the path (arc from A -> formation distance from A), only where
    its slope changes."""
    prefix = np.concatenate([[0.0], np.cumsum(formation)])
    inside = (grid > path_from + DISTANCE_TOLERANCE) & (grid < path_to - DISTANCE_TOLERANCE)
    arcs = np.concatenate([[path_from], grid[inside], [path_to]])
    # G is the identity off the stretched cells, which lie inside the path: measure from A
    at_a = np.interp(path_from, grid, prefix)
    values = np.interp(arcs, grid, prefix) - at_a
    knots = np.column_stack([arcs - path_from, values])
    slopes = np.diff(knots[:, 1]) / np.diff(knots[:, 0])
    keep = np.ones(len(knots), bool)
    keep[1:-1] = np.abs(np.diff(slopes)) > 1e-9
    return knots[keep]
