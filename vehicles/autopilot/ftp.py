"""MAVLink FTP (FILE_TRANSFER_PROTOCOL), which the simulated vehicle does not implement: every
request is answered at once, so that a tool that tries it first (MAVProxy and MAVSDK download
ArduPilot's parameters as ``@PARAM/param.pck`` over FTP) falls back to PARAM_REQUEST_LIST
without waiting for its FTP timeouts. AUTOPILOT_VERSION does not announce
MAV_PROTOCOL_CAPABILITY_FTP.

The answer is the MAVLink FTP reply to the request (same session, sequence number + 1,
``req_opcode`` = the request's opcode): ResetSessions is acknowledged (there are none); the
other requests get a NAK whose error says why: no file or directory exists (OpenFileRO,
OpenFileWO, ListDirectory, CalcFileCRC32, RemoveFile, RemoveDirectory, Rename, TruncateFile:
``FileNotFound``), no session was ever opened (TerminateSession, ReadFile, BurstReadFile,
WriteFile: ``InvalidSession``), nothing can be created (CreateFile, CreateDirectory:
``Fail``), or the opcode is not FTP's (``UnknownCommand``).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicles.autopilot.types import Stamp

if TYPE_CHECKING:
    from vehicles.autopilot.core import Autopilot

#: The request header: seq_number, session, opcode, size, req_opcode, burst_complete, padding,
#: offset (then up to 239 bytes of data).
_HEADER = struct.Struct("<HBBBBBBI")
PAYLOAD_BYTES = 251

# opcodes (MAVLink FTP)
TERMINATE_SESSION = 1
RESET_SESSIONS = 2
LIST_DIRECTORY = 3
OPEN_FILE_RO = 4
READ_FILE = 5
CREATE_FILE = 6
WRITE_FILE = 7
REMOVE_FILE = 8
CREATE_DIRECTORY = 9
REMOVE_DIRECTORY = 10
OPEN_FILE_WO = 11
TRUNCATE_FILE = 12
RENAME = 13
CALC_FILE_CRC32 = 14
BURST_READ_FILE = 15
ACK = 128
NAK = 129

# NAK errors (MAVLink FTP)
ERR_FAIL = 1
ERR_INVALID_SESSION = 4
ERR_UNKNOWN_COMMAND = 7
ERR_FILE_NOT_FOUND = 10

#: The NAK error of each request (ResetSessions is acknowledged).
NAK_ERRORS = {
    TERMINATE_SESSION: ERR_INVALID_SESSION,
    READ_FILE: ERR_INVALID_SESSION,
    BURST_READ_FILE: ERR_INVALID_SESSION,
    WRITE_FILE: ERR_INVALID_SESSION,
    LIST_DIRECTORY: ERR_FILE_NOT_FOUND,
    OPEN_FILE_RO: ERR_FILE_NOT_FOUND,
    OPEN_FILE_WO: ERR_FILE_NOT_FOUND,
    REMOVE_FILE: ERR_FILE_NOT_FOUND,
    REMOVE_DIRECTORY: ERR_FILE_NOT_FOUND,
    TRUNCATE_FILE: ERR_FILE_NOT_FOUND,
    RENAME: ERR_FILE_NOT_FOUND,
    CALC_FILE_CRC32: ERR_FILE_NOT_FOUND,
    CREATE_FILE: ERR_FAIL,
    CREATE_DIRECTORY: ERR_FAIL,
}


@dataclass(frozen=True)
class FtpOp:
    """One MAVLink FTP header (the data bytes after it are not needed here)."""

    seq: int
    session: int
    opcode: int
    size: int = 0
    req_opcode: int = 0
    offset: int = 0

    @classmethod
    def unpack(cls, payload: bytes | list[int]) -> FtpOp:
        seq, session, opcode, size, req_opcode, _, _, offset = _HEADER.unpack_from(
            bytes(payload[: _HEADER.size])
        )
        return cls(seq, session, opcode, size, req_opcode, offset)


def reply(request: FtpOp) -> tuple[FtpOp, bytes]:
    """The answer to ``request``: the reply header and its data (the NAK's error code)."""
    seq = (request.seq + 1) & 0xFFFF
    if request.opcode == RESET_SESSIONS:
        return FtpOp(seq, request.session, ACK, 0, request.opcode), b""
    error = NAK_ERRORS.get(request.opcode, ERR_UNKNOWN_COMMAND)
    return FtpOp(seq, request.session, NAK, 1, request.opcode), bytes([error])


def pack(op: FtpOp, data: bytes) -> list[int]:
    """FILE_TRANSFER_PROTOCOL's payload (251 bytes) for ``op`` and its data."""
    header = _HEADER.pack(op.seq, op.session, op.opcode, op.size, op.req_opcode, 0, 0, op.offset)
    return list((header + data).ljust(PAYLOAD_BYTES, b"\x00"))


def on_file_transfer_protocol(ap: Autopilot, msg: mavlink.MAVLink_message, stamp: Stamp) -> None:
    """Answer a MAVLink FTP request at once (see the module docstring)."""
    request = FtpOp.unpack(msg.payload)
    if request.opcode in (ACK, NAK):
        return  # a reply, not a request
    op, data = reply(request)
    ap.send(
        mavlink.MAVLink_file_transfer_protocol_message(
            0, msg.get_srcSystem(), msg.get_srcComponent(), pack(op, data)
        )
    )
