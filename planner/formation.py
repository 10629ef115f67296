"""Line-formation spacings and fleet size (paper sec. IV-A, eqs. 9 and 28)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SQRT2 = math.sqrt(2.0)

#: Comparison tolerance on distances, metres (docs/design.md 3.2).
DISTANCE_TOLERANCE = 1e-6
#: Comparison tolerance on angles, radians (docs/design.md 3.2).
ANGLE_TOLERANCE = 1e-9


def collision_spacing(safety_margin: float) -> float:
    """dS_c = 2*sqrt(2)*rho_c: spacing of parked UAVs that rules out collisions."""
    return 2.0 * SQRT2 * safety_margin


def radio_spacing(safety_margin: float, radio_range: float) -> float:
    """dS_r = rho_R - 2*rho_c: spacing along the path that keeps radio contact."""
    return radio_range - 2.0 * safety_margin


def min_radio_range(safety_margin: float) -> float:
    """Smallest radio range the formation works with: 2(1+sqrt 2) rho_c (eq. 9)."""
    return 2.0 * (1.0 + SQRT2) * safety_margin


def min_fleet_size(path_length: float, safety_margin: float, radio_range: float) -> int:
    """N = ceil(len(P) / dS_r) (eq. 28), at least 1.

    A tolerance keeps an exact multiple of dS_r from rounding up to one UAV more.
    """
    spacing = radio_spacing(safety_margin, radio_range)
    if spacing <= 0:
        raise ValueError("radio_range must exceed 2 * safety_margin")
    return max(1, math.ceil(path_length / spacing - DISTANCE_TOLERANCE))


def unit(angle_rad: float) -> np.ndarray:
    """Unit vector at an absolute angle (radians, counter-clockwise from +x)."""
    return np.array([math.cos(angle_rad), math.sin(angle_rad)])


def row_direction(start: np.ndarray, goal: np.ndarray, angle_deg: float) -> np.ndarray:
    """Unit vector at `angle_deg` counter-clockwise from the direction A->B.

    For the start row this is e_0, the direction UAVs move along it towards A (the row itself
    lies behind A, at pi + theta_A); for the goal row it is e_K, pointing from B along the row.
    """
    ab = np.asarray(goal, float) - np.asarray(start, float)
    return unit(math.atan2(ab[1], ab[0]) + math.radians(angle_deg))


#: Length used for the paper's infinite parking rays (parking: ray), metres.
RAY_LENGTH = 1e7


@dataclass(frozen=True, eq=False)
class ParkingRows:
    """The two parking rows as segments: Delta_A behind A and Delta_B beyond B (eqs. 14-17).

    `start_row` runs from A backwards (A, A - length*e_0); `goal_row` from B forwards.
    With parking "segment" each row is as long as N UAVs need, (N-1) dS_c, plus rho_c;
    with "ray" (the paper's reading) they are effectively infinite.

    Legs of a route (`planner.route`, docs/design.md 7) generalise both: `start_row` may be a
    polyline, the route flown so far from the leg's start back to A and on along Delta_A (its
    first piece is the previous leg's last segment, e_0 its direction), and `open_goal`
    means no row beyond the goal (`goal_row` is then the point B twice) and no arrival
    angle: the leg ends on a station point.
    """

    start_row: np.ndarray  # (M, 2), M >= 2: a segment, or a leg's polyline
    goal_row: np.ndarray  # (2, 2)
    start_direction: np.ndarray  # e_0, unit, towards A
    goal_direction: np.ndarray  # e_K, unit, away from B
    open_goal: bool = False

    @property
    def start_rest(self) -> np.ndarray | None:
        """The start row without its first piece (what a first segment must keep 2 rho_c
        from, condition 5 across legs), or None for a plain parking row."""
        return self.start_row[1:] if len(self.start_row) > 2 else None


def parking_rows(
    start: np.ndarray,
    goal: np.ndarray,
    start_angle_deg: float,
    goal_angle_deg: float,
    fleet_size: int,
    safety_margin: float,
    parking: str = "segment",
) -> ParkingRows:
    """Parking rows for `fleet_size` UAVs (docs/design.md 3.2: finite rows unless
    `parking == "ray"`)."""
    start = np.asarray(start, float)
    goal = np.asarray(goal, float)
    e0 = row_direction(start, goal, start_angle_deg)
    ek = row_direction(start, goal, goal_angle_deg)
    if parking == "ray":
        length = RAY_LENGTH
    elif parking == "segment":
        length = (fleet_size - 1) * collision_spacing(safety_margin) + safety_margin
    else:
        raise ValueError(f"parking must be 'segment' or 'ray', not {parking!r}")
    return ParkingRows(
        start_row=np.array([start, start - length * e0]),
        goal_row=np.array([goal, goal + length * ek]),
        start_direction=e0,
        goal_direction=ek,
    )
