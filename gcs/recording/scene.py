"""What Foxglove's 3-D and Map panels show of a mission: scene entities, transforms, GeoJSON.

Built once per run from the plan (`SceneGeometry.from_plan`), then per tick from the fleet's
positions. No I/O here: `gcs.recording.recording` writes what these functions return.

3-D panel (`/scene`, `foxglove.SceneUpdate`, fixed frame `map` = the mission's local frame,
x east, y north, z up, metres):
* obstacles extruded to `DISPLAY_HEIGHT_FACTOR` x the cruise altitude (the paper's obstacles
  are 2-D: the fleet flies around them, so they are drawn taller than it flies), walls as
  vertical panels, their rho_c margins (mitre corners, square caps, as the planner's graph
  assumes; docs/design.md 3.1) as red outlines at the cruise altitude;
* the planned path at the cruise altitude, the parking rows and slots on the ground, base
  stations (A, B and the mission's extra ones) as masts, ground users as cubes; for a
  stations mission (docs/design.md 7) the route, each monitoring point as a gold column named after
  the point and the UAV that holds it, and every UAV's station on the route as a small disc
  at the cruise altitude;
* each UAV as a sphere in frame `uav<n>`, its virtual target V_n(t) (eq. 27) as a ring of
  radius rho_c in frame `uav<n>/target` (the UAV should stay inside it), both frame-locked: the
  transforms on `/tf` move them at every tick;
* radio links: every UAV-UAV and UAV-base-station pair within the radio range (unit disk,
  horizontal distance, as `planner.guarantees`), redrawn at every tick.

Every `/scene` message is complete (static part + links), so a seek or a late live client
shows the whole scene at once; the static part is protobuf-encoded once and concatenated with
the links of the tick (protobuf concatenation merges repeated fields).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)

from gcs.geodesy import Origin, local_to_lonlat
from planner.formation import DISTANCE_TOLERANCE
from planner.obstacles import Obstacles

#: The fixed frame of the 3-D scene (the mission's local east-north-up frame).
MAP_FRAME = "map"
#: Obstacles are drawn this many times the cruise altitude high (display only).
DISPLAY_HEIGHT_FACTOR = 1.5
#: Height of a base-station mast, m (display only).
MAST_HEIGHT_M = 12.0
#: Diameter of a UAV's sphere, m (display only: the physical radius is `vehicle.radius`).
UAV_DIAMETER_M = 2.0
#: Points on a target ring.
RING_POINTS = 32

#: Identity rotation. `Quaternion()` defaults to w = 0, which is not a rotation.
IDENTITY = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)

#: Per-UAV colours (matplotlib's tab10, without importing matplotlib here).
PALETTE = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)


def uav_frame(uav: int) -> str:
    """Frame of UAV `uav` (1-based) in `/tf`."""
    return f"uav{uav}"


def target_frame(uav: int) -> str:
    """Frame of UAV `uav`'s virtual target V_n(t) in `/tf`."""
    return f"uav{uav}/target"


def uav_colour(uav: int) -> str:
    """Hex colour of UAV `uav` (1-based), the same in every view."""
    return PALETTE[(uav - 1) % len(PALETTE)]


def _rgba(hex_colour: str, alpha: float = 1.0) -> Color:
    value = hex_colour.lstrip("#")
    r, g, b = (int(value[i : i + 2], 16) / 255.0 for i in (0, 2, 4))
    return Color(r=r, g=g, b=b, a=alpha)


GREY = Color(r=0.45, g=0.47, b=0.52, a=0.85)
MARGIN_RED = Color(r=0.9, g=0.2, b=0.2, a=0.9)
PATH_ORANGE = Color(r=1.0, g=0.55, b=0.0, a=1.0)
ROW_BLUE = Color(r=0.12, g=0.47, b=0.71, a=0.9)
STATION_GREEN = Color(r=0.17, g=0.63, b=0.17, a=1.0)
POINT_GOLD = Color(r=1.0, g=0.84, b=0.0, a=1.0)
USER_PURPLE = Color(r=0.58, g=0.4, b=0.74, a=1.0)
LINK_GREEN = Color(r=0.2, g=0.85, b=0.3, a=0.7)
LINK_RED = Color(r=0.9, g=0.2, b=0.15, a=0.7)  # in range, through a building
WHITE = Color(r=1.0, g=1.0, b=1.0, a=1.0)


