"""Writes the city-map benchmark's missions (BENCHMARKS.md, `python -m bench maps`) from
public building footprints that may not be redistributed, so they are not in the repository:

    python -m bench.city_maps DATA OUT
    FLEETLINE_BENCH_MAPS=OUT python -m bench maps

DATA holds the three source files under the names of `SOURCES` (the command prints how to
download any that is missing); OUT receives one mission per route, the converted footprint
files and a synthetic terraced district (generated here, seeded).

The routes were drawn once, not chosen: points uniformly at random (seed 1) at least 12 m
(Vienna), 15 m (Bet Shemesh) or 10 m (Mumbai) from every footprint, paired at the nominal
distance +- 15 m (seed 7), the first pairs in draw order whose parking rows `gcs mission
check` accepts, with the angles it suggested where it refused 0 degrees. The terraced
district's route runs corner to corner. Routes are in metres east and north of the map's
origin below.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gcs.geodesy import Origin, local_to_lonlat


@dataclass(frozen=True)
class Source:
    """A public footprint file: its repository, the commit read, its path there."""

    repo: str
    commit: str
    path: str

    @property
    def url(self) -> str:
        return f"https://raw.githubusercontent.com/{self.repo}/{self.commit}/{self.path}"


SOURCES = {
    "vienna.geojson": Source(
        "AliceR/InteractiveWalkVienna",
        "32595ca5e48667757cc4f9d8497091c579ea57cd",
        "data/buildings.geojson",
    ),
    "betshemesh.geojson": Source(
        "NegevUrbanResearch/ShelterBetShemesh",
        "d7924533a73b4e17469c61c876ffaf0b812511b6",
        "data/buildings.geojson",
    ),
    "mumbai.js": Source(
        "dsonigladiator/drilldown-leaflet",
        "9d9bd799d64e2db29329765091406db89d3c46a8",
        "data/building.js",
    ),
}


@dataclass(frozen=True)
class Route:
    """One benchmark mission: A and B (m east, north of the origin) and their row angles."""

    name: str
    footprints: str
    origin: Origin
    start: tuple[float, float, float]  # x, y, theta_deg
    goal: tuple[float, float, float]
    altitude: float = 5.0
    comment: str = ""


VIENNA = Origin(lat=48.2058, lon=16.3676, alt=0.0)
BET_SHEMESH = Origin(lat=31.7359, lon=34.9836, alt=0.0)
MUMBAI = Origin(lat=19.1471, lon=72.8331, alt=0.0)
TERRACED = Origin(lat=52.0907, lon=5.1214, alt=0.0)

ROUTES = (
    Route("mumbai-960m-1", "mumbai.geojson", MUMBAI, (-369, 192, 0), (362, -421, 0)),
    Route("vienna-1.5km-1", "vienna.geojson", VIENNA, (1446, -1950, 0), (2919, -2164, 54.3)),
    Route("vienna-1.5km-2", "vienna.geojson", VIENNA, (893, -426, -81.4), (1879, 723, -102.7)),
    Route("vienna-3.7km-1", "vienna.geojson", VIENNA, (101, 1441, 63.7), (1984, 4636, 62.1)),
    Route("vienna-3.7km-2", "vienna.geojson", VIENNA, (1446, -1950, 106.4), (2942, 1447, 113.4)),
    Route("vienna-3.7km-3", "vienna.geojson", VIENNA, (-239, 3970, -60.9), (1769, 868, 151.1)),
    Route(
        "betshemesh-1.1km-1", "betshemesh.geojson", BET_SHEMESH, (-349, -1506, 0), (698, -1839, 0)
    ),
    Route("betshemesh-2km-1", "betshemesh.geojson", BET_SHEMESH, (-349, -1506, 0), (-976, 378, 0)),
    Route("betshemesh-2km-2", "betshemesh.geojson", BET_SHEMESH, (2018, 4219, 0), (3117, 2561, 0)),
    Route(
        "betshemesh-2km-3", "betshemesh.geojson", BET_SHEMESH, (593, -2944, -70.6), (2303, -1888, 0)
    ),
    Route("betshemesh-2km-4", "betshemesh.geojson", BET_SHEMESH, (2247, 1880, 0), (501, 917, 0)),
    Route(
        "betshemesh-11km-1", "betshemesh.geojson", BET_SHEMESH, (-3387, 4317, 0), (3430, -4323, 0)
    ),
    Route(
        "betshemesh-2km-heights",
        "betshemesh-levels.geojson",
        BET_SHEMESH,
        (2247, 1880, 0),
        (501, 917, 0),
        altitude=20.0,
        comment="footprints of 6 floors or more (building:levels x 3 m > 15 m)",
    ),
    Route(
        "terraced-1.3km",
        "terraced.geojson",
        TERRACED,
        (-7, -7, 0),
        (1080, 725, 0),
        comment="synthetic terraced district (terraced_district(seed=10)), 14 m streets",
    ),
)

MISSION = """# {comment}
# Written by bench/city_maps.py; footprints: {source}
version: 1
name: {name}
origin: {{lat: {lat}, lon: {lon}, alt: 0.0}}
start: {{x: {ax:g}, y: {ay:g}, theta_deg: {ta:g}}}
goal: {{x: {bx:g}, y: {by:g}, theta_deg: {tb:g}}}
safety_margin: 5
radio_range: 150
altitude: {altitude:g}
speed: {{max: 5}}
fleet: {{size: auto, backend: sim}}
vehicle: {{max_speed: 12, max_acceleration: 5, radius: 0.5}}
obstacles:
  - geojson: {footprints}
