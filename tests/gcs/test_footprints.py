"""Footprint files (gcs.mission.footprints): messy GeoJSON skipped / repaired / dropped and reported
in one warning line, strict refusals, projected CRSs, heights, the optional OSM and GIS readers
(skipped when their extra is absent) and the plan JSON's `map`. In-process and fast."""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

import numpy as np
import pytest
import shapely

from gcs.errors import InputError
from gcs.geodesy import local_to_lonlat, lonlat_to_local
from gcs.mission import load_mission
from gcs.mission.footprints import (
    FootprintOptions,
    feature_height,
    file_format,
    footprint_file,
    map_json,
    parse_height,
    read_footprints,
)
from tests.mission_texts import LYON, MINIMAL

MISSION = (
    MINIMAL.replace("version: 1\n", "version: 1\norigin: {lat: 45.7640, lon: 4.8357, alt: 170}\n")
    + "obstacles:\n"
)


def lonlat(local: list | np.ndarray, close: bool = True) -> list[list[float]]:
    """Local (x, y) points -> a lon/lat position list (closed when asked)."""
    local = np.asarray(local, float)
    if close:
        local = np.vstack([local, local[:1]])
    return local_to_lonlat(local, LYON).tolist()


def square(x: float, y: float, side: float = 20.0) -> np.ndarray:
    return np.array([[x, y], [x + side, y], [x + side, y + side], [x, y + side]], float)


def feature(geometry: dict | None, **properties) -> dict:
    return {"type": "Feature", "properties": properties, "geometry": geometry}


def polygon(local: np.ndarray) -> dict:
    return {"type": "Polygon", "coordinates": [lonlat(local)]}


def mission_with(tmp_path: Path, features: list[dict], item: str = "b.geojson", **doc) -> Path:
    (tmp_path / "b.geojson").write_text(
        json.dumps({"type": "FeatureCollection", **doc, "features": features})
    )
    path = tmp_path / "m.yaml"
    path.write_text(MISSION + f"  - geojson: {item}\n")
    return path


def refusal(path: Path) -> InputError:
    with pytest.raises(InputError) as caught:
        load_mission(path)
    return caught.value


def warnings_of(caplog) -> list[str]:
    return [
        r.getMessage()
        for r in caplog.records
        if r.name == "gcs.mission.footprints" and r.levelno == logging.WARNING
    ]


# --- messy files --------------------------------------------------------------------------------

BOW_TIE = np.array([[500, 0], [540, 40], [540, 0], [500, 40]], float)  # two triangles
MESSY = [
    feature(polygon(BOW_TIE)),  # 0: repaired into two footprints
    feature({"type": "Point", "coordinates": lonlat([[600, 600]], close=False)[0]}),  # 1
    feature({"type": "MultiPoint", "coordinates": lonlat([[600, 600], [610, 600]], False)}),
    feature(polygon(np.array([[500, 300], [520, 300], [540, 300]]))),  # 3: zero area
    feature(polygon(square(600, 0))),  # 4: clean
    feature(  # 5: a collection without footprints
        {
            "type": "GeometryCollection",
            "geometries": [{"type": "Point", "coordinates": [4.84, 45.77]}],
        }
    ),
    feature(  # 6: a collection with a polygon
        {"type": "GeometryCollection", "geometries": [polygon(square(700, 0))]}
    ),
    feature(None),  # 7: no geometry
]
MESSY_LINE = (
    "b.geojson: used 3 footprints; skipped 4 (features[1] Point, features[2] MultiPoint, "
    "features[5] GeometryCollection, ...), repaired 1 (features[0]), dropped 1 zero-area "
    "(features[3])"
)