@dataclass(frozen=True, eq=False)
class SceneGeometry:
    """The mission's geometry in the local frame, as the views need it."""

    name: str
    origin: Origin
    obstacles: Obstacles
    obstacle_names: tuple[str, ...]  # key path of each of `obstacles.geometries`
    safety_margin: float
    radio_range: float
    altitude: float
    path: np.ndarray  # (K, 2) planned path, A ... B (a stations mission: its route)
    rows: np.ndarray  # (R, 2, 2) parking rows behind A and beyond B (no B row: R = 1)
    slots: np.ndarray  # (2N, 2) parking slots at A then at B (a stations mission: at A)
    stations: np.ndarray  # (B, 2) A, B, then the extra base stations
    station_names: tuple[str, ...]
    ground_users: np.ndarray  # (U, 2)
    fleet_size: int
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (m, 2), in order
    point_names: tuple[str, ...] = ()  # "name (UAV n)" of each monitoring point
    uav_stations: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (N, 2)

    @classmethod
    def from_plan(cls, plan) -> SceneGeometry:
        """From a valid `gcs.planning.MissionPlan`."""
        mission = plan.mission
        formation = plan.formation
        rows = plan.path_plan.rows
        stations = mission.base_station_points
        names = mission.base_station_names
        route = plan.route
        points, point_names, uav_stations = np.zeros((0, 2)), (), np.zeros((0, 2))
        slots = np.vstack([formation.start_slots, formation.goal_slots])
        row_list = [rows.start_row, rows.goal_row]
        if route is not None:
            order = route.order.tolist()
            points = np.array([mission.stations[i].xy for i in order], float).reshape(-1, 2)
            point_names = tuple(
                f"{mission.stations[i].name} (UAV {uav})"
                for i, uav in zip(order, route.layout.holders.tolist(), strict=True)
            )
            uav_stations = formation.station_slots
            slots, row_list = formation.start_slots, [rows.start_row]
        return cls(
            name=mission.name,
            origin=mission.origin,
            obstacles=mission.obstacles,
            obstacle_names=tuple(mission.obstacle_keys),
            safety_margin=float(mission.safety_margin),
            radio_range=float(mission.radio_range),
            altitude=float(mission.altitude),
            path=np.asarray(formation.path, float),
            rows=np.array(row_list, float),
            slots=slots,
            stations=np.array(stations, float).reshape(-1, 2),
            station_names=names,
            ground_users=np.array([[u.x, u.y] for u in mission.ground_users], float).reshape(-1, 2),
            fleet_size=int(formation.fleet_size),
            points=points,
            point_names=point_names,
            uav_stations=uav_stations,
        )

    @property
    def obstacle_height(self) -> float:
        return DISPLAY_HEIGHT_FACTOR * max(self.altitude, 10.0)


# --------------------------------------------------------------------------- 3-D primitives
def _points(xyz: np.ndarray) -> list[Point3]:
    return [Point3(x=x, y=y, z=z) for x, y, z in np.asarray(xyz, float).reshape(-1, 3).tolist()]


def _with_z(xy: np.ndarray, z: float) -> np.ndarray:
    xy = np.asarray(xy, float).reshape(-1, 2)
    return np.column_stack([xy, np.full(len(xy), z)])


def _pose(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=IDENTITY)


def _segments_of_rings(rings: np.ndarray) -> np.ndarray:
    """Closed shapely rings/lines -> (S, 2, 2) consecutive vertex pairs, all rings at once."""
    coords, index = shapely.get_coordinates(rings, return_index=True)
    same = index[:-1] == index[1:]
    return np.stack([coords[:-1][same], coords[1:][same]], axis=1)


def extruded_obstacles(obstacles: Obstacles, height: float) -> np.ndarray:
    """Triangles (T, 3, 3) of the obstacles extruded from the ground to `height`: polygon tops
    (constrained Delaunay) and walls, and every edge (polygon sides, free walls) as a panel."""
    parts = []
    if obstacles.polygons:
        solids = obstacles.geometries[: len(obstacles.polygons)]
        triangles = shapely.get_parts(shapely.constrained_delaunay_triangles(solids))
        tops = shapely.get_coordinates(triangles).reshape(-1, 4, 2)[:, :3]
        parts.append(np.concatenate([tops, np.full(tops.shape[:2] + (1,), height)], axis=2))
    edges = obstacles.segments  # (M, 2, 2): polygon edges then walls
    if len(edges):
        a, b = edges[:, 0], edges[:, 1]
        low = np.zeros(len(edges))
        high = np.full(len(edges), height)
        a0, b0 = np.column_stack([a, low]), np.column_stack([b, low])
        a1, b1 = np.column_stack([a, high]), np.column_stack([b, high])
        parts.append(np.stack([a0, b0, b1], axis=1))
        parts.append(np.stack([a0, b1, a1], axis=1))
    return np.concatenate(parts) if parts else np.zeros((0, 3, 3))


