"""MAVLink 2 signing: the fleet key file, the ground station's links and the simulated vehicles
(real UDP on loopback, real `vehicles sim` processes), provisioning by SETUP_SIGNING, and a
vehicle process that never outlives its ground station."""

from __future__ import annotations

import hashlib
import random
import re
import socket
import stat
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.modes import COPTER_MODE
from fleetwire.signing import ClockedSigning, clock_timestamp
from gcs.errors import InputError
from gcs.transport.link import Link
from gcs.transport.signing import EphemeralKey, FleetSigning, RejectionLog, load_or_create_key
from tests.attacker import codec, timestamp_now
from tests.flying import alive, environment
from tests.links import drain
from vehicles.link import make_codec
from vehicles.signing import KeyFileError, VehicleSigning, read_key_file
from vehicles.testing import GroundStation, VehicleProcess

SPEEDUP = 4.0
RNG = random.Random(8)  # keys of the tests and of their attackers
GUIDED, LAND = COPTER_MODE["GUIDED"], COPTER_MODE["LAND"]


# --------------------------------------------------------------------------- the key file
def test_a_missing_key_file_is_created_owner_only_and_read_back(tmp_path: Path):
    path = tmp_path / "fleet.key"
    created = load_or_create_key(path)
    assert created.created and path.exists()
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    passphrase = path.read_text().strip()
    assert len(passphrase) == 64 and int(passphrase, 16) >= 0  # 256 random bits, in hex
    # the key is MAVProxy's `signing setup PASSPHRASE`: SHA-256 of the passphrase
    assert created.key == hashlib.sha256(passphrase.encode()).digest()
    again = load_or_create_key(path)
    assert not again.created and again.key == created.key
    assert read_key_file(path) == created.key  # the vehicles read the same file the same way
    assert load_or_create_key(tmp_path / "other.key").key != created.key


@pytest.mark.parametrize(
    ("case", "expected"),
    [
        ("group-readable", "chmod 600"),
        ("short", "at least 16 characters"),
        ("empty", "at least 16 characters"),
        ("no-folder", "existing folder"),
        ("folder", "regular file"),
    ],
)
def test_a_bad_key_file_is_one_line_naming_the_key(tmp_path: Path, case: str, expected: str):
    path = tmp_path / "fleet.key"
    if case == "no-folder":
        path = tmp_path / "missing" / "fleet.key"
    elif case == "folder":
        path.mkdir()
    else:
        text = {"group-readable": "a" * 64, "short": "secret", "empty": ""}[case]
        path.write_text(text + "\n")
        path.chmod(0o640 if case == "group-readable" else 0o600)
    with pytest.raises(InputError) as refused:
        load_or_create_key(path, source=tmp_path / "m.yaml")
    message = str(refused.value)
    assert "\n" not in message and "m.yaml: signing.key_file: expected" in message
    assert expected in message
    if case != "no-folder":
        with pytest.raises(KeyFileError, match=expected.split()[0]):
            read_key_file(path)


def test_the_run_key_of_a_simulated_fleet_lives_in_a_private_folder_removed_at_the_end():
    ephemeral = EphemeralKey()
    path = ephemeral.fleet_key.path
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert read_key_file(path) == ephemeral.fleet_key.key
    ephemeral.close()
    assert not path.parent.exists()


# --------------------------------------------------------------------------- links
def signed_link(key: bytes, events: list) -> tuple[Link, socket.socket, FleetSigning]:
    """A ground-station link to UAV 1, signed with `key`, and the vehicle's end of it."""
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    link = Link(f"udpout:127.0.0.1:{vehicle.getsockname()[1]}", system_id=1)
    signing = FleetSigning(key, RejectionLog(lambda *args, **kw: events.append(args)))
    signing.apply(link, 1)
    return link, vehicle, signing


