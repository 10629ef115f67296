"""One-off generator of the example data files (run once; its output is committed).

    .venv/bin/python examples/generate.py   (from the repository root)

* `table-ii.yaml`: the paper's Table II scenario (docs/design.md 6) from `planner.scenarios`
  (10 axis-aligned rectangles of random size in the 2000 m x 2000 m area, clear of A, B and
  their parking rows), with a seed that puts two of them across the straight line A->B so
  that the path has to bend; 6 ground users in the open.
* `city-blocks.geojson`: a grid of city-block footprints (lon/lat, RFC 7946) around the
  origin of `city-blocks.yaml`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import shapely

from gcs.geodesy import Origin, local_to_lonlat
from planner.scenarios import paper_scenario

HERE = Path(__file__).resolve().parent

#: Seed of planner.scenarios.paper_scenario: the default seed's map leaves the straight line
#: A->B free; this one puts two rectangles across it, so the path has to bend.
TABLE_II_SEED = 8

CITY_ORIGIN = Origin(lat=45.7640, lon=4.8357, alt=170.0)
BLOCK, STREET = (90.0, 60.0), 20.0
GRID = (6, 5)  # columns, rows of blocks; the grid's south-west corner is at the origin


def table_ii_yaml(seed: int) -> str:
    scenario = paper_scenario(seed)
    rects = np.round(scenario.rectangles, 1)  # the generator keeps 1 m spare: rounding is safe
    crossing = shapely.intersects(
        scenario.obstacles.geometries, shapely.LineString([scenario.start, scenario.goal])
    )
    assert crossing.sum() >= 2, f"seed {seed}: fewer than 2 rectangles across A->B"
    boxes = shapely.union_all(scenario.obstacles.geometries)
    rng = np.random.default_rng(seed + 1000)
    users: list[np.ndarray] = []
    while len(users) < 6:  # ground users in the open, around the A-B area
        user = rng.uniform([150, 150], [800, 800]).round()
        if boxes.distance(shapely.Point(user)) > 10:
            users.append(user)
    lines = [
        f"# The paper's Table II scenario: planner.scenarios.paper_scenario({seed}), written by",
        "# examples/generate.py (10 rectangles of random size in 2000 m x 2000 m).",
        "version: 1",
        "name: table-ii",
        "origin: {lat: 45.7640, lon: 4.8357, alt: 170.0}",
        "start: {x: 200, y: 200, theta_deg: 0}",
        "goal: {x: 700, y: 700, theta_deg: 0}",
        "safety_margin: 5",
        "radio_range: 220",
        "altitude: 30",
        "parking: segment",
        "speed:",
        "  max: 10",
        "  initial: 10",
        "  changes:",
        "    - {at: 60, speed: 5}",
        "    - {at: 100, speed: 10, leader: 4}",
        "fleet:",
        "  size: 9        # the paper flew 9; eq. 28 needs fewer",
        "  backend: sim",
        "vehicle:",
        "  max_speed: 15",
        "  max_acceleration: 8    # 10 m/s is safe at this path's bends from about 7 (docs/design.md 3.5)",
        "  radius: 0.5",
        "obstacles:",
    ]
    for cx, cy, width, height, angle in rects:
        lines.append(
            f"  - rectangle: {{center: [{cx:g}, {cy:g}], size: [{width:g}, {height:g}], "
            f"angle_deg: {angle:g}}}"
        )
    lines.append("ground_users:")
    for x, y in users:
        lines.append(f"  - {{x: {x:g}, y: {y:g}, rate_bps: 800}}")
    lines += [
        "sim:",
        "  setpoint_rate_hz: 10",
        f"  seed: {seed}",
        "radio:",
        "  enabled: true",
        "  hop_latency_ms: 2",
        "  jitter_ms: 1",
        "  loss: 0.0",
    ]
    return "\n".join(lines) + "\n"


def city_geojson() -> dict:
    """GRID blocks of BLOCK metres separated by STREET-wide streets, as lon/lat polygons."""
    features = []
    for i in range(GRID[0]):
        for j in range(GRID[1]):
            x0 = i * (BLOCK[0] + STREET)
            y0 = j * (BLOCK[1] + STREET)
            ring = np.array(
                [[x0, y0], [x0 + BLOCK[0], y0], [x0 + BLOCK[0], y0 + BLOCK[1]], [x0, y0 + BLOCK[1]]]
            )
            lonlat = local_to_lonlat(ring, CITY_ORIGIN)
            closed = [[round(float(lo), 8), round(float(la), 8)] for lo, la in lonlat]
            closed.append(closed[0])
            features.append(
                {
                    "type": "Feature",
                    "properties": {"block": f"{i}-{j}", "building": "yes"},
                    "geometry": {"type": "Polygon", "coordinates": [closed]},
                }
            )
    return {"type": "FeatureCollection", "features": features}


def main() -> None:
    (HERE / "table-ii.yaml").write_text(table_ii_yaml(TABLE_II_SEED))
    (HERE / "city-blocks.geojson").write_text(json.dumps(city_geojson(), indent=1) + "\n")
    width = GRID[0] * (BLOCK[0] + STREET) - STREET
    height = GRID[1] * (BLOCK[1] + STREET) - STREET
    print(f"wrote table-ii.yaml and city-blocks.geojson ({width:g} x {height:g} m of blocks)")
    assert math.isfinite(width)


if __name__ == "__main__":
    main()
