"""Reproducible planning scenarios shared by tests, benchmarks and examples (pure, seeded).

* `paper_scenario(seed)`: the paper's Table II map (sec. V): 10 axis-aligned rectangles of
  random size in a 2000 m x 2000 m area, A=(200,200), B=(700,700), rho_c 5 m, rho_R 220 m,
  theta_A = theta_B = 0.
* `random_buildings(n, seed)`: n non-overlapping, randomly rotated rectangles in a square area,
  A and B near opposite corners.
* `city_grid(cols, rows, block, street)`: a Manhattan grid of square blocks with streets all
  round; A and B in the corner intersections.
* `fine_polygon(vertices)`: one seven-lobed polygon drawn with many vertices (a traced
  coastline or a building digitised finely), between A and B.

Random rectangles are resampled until they keep A, B and the parking rows (the paper's rays,
clipped to the area, which covers every finite row) clear by the safety margin, with a spare
metre, so that every scenario passes eqs. 14-15 for any fleet size and either parking mode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import shapely

from planner.formation import row_direction
from planner.obstacles import Obstacles
from planner.types import PathProblem

#: The paper's varying-speed runs (sec. V): the leader asks for these speeds, (mission time
#: it asks, speed m/s); `gcs eval paper` and the study file's `leader` axis fly them.
LEADER_REQUESTS = ((30.0, 5.0), (90.0, 10.0), (150.0, 2.0), (210.0, 10.0))

#: Extra clearance (m) random rectangles keep from A, B and the rows, beyond the margin.
_SPARE = 1.0


@dataclass(frozen=True, eq=False)
class Scenario:
    """A map with its mission geometry; `rectangles` is (R, 5): centre x, y, width, height,
    angle in degrees (what a mission file's `rectangle:` entries need)."""

    name: str
    obstacles: Obstacles
    start: np.ndarray
    goal: np.ndarray
    start_angle_deg: float
    goal_angle_deg: float
    safety_margin: float
    radio_range: float
    rectangles: np.ndarray
    area: tuple[float, float, float, float]  # xmin, ymin, xmax, ymax


def rectangle_rings(rectangles: np.ndarray) -> np.ndarray:
    """Corner rings (R, 4, 2), counter-clockwise, of rectangles given as (cx, cy, w, h, deg)."""
    rect = np.asarray(rectangles, float).reshape(-1, 5)
    half = rect[:, 2:4] / 2.0
    local = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    corners = local[None, :, :] * half[:, None, :]
    angle = np.radians(rect[:, 4])
    cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
    x = corners[..., 0] * cos - corners[..., 1] * sin
    y = corners[..., 0] * sin + corners[..., 1] * cos
    return np.stack([x, y], axis=-1) + rect[:, None, :2]


def _rectangles_scenario(
    name: str,
    rectangles: np.ndarray,
    start: np.ndarray,
    goal: np.ndarray,
    safety_margin: float,
    radio_range: float,
    area: tuple[float, float, float, float],
) -> Scenario:
    """A map of rectangular obstacles (cx, cy, w, h, deg), both rows along A->B
    (theta_A = theta_B = 0)."""
    return Scenario(
        name=name,
        obstacles=Obstacles(polygons=tuple(rectangle_rings(rectangles))),
        start=start,
        goal=goal,
        start_angle_deg=0.0,
        goal_angle_deg=0.0,
        safety_margin=safety_margin,
        radio_range=radio_range,
        rectangles=rectangles,
        area=area,
    )


def _keep_out(
    start: np.ndarray,
    goal: np.ndarray,
    start_angle_deg: float,
    goal_angle_deg: float,
    area: tuple[float, float, float, float],
) -> shapely.Geometry:
    """A, B and both rows as rays clipped to the area (with a generous overshoot)."""
    span = 2.0 * math.hypot(area[2] - area[0], area[3] - area[1])
    e0 = row_direction(start, goal, start_angle_deg)
    ek = row_direction(start, goal, goal_angle_deg)
    return shapely.MultiLineString([[start, start - span * e0], [goal, goal + span * ek]])


def _sample_rectangles(
    rng: np.random.Generator,
    count: int,
    area: tuple[float, float, float, float],
    size_range: tuple[float, float],
    keep_out: shapely.Geometry,
    clearance: float,
    rotate: bool,
    gap: float | None,
) -> np.ndarray:
    """`count` rectangles clear of `keep_out` by `clearance`; if `gap` is set, also at least
    `gap` apart from each other. Rejected draws are resampled (fixed `rng`, reproducible)."""
    accepted: list[np.ndarray] = []
    placed: list[shapely.Geometry] = []
    while len(accepted) < count:
        batch = 4 * (count - len(accepted)) + 8
        rect = np.column_stack(
            [
                rng.uniform(area[0], area[2], batch),
                rng.uniform(area[1], area[3], batch),
                rng.uniform(*size_range, batch),
                rng.uniform(*size_range, batch),
                rng.uniform(0.0, 180.0, batch) if rotate else np.zeros(batch),
            ]
        )
        polys = shapely.polygons(rectangle_rings(rect))
        inside = shapely.contains(shapely.box(*area), polys)
        clear = ~shapely.dwithin(polys, keep_out, clearance)
        for r, poly in zip(rect[inside & clear], polys[inside & clear], strict=True):
            if len(accepted) == count:
                break
            if gap is not None and placed:
                tree = shapely.STRtree(placed)
                if len(tree.query(poly, predicate="dwithin", distance=gap)):
                    continue
            accepted.append(r)
            placed.append(poly)
    return np.array(accepted)


def paper_scenario(seed: int = 25) -> Scenario:
    """The paper's Table II map: 10 rectangles of random size (fixed seed), 2000 m x 2000 m."""
    area = (0.0, 0.0, 2000.0, 2000.0)
    start, goal = np.array([200.0, 200.0]), np.array([700.0, 700.0])
    rho = 5.0
    keep_out = _keep_out(start, goal, 0.0, 0.0, area)
    rng = np.random.default_rng(seed)
    rect = _sample_rectangles(
        rng, 10, area, (40.0, 400.0), keep_out, rho + _SPARE, rotate=False, gap=None
    )
    return _rectangles_scenario(f"paper-table-ii-seed{seed}", rect, start, goal, rho, 220.0, area)


def random_buildings(
    n: int = 200,
    seed: int = 1,
    size: float = 2000.0,
    building_size: tuple[float, float] = (20.0, 90.0),
    safety_margin: float = 5.0,
    radio_range: float = 220.0,
) -> Scenario:
    """`n` randomly rotated rectangular buildings, at least 2 rho_c + 1 m apart (so every gap
    is flyable in principle), in a `size` x `size` area; A and B near opposite corners."""
    area = (0.0, 0.0, size, size)
    start, goal = np.array([0.05 * size, 0.05 * size]), np.array([0.95 * size, 0.95 * size])
    keep_out = _keep_out(start, goal, 0.0, 0.0, area)
    rng = np.random.default_rng(seed)
    rect = _sample_rectangles(
        rng,
        n,
        area,
        building_size,
        keep_out,
        safety_margin + _SPARE,
        rotate=True,
        gap=2.0 * safety_margin + 1.0,
    )
    name = f"random-{n}-buildings-seed{seed}"
    return _rectangles_scenario(name, rect, start, goal, safety_margin, radio_range, area)


def city_grid(
    cols: int = 20,
    rows: int = 16,
    block: float = 40.0,
    street: float = 20.0,
    safety_margin: float = 5.0,
    radio_range: float = 220.0,
) -> Scenario:
    """`cols` x `rows` square blocks of side `block`, `street` wide streets all round them;
    A in the south-west corner intersection, B in the north-east one."""
    pitch = block + street
    ix, iy = np.meshgrid(np.arange(cols), np.arange(rows), indexing="ij")
    centre = street + block / 2.0 + pitch * np.column_stack([ix.ravel(), iy.ravel()])
    rect = np.column_stack(
        [centre, np.full((len(centre), 2), block), np.zeros(len(centre))]
    ).astype(float)
    width, height = street + cols * pitch, street + rows * pitch
    return _rectangles_scenario(
        f"city-grid-{cols}x{rows}",
        rect,
        np.array([street / 2.0, street / 2.0]),
        np.array([width - street / 2.0, height - street / 2.0]),
        safety_margin,
        radio_range,
        (0.0, 0.0, width, height),
    )


def fine_polygon(vertices: int, safety_margin: float = 5.0, radio_range: float = 120.0) -> Scenario:
    """One polygon of `vertices` vertices, radius 50 +- 8 m in seven lobes, centred at
    (150, 50); A = (0, 0), B = (300, 100), both headings 0: the path wraps its north side."""
    angle = np.linspace(0.0, 2.0 * math.pi, vertices, endpoint=False)
    radius = 50.0 + 8.0 * np.sin(7.0 * angle)
    ring = np.column_stack([150.0 + radius * np.cos(angle), 50.0 + radius * np.sin(angle)])
    return Scenario(
        name=f"fine-polygon-{vertices}",
        obstacles=Obstacles(polygons=(ring,)),
        start=np.array([0.0, 0.0]),
        goal=np.array([300.0, 100.0]),
        start_angle_deg=0.0,
        goal_angle_deg=0.0,
        safety_margin=safety_margin,
        radio_range=radio_range,
        rectangles=np.zeros((0, 5)),
        area=(-50.0, -50.0, 350.0, 150.0),
    )


def walled_in(base: Scenario, half: float, gap: float = 0.0) -> Scenario:
    """`base` with a square of walls `half` x 2 wide round B, open at the corner the goal row
    leaves through when `gap` > 0. No valid path either way: closed, B is cut off; open,
    every way in reaches B against its row (a sharp arrival)."""
    c = base.goal
    d = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) * half + c
    walls = [[d[0], d[1]], [d[3], d[0]]]  # south and west sides
    walls += [[d[1], d[2] - [0.0, gap]], [d[2] - [gap, 0.0], d[3]]]  # east, north (gap at NE)
    obstacles = Obstacles(polygons=base.obstacles.polygons, walls=np.array(walls))
    return replace(base, name=f"{base.name}, B walled in", obstacles=obstacles)


def scenario_problem(scenario: Scenario, **overrides):
    """A `PathProblem` for `scenario`; keyword arguments override its fields."""
    fields = dict(
        start=scenario.start,
        goal=scenario.goal,
        start_angle_deg=scenario.start_angle_deg,
        goal_angle_deg=scenario.goal_angle_deg,
        safety_margin=scenario.safety_margin,
        radio_range=scenario.radio_range,
        obstacles=scenario.obstacles,
    )
    fields.update(overrides)
    return PathProblem(**fields)