@pytest.mark.slow
def test_the_ground_station_signs_and_refuses_unsigned_forged_and_replayed_telemetry():
    key = RNG.randbytes(32)
    events: list = []
    link, vehicle, signing = signed_link(key, events)
    try:
        link.send(link.mav.heartbeat_encode(6, 8, 0, 0, 4), time.monotonic())
        data, gcs_address = vehicle.recvfrom(2048)
        assert data[0] == 0xFD and data[2] & mavlink.MAVLINK_IFLAG_SIGNED  # signed
        uav = codec(1, 1, key, timestamp_now())
        genuine = [uav.heartbeat_encode(2, 3, 217, GUIDED, 4).pack(uav) for _ in range(3)]
        forged = {
            "unsigned": codec(1, 1, None),
            "bad_signature": codec(1, 1, RNG.randbytes(32), timestamp_now()),
            # a forged frame from far in the future, before the genuine ones: pymavlink alone
            # would record its timestamp and refuse everything genuine after it
            "future": codec(1, 1, RNG.randbytes(32), timestamp_now(3600)),
        }
        for mav in forged.values():
            vehicle.sendto(mav.heartbeat_encode(2, 3, 81, LAND, 5).pack(mav), gcs_address)
        vehicle.sendto(genuine[1], gcs_address)
        (accepted,) = drain(link, lambda got: got)
        assert accepted.custom_mode == GUIDED and accepted.get_signed()
        vehicle.sendto(genuine[0], gcs_address)  # older than the one accepted: a replay
        vehicle.sendto(genuine[1], gcs_address)  # the same again: a replay
        vehicle.sendto(genuine[2], gcs_address)
        (last,) = drain(link, lambda got: got)
        assert last.get_msgbuf() == genuine[2]
        assert drain(link, lambda got: got, seconds=0.3) == []
        assert link.counters.received == 2  # refused frames never make the link alive
        assert signing.totals() == {"1": {"unsigned": 1, "bad_signature": 2, "replayed": 2}}
        assert events and "UAV 1 link: refused" in events[0][1]
    finally:
        link.close()
        vehicle.close()


def test_plain_pymavlink_would_let_one_forged_frame_lock_the_real_sender_out():
    """Why `SignatureCheck` exists (pymavlink 2.4.50; if this fails, pymavlink checks the
    signature first now and the guard may go)."""
    key = RNG.randbytes(32)
    receiver = mavlink.MAVLink(None)
    receiver.robust_parsing = True
    receiver.signing.secret_key = key
    forger = codec(1, 1, RNG.randbytes(32), timestamp_now(3600))
    genuine = codec(1, 1, key, timestamp_now())
    receiver.parse_buffer(forger.heartbeat_encode(2, 3, 0, 0, 4).pack(forger))
    (message,) = receiver.parse_buffer(genuine.heartbeat_encode(2, 3, 0, 0, 4).pack(genuine))
    assert message.get_type() == "BAD_DATA"  # the genuine frame is refused as a replay


# --------------------------------------------------------------------------- vehicles
def refusals(station: GroundStation, since: int = 0) -> Counter:
    """Refused frames the vehicle reported in its STATUSTEXTs."""
    total: Counter = Counter()
    for text in station.texts[since:]:
        found = re.fullmatch(r"Signing: refused (\d+) unsigned, (\d+) bad, (\d+) old", text.text)
        if found:
            total.update(unsigned=int(found[1]), bad=int(found[2]), old=int(found[3]))
    return +total


def key_file(folder: Path) -> Path:
    path = folder / "fleet.key"
    load_or_create_key(path)
    return path


def ground_station(port: int, key: bytes | None, sysid: int = 255) -> GroundStation:
    station = GroundStation(port, speedup=SPEEDUP, sysid=sysid)
    if key is not None:
        station.conn.setup_signing(key, sign_outgoing=True, link_id=0)
    return station


@pytest.mark.slow
def test_a_vehicle_with_a_key_obeys_signed_commands_only(tmp_path: Path):
    path = key_file(tmp_path)
    key = read_key_file(path)
    with VehicleProcess(
        count=1, speedup=SPEEDUP, args=["--signing-key-file", str(path), "--gcs-timeout", "1000"]
    ) as process:
        station = ground_station(process.port(), key)
        try:
            station.connect()
            assert station.latest["HEARTBEAT"].get_signed()  # its telemetry is signed too
            station.wait_armable()
            # an attacker: unsigned, wrongly signed, with a future timestamp, SETUP_SIGNING
            attacker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            forms = [
                codec(255, 190, None),
                codec(255, 190, RNG.randbytes(32), timestamp_now()),
                codec(255, 190, RNG.randbytes(32), timestamp_now(3600)),
            ]
            for mav in forms:
                for message in (
                    mav.command_long_encode(1, 1, 176, 0, 1, LAND, 0, 0, 0, 0, 0),
                    mav.set_mode_encode(1, 1, LAND),
                    mav.setup_signing_encode(1, 1, list(RNG.randbytes(32)), timestamp_now()),
                ):
                    attacker.sendto(message.pack(mav), ("127.0.0.1", process.port()))
            attacker.close()
            expected = Counter(unsigned=3, bad=6)
            station.wait_for(lambda: refusals(station) == expected, 10, "the refusals reported")
            assert station.latest["HEARTBEAT"].custom_mode != LAND
            # the ground station, signed (after the forged future frame): obeyed
            assert station.set_mode(GUIDED) == mavlink.MAV_RESULT_ACCEPTED
            station.wait_for(lambda: station.heartbeat_is(GUIDED), 5, "GUIDED")
            # a replay of an earlier genuine command is refused
            replay = station.mav.command_long_encode(1, 1, 176, 0, 1, LAND, 0, 0, 0, 0, 0)
            old = replay.pack(station.mav)
            station.mav.heartbeat_send(6, 8, 0, 0, 4)  # a newer genuine frame
            station.conn.write(old)
            expected["old"] += 1
            station.wait_for(lambda: refusals(station) == expected, 10, "the replay refused")
            assert station.heartbeat_is(GUIDED)
        finally:
            station.close()


