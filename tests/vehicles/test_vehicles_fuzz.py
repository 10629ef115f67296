"""Fuzz: 100,000+ random and mutated datagrams at a flying vehicle over UDP; afterwards it
still answers, flies and follows a setpoint."""

from __future__ import annotations

import random
import socket
import struct
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.testing import GroundStation, VehicleProcess, local_of

# Every test here starts a process or flies over UDP.
pytestmark = pytest.mark.slow

SPEEDUP = 4.0
DATAGRAMS = 100_000
BATCH = 2_000
COMMANDS = [11, 16, 20, 21, 22, 176, 178, 192, 400, 510, 511, 512, 520, 12345, 0, 65535]


def _float(rng: random.Random) -> float:
    return rng.choice(
        [
            0.0,
            -1.0,
            1.0,
            float("nan"),
            float("inf"),
            -float("inf"),
            1e38,
            -1e38,
            4.0,
            9.0,
            17.0,
            2989.0,
            21196.0,
        ]
        + [rng.uniform(-1e4, 1e4)] * 4
    )


def _message(rng: random.Random, vehicle: int) -> mavlink.MAVLink_message:
    """A structurally valid message with hostile field values and sometimes the wrong target."""
    target = rng.choice([vehicle] * 6 + [0, 2, 255, rng.randrange(256)])
    component = rng.choice([1, 1, 0, 100, 190])
    floats = [_float(rng) for _ in range(11)]
    ints = [rng.randrange(-(2**31), 2**31) for _ in range(2)]
    kind = rng.randrange(12)
    if kind == 0:
        return mavlink.MAVLink_command_long_message(
            target, component, rng.choice(COMMANDS), 0, *floats[:7]
        )
    if kind == 1:
        return mavlink.MAVLink_command_int_message(
            target,
            component,
            rng.randrange(256),
            rng.choice(COMMANDS),
            0,
            0,
            *floats[:4],
            *ints,
            floats[4],
        )
    if kind == 2:
        return mavlink.MAVLink_set_position_target_local_ned_message(
            0, target, component, rng.randrange(256), rng.randrange(65536), *floats
        )
    if kind == 3:
        return mavlink.MAVLink_set_position_target_global_int_message(
            0, target, component, rng.randrange(256), rng.randrange(65536), *ints, *floats[:9]
        )
    if kind == 4:
        return mavlink.MAVLink_set_mode_message(target, rng.randrange(256), rng.randrange(2**32))
    if kind == 5:
        return mavlink.MAVLink_heartbeat_message(rng.randrange(256), rng.randrange(256), 0, 0, 0, 3)
    if kind == 6:
        return mavlink.MAVLink_param_set_message(target, component, b"FS_GCS_TIMEOUT", floats[0], 9)
    if kind == 7:
        return mavlink.MAVLink_mission_item_int_message(
            target,
            component,
            0,
            rng.randrange(256),
            16,
            rng.choice([0, 2, 3]),
            0,
            *floats[:4],
            *ints,
            floats[4],
        )
    if kind == 8:
        return mavlink.MAVLink_named_value_int_message(0, rng.choice([b"MSN_TIME", b"X"]), ints[0])
    if kind == 9:
        return mavlink.MAVLink_command_ack_message(
            178, rng.randrange(256), 0, ints[0], target, component
        )
    if kind == 10:
        return mavlink.MAVLink_param_request_read_message(
            target, component, b"\xff\xfe", rng.randrange(-1, 40)
        )
    return mavlink.MAVLink_statustext_message(
        rng.randrange(256), bytes(rng.randrange(256) for _ in range(50))
    )


def _mutate(rng: random.Random, frame: bytes) -> bytes:
    """Bit flips, truncation, extension, splicing, garbage and empty datagrams."""
    choice = rng.randrange(8)
    data = bytearray(frame)
    if choice == 0:
        for _ in range(rng.randint(1, 8)):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    elif choice == 1:
        data = data[: rng.randrange(len(data))]
    elif choice == 2:
        data += bytes(rng.randrange(256) for _ in range(rng.randint(1, 40)))
    elif choice == 3:
        data = bytearray(
            bytes([0xFD]) + bytes(rng.randrange(256) for _ in range(rng.randint(0, 300)))
        )
    elif choice == 4:
        data[1] = rng.randrange(256)  # declared length
    elif choice == 5:
        data[7:10] = struct.pack("<I", rng.randrange(2**24))[:3]  # message id, CRC now wrong
    elif choice == 6:
        data = bytearray(bytes(rng.randrange(256) for _ in range(rng.randint(0, 64))))
    else:
        data = data + data[: rng.randrange(len(data))]  # a frame and a piece of another
    return bytes(data)


