"""Recordings carry the mission's footprint files in every form (issue 13), and the report
reads the mission back from them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gcs.mission import load_mission
from gcs.recording.logreader import Recording
from gcs.recording.recording import mission_geojson_files
from gcs.recording.report import _mission
from tests.footprint_files import MESSY
from tests.mission_texts import MINIMAL

MISSION = MINIMAL.replace("version: 1\n", "version: 1\norigin: {lat: 0.0, lon: 0.0, alt: 0.0}\n")


def _recording(attachments: dict[str, bytes], mission_text: str) -> Recording:
    return Recording(
        path=Path("run.mcap"),
        profile="",
        topics={},
        attachments={"mission.yaml": mission_text.encode(), **attachments},
        metadata={},
        truncated=False,
        truncation=None,
        bytes_read=0,
        size=0,
    )


@pytest.mark.parametrize(
    "item", ["geojson: maps/messy.geojson", "geojson: {file: maps/messy.geojson, strict: false}"]
)
def test_footprint_files_are_attached_and_read_back_in_either_form(tmp_path, item):
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / "messy.geojson").write_text(json.dumps(MESSY))
    text = MISSION + f"obstacles:\n  - {item}\n"
    (tmp_path / "m.yaml").write_text(text)
    mission = load_mission(tmp_path / "m.yaml")
    files = mission_geojson_files(mission)
    assert list(files) == ["maps/messy.geojson"]
    attachments = {f"geojson/{name}": data for name, data in files.items()}
    again = _mission(_recording(attachments, text))
    assert again is not None and len(again.obstacles) == len(mission.obstacles) == 1
    assert again.obstacles.polygons[0] == pytest.approx(mission.obstacles.polygons[0])


def test_a_shapefile_is_attached_with_its_side_files_and_read_back(tmp_path):
    pyogrio = pytest.importorskip("pyogrio")
    shapely = pytest.importorskip("shapely")
    import numpy as np

    square = shapely.Polygon([(-0.0003, 0.0003), (-0.0002, 0.0003), (-0.0002, 0.0004),
                              (-0.0003, 0.0004)])  # fmt: skip
    pyogrio.raw.write(
        str(tmp_path / "city.shp"),
        geometry=np.array([shapely.to_wkb(square)], dtype=object),
        field_data=[],
        fields=[],
        geometry_type="Polygon",
        crs="EPSG:4326",
        driver="ESRI Shapefile",
    )
    text = MISSION + "obstacles:\n  - geojson: {file: city.shp}\n"
    (tmp_path / "m.yaml").write_text(text)
    mission = load_mission(tmp_path / "m.yaml")
    files = mission_geojson_files(mission)
    assert {"city.shp", "city.shx", "city.dbf"} <= set(files)
    attachments = {f"geojson/{name}": data for name, data in files.items()}
    again = _mission(_recording(attachments, text))
    assert again is not None and len(again.obstacles) == 1
    assert again.obstacles.polygons[0] == pytest.approx(mission.obstacles.polygons[0])
