"""Hand-made planning maps shared by the planner's tests: a `PathProblem` builder and squares."""

from __future__ import annotations

import numpy as np

from planner.obstacles import Obstacles
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