def margin_segments(obstacles: Obstacles, safety_margin: float) -> np.ndarray:
    """(S, 2, 2) outline segments of every obstacle's rho_c margin (mitre joins, square caps)."""
    if len(obstacles) == 0:
        return np.zeros((0, 2, 2))
    margins = shapely.buffer(
        obstacles.geometries, safety_margin, join_style="mitre", cap_style="square"
    )
    return _segments_of_rings(shapely.get_rings(shapely.get_parts(margins)))


def _line_list(segments_xyz: np.ndarray, colour: Color, thickness: float) -> LinePrimitive:
    return LinePrimitive(
        type=LinePrimitiveLineType.LineList,
        pose=_pose(),
        thickness=thickness,
        points=_points(np.asarray(segments_xyz).reshape(-1, 3)),
        color=colour,
    )


def _label(text: str, z: float, colour: Color = WHITE) -> TextPrimitive:
    return TextPrimitive(
        pose=_pose(0.0, 0.0, z),
        billboard=True,
        font_size=14.0,
        scale_invariant=True,
        color=colour,
        text=text,
    )


def static_entities(geometry: SceneGeometry) -> list[SceneEntity]:
    """Everything of the scene that the transforms move or that never moves."""
    g = geometry
    cruise = g.altitude
    entities = []
    triangles = extruded_obstacles(g.obstacles, g.obstacle_height)
    margins = margin_segments(g.obstacles, g.safety_margin)
    entities.append(
        SceneEntity(
            frame_id=MAP_FRAME,
            id="obstacles",
            triangles=[TriangleListPrimitive(pose=_pose(), points=_points(triangles), color=GREY)]
            if len(triangles)
            else [],
            lines=[_line_list(_with_z(margins.reshape(-1, 2), cruise), MARGIN_RED, 0.3)]
            if len(margins)
            else [],
        )
    )
    rows = _with_z(g.rows.reshape(-1, 2), 0.2)
    entities.append(
        SceneEntity(
            frame_id=MAP_FRAME,
            id="plan",
            lines=[
                LinePrimitive(
                    type=LinePrimitiveLineType.LineStrip,
                    pose=_pose(),
                    thickness=0.8,
                    points=_points(_with_z(g.path, cruise)),
                    color=PATH_ORANGE,
                ),
                _line_list(rows, ROW_BLUE, 0.4),
            ],
            spheres=[
                SpherePrimitive(
                    pose=_pose(x, y, 0.3), size=Vector3(x=1.0, y=1.0, z=1.0), color=ROW_BLUE
                )
                for x, y in g.slots.tolist()
            ],  # fmt: skip
        )
    )
    for name, (x, y) in zip(g.station_names, g.stations.tolist(), strict=True):
        entities.append(
            SceneEntity(
                frame_id=MAP_FRAME,
                id=f"station/{name}",
                cylinders=[
                    CylinderPrimitive(
                        pose=_pose(x, y, MAST_HEIGHT_M / 2),
                        size=Vector3(x=2.0, y=2.0, z=MAST_HEIGHT_M),
                        bottom_scale=1.0,
                        top_scale=0.3,
                        color=STATION_GREEN,
                    )
                ],
                texts=[
                    TextPrimitive(
                        pose=_pose(x, y, MAST_HEIGHT_M + 3),
                        billboard=True,
                        font_size=14.0,
                        scale_invariant=True,
                        color=STATION_GREEN,
                        text=name,
                    )
                ],
            )
        )
    for name, (x, y) in zip(g.point_names, g.points.tolist(), strict=True):
        entities.append(
            SceneEntity(
                frame_id=MAP_FRAME,
                id=f"point/{name}",
                cylinders=[
                    CylinderPrimitive(
                        pose=_pose(x, y, cruise / 2),
                        size=Vector3(x=1.5, y=1.5, z=cruise),
                        bottom_scale=1.0,
                        top_scale=1.0,
                        color=POINT_GOLD,
                    )
                ],
                texts=[
                    TextPrimitive(
                        pose=_pose(x, y, cruise + 4),
                        billboard=True,
                        font_size=14.0,
                        scale_invariant=True,
                        color=POINT_GOLD,
                        text=name,
                    )
                ],
            )
        )
    if len(g.uav_stations):
        entities.append(
            SceneEntity(
                frame_id=MAP_FRAME,
                id="uav_stations",
                cylinders=[
                    CylinderPrimitive(
                        pose=_pose(x, y, cruise),
                        size=Vector3(x=3.0, y=3.0, z=0.2),
                        bottom_scale=1.0,
                        top_scale=1.0,
                        color=_rgba(uav_colour(uav), 0.6),
                    )
                    for uav, (x, y) in enumerate(g.uav_stations.tolist(), start=1)
                ],
            )
        )
    if len(g.ground_users):
        entities.append(
            SceneEntity(
                frame_id=MAP_FRAME,
                id="ground_users",
                cubes=[
                    CubePrimitive(
                        pose=_pose(x, y, 1.0), size=Vector3(x=2.0, y=2.0, z=2.0), color=USER_PURPLE
                    )
                    for x, y in g.ground_users.tolist()
                ],  # fmt: skip
            )
        )
    angles = np.linspace(0.0, 2 * math.pi, RING_POINTS, endpoint=False)
    ring = np.column_stack(
        [g.safety_margin * np.cos(angles), g.safety_margin * np.sin(angles), np.zeros_like(angles)]
    )
    for uav in range(1, g.fleet_size + 1):
        colour = _rgba(uav_colour(uav))
        entities.append(
            SceneEntity(
                frame_id=uav_frame(uav),
                id=f"uav{uav}",
                frame_locked=True,
                spheres=[
                    SpherePrimitive(
                        pose=_pose(),
                        size=Vector3(x=UAV_DIAMETER_M, y=UAV_DIAMETER_M, z=UAV_DIAMETER_M),
                        color=colour,
                    )
                ],
                texts=[_label(f"UAV {uav}", 3.0, colour)],
            )
        )
        entities.append(
            SceneEntity(
                frame_id=target_frame(uav),
                id=f"uav{uav}/target",
                frame_locked=True,
                lines=[
                    LinePrimitive(
                        type=LinePrimitiveLineType.LineLoop,
                        pose=_pose(),
                        thickness=0.25,
                        points=_points(ring),
                        color=_rgba(uav_colour(uav), 0.8),
                    )
                ],
                spheres=[
                    SpherePrimitive(pose=_pose(), size=Vector3(x=0.6, y=0.6, z=0.6), color=colour)
                ],
            )
        )
    return entities


