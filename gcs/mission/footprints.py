"""Obstacle footprints from map files -> local solid polygons and walls, with a report.

One job: read the file an `obstacles[i].geojson` item names and return its footprints in the
mission's local frame (gcs.geodesy), together with a `FootprintReport` of what was used, skipped,
repaired, dropped and left out. `gcs.mission` calls `read_footprints` and turns a
`FootprintError` into its one-line refusal (file, key, what is expected; exit 2).

Formats, by the file name's suffix (docs/mission-file.md):

* GeoJSON (any other suffix): a FeatureCollection, a Feature or a bare geometry; positions in
  lon/lat unless the file's legacy `crs` member or the item's `crs:` key names another CRS
  (then pyproj transforms them, extra `crs`).
* OpenStreetMap (`.osm.pbf`, `.pbf`, `.osm`; extra `osm`, pyosmium): buildings (ways and
  multipolygon relations tagged `building=*`) and barriers (`barrier=wall|fence`, as walls),
  inside the item's `bbox` (default: within `MAX_FOOTPRINT_DISTANCE_M` of the origin).
* Shapefile and GeoPackage (`.shp`, `.gpkg`; extra `gis`, pyogrio): the first layer, its CRS
  from the file.

Messy files: features that are not footprints (Point, MultiPoint, a GeometryCollection without
polygons or lines, no geometry) are skipped; invalid polygons (bow-ties, spikes) are repaired
with shapely's `make_valid` (the polygonal parts kept, each its own footprint); zero-area ones
are dropped; footprints whose height (`height`, `building:levels` x 3 m or the item's
`height_key`) is not above the flight (altitude - safety_margin) are left out. `strict: true`
refuses the file at the first footprint that is not one or is not simple with non-zero area.
Holes are ignored (the outer ring is solid: a courtyard is not flyable).

Malformed files are refused whatever `strict` says: unreadable, not JSON, positions that are
not finite numbers (or not lon/lat after the transform), rings that do not close, footprints
more than `MAX_FOOTPRINT_DISTANCE_M` from the origin, a file with no footprint at all.

Vectorised: every ring of the file is converted to one array, projected with one call to
`lonlat_to_local`, and checked with shapely's array functions; only the repaired ones are
handled one by one.
"""

from __future__ import annotations

import gc
import json
import logging
import math
import os
import re
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from fleetline.errors import EXIT_BAD_INPUT, FleetlineError
from fleetwire.files import FOOTPRINT_BYTES, FileRefused, read_text_bounded
from gcs.geodesy import Origin, lonlat_to_local
from planner.formation import DISTANCE_TOLERANCE

log = logging.getLogger(__name__)

#: Footprints further than this from the origin are refused (a wrong origin, most likely); the
#: default bounding box of an OSM extract.
MAX_FOOTPRINT_DISTANCE_M = 100_000.0
#: Height of one `building:levels` level, metres.
METRES_PER_LEVEL = 3.0
#: How many features each category of the warning line names.
FIRST = 3
#: File suffixes read by the optional readers (anything else is read as GeoJSON).
OSM_SUFFIXES = (".osm.pbf", ".pbf", ".osm")
GIS_SUFFIXES = (".shp", ".gpkg")
#: CRS names that are GeoJSON's own lon/lat (no transform, pyproj not needed).
LONLAT_CRS = frozenset(
    {
        "EPSG:4326",
        "EPSG::4326",
        "URN:OGC:DEF:CRS:EPSG::4326",
        "URN:OGC:DEF:CRS:EPSG:6.6:4326",
        "URN:OGC:DEF:CRS:OGC:1.3:CRS84",
        "URN:OGC:DEF:CRS:OGC::CRS84",
        "OGC:CRS84",
        "CRS84",
        "WGS84",
    }
)
_OSM_BARRIERS = ("wall", "fence")
_HEIGHT = re.compile(r"\s*([0-9]+(?:[.,][0-9]*)?|[.,][0-9]+)\s*(?:m|metres|meters)?\s*\Z", re.I)


class FootprintError(FleetlineError):
    """A refused footprint file: what is expected, and the item's sub-key it concerns
    (`""` for the item itself, else e.g. `crs`, `bbox`)."""

    exit_status = EXIT_BAD_INPUT

    def __init__(self, expected: str, key: str = "") -> None:
        super().__init__(expected)
        self.expected = expected
        self.key = key


@dataclass(frozen=True)
class FootprintOptions:
    """The `obstacles[i].geojson` item: `FILE` or `{file, strict, crs, height_key, bbox}`."""

    file: str
    strict: bool = False
    crs: str | None = None
    height_key: str | None = None
    #: [west, south, east, north] in degrees: only footprints whose envelope meets it are read.
    bbox: tuple[float, float, float, float] | None = None


