"""Local east-north-up frame <-> WGS84 through the mission origin (pymap3d).

The mission's local frame (docs/mission-file.md) has x east, y north in metres and altitudes above
the origin; `Origin` anchors it on the WGS84 ellipsoid. Conversions are vectorised over arrays.
ENU -> WGS84 is `fleetwire.geodesy` (pymap3d's closed form without its per-call overhead: the
core converts every tick's setpoints), shared with the simulated vehicles.
"""

from __future__ import annotations

import numpy as np

from fleetwire.geodesy import Origin

__all__ = [
    "Origin",
    "enu_to_geodetic",
    "geodetic_point_to_enu",
    "geodetic_to_enu",
    "local_to_lonlat",
    "lonlat_to_local",
]


def geodetic_to_enu(
    lat: np.ndarray | float, lon: np.ndarray | float, alt: np.ndarray | float, origin: Origin
) -> np.ndarray:
    """WGS84 (degrees, metres) -> local (..., 3) east, north, up in metres."""
    import pymap3d  # here: its import (dateutil, its time modules) costs every `gcs` start

    e, n, u = pymap3d.geodetic2enu(lat, lon, alt, origin.lat, origin.lon, origin.alt)
    return np.stack(np.broadcast_arrays(e, n, u), axis=-1).astype(float)


def geodetic_point_to_enu(lat: float, lon: float, alt: float, origin: Origin) -> np.ndarray:
    """One WGS84 point -> (3,) east, north, up: the same exact closed form as
    `geodetic_to_enu`, in scalar arithmetic (the drivers convert every position message, and
    numpy's per-call overhead dominates for one point; `fleetwire.geodesy`)."""
    return np.array(origin.enu_frame.point_to_local(lat, lon, alt))


def enu_to_geodetic(
    east: np.ndarray | float, north: np.ndarray | float, up: np.ndarray | float, origin: Origin
) -> np.ndarray:
    """Local east, north, up (metres) -> (..., 3) latitude, longitude (degrees), altitude (m)."""
    lat, lon, alt = origin.enu_frame.to_geodetic(east, north, up)
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