def test_messy_file_is_used_and_reported_in_one_warning_line(tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="gcs.mission.footprints")
    mission = load_mission(mission_with(tmp_path, MESSY))
    assert warnings_of(caplog) == [MESSY_LINE]
    assert mission.obstacle_keys == (
        "obstacles[0].geojson.features[0]",  # the bow-tie's two triangles
        "obstacles[0].geojson.features[0]",
        "obstacles[0].geojson.features[4]",
        "obstacles[0].geojson.features[6]",
    )
    triangles = [shapely.Polygon(p) for p in mission.obstacles.polygons[:2]]
    assert all(t.is_valid for t in triangles)
    assert sum(t.area for t in triangles) == pytest.approx(2 * 400, rel=1e-4)
    (report,) = mission.footprints
    assert (report.used, report.skipped, report.repaired, report.dropped) == (3, 4, 1, 1)
    assert (report.polygons, report.walls, report.features) == (4, 0, 8)
    assert report.first_skipped == (
        "features[1] Point",
        "features[2] MultiPoint",
        "features[5] GeometryCollection",
    )
    assert report.line() == MESSY_LINE


def test_strict_keeps_todays_refusals(tmp_path):
    path = mission_with(tmp_path, MESSY, "{file: b.geojson, strict: true}")
    error = refusal(path)
    assert error.key_path == "obstacles[0].geojson"
    assert "b.geojson features[1] is Point" in str(error)
    only_bow_tie = mission_with(tmp_path, [MESSY[0], MESSY[4]], "{file: b.geojson, strict: true}")
    error = refusal(only_bow_tie)
    assert "simple footprints with non-zero area (b.geojson features[0] is not)" in str(error)
    assert len(str(error).splitlines()) == 1


def test_clean_files_give_no_warning_and_the_same_obstacles(tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="gcs.mission.footprints")
    features = [feature(polygon(square(500 + 40 * k, 300))) for k in range(3)]
    plain = load_mission(mission_with(tmp_path, features))
    mapped = load_mission(mission_with(tmp_path, features, "{file: b.geojson}"))
    assert warnings_of(caplog) == []
    for mission in (plain, mapped):
        assert len(mission.obstacles.polygons) == 3
        expected = lonlat_to_local(np.array(lonlat(square(500, 300)))[:-1], LYON)
        assert np.array_equal(mission.obstacles.polygons[0], expected)
        assert not mission.footprints[0].noteworthy


def test_only_points_is_refused_as_a_file_without_footprints(tmp_path):
    error = refusal(mission_with(tmp_path, [MESSY[1], MESSY[7]]))
    assert "at least one footprint in b.geojson, found none" in str(error)


def test_malformed_files_are_still_refused_whatever_strict_says(tmp_path):
    ring = lonlat(square(500, 300))[:-1]  # not closed
    error = refusal(mission_with(tmp_path, [feature({"type": "Polygon", "coordinates": [ring]})]))
    assert "closed rings of at least 4 positions (b.geojson features[0])" in str(error)
    bad = lonlat(square(500, 300))
    bad[1] = [bad[1][0], "45.7"]  # a string is never converted
    error = refusal(mission_with(tmp_path, [feature({"type": "Polygon", "coordinates": [bad]})]))
    assert "[longitude, latitude] positions in degrees (b.geojson features[0])" in str(error)
    bad[1] = [True, 45.7]
    error = refusal(mission_with(tmp_path, [feature({"type": "Polygon", "coordinates": [bad]})]))
    assert "features[0]" in str(error)


def test_mixed_2d_and_3d_positions_are_read(tmp_path):
    ring = lonlat(square(500, 300))
    ring[1] = [*ring[1], 12.0]
    mission = load_mission(mission_with(tmp_path, [feature(polygon(square(600, 300))), feature(
        {"type": "Polygon", "coordinates": [ring]}
    )]))  # fmt: skip
    assert shapely.Polygon(mission.obstacles.polygons[1]).area == pytest.approx(400, rel=1e-4)


def test_item_keys_are_checked(tmp_path):
    features = [feature(polygon(square(500, 300)))]
    error = refusal(mission_with(tmp_path, features, "{file: b.geojson, colour: red}"))
    assert error.key_path == "obstacles[0].geojson.colour"
    error = refusal(mission_with(tmp_path, features, "{file: b.geojson, strict: 'yes'}"))
    assert error.key_path == "obstacles[0].geojson.strict"
    error = refusal(mission_with(tmp_path, features, "{file: b.geojson, bbox: [5, 45, 4, 46]}"))
    assert error.key_path == "obstacles[0].geojson.bbox" and "west < east" in str(error)
    error = refusal(mission_with(tmp_path, features, "{strict: true}"))
    assert error.key_path == "obstacles[0].geojson.file"