@dataclass(frozen=True)
class FootprintReport:
    """What one footprint file gave (counts are features; `polygons`, `walls` obstacles).

    `used` features gave at least one obstacle (the `repaired` ones included); `skipped` were
    not footprints; `dropped` had zero area (or zero length) even after repair;
    `below_altitude` were not above `height_limit_m` = altitude - safety_margin;
    `outside_bbox` lay outside the bounding box. `first_*` name the first few features of each
    category (`features[k]` in GeoJSON/GIS files, `way/ID` or `relation/ID` in OSM files).
    """

    key: str
    file: str
    format: str
    crs: str | None
    features: int
    used: int
    polygons: int
    walls: int
    skipped: int = 0
    repaired: int = 0
    dropped: int = 0
    below_altitude: int = 0
    outside_bbox: int = 0
    height_limit_m: float | None = None
    first_skipped: tuple[str, ...] = ()
    first_repaired: tuple[str, ...] = ()
    first_dropped: tuple[str, ...] = ()
    first_below_altitude: tuple[str, ...] = ()

    @property
    def noteworthy(self) -> bool:
        """Something was skipped, repaired, dropped or left out: worth a warning."""
        return bool(self.skipped or self.repaired or self.dropped or self.below_altitude)

    def line(self) -> str:
        """The one warning line, e.g. `city.geojson: used 4,996 footprints; skipped 2
        (features[17] Point, features[80] MultiPoint), repaired 1 (features[3]), dropped 1
        zero-area (features[9])`."""

        def named(count: int, first: tuple[str, ...]) -> str:
            more = ", ..." if count > len(first) else ""
            return f"({', '.join(first)}{more})"

        parts = []
        if self.skipped:
            parts.append(f"skipped {self.skipped:,} {named(self.skipped, self.first_skipped)}")
        if self.repaired:
            parts.append(f"repaired {self.repaired:,} {named(self.repaired, self.first_repaired)}")
        if self.dropped:
            parts.append(
                f"dropped {self.dropped:,} zero-area {named(self.dropped, self.first_dropped)}"
            )
        if self.below_altitude:
            limit = _fmt(self.height_limit_m) if self.height_limit_m is not None else "?"
            parts.append(
                f"left out {self.below_altitude:,} not above altitude - safety_margin = "
                f"{limit} m {named(self.below_altitude, self.first_below_altitude)}"
            )
        head = f"{self.file}: used {self.used:,} footprint{'' if self.used == 1 else 's'}"
        return "; ".join([head, ", ".join(parts)]) if parts else head

    def as_json(self) -> dict[str, Any]:
        """The plan JSON's `map.files[i]` (docs/outputs.md)."""
        return {
            "key": self.key,
            "file": self.file,
            "format": self.format,
            "crs": self.crs,
            "features": self.features,
            "used": self.used,
            "polygons": self.polygons,
            "walls": self.walls,
            "skipped": self.skipped,
            "repaired": self.repaired,
            "dropped": self.dropped,
            "below_altitude": self.below_altitude,
            "outside_bbox": self.outside_bbox,
            "height_limit_m": self.height_limit_m,
            "first": {
                "skipped": list(self.first_skipped),
                "repaired": list(self.first_repaired),
                "dropped": list(self.first_dropped),
                "below_altitude": list(self.first_below_altitude),
            },
        }


def map_json(reports: tuple[FootprintReport, ...] | list[FootprintReport]) -> dict[str, Any]:
    """The plan JSON's `map` key: totals over the footprint files and one entry per file."""
    total = {
        name: sum(getattr(r, name) for r in reports)
        for name in ("used", "skipped", "repaired", "dropped", "below_altitude")
    }
    return {**total, "files": [r.as_json() for r in reports]}


@dataclass(frozen=True, eq=False)
class Footprints:
    """A file's obstacles in the local frame, in feature order: (label, (k, 2) ring, not
    closed) and (label, (2, 2) wall segment), and the report."""

    polygons: tuple[tuple[str, np.ndarray], ...]
    walls: tuple[tuple[str, np.ndarray], ...]
    report: FootprintReport


#: The files beside a shapefile that it needs (recordings attach them with it).
SHAPEFILE_SIDES = (".shx", ".dbf", ".prj", ".cpg")


def footprint_file(item: Any) -> str | None:
    """The file name an `obstacles[i]` item of the raw YAML names, in either form, or None."""
    if not isinstance(item, dict):
        return None
    spec = item.get("geojson")
    if isinstance(spec, dict):
        spec = spec.get("file")
    return spec if isinstance(spec, str) else None


def file_format(name: str) -> str:
    """`osm`, `gis` or `geojson`, from the file name's suffix."""
    lower = name.lower()
    if lower.endswith(OSM_SUFFIXES):
        return "osm"
    if lower.endswith(GIS_SUFFIXES):
        return "gis"
    return "geojson"