"""


def terraced_district(seed: int = 10) -> list[np.ndarray]:
    """Two rows of terraced houses per block (touching, as real ones do), back to back
    across 6 m gardens, blocks 14 m apart; about half the houses have a rear extension into
    the garden (an L-shaped footprint). Local metres, south-west corner at (0, 0)."""
    rng = np.random.default_rng(seed)
    street, depth, garden, block = 14.0, 11.0, 6.0, 80.0
    houses: list[np.ndarray] = []
    for row in range(13):
        y = row * (2 * depth + garden + street)
        for column in range(12):
            x = column * (block + street)
            # (back line, direction of the street side): the lower row faces south
            for back, side in ((y + depth, -1.0), (y + depth + garden, 1.0)):
                hx = x
                while hx < x + block - 5.0:
                    width = min(rng.uniform(5.0, 9.0), x + block - hx)
                    front = back + side * (depth - rng.uniform(0.0, 2.5))
                    ring = [(hx, front), (hx + width, front), (hx + width, back)]
                    if rng.random() < 0.5:
                        half = hx + width * rng.uniform(0.4, 0.6)
                        rear = back - side * rng.uniform(2.0, 3.0)
                        ring += [(half, back), (half, rear), (hx, rear)]
                    else:
                        ring += [(hx, back)]
                    houses.append(np.array(ring + ring[:1]))
                    hx += width
    return houses


def _feature(ring_lonlat: np.ndarray, properties: dict) -> dict:
    return {
        "type": "Feature",
        "properties": properties,
        "geometry": {"type": "Polygon", "coordinates": [ring_lonlat.round(7).tolist()]},
    }


def write_maps(data: Path, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    for name in ("vienna.geojson", "betshemesh.geojson"):
        shutil.copyfile(data / name, out / name)
    text = (data / "mumbai.js").read_text(encoding="utf-8")
    mumbai = json.loads(text[text.index("{") :].rstrip().rstrip(";"))
    (out / "mumbai.geojson").write_text(json.dumps(mumbai))
    shemesh = json.loads((data / "betshemesh.geojson").read_text(encoding="utf-8"))
    for feature in shemesh["features"]:
        floors = (feature.get("properties") or {}).get("Floors")
        feature["properties"] = {"building:levels": floors} if floors else {}
    (out / "betshemesh-levels.geojson").write_text(json.dumps(shemesh))
    houses = terraced_district()
    features = [_feature(local_to_lonlat(ring, TERRACED), {}) for ring in houses]
    (out / "terraced.geojson").write_text(
        json.dumps({"type": "FeatureCollection", "features": features})
    )
    written = []
    for route in ROUTES:
        source = SOURCES.get(route.footprints)
        path = out / f"{route.name}.yaml"
        path.write_text(
            MISSION.format(
                comment=route.comment or route.name,
                source=source.url if source else "generated",
                name=route.name,
                lat=route.origin.lat,
                lon=route.origin.lon,
                ax=route.start[0],
                ay=route.start[1],
                ta=route.start[2],
                bx=route.goal[0],
                by=route.goal[1],
                tb=route.goal[2],
                altitude=route.altitude,
                footprints=route.footprints,
            )
        )
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.city_maps", description=__doc__)
    parser.add_argument("data", type=Path, help="folder holding the downloaded source files")
    parser.add_argument("out", type=Path, help="folder to write the missions to")
    args = parser.parse_args(argv)
    missing = [name for name in SOURCES if not (args.data / name).is_file()]
    if missing:
        for name in missing:
            print(f"curl -L -o {args.data / name} {SOURCES[name].url}", file=sys.stderr)
        print(f"{args.data}: download the files above first", file=sys.stderr)
        return 2
    for path in write_maps(args.data, args.out):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
