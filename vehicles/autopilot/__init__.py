"""ArduCopter-compatible MAVLink behaviour of one simulated vehicle (no sockets, no clocks).

The sim hands each decoded message to :meth:`Autopilot.handle` and calls :meth:`Autopilot.tick`
at the control rate with the current :class:`Stamp` (simulated and wall-clock seconds); the
autopilot writes references into the shared :class:`~vehicles.dynamics.FleetDynamics` and
appends the messages to send to ``outbox``.

Identity and modes follow ArduCopter (``tests/sitl/README.md``, ArduPilot's source where
the transcripts are silent): HEARTBEAT type 2 (quadrotor), autopilot 3 (ArduPilotMega),
custom_mode = Copter mode number (STABILIZE 0, AUTO 3, GUIDED 4, LOITER 5, RTL 6, LAND 9,
BRAKE 17); ``MAV_CMD_DO_SET_MODE`` is acknowledged, ``SET_MODE`` is not; an unknown mode gets
STATUSTEXT ``No such mode N``; it boots in STABILIZE and arms in STABILIZE, GUIDED and LOITER
(elsewhere ``Arm: Mode not armable`` and ACK FAILED), disarming by itself after DISARM_DELAY on
the ground; ``MAV_CMD_NAV_TAKEOFF`` needs GUIDED, armed and landed; landing ends in an automatic
disarm; position targets outside GUIDED are ignored silently; a position-only target never
times out, velocity and acceleration targets stop after GUID_TIMEOUT; the mission protocol
and AUTO (``missions``, ``auto``); MAVFTP is refused at once (``ftp``); unknown commands are
UNSUPPORTED. Differences from ArduCopter, on purpose: refusals always carry a STATUSTEXT
reason; a stream of position + velocity targets (the fleetline ground station's) that stops for
``setpoint_timeout_s`` (GUID_TIMEOUT, 1 s by default here, 3 s in ArduCopter) makes the vehicle
brake (at WPNAV_ACCEL, as ArduCopter's guided mode) and hold at its stopping point rather than
at the last target, saying so (it stays in GUIDED and follows again when setpoints resume);
losing the GCS (no valid message from its system id) makes it hold (BRAKE), then LAND.

Timeouts count simulated time and never fire before a wall-clock floor (``wall_floor_s``), so a
busy machine at a high speedup does not trip them. See :mod:`vehicles.fleet_speed` for the
mission clock, speed changes and leader requests.

One module per job: ``core`` (the :class:`Autopilot` facade: state, routing, tick, telemetry),
``status`` (the frozen :class:`AutopilotStatus` the telemetry reads), ``modes``, ``failsafes``,
``commands``, ``setpoints``, ``speed``, ``parameters``, ``missions`` (the mission protocol),
``auto`` (AUTO flying the mission), ``ftp`` (MAVFTP refused), ``config``, ``types``.
"""

from vehicles.autopilot.commands import FORCE_ARM_MAGIC, FORCE_DISARM_MAGIC
from vehicles.autopilot.config import AutopilotConfig, FailsafeConfig
from vehicles.autopilot.core import Autopilot
from vehicles.autopilot.status import AutopilotStatus, BatteryState
from vehicles.autopilot.types import ARMABLE_MODES, AUTOPILOT_COMPONENT, Guided, Mode, Stamp

__all__ = [
    "ARMABLE_MODES",
    "AUTOPILOT_COMPONENT",
    "FORCE_ARM_MAGIC",
    "FORCE_DISARM_MAGIC",
    "Autopilot",
    "AutopilotConfig",
    "AutopilotStatus",
    "BatteryState",
    "FailsafeConfig",
    "Guided",
    "Mode",
    "Stamp",
]