def parse_height(value: Any) -> float | None:
    """A height in metres from a property: a number, or a string such as `12`, `12.5`,
    `12 m`, `12,5`; None when absent, negative or not understood."""
    if value is None or isinstance(value, bool):
        return None
    if isinstance(value, int | float | np.integer | np.floating):
        number = float(value)
    elif isinstance(value, str):
        match = _HEIGHT.match(value)
        if not match:
            return None
        number = float(match.group(1).replace(",", "."))
    else:
        return None
    return number if math.isfinite(number) and number >= 0 else None


def feature_height(properties: Any, height_key: str | None = None) -> float | None:
    """A footprint's height: the `height_key` property (default `height`), else
    `building:levels` x `METRES_PER_LEVEL`; None without height information."""
    if not isinstance(properties, dict):
        return None
    height = parse_height(properties.get(height_key or "height"))
    if height is None:
        levels = parse_height(properties.get("building:levels"))
        height = None if levels is None else levels * METRES_PER_LEVEL
    return height


def read_footprints(
    path: Path,
    options: FootprintOptions,
    origin: Origin,
    *,
    key: str = "",
    height_limit: float | None = None,
) -> Footprints:
    """Read the footprint file at `path` (named `options.file` in messages and the report).

    `height_limit` (altitude - safety_margin): footprints with a known height not above it
    are left out. Raises `FootprintError` on anything refused.
    """
    name = options.file
    kind = file_format(name)
    try:
        mode = os.stat(path).st_mode
    except OSError:
        mode = stat.S_IFREG  # missing or unreadable: each reader says so in its own words
    if not stat.S_ISREG(mode):  # a device is read forever, a FIFO blocks: neither is opened
        raise FootprintError(f"a footprint file: {name} is not a regular file")
    col = _Collector(name, options, height_limit)
    with _gc_paused():
        if kind == "osm":
            _read_osm(path, col, origin)
        elif kind == "gis":
            _read_gis(path, col)
        else:
            _read_geojson(path, col)
        return col.build(origin, key, kind)