def test_bbox_reads_only_the_footprints_it_meets(tmp_path):
    near, far = feature(polygon(square(500, 300))), feature(polygon(square(5000, 5000)))
    west, south = local_to_lonlat(np.array([0.0, 0.0]), LYON)[[0, 1]]
    east, north = local_to_lonlat(np.array([1000.0, 1000.0]), LYON)[[0, 1]]
    item = f"{{file: b.geojson, bbox: [{west}, {south}, {east}, {north}]}}"
    mission = load_mission(mission_with(tmp_path, [near, far], item))
    assert len(mission.obstacles.polygons) == 1
    assert mission.footprints[0].outside_bbox == 1


def test_helpers():
    assert footprint_file({"geojson": "a.geojson"}) == "a.geojson"
    assert footprint_file({"geojson": {"file": "b.osm.pbf", "strict": True}}) == "b.osm.pbf"
    assert footprint_file({"polygon": [[0, 0]]}) is None
    assert [file_format(n) for n in ("a.geojson", "a.json", "A.OSM.PBF", "b.shp", "c.gpkg")] == [
        "geojson",
        "geojson",
        "osm",
        "gis",
        "gis",
    ]


# --- heights ------------------------------------------------------------------------------------


def test_parse_height():
    assert parse_height(12) == 12.0
    assert parse_height("12 m") == 12.0
    assert parse_height("12.5") == 12.5
    assert parse_height("12,5") == 12.5
    assert parse_height(" 7m ") == 7.0
    for nothing in (None, True, "tall", "-3", -3, float("nan"), "12 ft", [12]):
        assert parse_height(nothing) is None, nothing
    assert feature_height({"building:levels": "4"}) == 12.0
    assert feature_height({"height": "20", "building:levels": 2}) == 20.0
    assert feature_height({"h": 9, "height": 40}, "h") == 9.0
    assert feature_height({}) is None and feature_height(None) is None


def test_heights_decide_which_footprints_are_obstacles(tmp_path, caplog):
    """altitude 30, safety_margin 5: a footprint is an obstacle above 25 m (or without height)."""
    caplog.set_level(logging.WARNING, logger="gcs.mission.footprints")
    features = [
        feature(polygon(square(500, 300)), height=10),  # 0 below
        feature(polygon(square(540, 300)), height="40 m"),  # 1 above
        feature(polygon(square(580, 300))),  # 2 no height: always an obstacle
        feature(polygon(square(620, 300)), **{"building:levels": 5}),  # 3 15 m: below
        feature(polygon(square(660, 300)), **{"building:levels": "10"}),  # 4 30 m: above
        feature(polygon(square(700, 300)), height=25),  # 5 exactly at the limit: below
        feature(polygon(square(740, 300)), height="unknown"),  # 6 not understood: obstacle
    ]
    mission = load_mission(mission_with(tmp_path, features))
    assert [k.rsplit(".", 1)[1] for k in mission.obstacle_keys] == [
        "features[1]",
        "features[2]",
        "features[4]",
        "features[6]",
    ]
    report = mission.footprints[0]
    assert report.below_altitude == 3 and report.height_limit_m == 25.0
    assert report.first_below_altitude == ("features[0]", "features[3]", "features[5]")
    assert warnings_of(caplog) == [
        "b.geojson: used 4 footprints; left out 3 not above altitude - safety_margin = 25 m "
        "(features[0], features[3], features[5])"
    ]
    assert map_json(mission.footprints)["below_altitude"] == 3


def test_height_key_names_the_height_property(tmp_path):
    features = [
        feature(polygon(square(500, 300)), h=50, height=1),  # h says above
        feature(polygon(square(540, 300)), h="3 m", height=90),  # h says below
        feature(polygon(square(580, 300)), height=1),  # no h: no height information
    ]
    mission = load_mission(mission_with(tmp_path, features, "{file: b.geojson, height_key: h}"))
    assert [k.rsplit(".", 1)[1] for k in mission.obstacle_keys] == ["features[0]", "features[2]"]
    assert mission.footprints[0].below_altitude == 1


