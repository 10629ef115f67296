"""Local east-north-up (ENU) metres <-> WGS84, written once for both ends of the wire (pure).

A MAVLink position is latitude, longitude and altitude; the ground station and the simulated
vehicles think in a local ENU frame anchored at a geodetic origin. `EnuFrame.point_to_local`
converts one geodetic point (every position message) in scalar arithmetic: the exact closed
form geodetic -> ECEF (prime-vertical radius of curvature N = a / sqrt(1 - e^2 sin^2 phi)),
then the ECEF -> ENU rotation at the origin. `EnuFrame.to_geodetic` is pymap3d's
``enu2geodetic`` without its per-call overhead, for the arrays of a few points that every
telemetry tick and every setpoint tick convert:

* ENU -> ECEF: the origin's ECEF position (pymap3d's ``geodetic2ecef``, computed once) plus the
  ENU vector rotated by the origin's latitude and longitude (pymap3d's ``enu2uvw``);
* ECEF -> geodetic: the closed form (no iteration) of R.-J. You, "Transformation of Cartesian
  to Geodetic Coordinates without Iterations", Journal of Surveying Engineering 126(1), 1-7,
  2000, doi:10.1061/(ASCE)0733-9453(2000)126:1(1): a reduced latitude from the confocal
  ellipsoid through the point (eqs. 4a-4b), one correction step (eq. 13), then latitude
  (eq. 4c) and height (eq. 7). It is the algorithm of pymap3d's ``ecef2geodetic``.

Both steps are pymap3d's own numpy operations, in its order, so the results are pymap3d's to the
last bit (`tests/fleetwire/test_fleetwire_geodesy.py` compares them over a range of points), but one
conversion of 9 points costs about 30 us instead of 100 us: pymap3d looks the ellipsoid up, tests
every point for the degenerate cases with `isclose` and assigns through boolean masks on every call,
and tests whether a point is below the ellipsoid where the confocal ellipsoid through it already
says so. The degenerate points (within 1 mm of the polar axis, where pymap3d patches the latitude
and height, or of the Earth's centre) are handed to pymap3d itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pymap3d
from pymap3d.ecef import geodetic2ecef, uvw2enu

#: WGS84, the ellipsoid pymap3d uses by default: semi-major and semi-minor axes (m).
_WGS84 = pymap3d.Ellipsoid.from_name("wgs84")
_A = _WGS84.semimajor_axis
_B = _WGS84.semiminor_axis
#: Linear eccentricity E (You's eq. 2) and E^2, as pymap3d computes them.
_E = np.sqrt(_A**2 - _B**2)
_E2 = _E**2
#: First eccentricity squared, e^2 = 1 - (b/a)^2.
_ECCENTRICITY2 = 1.0 - (_B / _A) ** 2
#: Points closer than this (m) to the polar axis or the Earth's centre go to pymap3d.
_DEGENERATE_M = 1e-3


@dataclass(frozen=True)
class _Rotation:
    """What a conversion from an `EnuFrame` needs of its origin, computed once."""

    ecef: tuple[float, float, float]  # the origin's ECEF position (m)
    cos_lat: float
    sin_lat: float
    cos_lon: float
    sin_lon: float


@dataclass(frozen=True)
class _PointRotation:
    """The origin's ECEF position and the ECEF -> ENU rotation (row-major), in Python floats,
    for `EnuFrame.point_to_local`."""

    ecef: tuple[float, float, float]
    rotation: tuple[float, float, float, float, float, float, float, float, float]


def _point_to_ecef(lat: float, lon: float, alt: float) -> tuple[float, float, float]:
    """WGS84 geodetic (degrees, m) -> ECEF (m), exact closed form in scalar arithmetic."""
    phi, lam = math.radians(lat), math.radians(lon)
    sin_phi, cos_phi = math.sin(phi), math.cos(phi)
    normal = _A / math.sqrt(1.0 - _ECCENTRICITY2 * sin_phi * sin_phi)
    return (
        (normal + alt) * cos_phi * math.cos(lam),
        (normal + alt) * cos_phi * math.sin(lam),
        (normal * (1.0 - _ECCENTRICITY2) + alt) * sin_phi,
    )


@dataclass(frozen=True)
class EnuFrame:
    """A local ENU frame: x east, y north, z up (m) from the geodetic point of its origin
    (latitude, longitude in degrees, altitude in metres above the WGS84 ellipsoid)."""

    latitude_deg: float
    longitude_deg: float
    altitude_m: float

    @cached_property
    def _rotation(self) -> _Rotation:
        x0, y0, z0 = geodetic2ecef(self.latitude_deg, self.longitude_deg, self.altitude_m)
        lat0, lon0 = np.radians(self.latitude_deg), np.radians(self.longitude_deg)
        return _Rotation((x0, y0, z0), np.cos(lat0), np.sin(lat0), np.cos(lon0), np.sin(lon0))

    @cached_property
    def _point_rotation(self) -> _PointRotation:
        phi, lam = math.radians(self.latitude_deg), math.radians(self.longitude_deg)
        sp, cp, sl, cl = math.sin(phi), math.cos(phi), math.sin(lam), math.cos(lam)
        return _PointRotation(
            _point_to_ecef(self.latitude_deg, self.longitude_deg, self.altitude_m),
            (-sl, cl, 0.0, -sp * cl, -sp * sl, cp, cp * cl, cp * sl, sp),
        )

    def point_to_local(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """One WGS84 point (degrees, m) -> east, north, up (m), in scalar arithmetic (numpy's
        per-call overhead would dominate for one point)."""
        frame = self._point_rotation
        x0, y0, z0 = frame.ecef
        r = frame.rotation
        x, y, z = _point_to_ecef(lat, lon, alt)
        dx, dy, dz = x - x0, y - y0, z - z0
        return (
            r[0] * dx + r[1] * dy,
            r[3] * dx + r[4] * dy + r[5] * dz,
            r[6] * dx + r[7] * dy + r[8] * dz,
        )

    def to_geodetic(self, east, north, up) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """ENU (m, arrays or scalars broadcast together) -> latitude, longitude (degrees) and
        altitude (m) arrays of their broadcast shape: pymap3d's ``enu2geodetic`` (module
        docstring)."""
        east, north, up = (np.asarray(v, dtype=float) for v in (east, north, up))
        rot = self._rotation
        # pymap3d's enu2uvw and enu2ecef
        t = rot.cos_lat * up - rot.sin_lat * north
        w = rot.sin_lat * up + rot.cos_lat * north
        u = rot.cos_lon * t - rot.sin_lon * east
        v = rot.sin_lon * t + rot.cos_lon * east
        x0, y0, z0 = rot.ecef
        return _ecef_to_geodetic(x0 + u, y0 + v, z0 + w)


def _ecef_to_geodetic(x: np.ndarray, y: np.ndarray, z: np.ndarray):
    """ECEF (m) -> latitude, longitude (degrees), altitude (m): You (2000), in the operations
    and order of pymap3d's ``ecef2geodetic`` (module docstring)."""
    r = np.sqrt(x**2 + y**2 + z**2)
    r2_e2 = r**2 - _E2
    u = np.sqrt(0.5 * r2_e2 + 0.5 * np.hypot(r2_e2, 2 * _E * z))  # eq. 4a
    hxy = np.hypot(x, y)
    lowest_u = np.minimum.reduce(u, axis=None, initial=np.inf)
    if (
        lowest_u <= _DEGENERATE_M
        or np.minimum.reduce(hxy, axis=None, initial=np.inf) <= _DEGENERATE_M
    ):
        lat, lon, alt = pymap3d.ecef2geodetic(x, y, z)
        return np.asarray(lat, dtype=float), np.asarray(lon, dtype=float), np.asarray(alt)
    hue = np.hypot(u, _E)
    beta = np.arctan(hue / u * z / hxy)  # eq. 4b
    a_hue, cos_beta = _A * hue, np.cos(beta)
    beta += ((_B * u - a_hue + _E2) * np.sin(beta)) / (a_hue / cos_beta - _E2 * cos_beta)  # eq. 13
    lat = np.arctan(_A / _B * np.tan(beta))  # eq. 4c
    lon = np.arctan2(y, x)
    alt = np.hypot(z - _B * np.sin(beta), hxy - _A * np.cos(beta))  # eq. 7
    # Below the ellipsoid the height is negative. u is the semi-minor axis of the confocal
    # ellipsoid through the point, so u > b (by far more than rounding) means outside.
    if lowest_u <= _B + _DEGENERATE_M:
        inside = x**2 / _A**2 + y**2 / _A**2 + z**2 / _B**2 < 1
        alt = np.where(inside, -alt, alt)
    return np.degrees(lat), np.degrees(lon), alt