def test_a_flying_vehicle_survives_100000_hostile_datagrams_and_still_flies():
    rng = random.Random(20240611)
    with VehicleProcess(
        count=1, speedup=SPEEDUP, args=["--seed", "9", "--gcs-timeout", "1000"]
    ) as process:
        gcs = GroundStation(process.port(), speedup=SPEEDUP)
        gcs.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        gcs.connect()
        gcs.take_off(10.0)
        gcs_codec = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        codecs = [
            gcs_codec,
            gcs_codec,
            gcs_codec,
            mavlink.MAVLink(None, srcSystem=7),
            mavlink.MAVLink(None, srcSystem=1),
        ]
        sent = 0
        marker = 0
        while sent < DATAGRAMS:
            for _ in range(BATCH):
                message = _message(rng, vehicle=1)
                codec = rng.choice(codecs)
                frame = message.pack(codec, force_mavlink1=rng.random() < 0.1)
                datagram = frame if rng.random() < 0.25 else _mutate(rng, frame)
                gcs.conn.port.sendto(datagram, gcs.conn.destination_addr)
                sent += 1
            marker += 1
            _wait_until_read(gcs, marker)
        assert process.process.poll() is None, "the vehicle process died"
        # it still answers; it counted the garbage; then it flies again and follows a setpoint
        assert gcs.command(12345).result == mavlink.MAV_RESULT_UNSUPPORTED
        for msg_id in (0, 1, 33, 32, 245, 108):
            assert (
                gcs.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 0).result
                == mavlink.MAV_RESULT_ACCEPTED
            )
        gcs.latest.pop("SYS_STATUS", None)
        status = gcs.wait_for(lambda: gcs.latest.get("SYS_STATUS"), 10.0, "SYS_STATUS")
        assert status.errors_comm > DATAGRAMS // 4
        _fly_again(gcs)
        # a setpoint 20 m from wherever the fuzz left it (in GLOBAL_INT, relative altitude)
        home = gcs.home()
        here = gcs.latest["GLOBAL_POSITION_INT"]
        start = local_of(
            home, here.lat * 1e-7, here.lon * 1e-7, home[2] + max(here.relative_alt / 1000.0, 8.0)
        )
        target = start + np.array([16.0, -12.0, 0.0])

        def reached() -> bool:
            gcs.send_position_target(home, target, np.zeros(3))
            now = gcs.latest["GLOBAL_POSITION_INT"]
            position = local_of(
                home, now.lat * 1e-7, now.lon * 1e-7, home[2] + now.relative_alt / 1000.0
            )
            return bool(np.linalg.norm(position - target) < 1.5)

        gcs.wait_for(reached, 30.0, f"the vehicle to reach {target} from {start}")
        gcs.close()
        code, stderr = process.stop()
        assert code == 0 and "Traceback" not in stderr, stderr


def _wait_until_read(gcs: GroundStation, marker: int) -> None:
    """Flow control: TIMESYNC is answered in order, so its echo proves the batch was read
    (the echo itself may be lost in our full receive buffer: ask again every 0.5 s)."""
    asked = time.monotonic()
    gcs.mav.timesync_send(0, marker)

    def echoed() -> bool:
        nonlocal asked
        if getattr(gcs.latest.get("TIMESYNC"), "ts1", None) == marker:
            return True
        if time.monotonic() - asked > 0.5:
            gcs.mav.timesync_send(0, marker)
            asked = time.monotonic()
        return False

    gcs.wait_for(echoed, 30.0, "the TIMESYNC echo")


def _fly_again(gcs: GroundStation) -> None:
    """Whatever the fuzz left (any mode, armed or not, falling), get back to GUIDED flight."""

    def state() -> tuple[bool, int]:
        return gcs.heartbeat_is(armed=True), gcs.latest["EXTENDED_SYS_STATE"].landed_state

    for _ in range(6):
        gcs.set_mode(4)
        armed, landed_state = state()
        if armed and landed_state == mavlink.MAV_LANDED_STATE_IN_AIR:
            return
        if landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND:
            gcs.arm()
            gcs.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 12.0)
        gcs.run_for(8.0)
    raise AssertionError(f"could not fly again: armed, landed state = {state()}")
