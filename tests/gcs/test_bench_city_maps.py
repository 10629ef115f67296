"""The city-map benchmark's mission writer (`python -m bench.city_maps`): from stand-ins of
the three public files (the real ones are not redistributable), every route becomes a mission
the ground station reads, and a missing source names how to get it."""

from __future__ import annotations

import json

import numpy as np

from bench import city_maps
from gcs.geodesy import local_to_lonlat
from gcs.mission import load_mission
from planner.obstacles import Obstacles


def _square_feature(lonlat: np.ndarray, properties: dict) -> dict:
    ring = np.vstack([lonlat, lonlat[:1]]).tolist()
    return {
        "type": "Feature",
        "properties": properties,
        "geometry": {"type": "Polygon", "coordinates": [ring]},
    }


def _write_sources(data) -> None:
    square = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 20.0], [0.0, 20.0]]) + 5000.0
    vienna = _square_feature(local_to_lonlat(square, city_maps.VIENNA), {})
    (data / "vienna.geojson").write_text(
        json.dumps({"type": "FeatureCollection", "features": [vienna]})
    )
    mumbai = _square_feature(local_to_lonlat(square, city_maps.MUMBAI), {})
    body = json.dumps({"type": "FeatureCollection", "features": [mumbai]})
    (data / "mumbai.js").write_text(f"export const buildingGeojson = {body};\n")
    # Bet Shemesh's file is in EPSG:3857 with a Floors count, as the real one is
    from pyproj import Transformer

    lonlat = local_to_lonlat(square, city_maps.BET_SHEMESH)
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:3857", always_xy=True).transform(*lonlat.T)
    shemesh = _square_feature(np.column_stack([x, y]), {"Floors": 7})
    (data / "betshemesh.geojson").write_text(
        json.dumps(
            {
                "type": "FeatureCollection",
                "crs": {"type": "name", "properties": {"name": "EPSG:3857"}},
                "features": [shemesh],
            }
        )
    )


def test_every_route_becomes_a_mission_the_ground_station_reads(tmp_path):
    data, out = tmp_path / "data", tmp_path / "out"
    data.mkdir()
    _write_sources(data)
    assert city_maps.main([str(data), str(out)]) == 0
    missions = sorted(out.glob("*.yaml"))
    assert [m.stem for m in missions] == sorted(r.name for r in city_maps.ROUTES)
    for path, route in zip(missions, sorted(city_maps.ROUTES, key=lambda r: r.name), strict=True):
        mission = load_mission(path, check_clearance=False)
        assert np.allclose(mission.start.xy, route.start[:2])
        assert np.allclose(mission.goal.xy, route.goal[:2])
        assert mission.start.theta_deg == route.start[2] and mission.altitude == route.altitude
        assert len(mission.obstacles) >= 1
    # the heights variant keeps Bet Shemesh's 7-floor footprint (21 m > 20 m - 5 m)
    heights = load_mission(out / "betshemesh-2km-heights.yaml", check_clearance=False)
    assert heights.footprints[0].below_altitude == 0 and len(heights.obstacles) == 1


def test_a_missing_source_prints_how_to_download_it(tmp_path, capsys):
    assert city_maps.main([str(tmp_path), str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    for name, source in city_maps.SOURCES.items():
        assert f"curl -L -o {tmp_path / name} {source.url}" in err
    assert not (tmp_path / "out").exists()


def test_the_terraced_district_is_rows_of_touching_houses():
    houses = city_maps.terraced_district()
    again = city_maps.terraced_district()  # seeded
    assert len(houses) == len(again)
    assert all(np.array_equal(a, b) for a, b in zip(houses, again, strict=True))
    occluders = Obstacles(polygons=[h[:-1] for h in houses]).merged(0.01)
    assert len(occluders) == 12 * 13 * 2  # one per row of houses: they touch