@contextmanager
def _gc_paused() -> Iterator[None]:
    """No cyclic garbage collection while millions of small lists are built (json.loads of a
    25 MB file: half its time is the collector walking them); what it held is freed after."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


# --- collecting features ---------------------------------------------------------------------


class _Collector:
    """Features as the readers find them: outer rings and lines as position lists, each owned
    by a feature (its index in `labels`), and what was skipped or left out."""

    def __init__(self, name: str, options: FootprintOptions, height_limit: float | None) -> None:
        self.name = name
        self.options = options
        self.height_limit = height_limit
        self.labels: list[str] = []
        self.rings: list[Any] = []
        self.ring_owner: list[int] = []
        self.lines: list[Any] = []
        self.line_owner: list[int] = []
        self.skipped: list[tuple[str, str]] = []
        self.below: list[str] = []
        self.features = 0
        self.file_crs: str | None = None

    def where(self, label: str) -> str:
        return f"{self.name} {label}"

    def skip(self, label: str, kind: str, *, null: bool = False) -> None:
        """A feature that is not a footprint; strict mode refuses it (not a null geometry)."""
        self.features += 1
        if self.options.strict and not null:
            raise FootprintError(
                f"Polygon, MultiPolygon, LineString or MultiLineString geometries with "
                f"coordinates ({self.where(label)} is {kind})"
            )
        self.skipped.append((label, kind))

    def add(self, label: str, rings: list, lines: list, properties: Any) -> None:
        """A footprint feature: its outer rings and lines, unless it is below the flight."""
        self.features += 1
        if self.height_limit is not None:
            height = feature_height(properties, self.options.height_key)
            if height is not None and height <= self.height_limit:
                self.below.append(label)
                return
        owner = len(self.labels)
        self.labels.append(label)
        self.rings.extend(rings)
        self.ring_owner.extend([owner] * len(rings))
        self.lines.extend(lines)
        self.line_owner.extend([owner] * len(lines))

    # the common, vectorised part

    def build(self, origin: Origin, key: str, kind: str) -> Footprints:
        crs = self.options.crs or self.file_crs
        crs_key = "crs" if self.options.crs else ""
        transformer = _transformer(crs, crs_key, self.name)
        rings, ring_owner = self.rings, np.asarray(self.ring_owner, np.intp)
        lines, line_owner = self.lines, np.asarray(self.line_owner, np.intp)
        ring_xy, ring_len = self._positions(rings, ring_owner, transformer is not None)
        line_xy, line_len = self._positions(lines, line_owner, transformer is not None)
        # rings: closed, at least 4 positions (checked on the file's own numbers)
        if len(ring_len):
            ends = np.cumsum(ring_len)
            starts = ends - ring_len
            short = ring_len < 4
            open_ = np.zeros(len(ring_len), bool)
            long = ~short
            open_[long] = (ring_xy[starts[long]] != ring_xy[ends[long] - 1]).any(axis=1)
            bad = np.flatnonzero(short | open_)
            if len(bad):
                raise FootprintError(
                    f"closed rings of at least 4 positions "
                    f"({self.where(self.labels[ring_owner[bad[0]]])})"
                )
        if len(line_len) and (line_len < 2).any():
            first = int(np.flatnonzero(line_len < 2)[0])
            raise FootprintError(
                f"lines of at least 2 positions ({self.where(self.labels[line_owner[first]])})"
            )
        xy = np.concatenate([ring_xy, line_xy]) if len(line_xy) else ring_xy
        lengths = np.concatenate([ring_len, line_len]).astype(np.intp)
        owners = np.concatenate([ring_owner, line_owner]).astype(np.intp)
        if transformer is not None and len(xy):
            lon, lat = transformer.transform(xy[:, 0], xy[:, 1])
            xy = np.column_stack([lon, lat])
        self._check_lonlat(xy, lengths, owners, crs)
        outside = 0
        bbox = self.options.bbox
        if bbox is None and kind == "osm":
            bbox = _default_bbox(origin)
        if bbox is not None and len(xy):
            keep_seq, outside = self._inside(xy, lengths, owners, bbox)
            if outside:
                keep_pos = np.repeat(keep_seq, lengths)
                xy, lengths, owners = xy[keep_pos], lengths[keep_seq], owners[keep_seq]
                n_rings = int(keep_seq[: len(ring_len)].sum())
                ring_len, ring_owner = lengths[:n_rings], owners[:n_rings]
                line_len, line_owner = lengths[n_rings:], owners[n_rings:]
        used_features = len(self.labels) - outside
        if used_features == 0 and not self.below:
            within = " within bbox" if bbox is not None else ""
            raise FootprintError(f"at least one footprint in {self.name}{within}, found none")
        local = lonlat_to_local(xy, origin) if len(xy) else np.zeros((0, 2))
        self._near_origin(local, lengths, owners)
        n_ring_pos = int(ring_len.sum())
        polygons, repaired, ring_ok = self._polygons(local[:n_ring_pos], ring_len, ring_owner)
        walls, line_ok = self._walls(local[n_ring_pos:], line_len, line_owner)
        gave = np.zeros(len(self.labels), bool)
        gave[ring_owner[ring_ok]] = True
        gave[line_owner[line_ok]] = True
        present = np.zeros(len(self.labels), bool)
        present[ring_owner] = True
        present[line_owner] = True
        dropped = [self.labels[i] for i in np.flatnonzero(present & ~gave)]
        repaired_labels = [self.labels[i] for i in sorted(set(repaired))]
        report = FootprintReport(
            key=key,
            file=self.name,
            format=kind,
            crs=crs if transformer is not None else None,
            features=self.features,
            used=int(gave.sum()),
            polygons=len(polygons),
            walls=len(walls),
            skipped=len(self.skipped),
            repaired=len(repaired_labels),
            dropped=len(dropped),
            below_altitude=len(self.below),
            outside_bbox=outside,
            height_limit_m=self.height_limit,
            first_skipped=tuple(f"{label} {kind}" for label, kind in self.skipped[:FIRST]),
            first_repaired=tuple(repaired_labels[:FIRST]),
            first_dropped=tuple(dropped[:FIRST]),
            first_below_altitude=tuple(self.below[:FIRST]),
        )
        return Footprints(polygons=tuple(polygons), walls=tuple(walls), report=report)

    def _positions(
        self, seqs: list, owner: np.ndarray, projected: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """Position lists -> (n, 2) float array (third coordinates dropped) and lengths."""
        if not seqs:
            return np.zeros((0, 2)), np.zeros(0, np.intp)
        array = None
        if all(type(s) is np.ndarray for s in seqs):  # OSM, GIS: shapely's coordinates
            lengths = np.fromiter(map(len, seqs), np.intp, len(seqs))
            return np.concatenate(seqs)[:, :2].astype(float), lengths
        if all(type(s) is list for s in seqs):
            lengths = np.fromiter(map(len, seqs), np.intp, len(seqs))
            flat = list(chain.from_iterable(seqs))
            try:
                array = np.array(flat, dtype=float)
            except (TypeError, ValueError):
                array = None
            if array is not None and (array.ndim != 2 or array.shape[1] < 2):
                array = None
            if array is not None:  # numbers only: no strings (converted), no booleans
                kinds = set(map(type, chain.from_iterable(flat)))
                if not kinds <= {int, float}:
                    array = None
        if array is None:  # slow path: find the culprit, or mixed 2-D/3-D positions
            parts = [self._sequence(s, int(o), projected) for s, o in zip(seqs, owner, strict=True)]
            lengths = np.fromiter(map(len, parts), np.intp, len(parts))
            array = np.concatenate(parts) if parts else np.zeros((0, 2))
        return np.ascontiguousarray(array[:, :2]), lengths

    def _sequence(self, coords: Any, owner: int, projected: bool) -> np.ndarray:
        what = (
            "[x, y] positions (numbers) in the file's CRS"
            if projected
            else "[longitude, latitude] positions in degrees"
        )
        valid = isinstance(coords, list) and all(
            isinstance(p, list) and len(p) >= 2 and all(_is_number(v) for v in p[:2])
            for p in coords
        )
        if not valid:
            raise FootprintError(f"{what} ({self.where(self.labels[owner])})")
        return np.array([p[:2] for p in coords], float).reshape(-1, 2)

    def _check_lonlat(
        self, xy: np.ndarray, lengths: np.ndarray, owners: np.ndarray, crs: str | None
    ) -> None:
        if not len(xy):
            return
        ok = np.isfinite(xy).all(axis=1) & (np.abs(xy[:, 0]) <= 180) & (np.abs(xy[:, 1]) <= 90)
        if ok.all():
            return
        bad = int(np.flatnonzero(~ok)[0])
        seq = int(np.searchsorted(np.cumsum(lengths), bad, side="right"))
        where = self.where(self.labels[owners[seq]])
        if crs is not None and crs.upper() not in LONLAT_CRS:
            raise FootprintError(
                f"positions that {crs} maps to longitude and latitude ({where} does not)"
            )
        hint = ""
        if np.isfinite(xy[bad]).all() and np.abs(xy[bad]).max() > 1000:
            hint = ": a projected CRS? name it with the item's crs: key"
        raise FootprintError(f"[longitude, latitude] positions in degrees ({where}{hint})")

    def _inside(
        self,
        lonlat: np.ndarray,
        lengths: np.ndarray,
        owners: np.ndarray,
        bbox: tuple[float, float, float, float],
    ) -> tuple[np.ndarray, int]:
        """Sequences of the features whose envelope meets `bbox`; how many features did not."""
        starts = np.r_[0, np.cumsum(lengths)[:-1]]
        lo = np.minimum.reduceat(lonlat, starts, axis=0)
        hi = np.maximum.reduceat(lonlat, starts, axis=0)
        west, south, east, north = bbox
        meets = (hi[:, 0] >= west) & (lo[:, 0] <= east) & (hi[:, 1] >= south) & (lo[:, 1] <= north)
        feature_meets = np.zeros(len(self.labels), bool)
        feature_meets[owners[meets]] = True
        present = np.zeros(len(self.labels), bool)
        present[owners] = True
        return feature_meets[owners], int((present & ~feature_meets).sum())

    def _near_origin(self, local: np.ndarray, lengths: np.ndarray, owners: np.ndarray) -> None:
        if not len(local):
            return
        far = np.abs(local).max(axis=1) > MAX_FOOTPRINT_DISTANCE_M
        if not far.any():
            return
        seq_far = np.logical_or.reduceat(far, np.r_[0, np.cumsum(lengths)[:-1]])
        seqs = np.flatnonzero(seq_far)
        seq = int(seqs[np.argmin(owners[seqs])])  # the first feature, as a file is read
        start = int(np.sum(lengths[:seq]))
        distance = np.abs(local[start : start + lengths[seq]]).max()
        raise FootprintError(
            f"footprints within {MAX_FOOTPRINT_DISTANCE_M / 1000:g} km of origin "
            f"({self.where(self.labels[owners[seq]])} is {distance / 1000:.0f} km away: "
            f"is origin right?)"
        )

    def _polygons(
        self, local: np.ndarray, lengths: np.ndarray, owners: np.ndarray
    ) -> tuple[list[tuple[str, np.ndarray]], list[int], np.ndarray]:
        """Local closed rings -> (label, unclosed ring) footprints, the owners of repaired
        rings, and which rings gave at least one footprint."""
        count = len(lengths)
        if count == 0:
            return [], [], np.zeros(0, bool)
        closing = np.cumsum(lengths) - 1
        keep = np.ones(len(local), bool)
        keep[closing] = False
        points = local[keep]
        sizes = lengths - 1
        rings = np.split(points, np.cumsum(sizes)[:-1])
        shapes = shapely.polygons(
            shapely.linearrings(points, indices=np.repeat(np.arange(count), sizes))
        )
        valid = shapely.is_valid(shapes)
        area = shapely.area(shapes)
        good = valid & (area > DISTANCE_TOLERANCE)
        if self.options.strict and not good.all():
            first = int(np.flatnonzero(~good)[0])
            raise FootprintError(
                f"simple footprints with non-zero area "
                f"({self.where(self.labels[owners[first]])} is not)"
            )
        invalid = np.flatnonzero(~valid)
        fixed: dict[int, list[np.ndarray]] = {}
        if len(invalid):
            for index, shape in zip(invalid, shapely.make_valid(shapes[invalid]), strict=True):
                parts = [
                    shapely.get_coordinates(shapely.get_exterior_ring(p))[:-1]
                    for p in _polygonal_parts(shape)
                    if shapely.area(p) > DISTANCE_TOLERANCE
                ]
                fixed[int(index)] = parts
        out: list[tuple[str, np.ndarray]] = []
        repaired: list[int] = []
        gave = good.copy()
        labels = self.labels
        for index in range(count):
            owner = int(owners[index])
            if good[index]:
                out.append((labels[owner], rings[index]))
            elif index in fixed and fixed[index]:
                out.extend((labels[owner], ring) for ring in fixed[index])
                repaired.append(owner)
                gave[index] = True
        return out, repaired, gave

    def _walls(
        self, local: np.ndarray, lengths: np.ndarray, owners: np.ndarray
    ) -> tuple[list[tuple[str, np.ndarray]], np.ndarray]:
        """Local lines -> (label, segment) walls (repeated positions removed), and which lines
        gave at least one wall."""
        count = len(lengths)
        if count == 0:
            return [], np.zeros(0, bool)
        line_id = np.repeat(np.arange(count), lengths)
        starts = np.r_[0, np.cumsum(lengths)[:-1]]
        step = np.r_[np.inf, np.linalg.norm(np.diff(local, axis=0), axis=1)]
        keep = step > DISTANCE_TOLERANCE
        keep[starts] = True
        kept, kept_id = local[keep], line_id[keep]
        pair = kept_id[:-1] == kept_id[1:]
        segments = np.stack([kept[:-1][pair], kept[1:][pair]], axis=1)
        segment_line = kept_id[:-1][pair]
        labels = self.labels
        walls = [
            (labels[owners[line]], segment)
            for line, segment in zip(segment_line.tolist(), segments, strict=True)
        ]
        gave = np.zeros(count, bool)
        gave[segment_line] = True
        return walls, gave


def _polygonal_parts(shape: shapely.Geometry) -> list[shapely.Geometry]:
    """The polygons of a (multi-)polygon or geometry collection, however nested."""
    kind = shapely.get_type_id(shape)
    if kind == 3:  # Polygon
        return [shape]
    if kind in (6, 7):  # MultiPolygon, GeometryCollection
        return [p for part in shapely.get_parts(shape) for p in _polygonal_parts(part)]
    return []


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def _default_bbox(origin: Origin) -> tuple[float, float, float, float]:
    """[west, south, east, north] enclosing everything within MAX_FOOTPRINT_DISTANCE_M."""
    dlat = math.degrees(MAX_FOOTPRINT_DISTANCE_M / 6_356_752.0)
    cos = max(math.cos(math.radians(min(abs(origin.lat) + dlat, 89.9))), 1e-6)
    dlon = min(math.degrees(MAX_FOOTPRINT_DISTANCE_M / (6_378_137.0 * cos)), 180.0)
    return (origin.lon - dlon, origin.lat - dlat, origin.lon + dlon, origin.lat + dlat)


def _missing(extra: str, module: str, name: str) -> FootprintError:
    return FootprintError(
        f"the '{extra}' extra to read {name} ({module} is not installed): "
        f"pip install 'fleetline[{extra}]'"
    )


def _transformer(crs: str | None, key: str, name: str):
    """A pyproj Transformer from `crs` to lon/lat (always_xy), or None for lon/lat itself."""
    if crs is None or crs.strip().upper() in LONLAT_CRS:
        return None
    try:
        import pyproj  # lazy: only projected files need it
    except ImportError:
        raise _missing("crs", "pyproj", f"{name} in {crs}") from None
    where = "" if key else f" (the crs of {name})"
    try:
        source = pyproj.CRS.from_user_input(crs)
    except pyproj.exceptions.CRSError:
        raise FootprintError(
            f"a coordinate reference system pyproj knows, e.g. EPSG:3857{where}, got {crs!r}",
            key,
        ) from None
    if source.is_geocentric:
        raise FootprintError(f"a geographic or projected CRS{where}, got {crs!r}", key)
    return pyproj.Transformer.from_crs(source, "EPSG:4326", always_xy=True)


# --- GeoJSON ---------------------------------------------------------------------------------

_FOOTPRINT_TYPES = ("Polygon", "MultiPolygon", "LineString", "MultiLineString")


def _read_geojson(path: Path, col: _Collector) -> None:
    name = col.name
    try:
        doc = json.loads(read_text_bounded(path, FOOTPRINT_BYTES))
    except FileRefused as exc:
        raise FootprintError(f"a GeoJSON file: {name}: {exc}") from None
    except (OSError, UnicodeDecodeError) as exc:
        reason = getattr(exc, "strerror", None) or type(exc).__name__
        raise FootprintError(f"a readable GeoJSON file: {name} ({reason})") from None
    except json.JSONDecodeError as exc:
        raise FootprintError(
            f"a GeoJSON file: {name} is not JSON (line {exc.lineno}, col {exc.colno})"
        ) from None
    kind = doc.get("type") if isinstance(doc, dict) else None
    if kind == "FeatureCollection" and isinstance(doc.get("features"), list):
        features = doc["features"]
    elif kind == "Feature":
        features = [doc]
    elif kind in _FOOTPRINT_TYPES or kind == "GeometryCollection":
        features = [{"type": "Feature", "geometry": doc, "properties": None}]
    else:
        raise FootprintError(f"a GeoJSON FeatureCollection, Feature or geometry in {name}")
    col.file_crs = _crs_member(doc, name)
    for k, feature in enumerate(features):
        label = f"features[{k}]"
        if type(feature) is not dict or feature.get("type") != "Feature":
            raise FootprintError(f"GeoJSON features ({name} {label} is not one)")
        geometry = feature.get("geometry")
        if geometry is None:
            col.skip(label, "without geometry", null=True)
            continue
        rings: list = []
        lines: list = []
        gkind = _geometry_parts(geometry, rings, lines, col, label)
        if gkind is not None:
            col.skip(label, gkind)
        else:
            col.add(label, rings, lines, feature.get("properties"))


def _geometry_parts(geometry: Any, rings: list, lines: list, col: _Collector, label: str):
    """Append a geometry's outer rings and lines; return its kind when it has none."""
    kind = geometry.get("type") if isinstance(geometry, dict) else None
    coords = geometry.get("coordinates") if isinstance(geometry, dict) else None
    where = col.where(label)
    if kind == "Polygon":
        rings.append(_outer_ring(coords, where))
    elif kind == "MultiPolygon":
        if not isinstance(coords, list):
            raise FootprintError(f"a multipolygon's list of polygons ({where})")
        rings.extend(_outer_ring(c, where) for c in coords)
    elif kind == "LineString":
        lines.append(coords)
    elif kind == "MultiLineString":
        if not isinstance(coords, list):
            raise FootprintError(f"a multilinestring's list of lines ({where})")
        lines.extend(coords)
    elif kind == "GeometryCollection" and isinstance(geometry.get("geometries"), list):
        before = len(rings) + len(lines)
        for part in geometry["geometries"]:
            if isinstance(part, dict) and part.get("type") in (
                *_FOOTPRINT_TYPES,
                "GeometryCollection",
            ):
                _geometry_parts(part, rings, lines, col, label)
        if len(rings) + len(lines) == before:
            return "GeometryCollection"
    else:
        return kind if isinstance(kind, str) else "without a geometry type"
    if kind != "GeometryCollection" and not (rings or lines):
        return f"empty {kind}"
    return None


