"""An autopilot on the bench: one `vehicles.autopilot.Autopilot` and its dynamics in-process,
driven with explicit stamps and fed real pymavlink frames as the ground station (`GCS`) packs
them and the vehicle's link decodes them."""

from __future__ import annotations

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.autopilot import Autopilot, AutopilotConfig, Guided, Mode, Stamp
from vehicles.dynamics import Disturbances, DynamicsConfig, FleetDynamics
from vehicles.link import make_codec
from vehicles.sim import DEFAULT_ORIGIN
from vehicles.telemetry import FleetSnapshot

#: The ground station (system 255, component 190) the bench's frames come from.
GCS = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)


class Bench:
    """One autopilot and its dynamics, driven with explicit stamps (simulated, wall)."""

    def __init__(self, config: AutopilotConfig | None = None, leader=()):
        self.dynamics = FleetDynamics(
            DynamicsConfig(disturbances=Disturbances().scaled(0.0)), np.zeros((1, 3)), [(0, 1)]
        )
        self.autopilot = Autopilot(
            sysid=1,
            index=0,
            count=1,
            config=config or AutopilotConfig(boot_time_s=0.0),
            dynamics=self.dynamics,
            origin=DEFAULT_ORIGIN,
            leader_requests=tuple(leader),
        )
        self.codec = make_codec(1)
        self.wall = 0.0
        self.sent: list = []
        self.heartbeats = False  # send a GCS heartbeat every simulated second while running

    def stamp(self) -> Stamp:
        return Stamp(self.dynamics.time_s, self.wall)

    def send(self, message) -> None:
        """Pack as the GCS would and decode as the vehicle's link does."""
        decoded = self.codec.parse_buffer(bytearray(message.pack(GCS)))
        for m in decoded or []:
            self.autopilot.handle(m, self.stamp())
        self.collect()

    def run(self, sim_s: float, speedup: float = 1.0) -> None:
        """Advance ``sim_s`` simulated seconds at ``speedup`` (ticks at 50 Hz)."""
        for k in range(round(sim_s / 0.02)):
            if self.heartbeats and k % 50 == 0:
                self.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
            self.dynamics.step(2)
            self.wall += 0.02 / speedup
            self.autopilot.tick(self.stamp(), FleetSnapshot(self.dynamics, DEFAULT_ORIGIN))
            self.collect()

    def collect(self) -> None:
        for message in self.autopilot.outbox:
            message.pack(self.codec)  # every message must be encodable
        self.sent.extend(self.autopilot.outbox)
        self.autopilot.outbox.clear()

    def texts(self) -> list[str]:
        return [m.text for m in self.sent if m.get_type() == "STATUSTEXT"]

    def acks(self, command: int) -> list[int]:
        return [
            m.result for m in self.sent if m.get_type() == "COMMAND_ACK" and m.command == command
        ]

    def command(self, command: int, *params: float) -> int:
        values = list(params) + [0.0] * (7 - len(params))
        self.send(mavlink.MAVLink_command_long_message(1, 1, command, 0, *values))
        return self.acks(command)[-1]

    def reset_in_flight(self, altitude: float = 10.0) -> None:
        """Put the flying vehicle back at rest at (0, 0, altitude), holding."""
        dyn = self.dynamics
        dyn.position[0] = (0.0, 0.0, altitude)
        dyn.velocity[0] = dyn.thrust_acceleration[0] = dyn.integral[0] = 0.0
        dyn.hold(0, np.array([0.0, 0.0, altitude]))
        self.autopilot.guided = Guided.HOLD
        self.sent.clear()

    def fly(self, altitude: float = 10.0) -> None:
        assert (
            self.command(mavlink.MAV_CMD_DO_SET_MODE, 1, Mode.GUIDED) == mavlink.MAV_RESULT_ACCEPTED
        )
        assert self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
        assert (
            self.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, altitude)
            == mavlink.MAV_RESULT_ACCEPTED
        )
        self.run(altitude / 2.5 + 4.0)
        assert self.autopilot.airborne() and self.autopilot.guided == Guided.HOLD

    def local_setpoint(
        self, x=0.0, y=0.0, z=-10.0, vx=0.0, vy=0.0, vz=0.0, mask=3520, frame=1, **fields
    ):
        values = dict(afx=0.0, afy=0.0, afz=0.0, yaw=0.0, yaw_rate=0.0) | fields
        self.send(
            mavlink.MAVLink_set_position_target_local_ned_message(
                0,
                1,
                1,
                frame,
                mask,
                x,
                y,
                z,
                vx,
                vy,
                vz,
                values["afx"],
                values["afy"],
                values["afz"],
                values["yaw"],
                values["yaw_rate"],
            )
        )