def encode_static_scene(geometry: SceneGeometry) -> bytes:
    """The static part of every `/scene` message, protobuf-encoded once."""
    return SceneUpdate(entities=static_entities(geometry)).encode()


# --------------------------------------------------------------------------- per tick
def radio_links(
    positions: np.ndarray, stations: np.ndarray, radio_range: float
) -> tuple[np.ndarray, np.ndarray]:
    """Links of the unit-disk graph (horizontal distance <= range, as planner.guarantees):
    `(uav_pairs (L, 2) 0-based, uav_station (S, 2) uav index, station index)`. UAVs whose
    position is unknown (NaN) have no links; stations are wired together, not listed."""
    xy = np.asarray(positions, float)[:, :2]
    known = np.isfinite(xy).all(axis=1)
    limit = radio_range + DISTANCE_TOLERANCE
    between = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    close = (between <= limit) & known[:, None] & known[None, :]
    pairs = np.argwhere(np.triu(close, k=1))
    to_station = np.hypot(*(xy[:, None, :] - stations[None, :, :]).transpose(2, 0, 1))
    reach = np.argwhere((to_station <= limit) & known[:, None])
    return pairs, reach


def links_update(
    positions: np.ndarray,
    stations: np.ndarray,
    pairs: np.ndarray,
    reach: np.ndarray,
    blocked: np.ndarray | None = None,
) -> bytes:
    """The `radio_links` entity (every link of `radio_links`), encoded: one green line list
    of the links in line of sight, one red of those whose chord meets an obstacle
    (`blocked`, one flag per pair then per station link; None: none). An empty list
    replaces the previous links."""
    xyz = np.asarray(positions, float)
    ends = [xyz[pairs[:, 0]], xyz[pairs[:, 1]]]
    if len(reach):
        ends[0] = np.vstack([ends[0], xyz[reach[:, 0]]])
        ends[1] = np.vstack([ends[1], _with_z(stations[reach[:, 1]], MAST_HEIGHT_M)])
    segments = np.stack(ends, axis=1)
    if blocked is None:
        blocked = np.zeros(len(segments), bool)
    lines = [
        _line_list(segments[mask], color, 0.3)
        for mask, color in ((~blocked, LINK_GREEN), (blocked, LINK_RED))
        if mask.any()
    ]
    entity = SceneEntity(frame_id=MAP_FRAME, id="radio_links", lines=lines)
    return SceneUpdate(entities=[entity]).encode()


