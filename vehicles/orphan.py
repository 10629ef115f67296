"""``vehicles sim --exit-when-orphaned``: a vehicle process never outlives its ground station.

A ground station that starts its own simulated vehicles (``gcs mission run``) passes this flag.
If the ground station dies without stopping them (SIGKILL, a crash), the vehicles behave as
real UAVs would: their failsafes take over (no setpoint: hold; no GCS heartbeat: hold, then
land; landed: disarm). Once the process notices it is orphaned (its parent process changed,
Linux re-parents orphans) AND every vehicle it hosts is disarmed on the ground, it exits
(status 0), so nothing is left running. A vehicle still flying keeps its process alive until
it has landed.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Sequence
from typing import Protocol

log = logging.getLogger(__name__)

#: The parent is looked at no more often than this (wall seconds).
CHECK_PERIOD_S = 0.2


class _Vehicle(Protocol):
    armed: bool


class OrphanExit:
    """``should_stop`` part: True once the parent is gone and every vehicle is disarmed."""

    def __init__(
        self,
        vehicles: Sequence[_Vehicle],
        parent_pid: int | None = None,
        getppid: Callable[[], int] = os.getppid,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.vehicles = vehicles
        self.parent_pid = getppid() if parent_pid is None else parent_pid
        self._getppid = getppid
        self._monotonic = monotonic
        self._next_check = -float("inf")
        self.orphaned = False

    def __call__(self) -> bool:
        now = self._monotonic()
        if now < self._next_check:
            return False
        self._next_check = now + CHECK_PERIOD_S
        if not self.orphaned and self._getppid() != self.parent_pid:
            self.orphaned = True
            log.warning("ground station (pid %d) gone: exiting once landed", self.parent_pid)
        if self.orphaned and not any(vehicle.armed for vehicle in self.vehicles):
            log.warning("orphaned and every vehicle disarmed on the ground: exiting")
            return True
        return False
