"""Local east-north-up frame <-> WGS84 through the mission origin (pymap3d).

The mission's local frame (CONTRACTS.md) has x east, y north in metres and altitudes above the
origin; `Origin` anchors it on the WGS84 ellipsoid. Conversions are vectorised over arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pymap3d

#: WGS84 (the ellipsoid pymap3d uses by default).
_WGS84 = pymap3d.Ellipsoid.from_name("wgs84")
_A = _WGS84.semimajor_axis
_E2 = 1.0 - (_WGS84.semiminor_axis / _A) ** 2


@dataclass(frozen=True)
class Origin:
    """Geodetic anchor of the local frame: latitude, longitude (degrees), altitude (m, AMSL)."""

    lat: float
    lon: float
    alt: float


def geodetic_to_enu(
    lat: np.ndarray | float, lon: np.ndarray | float, alt: np.ndarray | float, origin: Origin
) -> np.ndarray:
    """WGS84 (degrees, metres) -> local (..., 3) east, north, up in metres."""
    e, n, u = pymap3d.geodetic2enu(lat, lon, alt, origin.lat, origin.lon, origin.alt)
    return np.stack(np.broadcast_arrays(e, n, u), axis=-1).astype(float)


def _ecef(lat: float, lon: float, alt: float) -> tuple[float, float, float]:
    """WGS84 geodetic (degrees, m) -> ECEF (m): the closed form pymap3d's geodetic2ecef uses."""
    phi, lam = math.radians(lat), math.radians(lon)
    sin_phi, cos_phi = math.sin(phi), math.cos(phi)
    normal = _A / math.sqrt(1.0 - _E2 * sin_phi * sin_phi)
    return (
        (normal + alt) * cos_phi * math.cos(lam),
        (normal + alt) * cos_phi * math.sin(lam),
        (normal * (1.0 - _E2) + alt) * sin_phi,
    )


@lru_cache(maxsize=16)
def _frame(origin: Origin) -> tuple[tuple[float, float, float], tuple[float, ...]]:
    """The origin's ECEF position and the ECEF -> ENU rotation (row-major)."""
    phi, lam = math.radians(origin.lat), math.radians(origin.lon)
    sp, cp, sl, cl = math.sin(phi), math.cos(phi), math.sin(lam), math.cos(lam)
    rotation = (-sl, cl, 0.0, -sp * cl, -sp * sl, cp, cp * cl, cp * sl, sp)
    return _ecef(origin.lat, origin.lon, origin.alt), rotation


def geodetic_point_to_enu(lat: float, lon: float, alt: float, origin: Origin) -> np.ndarray:
    """One WGS84 point -> (3,) east, north, up: the same exact closed form as
    `geodetic_to_enu`, in scalar arithmetic (the drivers convert every position message, and
    numpy's per-call overhead dominates for one point)."""
    (x0, y0, z0), r = _frame(origin)
    x, y, z = _ecef(lat, lon, alt)
    dx, dy, dz = x - x0, y - y0, z - z0
    return np.array(
        [
            r[0] * dx + r[1] * dy,
            r[3] * dx + r[4] * dy + r[5] * dz,
            r[6] * dx + r[7] * dy + r[8] * dz,
        ]
    )


def enu_to_geodetic(
    east: np.ndarray | float, north: np.ndarray | float, up: np.ndarray | float, origin: Origin
) -> np.ndarray:
    """Local east, north, up (metres) -> (..., 3) latitude, longitude (degrees), altitude (m)."""
    lat, lon, alt = pymap3d.enu2geodetic(east, north, up, origin.lat, origin.lon, origin.alt)
    return np.stack(np.broadcast_arrays(lat, lon, alt), axis=-1).astype(float)


def lonlat_to_local(lonlat: np.ndarray, origin: Origin) -> np.ndarray:
    """GeoJSON-ordered (..., 2) longitude, latitude at the origin's altitude -> (..., 2) x, y.

    Footprints are projected horizontally: the altitude used is the origin's, so the
    east/north coordinates do not pick up the tangent plane's curvature drop.
    """
    lonlat = np.asarray(lonlat, float)
    enu = geodetic_to_enu(lonlat[..., 1], lonlat[..., 0], origin.alt, origin)
    return enu[..., :2]


def local_to_lonlat(xy: np.ndarray, origin: Origin) -> np.ndarray:
    """Inverse of `lonlat_to_local`: local (..., 2) x, y -> (..., 2) longitude, latitude.

    The point sought lies at the origin's altitude, below the tangent plane by about
    d^2 / 2R (0.2 m at 1.6 km); a few fixed-point steps on the up coordinate find it.
    """
    xy = np.asarray(xy, float)
    up = np.zeros(xy.shape[:-1])
    for _ in range(4):
        geo = enu_to_geodetic(xy[..., 0], xy[..., 1], up, origin)
        up = up - (geo[..., 2] - origin.alt)
    return geo[..., [1, 0]]
