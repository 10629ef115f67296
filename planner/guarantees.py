"""Sampled checks of the paper's guarantees (theorems 3-5, objectives 1-3; docs/design.md 3.4
and 5).

From positions of N UAVs at T instants (virtual targets now, flown tracks later) compute, per
sample: the smallest horizontal UAV-UAV distance (theorem 4 promises >= 2 rho_c for the virtual
targets), the smallest UAV-obstacle distance (theorem 3: >= rho_c) and whether every UAV has a
multi-hop radio path, every hop no longer than the radio range, to a base station (theorem 5,
eqs. 7-8); with a `Sight`, every hop also needs its chord clear of the buildings (line of
sight, `planner.sight`). Distances equal to the range count as links, with DISTANCE_TOLERANCE (1e-6 m) to
absorb rounding. Everything is vectorised over samples; memory is bounded by working through
the samples in chunks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.formation import DISTANCE_TOLERANCE
from planner.obstacles import Obstacles
from planner.sight import Sight

# Work on at most this many (sample, node, node) cells at once.
_CHUNK_CELLS = 2_000_000


@dataclass(frozen=True, eq=False)
class GuaranteeSamples:
    """Per-sample guarantee metrics, each indexed by sample (T,)."""

    min_uav_uav_m: np.ndarray  # (T,) smallest pairwise distance; inf with one UAV
    min_uav_obstacle_m: np.ndarray  # (T,) inf without obstacles; 0 inside a solid one
    connected: np.ndarray  # (T,) bool: every UAV reaches a base station
    max_hops: np.ndarray  # (T,) int: hops of the worst-connected UAV, -1 if one is cut off
    hops: np.ndarray  # (T, N) int: hops from each UAV to its nearest base station, -1 if none

    def summary(self) -> dict:
        """Whole-run figures: minima (None when there is nothing to measure) and fractions."""

        def finite_min(values: np.ndarray) -> float | None:
            if values.size == 0 or not np.isfinite(values).any():
                return None
            return float(np.min(values))

        samples = int(self.connected.size)
        return {
            "samples": samples,
            "min_uav_uav_m": finite_min(self.min_uav_uav_m),
            "min_uav_obstacle_m": finite_min(self.min_uav_obstacle_m),
            "connected_fraction": float(self.connected.mean()) if samples else None,
            "max_hops": int(self.max_hops.max()) if samples else None,
        }


def _chunk_metrics(
    positions: np.ndarray,
    base_stations: np.ndarray,
    radio_range: float,
    heights: np.ndarray | None = None,
    sight: Sight | None = None,
):
    """Smallest UAV-UAV distance (T,) and hop counts (T, N) of a chunk of samples; with
    `heights` (T, N) the UAV-UAV distances are 3-D (the stations are reached horizontally);
    with `sight`, a link within range also needs a clear chord (horizontal).

    Hops: breadth-first search run on all samples at once; the frontier (T, N) grows through
    the UAV-UAV adjacency (T, N, N) until no sample gains a UAV. -1 = no path to a station.
    (A run checks one sample per tick: the reductions are numpy's ufunc reductions, without
    the Python layer of `ndarray.any` and `min`.)
    """
    samples, count = positions.shape[:2]
    limit = (radio_range + DISTANCE_TOLERANCE) ** 2
    to_base = positions[:, :, None, :] - base_stations[None, None, :, :]
    to_base = np.einsum("tnbd,tnbd->tnb", to_base, to_base) <= limit
    flat = positions
    if sight is not None:
        t, n, b = np.nonzero(to_base)
        to_base[t, n, b] = sight.clear(positions[t, n], base_stations[b])
    frontier = np.logical_or.reduce(to_base, axis=2)
    hops = np.where(frontier, 1, -1)
    if heights is not None:
        positions = np.concatenate([positions, heights[..., None]], axis=2)
    between = positions[:, :, None, :] - positions[:, None, :, :]
    squared = np.einsum("tijd,tijd->tij", between, between)
    adjacency = squared <= limit
    if sight is not None:
        t, i, j = np.nonzero(np.triu(adjacency, 1))
        clear = sight.clear(flat[t, i], flat[t, j])
        adjacency[t[~clear], i[~clear], j[~clear]] = False
        adjacency[t[~clear], j[~clear], i[~clear]] = False
    if count > 1:
        flat = squared.reshape(samples, count * count)
        flat[:, :: count + 1] = np.inf  # the diagonal
        closest = np.sqrt(np.minimum.reduce(flat, axis=1))
    else:
        closest = np.full(samples, np.inf)
    reached = frontier.copy()
    level = 1
    while np.count_nonzero(frontier):
        level += 1
        heard = np.logical_or.reduce(adjacency & frontier[:, None, :], axis=2)
        frontier = heard & ~reached
        reached |= frontier
        hops[frontier] = level
    return closest, hops


def check_positions(
    positions: np.ndarray,
    obstacles: Obstacles,
    base_stations: np.ndarray,
    radio_range: float,
    heights: np.ndarray | None = None,
    sight: Sight | None = None,
) -> GuaranteeSamples:
    """Guarantee metrics of UAV positions (T, N, 2) (horizontal; extra columns are ignored).

    `base_stations` (B, 2) are A, B and the mission's extra ones: the ground network joins them,
    so reaching any of them is enough (eq. 3 with more stations). `heights` (T, N), when some
    UAV flies in another layer (a relief, `planner.relief`): UAV-UAV distances and links are
    then 3-D; obstacles (prisms) and base stations are still reached horizontally. `sight`:
    `connected` and the hops count line-of-sight links only (`planner.sight`).
    """
    positions = np.asarray(positions, dtype=float)
    if positions.ndim == 2:
        positions = positions[None]
    if positions.ndim != 3 or positions.shape[2] < 2:
        raise ValueError("positions must be (T, N, 2)")
    positions = positions[..., :2]
    if heights is not None:
        heights = np.broadcast_to(np.asarray(heights, dtype=float), positions.shape[:2])
    stations = np.asarray(base_stations, dtype=float).reshape(-1, 2)
    if not radio_range > 0:
        raise ValueError("radio_range must be > 0")
    samples, count = positions.shape[:2]

    if count:
        to_obstacles = obstacles.distance_to_points(positions).min(axis=1)
    else:
        to_obstacles = np.full(samples, np.inf)

    step = max(1, _CHUNK_CELLS // max(1, count * (count + len(stations))))
    if samples <= step:
        closest, hops = _chunk_metrics(positions, stations, radio_range, heights, sight)
    else:
        closest = np.full(samples, np.inf)
        hops = np.full((samples, count), -1, dtype=int)
        for start in range(0, samples, step):
            chunk = slice(start, start + step)
            closest[chunk], hops[chunk] = _chunk_metrics(
                positions[chunk],
                stations,
                radio_range,
                None if heights is None else heights[chunk],
                sight,
            )
    connected = (hops >= 0).all(axis=1)
    max_hops = np.where(connected, hops.max(axis=1, initial=0), -1)
    return GuaranteeSamples(
        min_uav_uav_m=closest,
        min_uav_obstacle_m=to_obstacles,
        connected=connected,
        max_hops=max_hops,
        hops=hops,
    )


#: At most this many formation distances are sampled by `planned_connected_fraction`, and
#: fewer for a large fleet, so that about `PLANNED_CHORDS` node pairs are tested in all
#: (a line-of-sight fleet of 56: 117 samples, 0.1 s instead of 0.8 s), at least
#: `PLANNED_MIN_SAMPLES`.
PLANNED_SAMPLES = 1000
PLANNED_CHORDS = 200_000
PLANNED_MIN_SAMPLES = 50


def planned_connected_fraction(
    formation, base_stations: np.ndarray, radio_range: float, sight: Sight | None = None
) -> float:
    """The share of the planned flight (formation distance S from 0 to the end, sampled
    evenly: at most `PLANNED_SAMPLES`, fewer for a large fleet, never more than one per
    metre of S) during
    which every UAV's virtual target reaches a base station; by line of sight with `sight`."""
    total = float(formation.total_distance)
    size = formation.fleet_size
    pairs = size * (size - 1) // 2 + size * len(base_stations)
    most = max(PLANNED_MIN_SAMPLES, min(PLANNED_SAMPLES, PLANNED_CHORDS // max(pairs, 1)))
    count = int(min(most, max(2, np.ceil(total) + 1)))
    positions = formation.positions(np.linspace(0.0, total, count))
    checked = check_positions(positions, Obstacles(), base_stations, radio_range, sight=sight)
    return float(checked.connected.mean())
