"""MAVLink frames read from their headers alone, without decoding them: which message a datagram
carries (the radio medium's routing, the ground station's shedding of stale telemetry)."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink

#: Telemetry the vehicles stream periodically: of a backlog, only the newest few matter.
STREAMED = frozenset(
    {
        mavlink.MAVLINK_MSG_ID_HEARTBEAT,
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
        mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
        mavlink.MAVLINK_MSG_ID_SIM_STATE,
        mavlink.MAVLINK_MSG_ID_ATTITUDE,
        mavlink.MAVLINK_MSG_ID_VFR_HUD,
        mavlink.MAVLINK_MSG_ID_SYS_STATUS,
        mavlink.MAVLINK_MSG_ID_BATTERY_STATUS,
        mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
        mavlink.MAVLINK_MSG_ID_GPS_RAW_INT,
        mavlink.MAVLINK_MSG_ID_EKF_STATUS_REPORT,
    }
)


def frames(datagram: bytes) -> list[tuple[int, int, bytes]]:
    """(message id, system id, payload) of each MAVLink frame of a datagram (several frames
    may share one), read from the headers only (no CRC check: the frames come from our own
    vehicles; signed frames are read the same way). Stops at anything that is not a frame."""
    out = []
    index, size = 0, len(datagram)
    while index + 8 <= size:
        magic, length = datagram[index], datagram[index + 1]
        if magic == 0xFD:
            if index + 10 > size:
                break
            signed = datagram[index + 2] & 0x01
            msgid = datagram[index + 7] | datagram[index + 8] << 8 | datagram[index + 9] << 16
            sysid, start = datagram[index + 5], index + 10
            end = start + length + 2 + (13 if signed else 0)
        elif magic == 0xFE:
            msgid, sysid, start = datagram[index + 5], datagram[index + 3], index + 6
            end = start + length + 2
        else:
            break
        out.append((msgid, sysid, bytes(datagram[start : start + length])))
        index = end
    return out


def newest_telemetry(datagrams: list[bytes], keep: int) -> list[bytes]:
    """A backlog of datagrams (oldest first) without its stale telemetry: of each streamed
    message (`STREAMED`, one frame a datagram) of each system, only the newest `keep`;
    everything else (acks, texts, commands, several frames, anything unreadable) stays, in
    order."""
    seen: dict[tuple[int, int], int] = {}
    kept = []
    for data in reversed(datagrams):
        found = frames(data)
        if len(found) == 1 and found[0][0] in STREAMED:
            key = found[0][:2]  # (message id, system id)
            seen[key] = seen.get(key, 0) + 1
            if seen[key] > keep:
                continue
        kept.append(data)
    kept.reverse()
    return kept
