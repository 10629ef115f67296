"""Planning maps shared by the planner's tests: a `PathProblem` builder, squares and rotated
rectangles, hand-made maps, and random route maps (a hypothesis strategy)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st

from planner.formation import min_radio_range
from planner.obstacles import Obstacles
from planner.route import RouteProblem
from planner.scenarios import rectangle_rings
from planner.types import PathProblem

#: The safety margin rho_c (m) of the hand-made maps.
RHO = 5.0

NO_OBSTACLES = Obstacles()


def problem(start, goal, obstacles=NO_OBSTACLES, theta_a=0.0, theta_b=0.0, **kw) -> PathProblem:
    """A->B with parking angles theta_A, theta_B (degrees), rho_c = `RHO` and rho_R = 220 m
    unless `safety_margin` / `radio_range` say otherwise; other keywords go to `PathProblem`."""
    return PathProblem(
        start=np.array(start, float),
        goal=np.array(goal, float),
        start_angle_deg=theta_a,
        goal_angle_deg=theta_b,
        safety_margin=kw.pop("safety_margin", RHO),
        radio_range=kw.pop("radio_range", 220.0),
        obstacles=obstacles,
        **kw,
    )


def square(x0, y0, size):
    """Corners of the axis-aligned square of side `size` with its lower-left corner at x0, y0."""
    return np.array([[x0, y0], [x0 + size, y0], [x0 + size, y0 + size], [x0, y0 + size]], float)


def terraced_rows(
    rows: int = 3,
    houses: int = 8,
    width: float = 8.0,
    depth: float = 12.0,
    street: float = 20.0,
    columns: int = 1,
) -> list[np.ndarray]:
    """Blocks of `houses` touching `width` x `depth` footprints (terraced houses share their
    side walls), in `rows` x `columns`, `street` apart, the first block's south-west corner at
    (0, 0)."""
    pitch = houses * width + street
    corners = [
        (x, y)
        for y in np.arange(rows) * (depth + street)
        for x0 in np.arange(columns) * pitch
        for x in x0 + np.arange(houses) * width
    ]
    rect = [(x + width / 2.0, y + depth / 2.0, width, depth, 0.0) for x, y in corners]
    return list(rectangle_rings(np.array(rect)))


def rectangle(center, size, angle_deg):
    """Corners of a rotated rectangle, counter-clockwise."""
    half = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * np.asarray(size) / 2
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    return half @ np.array([[c, s], [-s, c]]) + np.asarray(center)


# A map (frozen from the property-test family) whose shortest walk meeting (1)-(4) comes
# back within 2 rho_c of itself: the repair search must find the valid path.
REPAIR = dict(
    start=(0.0, 0.0),
    goal=(-17.0, 21.7),
    theta_a=7.0,
    theta_b=125.0,
    obstacles=Obstacles(
        polygons=(np.array([[-80.0, -133.8], [-55.7, -133.8], [-55.7, -107.7], [-80.0, -107.7]]),),
        walls=np.array([[[97.3, 97.2], [102.9, 114.7]]]),
    ),
)


@st.composite
def route_maps(draw):
    """A 400 m x 300 m map, A on the left, 1-8 points, up to 5 rectangles."""
    rho = draw(st.floats(2.0, 6.0))
    radio = draw(st.floats(min_radio_range(rho) + 1.0, 120.0))
    start = np.array([draw(st.floats(0.0, 30.0)), draw(st.floats(0.0, 300.0))])
    polygons = tuple(
        rectangle(
            (draw(st.floats(60.0, 380.0)), draw(st.floats(0.0, 300.0))),
            (draw(st.floats(5.0, 60.0)), draw(st.floats(5.0, 90.0))),
            draw(st.floats(0.0, 90.0)),
        )
        for _ in range(draw(st.integers(0, 5)))
    )
    obstacles = Obstacles(polygons=polygons)
    count = draw(st.integers(1, 8))
    points = np.array(
        [[draw(st.floats(50.0, 400.0)), draw(st.floats(0.0, 300.0))] for _ in range(count)]
    )
    problem = RouteProblem(
        start=start,
        points=points,
        start_angle_deg=draw(st.floats(-60.0, 60.0)),
        safety_margin=rho,
        radio_range=radio,
        obstacles=obstacles,
        order=draw(st.sampled_from(["tsp", "given"])),
        max_expansions=200_000,
    )
    return problem