def test_a_file_all_below_the_flight_is_accepted_and_empty(tmp_path):
    mission = load_mission(mission_with(tmp_path, [feature(polygon(square(500, 300)), height=3)]))
    assert len(mission.obstacles) == 0 and mission.footprints[0].below_altitude == 1


def test_plan_json_has_the_map_key(tmp_path, gcs_main):
    features = [*MESSY, feature(polygon(square(800, 0)), height=3)]
    code, out, _ = gcs_main("mission", "plan", mission_with(tmp_path, features), "--json")
    assert code == 0
    plan = json.loads(out)
    assert plan["map"]["used"] == 3 and plan["map"]["below_altitude"] == 1
    (entry,) = plan["map"]["files"]
    assert entry["key"] == "obstacles[0].geojson" and entry["file"] == "b.geojson"
    assert (entry["skipped"], entry["repaired"], entry["dropped"]) == (4, 1, 1)
    assert entry["first"]["repaired"] == ["features[0]"]
    assert entry["format"] == "geojson" and entry["crs"] is None
    code, out, _ = gcs_main("mission", "plan", mission_with(tmp_path, MESSY[4:5]), "--json")
    assert json.loads(out)["map"]["files"][0]["used"] == 1


# --- projected CRS ------------------------------------------------------------------------------

LOCAL_SQUARES = [square(500, 300), square(-800, 1200, 35), square(2500, -1500, 12)]


def projected(crs: str) -> list[list[list[float]]]:
    pyproj = pytest.importorskip("pyproj")
    to = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    rings = []
    for local in LOCAL_SQUARES:
        ll = np.array(lonlat(local))
        x, y = to.transform(ll[:, 0], ll[:, 1])
        rings.append(np.column_stack([x, y]).tolist())
    return rings


@pytest.mark.parametrize(
    ("crs", "in_file"),
    [("urn:ogc:def:crs:EPSG::3857", True), ("EPSG:3035", False), ("EPSG:3035", True)],
)
def test_projected_crs_round_trip_within_a_centimetre(tmp_path, crs, in_file):
    rings = projected(crs)
    features = [feature({"type": "Polygon", "coordinates": [r]}) for r in rings]
    doc = {"crs": {"type": "name", "properties": {"name": crs}}} if in_file else {}
    item = "b.geojson" if in_file else f"{{file: b.geojson, crs: '{crs}'}}"
    mission = load_mission(mission_with(tmp_path, features, item, **doc))
    for got, local in zip(mission.obstacles.polygons, LOCAL_SQUARES, strict=True):
        # against the pymap3d projection of the original lon/lat, and the original local frame
        direct = lonlat_to_local(np.array(lonlat(local))[:-1], LYON)
        assert np.abs(got - direct).max() < 0.01
        assert np.abs(got - local).max() < 0.01
    assert mission.footprints[0].crs == crs


