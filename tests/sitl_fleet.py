"""Fake ArduPilot / PX4 SITL fleets for the tests that fly against them: the fakes booted where
`gcs sitl launch-plan` puts each SITL instance, and the speed-up they run at."""

from __future__ import annotations

from gcs.sim.sitl import launch_plan
from tests.fakes.ardupilot import ArduCopterModel
from tests.fakes.common import FakeEndpoint, Home
from tests.fakes.px4 import Px4Model
from tests.flying import flight_speedup
from vehicles.ports import free_udp_ports

#: The fakes run in threads of this process, beside the GCS: at 10x, 0.1 s of CPU starvation
#: would be 1 s of mission time. (PX4's offboard-loss timeout stays 1 s wall.)
SPEEDUP = {"ardupilot": flight_speedup(5.0), "px4": flight_speedup(5.0)}


def fake_fleet(mission, backend: str, speedup: float):
    """Fake SITL instances where `gcs sitl launch-plan` puts them, and the URLs to fly them."""
    fakes, urls = [], []
    for v in launch_plan(mission, backend).vehicles:
        home = Home(v.latitude, v.longitude, v.altitude)
        if backend == "px4":
            port = free_udp_ports()
            model = Px4Model(home, system_id=v.system_id, speedup=speedup, seed=v.uav_id)
            fakes.append(FakeEndpoint(model, f"udpout:127.0.0.1:{port}"))
            urls.append(f"udpin:127.0.0.1:{port}")
        else:
            model = ArduCopterModel(home, system_id=v.system_id, speedup=speedup)
            fakes.append(FakeEndpoint(model, "udpin:127.0.0.1:0"))
            urls.append(f"udpout:127.0.0.1:{fakes[-1].port}")
    return fakes, urls
