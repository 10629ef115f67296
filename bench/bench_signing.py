"""MAVLink 2 signing: what it costs per frame, and what a flood of forged frames costs.

Packs a setpoint (the ground station's hot path) and parses a SIM_STATE (the vehicles'
telemetry) with pymavlink, unsigned and signed (the ground station's `FleetSigning`, the
vehicles' `VehicleSigning`, signature checked before the timestamp), and parses frames signed
with another key, which are refused. Microseconds per frame, best of five runs of 2000.
"""

from __future__ import annotations

import random
import time

from rich.console import Console
from rich.table import Table

from gcs.transport.signing import ClockedSigning
from gcs.transport.signing import mavlink as gcs_mavlink
from vehicles.link import make_codec
from vehicles.signing import VehicleSigning

FRAMES = 2000
REPEATS = 5


def _best(run) -> float:
    best = float("inf")
    for _ in range(REPEATS):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best / FRAMES * 1e6


def _setpoint(mav):
    return mav.set_position_target_global_int_encode(
        0, 1, 1, 6, 3072, 457640000, 48357000, 20.0, 1, 2, 0, 0.1, 0.1, 0, 0, 0
    )


def main() -> None:
    key = random.Random(3).randbytes(32)
    other = random.Random(4).randbytes(32)
    plain = gcs_mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    signed = gcs_mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    state = ClockedSigning(gcs_mavlink.MAVLinkSigning())
    state.secret_key, state.sign_outgoing = key, True
    signed.signing = state

    def pack(mav):
        return lambda: [_setpoint(mav).pack(mav) for _ in range(FRAMES)]

    def frames(mav_key: bytes | None) -> list[bytes]:
        mav = gcs_mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        if mav_key is not None:
            clocked = ClockedSigning(gcs_mavlink.MAVLinkSigning())
            clocked.secret_key, clocked.sign_outgoing = mav_key, True
            mav.signing = clocked
        message = mav.sim_state_encode(*[0.0] * 21, 457640000, 48357000)
        return [bytes(message.pack(mav)) for _ in range(FRAMES)]

    def parse(data: list[bytes], receiver_key: bytes | None):
        def run():
            codec = make_codec(9)
            VehicleSigning(codec, receiver_key)
            for frame in data:
                codec.parse_buffer(frame)

        return run

    rows = [
        ("pack a setpoint, unsigned", _best(pack(plain))),
        ("pack a setpoint, signed", _best(pack(signed))),
        ("parse SIM_STATE, unsigned", _best(parse(frames(None), None))),
        ("parse SIM_STATE, signed, accepted", _best(parse(frames(key), key))),
        ("parse SIM_STATE, other key, refused", _best(parse(frames(other), key))),
        ("parse SIM_STATE, unsigned, refused", _best(parse(frames(None), key))),
    ]
    table = Table(title="MAVLink 2 signing (pymavlink), per frame")
    table.add_column("operation")
    table.add_column("us / frame", justify="right")
    for name, micros in rows:
        table.add_row(name, f"{micros:.1f}")
    Console().print(table)


if __name__ == "__main__":
    main()