def _outer_ring(coords: Any, where: str) -> Any:
    if not isinstance(coords, list) or not coords:
        raise FootprintError(f"a polygon's list of rings ({where})")
    return coords[0]  # outer ring; holes ignored


def _crs_member(doc: Any, name: str) -> str | None:
    """The legacy (GeoJSON 2008) `crs` member: `{"type": "name", "properties": {"name": N}}`
    (or `{"type": "EPSG", "properties": {"code": C}}`), or None."""
    crs = doc.get("crs") if isinstance(doc, dict) else None
    if crs is None:
        return None
    props = crs.get("properties") if isinstance(crs, dict) else None
    ctype = crs.get("type") if isinstance(crs, dict) else None
    if ctype == "name" and isinstance(props, dict) and isinstance(props.get("name"), str):
        return props["name"]
    if ctype == "EPSG" and isinstance(props, dict) and _is_number(props.get("code")):
        return f"EPSG:{int(props['code'])}"
    raise FootprintError(
        f'a named crs member in {name}, e.g. {{"type": "name", "properties": '
        f'{{"name": "EPSG:3857"}}}} (or the item\'s crs: key)'
    )


# --- OpenStreetMap (pyosmium) ----------------------------------------------------------------


def _read_osm(path: Path, col: _Collector, origin: Origin) -> None:  # noqa: C901 (over 15 branches: to split)
    """Buildings and barriers of an OSM extract. Geometries are built by libosmium (WKB) and
    decoded by shapely in one call; Python touches each way once, never each node."""
    try:
        import osmium  # lazy: the `osm` extra
    except ImportError:
        raise _missing("osm", "pyosmium", col.name) from None
    if not path.is_file():
        raise FootprintError(f"a readable OSM file: {col.name} (No such file)")
    factory = osmium.geom.WKBFactory()
    broken = (RuntimeError, ValueError, osmium.InvalidLocationError)
    height_keys = (col.options.height_key or "height", "building:levels")
    ways: list[tuple[str, bool, dict, str]] = []  # label, is a building ring, props, WKB
    areas: list[tuple[str, dict, str]] = []
    try:
        processor = (
            osmium.FileProcessor(str(path), osmium.osm.NODE | osmium.osm.WAY | osmium.osm.RELATION)
            .with_locations()
            .with_areas(osmium.filter.KeyFilter("building"))
            .with_filter(osmium.filter.KeyFilter("building", "barrier"))
        )
        for obj in processor:
            tags = obj.tags
            building = tags.get("building")
            if obj.is_area():
                if obj.from_way() or building in (None, "no"):
                    continue  # closed ways are read as ways
                label = f"relation/{obj.orig_id()}"
                try:
                    wkb = factory.create_multipolygon(obj)
                except broken:
                    col.skip(label, "broken multipolygon")
                    continue
                areas.append((label, {k: tags.get(k) for k in height_keys}, wkb))
            elif obj.is_way():
                label = f"way/{obj.id}"
                is_building = building is not None and building != "no"
                if is_building:
                    nodes = obj.nodes
                    if len(nodes) < 4 or nodes[0].ref != nodes[-1].ref:
                        col.skip(label, "open building way")
                        continue
                elif tags.get("barrier") not in _OSM_BARRIERS:
                    continue
                try:
                    wkb = factory.create_linestring(obj)
                except broken:
                    col.skip(label, "way with nodes missing or repeated")
                    continue
                ways.append((label, is_building, {k: tags.get(k) for k in height_keys}, wkb))
    except FootprintError:
        raise
    except broken as exc:
        raise FootprintError(f"a readable OSM file: {col.name} ({exc})") from None
    if ways:
        shapes = shapely.from_wkb([w for *_, w in ways])
        coords = shapely.get_coordinates(shapes)
        counts = shapely.get_num_coordinates(shapes)
        for (label, is_building, props, _), xy in zip(
            ways, np.split(coords, np.cumsum(counts)[:-1]), strict=True
        ):
            if not is_building:
                col.add(label, [], [xy], props)
            elif len(xy) >= 4:  # libosmium drops repeated nodes
                col.add(label, [xy], [], props)
            else:
                col.skip(label, "degenerate building way")
    for (label, props, _), shape in zip(
        areas, shapely.from_wkb([a[-1] for a in areas]), strict=True
    ):
        rings: list = []
        _shape_parts(shape, rings, [])
        if rings:
            col.add(label, rings, [], props)
        else:
            col.skip(label, "multipolygon without outer ring")


