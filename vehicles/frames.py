"""Local ENU frame <-> WGS84 and the MAVLink frames the vehicles speak (pure, pymap3d).

The simulation's local frame is ENU metres (x east, y north, z up) anchored at a geodetic
origin (the ``--home`` of ``vehicles sim``); MAVLink local frames are NED. Altitudes are metres
above the WGS84 ellipsoid as pymap3d computes them; the vehicles report them as AMSL (a flat
simulated world has no geoid). ENU -> WGS84 is the ground station's conversion too
(`fleetwire.geodesy`: pymap3d's closed form without its per-call overhead).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from pymap3d.ecef import geodetic2ecef, uvw2enu

from fleetwire.geodesy import EnuFrame


@dataclass(frozen=True)
class GeodeticOrigin:
    """The geodetic point of local (0, 0, 0): latitude and longitude in degrees, altitude m."""

    latitude_deg: float
    longitude_deg: float
    altitude_m: float

    def to_geodetic(self, enu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N, 3) local ENU -> latitude deg, longitude deg, altitude m arrays."""
        enu = np.asarray(enu, dtype=float).reshape(-1, 3)
        return self._frame.to_geodetic(enu[:, 0], enu[:, 1], enu[:, 2])

    @cached_property
    def _frame(self) -> EnuFrame:
        return EnuFrame(self.latitude_deg, self.longitude_deg, self.altitude_m)

    @cached_property
    def _ecef(self) -> tuple[float, float, float]:
        x, y, z = geodetic2ecef(self.latitude_deg, self.longitude_deg, self.altitude_m)
        return float(x), float(y), float(z)

    def to_local(self, latitude_deg: float, longitude_deg: float, altitude_m: float) -> np.ndarray:
        """One geodetic point -> local ENU (3,): pymap3d's geodetic2enu with the origin's ECEF cached."""
        x, y, z = geodetic2ecef(latitude_deg, longitude_deg, altitude_m)
        x0, y0, z0 = self._ecef
        east, north, up = uvw2enu(x - x0, y - y0, z - z0, self.latitude_deg, self.longitude_deg)
        return np.array([float(east), float(north), float(up)])


def ned_to_enu(vector: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    """One (north, east, down) vector -> (east, north, up)."""
    north, east, down = vector
    return np.array([east, north, -down], dtype=float)


def rotate_body_to_ned(vector_frd: np.ndarray, yaw_rad: float) -> np.ndarray:
    """Forward-right-down offsets of a vehicle heading ``yaw_rad`` -> north-east-down."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    forward, right, down = vector_frd
    return np.array([c * forward - s * right, s * forward + c * right, down])