@dataclass(frozen=True)
class Origin:
    """Geodetic anchor of the local frame, for the ground station and the vehicles alike:
    latitude, longitude (degrees), altitude (m, AMSL) of local (0, 0, 0)."""

    lat: float
    lon: float
    alt: float

    @cached_property
    def enu_frame(self) -> EnuFrame:
        """The local frame this origin anchors (ENU <-> WGS84)."""
        return EnuFrame(self.lat, self.lon, self.alt)

    def to_geodetic(self, enu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N, 3) local ENU -> latitude deg, longitude deg, altitude m arrays."""
        enu = np.asarray(enu, dtype=float).reshape(-1, 3)
        return self.enu_frame.to_geodetic(enu[:, 0], enu[:, 1], enu[:, 2])

    @cached_property
    def _ecef(self) -> tuple[float, float, float]:
        x, y, z = geodetic2ecef(self.lat, self.lon, self.alt)
        return float(x), float(y), float(z)

    def to_local(self, lat: float, lon: float, alt: float) -> np.ndarray:
        """One geodetic point -> local ENU (3,): pymap3d's geodetic2enu with the origin's ECEF
        cached (the vehicles' setpoints in the global frame)."""
        x, y, z = geodetic2ecef(lat, lon, alt)
        x0, y0, z0 = self._ecef
        east, north, up = uvw2enu(x - x0, y - y0, z - z0, self.lat, self.lon)
        return np.array([float(east), float(north), float(up)])
