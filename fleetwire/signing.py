"""MAVLink 2 signing as both ends of the fleet's links do it (pymavlink's signing): the fleet key
file, the signing timestamp, and the signature checked before the timestamp is recorded.

The key file. A text file holding a passphrase on its first line; the 32-byte signing key is
the SHA-256 of that passphrase, exactly what MAVProxy's `signing setup PASSPHRASE` derives, so
the same file provisions ArduPilot or PX4 SITL through MAVProxy. A usable key file is a regular
file only its owner can access, whose passphrase has at least `MIN_PASSPHRASE_CHARS`
characters; `create_key_file` writes one with 64 random hex digits (256 bits).

The timestamp (`ClockedSigning`). pymavlink starts it at the clock and adds 1 (10 us) per frame
sent, so a busy link falls behind the clock; MAVLink 2 asks a system with a clock to use it, so
the timestamp read for each frame is max(the counter, the clock).

The check (`SignatureCheck`). pymavlink 2.4.50's `check_signature` records a stream's timestamp
BEFORE it compares the signature (history: ArduPilot/pymavlink#961), so one forged frame with a
future timestamp would make every later genuine frame of that stream look like a replay (the
MAVLink C library checks the signature first). Here the signature is compared first, and only
then pymavlink checks and records the timestamp. Refused frames are `REJECTION_KINDS`.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import stat
import time
import types
from collections.abc import Callable
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetline.errors import EXIT_BAD_INPUT, FleetlineError

#: MAVLink 2 signing timestamps count 10 us from 2015-01-01.
SIGNING_EPOCH = 1420070400
#: Link id of the fleet's signed streams (the ground station's and each vehicle's).
LINK_ID = 0
#: Length of a MAVLink 2 signing key.
KEY_BYTES = 32
#: A passphrase shorter than this is refused (the key is only as strong as the passphrase).
MIN_PASSPHRASE_CHARS = 16
#: Kinds of refused frames.
REJECTION_KINDS = ("unsigned", "bad_signature", "replayed")
_SIGNATURE_BYTES = 6

#: Called for each refused frame: (kind, source system or None, message id or None).
OnReject = Callable[[str, int | None, int | None], None]


# --------------------------------------------------------------------------- the key file
def key_from_passphrase(passphrase: str) -> bytes:
    """The 32-byte signing key of a passphrase: SHA-256, as MAVProxy's `signing setup`."""
    return hashlib.sha256(passphrase.encode()).digest()


def check_key(key: bytes) -> None:
    """`ValueError` unless `key` can be a MAVLink 2 signing key."""
    if len(key) != KEY_BYTES:
        raise ValueError("a MAVLink 2 signing key is 32 bytes")


class KeyFileError(FleetlineError, ValueError):
    """A key file that cannot be used: `expected` says what was expected (naming the file),
    `kind` which rule failed ("unreadable", "not_regular", "not_owner_only", "passphrase")."""

    exit_status = EXIT_BAD_INPUT

    def __init__(self, path: Path, kind: str, expected: str) -> None:
        self.path = path
        self.kind = kind
        self.expected = expected
        super().__init__(f"expected {expected}")


def create_key_file(path: str | Path) -> str:
    """Create the key file `path` (owner-only, 256 random bits in hex); its passphrase.

    `OSError` if it cannot be created (`FileExistsError`: it exists already).
    """
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    passphrase = secrets.token_hex(32)
    with os.fdopen(descriptor, "w") as handle:
        handle.write(passphrase + "\n")
    return passphrase


