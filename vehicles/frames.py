"""Local ENU frame <-> WGS84 and the MAVLink frames the vehicles speak (pure, pymap3d).

The simulation's local frame is ENU metres (x east, y north, z up) anchored at a geodetic
origin (the ``--home`` of ``vehicles sim``); MAVLink local frames are NED. Altitudes are metres
above the WGS84 ellipsoid as pymap3d computes them; the vehicles report them as AMSL (a flat
simulated world has no geoid). ENU -> WGS84 is the ground station's conversion too
(`fleetwire.geodesy`: pymap3d's closed form without its per-call overhead).
"""

from __future__ import annotations

import numpy as np


def ned_to_enu(vector: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    """One (north, east, down) vector -> (east, north, up)."""
    north, east, down = vector
    return np.array([east, north, -down], dtype=float)


def rotate_body_to_ned(vector_frd: np.ndarray, yaw_rad: float) -> np.ndarray:
    """Forward-right-down offsets of a vehicle heading ``yaw_rad`` -> north-east-down."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    forward, right, down = vector_frd
    return np.array([c * forward - s * right, s * forward + c * right, down])
