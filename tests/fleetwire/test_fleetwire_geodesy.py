"""`fleetwire.geodesy` against pymap3d: the ENU -> WGS84 closed form (You 2000) must give
pymap3d's results (the same operations: to the last bit, sub-millimetre whatever happens), over
origins from the equator to the poles, points from millimetres to hundreds of kilometres away,
above and below the ellipsoid, the degenerate ones on the polar axis included."""

from __future__ import annotations

import numpy as np
import pymap3d
import pytest

from fleetwire.geodesy import EnuFrame, Origin
from gcs.geodesy import enu_to_geodetic, geodetic_point_to_enu


def _cases():
    rng = np.random.default_rng(2000)
    for _ in range(400):
        lat0 = rng.uniform(-89.9, 89.9)
        lon0 = rng.uniform(-180.0, 180.0)
        alt0 = rng.choice([0.0, rng.uniform(-400.0, 9000.0)])
        count = int(rng.integers(1, 30))
        scale = 10 ** rng.uniform(-3, 5.5)
        east, north = rng.uniform(-scale, scale, (2, count))
        up = rng.choice([0.0, 1.0], count) * rng.uniform(-scale, scale, count)
        yield (lat0, lon0, alt0), east, north, up


def test_enu_to_geodetic_is_pymap3d_to_the_last_bit():
    worst = np.zeros(3)
    for (lat0, lon0, alt0), east, north, up in _cases():
        mine = EnuFrame(lat0, lon0, alt0).to_geodetic(east, north, up)
        theirs = pymap3d.enu2geodetic(east, north, up, lat0, lon0, alt0)
        for k, (a, b) in enumerate(zip(mine, theirs, strict=True)):
            assert np.shape(a) == np.shape(b)
            worst[k] = max(worst[k], float(np.max(np.abs(a - b))))
    # degrees, degrees, metres: identical operations, identical results
    assert worst.tolist() == [0.0, 0.0, 0.0]


def test_enu_to_geodetic_is_sub_millimetre_at_the_poles_and_for_scalars():
    for lat0 in (90.0, -90.0, 89.9999999):
        east = np.array([0.0, 1e-4, 3.0, -250.0])
        north = np.array([0.0, 0.0, -2.0, 400.0])
        up = np.array([0.0, 5.0, -1.0, 30.0])
        mine = EnuFrame(lat0, 12.0, 100.0).to_geodetic(east, north, up)
        theirs = pymap3d.enu2geodetic(east, north, up, lat0, 12.0, 100.0)
        back = pymap3d.geodetic2enu(*mine, lat0, 12.0, 100.0)
        assert np.allclose(mine[0], theirs[0], rtol=0, atol=1e-12)
        assert np.allclose(mine[2], theirs[2], rtol=0, atol=1e-6)
        assert np.allclose(np.stack(back), np.stack([east, north, up]), rtol=0, atol=1e-3)
    lat, lon, alt = EnuFrame(45.764, 4.8357, 170.0).to_geodetic(12.5, -40.0, 30.0)
    assert (float(lat), float(lon), float(alt)) == tuple(
        float(v) for v in pymap3d.enu2geodetic(12.5, -40.0, 30.0, 45.764, 4.8357, 170.0)
    )


def test_the_ground_station_and_the_vehicles_share_the_conversion():
    origin = Origin(45.764, 4.8357, 170.0)
    xyz = np.array([[0.0, 0.0, 0.0], [300.0, -120.0, 30.0], [1500.0, 900.0, 45.0]])
    station = enu_to_geodetic(xyz[:, 0], xyz[:, 1], xyz[:, 2], origin)
    vehicles = np.column_stack(Origin(45.764, 4.8357, 170.0).to_geodetic(xyz))
    assert np.array_equal(station, vehicles)
    theirs = np.column_stack(
        pymap3d.enu2geodetic(xyz[:, 0], xyz[:, 1], xyz[:, 2], 45.764, 4.8357, 170.0)
    )
    assert np.array_equal(station, theirs)


def test_one_geodetic_point_to_local_matches_pymap3d_sub_millimetre():
    rng = np.random.default_rng(7)
    for _ in range(500):
        origin = Origin(rng.uniform(-85, 85), rng.uniform(-180, 180), rng.uniform(-100, 3000))
        lat = origin.lat + rng.normal(0.0, 0.05)
        lon = origin.lon + rng.normal(0.0, 0.05)
        alt = origin.alt + rng.normal(0.0, 200.0)
        mine = geodetic_point_to_enu(lat, lon, alt, origin)
        theirs = pymap3d.geodetic2enu(lat, lon, alt, origin.lat, origin.lon, origin.alt)
        assert mine == pytest.approx(np.array(theirs, dtype=float), abs=1e-4)