def read_key_file(path: str | Path) -> bytes:
    """The key of an owner-only key file; `KeyFileError` if it is not one."""
    path = Path(path)
    try:
        info = path.stat()
    except OSError as error:
        raise KeyFileError(
            path, "unreadable", f"a readable key file ({error.strerror}: {path})"
        ) from None
    if not stat.S_ISREG(info.st_mode):
        raise KeyFileError(path, "not_regular", f"a regular file, got {path}")
    if info.st_mode & 0o077:
        raise KeyFileError(
            path,
            "not_owner_only",
            f"a key file only its owner can access (chmod 600 {path}), "
            f"got mode {stat.S_IMODE(info.st_mode):03o}",
        )
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        raise KeyFileError(path, "unreadable", f"a readable UTF-8 key file ({path})") from None
    lines = text.splitlines()
    passphrase = lines[0].strip() if lines else ""
    if len(passphrase) < MIN_PASSPHRASE_CHARS:
        raise KeyFileError(
            path,
            "passphrase",
            f"a passphrase of at least {MIN_PASSPHRASE_CHARS} characters on the first line of "
            f"{path}",
        )
    return key_from_passphrase(passphrase)


# --------------------------------------------------------------------------- the links
def clock_timestamp() -> int:
    """The wall clock as a MAVLink 2 signing timestamp (10 us units since 2015-01-01)."""
    return int(max(time.time() - SIGNING_EPOCH, 0.0) * 100_000)


class ClockedSigning(mavlink.MAVLinkSigning):
    """pymavlink's signing state, with a timestamp that never falls behind the wall clock.

    pymavlink starts the timestamp at the clock and adds 1 (10 us) per frame sent, so a link
    sending a few hundred frames a second signs with timestamps that fall further behind the
    clock every second; then a frame recorded earlier by someone holding the key, or any frame
    dated by the clock, would be newer than everything genuine. MAVLink 2 asks a system with a
    clock to use it: the timestamp read for each frame is max(the counter, the clock).

    `state`: a codec's signing state to take over (key, link id, callbacks, timestamp).
    """

    def __init__(self, state: mavlink.MAVLinkSigning | None = None) -> None:
        self._timestamp = 0
        super().__init__()
        if state is not None:
            self.__dict__.update({k: v for k, v in vars(state).items() if k != "timestamp"})
            self.timestamp = state.timestamp

    @property
    def timestamp(self) -> int:
        return max(self._timestamp, clock_timestamp())

    @timestamp.setter
    def timestamp(self, value: int) -> None:
        self._timestamp = int(value)


def message_id(msgbuf: bytes) -> int | None:
    """Message id from a MAVLink 2 header (bytes 7-9), None if it is not one."""
    if len(msgbuf) >= 10 and msgbuf[0] == mavlink.PROTOCOL_MARKER_V2:
        return msgbuf[7] | msgbuf[8] << 8 | msgbuf[9] << 16
    return None


class SignatureCheck:
    """Installed on one pymavlink `MAVLink` codec: the signature is compared before pymavlink
    checks and records the stream's timestamp, and every refusal is reported to `on_reject`.

    pymavlink calls `allow_unsigned_callback` for unsigned frames and again after a failed
    signature check; `unsigned` (the codec's callback) tells the two apart and never accepts.
    """

    def __init__(self, mav, on_reject: OnReject) -> None:
        self.mav = mav
        self.on_reject = on_reject
        # pymavlink's own method, bound (even if an earlier check shadows it on the instance)
        self._pymavlink_check = types.MethodType(type(mav).check_signature, mav)
        self._failed = False
        mav.check_signature = self.check  # the instance attribute shadows the method

    def check(self, msgbuf: bytearray, source_system: int, source_component: int) -> bool:
        key = self.mav.signing.secret_key
        digest = hashlib.sha256(key + bytes(msgbuf[:-_SIGNATURE_BYTES])).digest()
        if not hmac.compare_digest(digest[:_SIGNATURE_BYTES], bytes(msgbuf[-_SIGNATURE_BYTES:])):
            self._refuse("bad_signature", source_system, message_id(msgbuf))
            return False
        if self._pymavlink_check(msgbuf, source_system, source_component):
            return True
        self._refuse("replayed", source_system, message_id(msgbuf))
        return False

    def unsigned(self, mav, msg_id: int) -> bool:
        if self._failed:  # pymavlink asks again after a failed check: already counted
            self._failed = False
            return False
        self.on_reject("unsigned", None, msg_id)
        return False

    def _refuse(self, kind: str, source_system: int, msg_id: int | None) -> None:
        self._failed = True
        self.on_reject(kind, source_system, msg_id)
