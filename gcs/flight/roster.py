"""Which UAV flies which row of a stations formation, and the reliefs in flight.

A stations mission starts with UAV n on row n of its `LineFormation`. Relieving a UAV
(`planner.relief`) takes it out: the UAVs still on station become a formation of one UAV
fewer, numbered by rank (`members[r]` flies row r; they come home onto the first slots of the
start row), and the relieved UAV flies its own motion home, above the chain, to the last free
slot. The ground-station core keeps one array per UAV (driver index); the roster maps the
formation's rows onto it (`expand`) and lays the relief's motions over them (`overlay`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from planner.kinematics import LineFormation, Reference
from planner.relief import Motion, ReliefPlan, plan_relief


@dataclass(frozen=True)
class Relief:
    """UAV `index` (0-based) relieved, asked at mission time `asked_s` by `source`
    ("operator", "battery")."""

    index: int
    plan: ReliefPlan
    source: str
    asked_s: float


class Roster:
    """The rows of a stations formation and the UAVs flying them (module docstring)."""

    def __init__(
        self,
        formation: LineFormation,
        point_distances: np.ndarray,
        point_names: tuple[str, ...],
        base_stations: np.ndarray,
    ) -> None:
        self.outbound = formation  # the outbound formation of the whole fleet
        self.size = formation.fleet_size
        self.point_distances = np.asarray(point_distances, dtype=float)
        self.point_names = point_names
        self.base_stations = np.asarray(base_stations, dtype=float).reshape(-1, 2)
        self.members = np.arange(self.size)  # driver index of each formation row
        self.stations = np.array(formation.stations, dtype=float)  # s_n per UAV, NaN: relieved
        self.holders = self._holders()
        self.reliefs: list[Relief] = []
        self.active: Relief | None = None  # the relief whose manoeuvre is flying

    @property
    def reshaped(self) -> bool:
        """Some UAV was relieved: rows and UAVs no longer coincide."""
        return bool(self.reliefs)

    @property
    def relieved(self) -> np.ndarray:
        """(N,) bool: the UAVs relieved (flying home alone, or landed)."""
        out = np.zeros(self.size, dtype=bool)
        out[[relief.index for relief in self.reliefs]] = True
        return out

    def station_xy(self) -> np.ndarray:
        """(N, 2) where each UAV holds now; NaN for the relieved."""
        out = np.full((self.size, 2), np.nan)
        held = np.isfinite(self.stations)
        out[held] = self.outbound.point_at(self.stations[held])
        return out

    def plan(
        self, uav: int, t: float, speed: float, max_acceleration: float, climb_speed: float
    ) -> ReliefPlan:
        """The relief of UAV `uav` (1-based) from mission time `t` (`planner.relief`); raises
        `ReliefRefused`."""
        return plan_relief(
            self.outbound,
            self.stations,
            self.point_distances,
            uav,
            t,
            speed,
            max_acceleration,
            self.base_stations,
            relieved_before=len(self.reliefs),
            point_names=self.point_names,
            climb_speed=climb_speed,
        )

    def adopt(self, plan: ReliefPlan, source: str, asked_s: float) -> LineFormation:
        """Fly `plan`: returns the formation of the UAVs left on station (the returning
        formation is built from it)."""
        relief = Relief(plan.layout.uav - 1, plan, source, asked_s)
        self.reliefs.append(relief)
        self.active = relief
        self.stations = plan.layout.stations.copy()
        self.members = plan.layout.members - 1
        self.holders = self._holders()
        return replace(
            self.outbound,
            fleet_size=len(self.members),
            stations=self.stations[self.members],
            return_distance=None,
        )

    def landing_xy(self) -> np.ndarray:
        """(N, 2): where the relieved UAVs land (NaN for the others)."""
        out = np.full((self.size, 2), np.nan)
        for relief in self.reliefs:
            out[relief.index] = relief.plan.landing_xy
        return out

    def expand(self, rows: np.ndarray, fill, axis: int = -1) -> np.ndarray:
        """An array over the formation's rows as one over the UAVs: along `axis` (length M ->
        N) row r goes to UAV `members[r]`, the relieved UAVs get `fill` (broadcast)."""
        rows = np.asarray(rows)
        if not self.reshaped:
            return rows
        axis = axis % rows.ndim
        shape = list(rows.shape)
        shape[axis] = self.size
        out = np.empty(shape, dtype=np.result_type(rows, np.asarray(fill)))
        index: list = [slice(None)] * rows.ndim
        index[axis] = np.flatnonzero(self.relieved)
        out[tuple(index)] = fill
        index[axis] = self.members
        out[tuple(index)] = rows
        return out

    def overlay(
        self, times: np.ndarray, virtual: np.ndarray, reference: Reference
    ) -> tuple[np.ndarray, Reference]:
        """Formation arrays over the UAVs (`expand`ed, (T, N, 2)) with the relieved UAVs on
        their landing slots and the active relief's motions laid over them."""
        if not self.reshaped:
            return virtual, reference
        landing = self.landing_xy()
        relieved = self.relieved
        virtual = virtual.copy()
        positions = reference.positions.copy()
        velocities = reference.velocities.copy()
        accelerations = reference.accelerations.copy()
        virtual[:, relieved] = landing[relieved]
        positions[:, relieved] = landing[relieved]
        velocities[:, relieved] = 0.0
        accelerations[:, relieved] = 0.0
        for index, motion in self._motions():
            p, v, a = motion.state(times)
            virtual[:, index] = p[:, :2]
            positions[:, index] = p[:, :2]
            velocities[:, index] = v[:, :2]
            accelerations[:, index] = a[:, :2]
        return virtual, Reference(positions, velocities, accelerations)

    def overlay_positions(self, times: np.ndarray, virtual: np.ndarray) -> np.ndarray:
        """`overlay` of the virtual positions alone (T, N, 2)."""
        if not self.reshaped:
            return virtual
        virtual = virtual.copy()
        for index, motion in self._motions():
            virtual[:, index] = motion.state(times)[0][:, :2]
        return virtual

    def _motions(self) -> list[tuple[int, Motion]]:
        """(UAV index, motion) of the active relief: the relieved UAV's, the gap's."""
        if self.active is None:
            return []
        plan = self.active.plan
        return [(self.active.index, plan.relieved)] + [
            (uav - 1, motion) for uav, motion in plan.moves
        ]

    def heights(self, t: float) -> np.ndarray:
        """(N, 3): height above the mission altitude, its rate and acceleration, at `t` (the
        relieved UAV of the active relief in its lane; 0 for the others)."""
        out = np.zeros((self.size, 3))
        if self.active is not None:
            p, v, a = self.active.plan.relieved.state(np.array(t, dtype=float))
            out[self.active.index] = (p[2], v[2], a[2])
        return out

    def _holders(self) -> np.ndarray:
        """(m,) the UAV (1-based) on each point (visiting order)."""
        held = np.where(np.isfinite(self.stations), self.stations, np.inf)
        gaps = np.abs(held[None, :] - self.point_distances[:, None])
        return np.argmin(gaps, axis=1) + 1
