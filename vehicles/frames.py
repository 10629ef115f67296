"""Local ENU frame <-> WGS84 and the MAVLink frames the vehicles speak (pure, pymap3d).

The simulation's local frame is ENU metres (x east, y north, z up) anchored at a geodetic
origin (the ``--home`` of ``vehicles sim``); MAVLink local frames are NED. Altitudes are metres
above the WGS84 ellipsoid as pymap3d computes them; the vehicles report them as AMSL (a flat
simulated world has no geoid).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pymap3d


@dataclass(frozen=True)
class GeodeticOrigin:
    """The geodetic point of local (0, 0, 0): latitude and longitude in degrees, altitude m."""

    latitude_deg: float
    longitude_deg: float
    altitude_m: float

    def to_geodetic(self, enu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N, 3) local ENU -> latitude deg, longitude deg, altitude m arrays."""
        enu = np.asarray(enu, dtype=float).reshape(-1, 3)
        lat, lon, alt = pymap3d.enu2geodetic(
            enu[:, 0], enu[:, 1], enu[:, 2], self.latitude_deg, self.longitude_deg, self.altitude_m
        )
        return np.asarray(lat), np.asarray(lon), np.asarray(alt)

    def to_local(self, latitude_deg: float, longitude_deg: float, altitude_m: float) -> np.ndarray:
        """One geodetic point -> local ENU (3,)."""
        east, north, up = pymap3d.geodetic2enu(
            latitude_deg,
            longitude_deg,
            altitude_m,
            self.latitude_deg,
            self.longitude_deg,
            self.altitude_m,
        )
        return np.array([float(east), float(north), float(up)])


def ned_to_enu(vector: np.ndarray) -> np.ndarray:
    """(north, east, down) -> (east, north, up), on the last axis."""
    vector = np.asarray(vector, dtype=float)
    return np.stack([vector[..., 1], vector[..., 0], -vector[..., 2]], axis=-1)


def enu_to_ned(vector: np.ndarray) -> np.ndarray:
    """(east, north, up) -> (north, east, down), on the last axis."""
    vector = np.asarray(vector, dtype=float)
    return np.stack([vector[..., 1], vector[..., 0], -vector[..., 2]], axis=-1)


def rotate_body_to_ned(vector_frd: np.ndarray, yaw_rad: float) -> np.ndarray:
    """Forward-right-down offsets of a vehicle heading ``yaw_rad`` -> north-east-down."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    forward, right, down = vector_frd
    return np.array([c * forward - s * right, s * forward + c * right, down])