# --- shapefile, GeoPackage (pyogrio) ---------------------------------------------------------


def _read_gis(path: Path, col: _Collector) -> None:
    try:
        import pyogrio  # lazy: the `gis` extra
    except ImportError:
        raise _missing("gis", "pyogrio", col.name) from None
    try:
        meta, _fids, geometry, field_data = pyogrio.raw.read(str(path))
    except Exception as exc:  # noqa: BLE001 - pyogrio raises its own DataSourceError family
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise FootprintError(f"a readable shapefile or GeoPackage: {col.name} ({reason})") from None
    col.file_crs = meta.get("crs")
    fields = [str(f) for f in meta.get("fields", [])]
    wanted = {col.options.height_key or "height", "building:levels"}
    columns = {f: field_data[i] for i, f in enumerate(fields) if f in wanted}
    shapes = shapely.from_wkb(geometry) if geometry is not None else []
    for k, shape in enumerate(shapes):
        label = f"features[{k}]"
        if shape is None or shapely.is_empty(shape):
            col.skip(label, "without geometry", null=shape is None)
            continue
        rings: list = []
        lines: list = []
        _shape_parts(shape, rings, lines)
        if not rings and not lines:
            col.skip(label, shape.geom_type)
            continue
        props = {f: values[k] for f, values in columns.items()}
        col.add(label, rings, lines, props)


def _shape_parts(shape: shapely.Geometry, rings: list, lines: list) -> None:
    kind = shapely.get_type_id(shape)
    if kind == 3:  # Polygon: outer ring, holes ignored
        rings.append(shapely.get_coordinates(shape.exterior))
    elif kind in (1, 2):  # LineString, LinearRing
        lines.append(shapely.get_coordinates(shape))
    elif kind in (5, 6, 7):  # MultiLineString, MultiPolygon, GeometryCollection
        for part in shapely.get_parts(shape):
            _shape_parts(part, rings, lines)