def test_lonlat_crs_names_need_no_transform(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyproj", None)  # not even imported
    features = [feature(polygon(square(500, 300)))]
    for name in ("urn:ogc:def:crs:OGC:1.3:CRS84", "EPSG:4326"):
        doc = {"crs": {"type": "name", "properties": {"name": name}}}
        assert len(load_mission(mission_with(tmp_path, features, **doc)).obstacles) == 1


def test_unknown_crs_is_refused_naming_the_key(tmp_path):
    pytest.importorskip("pyproj")
    features = [feature(polygon(square(500, 300)))]
    error = refusal(mission_with(tmp_path, features, "{file: b.geojson, crs: 'EPSG:999999'}"))
    assert error.key_path == "obstacles[0].geojson.crs" and "EPSG:999999" in str(error)
    doc = {"crs": {"type": "name", "properties": {"name": "urn:nowhere"}}}
    error = refusal(mission_with(tmp_path, features, **doc))
    assert error.key_path == "obstacles[0].geojson" and "the crs of b.geojson" in str(error)
    error = refusal(mission_with(tmp_path, features, crs={"type": "link"}))
    assert "a named crs member in b.geojson" in str(error)


def test_projected_numbers_without_a_crs_get_a_hint(tmp_path):
    ring = [[400000.0, 5000000.0], [400020.0, 5000000.0], [400020.0, 5000020.0]]
    ring.append(ring[0])
    error = refusal(mission_with(tmp_path, [feature({"type": "Polygon", "coordinates": [ring]})]))
    assert "a projected CRS? name it with the item's crs: key" in str(error)


# --- optional extras ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "module", "extra", "item"),
    [
        ("city.osm.pbf", "osmium", "osm", "city.osm.pbf"),
        ("city.gpkg", "pyogrio", "gis", "city.gpkg"),
        ("roads.shp", "pyogrio", "gis", "roads.shp"),
        ("b.geojson", "pyproj", "crs", "{file: b.geojson, crs: 'EPSG:3035'}"),
    ],
)
def test_a_missing_extra_is_one_line_naming_it(tmp_path, monkeypatch, name, module, extra, item):
    monkeypatch.setitem(sys.modules, module, None)
    path = mission_with(tmp_path, [feature(polygon(square(500, 300)))], item)
    error = refusal(path)
    assert error.key_path == "obstacles[0].geojson"
    assert f"the '{extra}' extra to read {name}" in str(error)
    assert str(error).endswith(f"pip install 'fleetline[{extra}]'")
    assert len(str(error).splitlines()) == 1


def write_osm(path: Path) -> None:
    """A small extract: buildings (ways, a multipolygon relation), walls, an open way, a
    building 200 km away."""
    osmium = pytest.importorskip("osmium")
    from osmium.osm.mutable import Node, Relation, Way

    writer = osmium.SimpleWriter(str(path))
    node_id = 1

    def nodes(local: np.ndarray, shift: tuple[float, float] = (0.0, 0.0)) -> list[int]:
        nonlocal node_id
        ids = []
        for lon, lat in local_to_lonlat(np.asarray(local, float), LYON):
            writer.add_node(Node(id=node_id, location=(lon + shift[0], lat + shift[1])))
            ids.append(node_id)
            node_id += 1
        return ids

    a = nodes(square(500, 300))
    writer.add_node(Node(id=9000, location=(4.8, 45.9)))  # an untagged stray node
    b = nodes(square(540, 300))
    c = nodes(square(580, 300))
    wall = nodes(np.array([[0.0, 300.0], [100.0, 300.0], [100.0, 400.0]]))
    open_way = nodes(square(620, 300))
    far = nodes(square(500, 300), shift=(2.0, 0.0))  # about 155 km east
    writer.add_way(Way(id=100, nodes=[*a, a[0]], tags={"building": "yes", "height": "40 m"}))
    writer.add_way(
        Way(id=101, nodes=[*b, b[0]], tags={"building": "house", "building:levels": "2"})
    )
    writer.add_way(Way(id=102, nodes=[*c, c[0]], tags={}))
    writer.add_way(Way(id=103, nodes=wall, tags={"barrier": "wall"}))
    writer.add_way(Way(id=104, nodes=open_way, tags={"building": "yes"}))
    writer.add_way(Way(id=105, nodes=[*far, far[0]], tags={"building": "yes"}))
    writer.add_way(Way(id=106, nodes=wall[:2], tags={"barrier": "hedge"}))  # not a wall
    writer.add_relation(
        Relation(
            id=500,
            members=[("w", 102, "outer")],
            tags={"type": "multipolygon", "building": "yes"},
        )
    )
    writer.close()


