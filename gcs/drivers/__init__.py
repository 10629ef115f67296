"""Driver registry: the ONE place that maps `fleet.backend` to a driver family (docs/outputs.md:
the GCS picks its driver from `fleet.backend`, never from the heartbeat).

A family lives in its own module `gcs/drivers/<backend>.py` with a `Driver` subclass (see
`gcs/drivers/base.py` for what it implements). Adding an autopilot is one line in `FAMILIES`.
"""

from __future__ import annotations

import importlib

from fleetline.errors import EXIT_BAD_INPUT, FleetlineError
from gcs.drivers.base import Driver

#: backend name -> "module:DriverClass"
FAMILIES: dict[str, str] = {
    "sim": "gcs.drivers.sim:SimDriver",
    "ardupilot": "gcs.drivers.ardupilot:ArduPilotDriver",
    "px4": "gcs.drivers.px4:PX4Driver",
}


class BackendUnavailable(FleetlineError, LookupError):
    """The backend is known but its driver is not installed (or not written yet)."""

    exit_status = EXIT_BAD_INPUT


def driver_class(backend: str) -> type[Driver]:
    """The driver class of `backend` (a `fleet.backend` value)."""
    try:
        target = FAMILIES[backend]
    except KeyError:
        raise BackendUnavailable(
            f"unknown backend {backend!r} (one of {', '.join(FAMILIES)})"
        ) from None
    module_name, class_name = target.split(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        if error.name != module_name:
            raise
        raise BackendUnavailable(
            f"backend {backend!r}: driver {module_name} is not available"
        ) from None
    return getattr(module, class_name)