def transforms(
    positions: np.ndarray, targets: np.ndarray | None, altitude: float, stamp: Timestamp
) -> FrameTransforms:
    """`map -> uav<n>` (the UAV's position) and `map -> uav<n>/target` (V_n(t) at the cruise
    altitude) for every UAV whose position (resp. target) is known."""
    xyz = np.asarray(positions, float).reshape(-1, 3)
    out = _placed(uav_frame, xyz, np.isfinite(xyz).all(axis=1), stamp)
    if targets is not None:
        xyz = _with_z(targets, altitude)
        out += _placed(target_frame, xyz, np.isfinite(xyz[:, :2]).all(axis=1), stamp)
    return FrameTransforms(transforms=out)


def _placed(frame_of, xyz: np.ndarray, known: np.ndarray, stamp: Timestamp) -> list:
    """`map -> frame_of(n)` at row n - 1 of `xyz`, for every row that is `known`."""
    return [
        FrameTransform(
            timestamp=stamp,
            parent_frame_id=MAP_FRAME,
            child_frame_id=frame_of(index + 1),
            translation=Vector3(x=x, y=y, z=z),
            rotation=IDENTITY,
        )
        for index, (x, y, z) in enumerate(xyz.tolist())
        if known[index]
    ]


# --------------------------------------------------------------------------- Map panel
def _lonlat(xy: np.ndarray, origin: Origin) -> list:
    return local_to_lonlat(np.asarray(xy, float).reshape(-1, 2), origin).tolist()


def _feature(geometry: dict, name: str, style: dict) -> dict:
    return {"type": "Feature", "geometry": geometry, "properties": {"name": name, "style": style}}


def obstacles_geojson(geometry: SceneGeometry) -> str:
    """Building footprints (polygons) and walls as lon/lat GeoJSON (RFC 7946 order)."""
    g = geometry
    style = {"color": "#555555", "fillColor": "#777777", "fillOpacity": 0.6, "weight": 1}
    features = []
    polygons = g.obstacles.polygons
    for name, ring in zip(g.obstacle_names, polygons, strict=False):
        coords = _lonlat(np.vstack([ring, ring[:1]]), g.origin)
        features.append(_feature({"type": "Polygon", "coordinates": [coords]}, name, style))
    wall_names = g.obstacle_names[len(polygons) :]
    for name, wall in zip(wall_names, g.obstacles.walls, strict=False):
        coords = _lonlat(wall, g.origin)
        features.append(
            _feature({"type": "LineString", "coordinates": coords}, name, {**style, "weight": 3})
        )
    return json.dumps({"type": "FeatureCollection", "features": features})


def plan_geojson(geometry: SceneGeometry) -> str:
    """Planned path, parking rows, base stations and ground users as lon/lat GeoJSON."""
    g = geometry
    features = [
        _feature(
            {"type": "LineString", "coordinates": _lonlat(g.path, g.origin)},
            "planned path",
            {"color": "#ff8c00", "weight": 4},
        )
    ]
    for name, row in zip(("parking row A", "parking row B"), g.rows, strict=False):
        features.append(
            _feature(
                {"type": "LineString", "coordinates": _lonlat(row, g.origin)},
                name,
                {"color": "#1f77b4", "weight": 3},
            )
        )
    for name, point in zip(g.station_names, _lonlat(g.stations, g.origin), strict=True):
        features.append(
            _feature({"type": "Point", "coordinates": point}, f"base station {name}", {})
        )
    for k, point in enumerate(_lonlat(g.ground_users, g.origin)):
        features.append(_feature({"type": "Point", "coordinates": point}, f"ground user {k}", {}))
    for name, point in zip(g.point_names, _lonlat(g.points, g.origin), strict=True):
        features.append(
            _feature({"type": "Point", "coordinates": point}, f"monitoring point {name}", {})
        )
    return json.dumps({"type": "FeatureCollection", "features": features})
