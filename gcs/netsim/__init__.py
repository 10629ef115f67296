"""Evaluate a flown mission on a real network simulator, ns-3 (docs/netsim.md).

`gcs.netsim.scenario` turns a flight (a recording of `gcs mission run`, or a fast run) into a
`NetScenario`: 10 Hz trajectories, base stations, ground users, the leaders' speed requests.
`gcs.netsim.ns3.run_network` flies it in ns-3 (802.11b ad hoc, AODV or OLSR, UDP data and the
speed-change relays) and returns a `NetResult`. Neither needs ns-3 to be imported: ns-3 (the
optional `ns3` extra) is imported inside `run_network` only.
"""

from gcs.netsim.scenario import (
    NetScenario,
    SpeedRequest,
    scenario_from_fast_run,
    scenario_from_recording,
)

__all__ = [
    "NetScenario",
    "SpeedRequest",
    "scenario_from_fast_run",
    "scenario_from_recording",
]