def test_osm_extract_buildings_and_walls(tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="gcs.mission.footprints")
    write_osm(tmp_path / "city.osm.pbf")
    path = tmp_path / "m.yaml"
    path.write_text(MISSION + "  - geojson: city.osm.pbf\n")
    mission = load_mission(path)
    assert mission.obstacle_keys == (
        "obstacles[0].geojson.way/100",
        "obstacles[0].geojson.relation/500",
        "obstacles[0].geojson.way/103",
        "obstacles[0].geojson.way/103",
    )
    assert np.abs(mission.obstacles.polygons[0] - square(500, 300)).max() < 0.01
    assert mission.obstacles.walls[1] == pytest.approx(np.array([[100, 300], [100, 400]]), abs=0.01)
    report = mission.footprints[0]
    assert report.format == "osm" and report.outside_bbox == 1
    assert (report.used, report.skipped, report.below_altitude) == (3, 1, 1)
    assert warnings_of(caplog) == [
        "city.osm.pbf: used 3 footprints; skipped 1 (way/104 open building way), "
        "left out 1 not above altitude - safety_margin = 25 m (way/101)"
    ]


def test_osm_bbox_key(tmp_path):
    write_osm(tmp_path / "city.osm.pbf")
    path = tmp_path / "m.yaml"
    west, south = local_to_lonlat(np.array([450.0, 250.0]), LYON)
    east, north = local_to_lonlat(np.array([530.0, 330.0]), LYON)
    bbox = f"[{west}, {south}, {east}, {north}]"
    path.write_text(MISSION + f"  - geojson: {{file: city.osm.pbf, bbox: {bbox}}}\n")
    mission = load_mission(path)
    assert mission.obstacle_keys == ("obstacles[0].geojson.way/100",)


def write_gis(path: Path, crs: str, driver: str) -> None:
    """Footprints written by pyogrio (WKB geometries and numpy fields, no geopandas)."""
    pyogrio = pytest.importorskip("pyogrio")
    pyproj = pytest.importorskip("pyproj")
    to = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    shapes = []
    for local in (square(500, 300), square(540, 300), BOW_TIE):
        ll = np.array(lonlat(local))
        x, y = to.transform(ll[:, 0], ll[:, 1])
        shapes.append(shapely.Polygon(np.column_stack([x, y])))
    pyogrio.raw.write(
        str(path),
        shapely.to_wkb(np.array(shapes, dtype=object)),
        [np.array([40.0, 10.0, np.nan])],
        ["height"],
        driver=driver,
        geometry_type="Polygon",
        crs=crs,
    )


@pytest.mark.parametrize(
    ("name", "driver"), [("city.gpkg", "GPKG"), ("city.shp", "ESRI Shapefile")]
)
def test_gis_files_in_a_projected_crs(tmp_path, name, driver):
    write_gis(tmp_path / name, "EPSG:3035", driver)
    path = tmp_path / "m.yaml"
    path.write_text(MISSION + f"  - geojson: {name}\n")
    mission = load_mission(path)
    # features[1] is 10 m high (left out); features[2], a bow-tie without height, repaired
    assert mission.obstacle_keys == (
        "obstacles[0].geojson.features[0]",
        "obstacles[0].geojson.features[2]",
        "obstacles[0].geojson.features[2]",
    )
    got = shapely.Polygon(mission.obstacles.polygons[0])  # a shapefile turns rings clockwise
    assert shapely.hausdorff_distance(got, shapely.Polygon(square(500, 300))) < 0.01
    report = mission.footprints[0]
    assert report.format == "gis" and report.crs is not None
    assert (report.below_altitude, report.repaired, report.used) == (1, 1, 2)


def test_read_footprints_on_its_own(tmp_path):
    """The module without a mission: labelled local rings, the report, FootprintError."""
    from gcs.mission.footprints import FootprintError

    mission_with(tmp_path, MESSY)
    found = read_footprints(tmp_path / "b.geojson", FootprintOptions("b.geojson"), LYON)
    assert [label for label, _ in found.polygons] == [
        "features[0]",
        "features[0]",
        "features[4]",
        "features[6]",
    ]
    assert found.report.below_altitude == 0 and found.report.height_limit_m is None
    with pytest.raises(FootprintError) as caught:
        read_footprints(tmp_path / "b.geojson", FootprintOptions("b.geojson", strict=True), LYON)
    assert caught.value.key == "" and "features[1] is Point" in caught.value.expected