@pytest.mark.slow
def test_setup_signing_is_taken_only_while_keyless_and_disarmed(tmp_path: Path):
    key = RNG.randbytes(32)
    with VehicleProcess(count=2, speedup=SPEEDUP, args=["--gcs-timeout", "1000"]) as process:
        first = ground_station(process.port(0), None)
        second = GroundStation(process.port(1), speedup=SPEEDUP, target=2)
        try:
            first.connect()
            second.connect()
            # vehicle 2, armed: refused
            second.wait_armable()
            assert second.set_mode(GUIDED) == mavlink.MAV_RESULT_ACCEPTED
            assert second.arm() == mavlink.MAV_RESULT_ACCEPTED
            second.mav.setup_signing_send(2, 1, list(key), timestamp_now())
            second.wait_for(
                lambda: second.text_matching("SETUP_SIGNING refused while armed"), 10, "refusal"
            )
            # vehicle 1, disarmed and keyless: provisioned
            first.mav.setup_signing_send(1, 1, list(key), timestamp_now())
            first.wait_for(lambda: first.text_matching("Signing: key set"), 10, "the key set")
            first.conn.setup_signing(key, sign_outgoing=True, link_id=0)
            count = len(first.texts)
            first.wait_for(lambda: first.latest["HEARTBEAT"].get_signed(), 5, "signed telemetry")
            # from now on unsigned input is refused, another SETUP_SIGNING (signed) too
            unsigned = codec(255, 190, None)
            first.conn.write(unsigned.set_mode_encode(1, 1, LAND).pack(unsigned))
            first.mav.setup_signing_send(1, 1, list(RNG.randbytes(32)), timestamp_now())
            first.wait_for(
                lambda: first.text_matching("SETUP_SIGNING refused, key already set", count),
                10,
                "the second key refused",
            )
            first.wait_for(
                lambda: refusals(first, count)["unsigned"] == 1, 10, "the unsigned one refused"
            )
            assert first.set_mode(GUIDED) == mavlink.MAV_RESULT_ACCEPTED
        finally:
            first.close()
            second.close()


@pytest.mark.slow
def test_an_orphaned_vehicle_process_exits_once_every_vehicle_is_disarmed(tmp_path: Path):
    """A parent that starts `vehicles sim --exit-when-orphaned` and dies at once: the vehicles
    (disarmed on the ground) leave too; without the flag they would run forever."""
    launch = (
        "import os, subprocess, sys;"
        "p = subprocess.Popen([sys.executable, '-m', 'vehicles', 'sim', '--count', '2',"
        " '--base-port', sys.argv[1], f'--exit-when-orphaned={os.getpid()}'],"
        " start_new_session=True);"
        "print(p.pid, flush=True)"
    )
    from vehicles.testing import free_udp_ports

    port = free_udp_ports(2)
    parent = subprocess.run(
        [sys.executable, "-c", launch, str(port)],
        capture_output=True,
        text=True,
        env=environment(),
        timeout=30,
    )
    pid = int(parent.stdout.split()[0])
    deadline = time.monotonic() + 20
    while alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)  # polling a process we do not own (it is not our child)
    assert not alive(pid), "the orphaned vehicle process is still running"


def test_signing_timestamps_follow_the_clock_so_a_recorded_frame_is_always_older():
    """pymavlink counts +10 us per frame from the start: a busy link falls behind the clock,
    and a frame recorded 10 s ago would then be newer than the link's own. Not here."""
    key = RNG.randbytes(32)
    state = ClockedSigning(mavlink.MAVLinkSigning())
    state.secret_key, state.sign_outgoing = key, True
    state.timestamp = clock_timestamp() - 6_000_000  # where a counter a minute behind would be
    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    gcs.signing = state
    before = clock_timestamp()
    frame = gcs.heartbeat_encode(6, 8, 0, 0, 4).pack(gcs)
    assert int.from_bytes(frame[-12:-6], "little") >= before
    vehicle = make_codec(1)
    signing = VehicleSigning(vehicle, key)
    (accepted,) = vehicle.parse_buffer(frame)
    assert accepted.get_type() == "HEARTBEAT"
    recorded = codec(255, 190, key, timestamp_now(-10))  # a LAND "captured" 10 s ago
    (refused,) = vehicle.parse_buffer(recorded.set_mode_encode(1, 1, LAND).pack(recorded))
    assert refused.get_type() == "BAD_DATA" and signing.rejected["replayed"] == 1
