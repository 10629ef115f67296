"""Links through buildings: 3GPP TR 38.901's UMi-Street Canyon path loss (pure, vectorised).

The paper's radio is a disk: two nodes within rho_R hear each other. In a city a building
between them changes that. TR 38.901 (Table 7.4.1-1, UMi-Street Canyon, 0.5-100 GHz) gives
the median path loss in dB, for a 3-D distance d (m), a carrier frequency f (GHz) and a
terminal height h (m, 1.5-22.5):

    PL_LOS  = 32.4 + 21 log10(d) + 20 log10(f)                       (d below the breakpoint)
    PL_NLOS = max(PL_LOS, 35.3 log10(d) + 22.4 + 21.3 log10(f) - 0.3 (h - 1.5))

We read rho_R as the range of a line-of-sight link: the link budget is PL_LOS(rho_R), so in the
open the radio is still the paper's disk. A link whose chord meets a building is non-line-of-
sight and lives while PL_NLOS(d) is within that budget: up to `nlos_range_m`, about a third
of rho_R (rho_R 150 m at 2.4 GHz and 22.5 m: 55 m). The breakpoint (4 h'^2 f / c with
h' = h - 1: 15 km at 22.5 m) lies far beyond any rho_R here, so PL_LOS has one slope. Heights
are clamped to the model's range (the fleet flies at 20-40 m; the UMi-AV model of TR 36.777
for aerial terminals needs the buildings' heights, which footprints seldom have). Medians
only: shadow fading (sigma 4 dB LOS, 7.82 dB NLOS) is not drawn, so a link's fate is a
function of the geometry, as the planner's guarantees assume.

`ThroughBuildings` wraps a line-of-sight test (`planner.sight.Sight`) into the medium's
`medium.radio.LineOfSight`: a chord is usable when it is clear or shorter than the NLOS range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from medium.radio import LineOfSight

#: TR 38.901 UMi-Street Canyon validity: carrier frequency (GHz) and terminal height (m).
FREQUENCY_RANGE_GHZ = (0.5, 100.0)
HEIGHT_RANGE_M = (1.5, 22.5)
#: The model's shortest distance (m): below it, the loss at 10 m.
MIN_DISTANCE_M = 10.0
#: 2.4 GHz: the ISM band of 802.11 and of most UAV telemetry radios.
DEFAULT_FREQUENCY_GHZ = 2.4


def _clamp_height(height_m: float) -> float:
    return float(np.clip(height_m, *HEIGHT_RANGE_M))


def los_path_loss_db(distance_m, frequency_ghz: float) -> np.ndarray:
    """Median PL_LOS (dB) of UMi-Street Canyon below the breakpoint (TR 38.901 Table 7.4.1-1)."""
    d = np.maximum(np.asarray(distance_m, dtype=float), MIN_DISTANCE_M)
    return 32.4 + 21.0 * np.log10(d) + 20.0 * math.log10(frequency_ghz)


def nlos_path_loss_db(distance_m, frequency_ghz: float, height_m: float) -> np.ndarray:
    """Median PL_NLOS (dB) of UMi-Street Canyon: never below PL_LOS."""
    d = np.maximum(np.asarray(distance_m, dtype=float), MIN_DISTANCE_M)
    h = _clamp_height(height_m)
    nlos = 35.3 * np.log10(d) + 22.4 + 21.3 * math.log10(frequency_ghz) - 0.3 * (h - 1.5)
    return np.maximum(los_path_loss_db(d, frequency_ghz), nlos)


def nlos_range_m(range_m: float, frequency_ghz: float, height_m: float) -> float:
    """The longest NLOS link within the budget of a LOS link of `range_m` (PL_NLOS inverted
    at PL_LOS(range_m)); never longer than `range_m`, infinite for an infinite range."""
    if math.isinf(range_m):
        return math.inf
    budget = float(los_path_loss_db(range_m, frequency_ghz))
    h = _clamp_height(height_m)
    intercept = 22.4 + 21.3 * math.log10(frequency_ghz) - 0.3 * (h - 1.5)
    reach = 10.0 ** ((budget - intercept) / 35.3)
    return float(min(reach, range_m))


@dataclass(frozen=True, eq=False)
class ThroughBuildings:
    """A chord is usable by the radio when it clears the buildings (`sight`) or is at most
    `nlos_range_m` long (0: every chord through a building is cut)."""

    sight: LineOfSight
    nlos_range_m: float = 0.0

    def clear(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        starts = np.asarray(starts, dtype=float).reshape(-1, 2)
        ends = np.asarray(ends, dtype=float).reshape(-1, 2)
        if self.nlos_range_m <= 0:
            return self.sight.clear(starts, ends)
        short = np.hypot(*(ends - starts).T) <= self.nlos_range_m
        usable = short.copy()
        if not short.all():
            usable[~short] = self.sight.clear(starts[~short], ends[~short])
        return usable
