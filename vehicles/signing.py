"""MAVLink 2 signing on a simulated vehicle's link (pymavlink's signing) and its provisioning.

A vehicle gets its key either when it starts (``vehicles sim --signing-key-file PATH``: a text
file whose first line is a passphrase; the 32-byte key is its SHA-256, what MAVProxy's
``signing setup PASSPHRASE`` derives, and what the ground station's key file holds), or from a
``SETUP_SIGNING`` message, accepted only while the vehicle has no key and is disarmed (as PX4
and ArduPilot do). With a key, the vehicle's codec signs everything it sends and refuses
unsigned, wrongly signed and replayed frames (a timestamp not newer than the last one of its
stream (link id, system, component), or a new stream more than a minute behind): a refused
frame never reaches the autopilot and never makes its sender the vehicle's peer; it counts in
SYS_STATUS ``errors_comm`` and in ``VehicleSigning.rejected``. A vehicle with a key refuses
every ``SETUP_SIGNING`` (an unsigned one never gets past the codec; a signed one cannot change
the key either). New refusals are reported to the ground station in a STATUSTEXT (WARNING,
``Signing: refused U unsigned, B bad, R old``) at most every ``REPORT_INTERVAL_S`` of
simulated time.

Hardening (as in the ground station's ``gcs/signing.py``): pymavlink 2.4.50 records a stream's
timestamp before comparing the signature, so one forged frame with a far-future timestamp
would lock the real ground station out; here the signature is compared first.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import stat
import time
from collections import Counter
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink

log = logging.getLogger(__name__)

SIGNING_EPOCH = 1420070400  # MAVLink 2 signing timestamps count 10 us from 2015-01-01
LINK_ID = 0
MIN_PASSPHRASE_CHARS = 16
REPORT_INTERVAL_S = 2.0
REJECTION_KINDS = ("unsigned", "bad_signature", "replayed")
_SIGNATURE_BYTES = 6


class KeyFileError(ValueError):
    """A key file that cannot be used (the message says why, naming the file)."""


def key_from_passphrase(passphrase: str) -> bytes:
    """The 32-byte signing key of a passphrase (SHA-256, as MAVProxy's ``signing setup``)."""
    return hashlib.sha256(passphrase.encode()).digest()


def read_key_file(path: str | Path) -> bytes:
    """The key of an owner-only key file; ``KeyFileError`` if it is not one."""
    path = Path(path)
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise KeyFileError(f"{path}: expected a regular key file")
        if info.st_mode & 0o077:
            raise KeyFileError(
                f"{path}: expected a key file only its owner can access (chmod 600), "
                f"got mode {stat.S_IMODE(info.st_mode):03o}"
            )
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise KeyFileError(
            f"{path}: expected a readable key file ({error.__class__.__name__})"
        ) from None
    passphrase = lines[0].strip() if lines else ""
    if len(passphrase) < MIN_PASSPHRASE_CHARS:
        raise KeyFileError(
            f"{path}: expected a passphrase of at least {MIN_PASSPHRASE_CHARS} characters "
            "on its first line"
        )
    return key_from_passphrase(passphrase)


def _now_timestamp() -> int:
    return int(max(time.time() - SIGNING_EPOCH, 0.0) * 100_000)


class ClockedSigning(mavlink.MAVLinkSigning):
    """pymavlink's signing state with a timestamp that never falls behind the wall clock
    (pymavlink adds 10 us per frame from the start, so a busy link's timestamps lag the clock;
    MAVLink 2 asks a system with a clock to use it), as the ground station's."""

    def __init__(self) -> None:
        self._timestamp = 0
        super().__init__()

    @property
    def timestamp(self) -> int:
        return max(self._timestamp, _now_timestamp())

    @timestamp.setter
    def timestamp(self, value: int) -> None:
        self._timestamp = int(value)


class VehicleSigning:
    """The signing state of one vehicle's codec: key, checks, refusal counters, reports."""

    def __init__(self, codec: mavlink.MAVLink, key: bytes | None = None) -> None:
        self.codec = codec
        self.rejected: Counter = Counter()
        self._reported: Counter = Counter()
        self._last_report_s: float | None = None
        self._failed = False
        self._pymavlink_check = codec.check_signature
        if key is not None:
            self.enable(key)

    @property
    def enabled(self) -> bool:
        return self.codec.signing.secret_key is not None

    def enable(self, key: bytes, initial_timestamp: int = 0) -> None:
        """Sign from now on with ``key`` (as mavutil's ``setup_signing``): unsigned input is
        refused, the timestamp starts at the wall clock (or ``initial_timestamp`` if later)."""
        if len(key) != 32:
            raise ValueError("a MAVLink 2 signing key is 32 bytes")
        signing = self.codec.signing = ClockedSigning()
        signing.secret_key = bytes(key)
        signing.sign_outgoing = True
        signing.link_id = LINK_ID
        signing.allow_unsigned_callback = self._unsigned
        signing.timestamp = int(initial_timestamp)  # the clock if later (ClockedSigning)
        self.codec.check_signature = self._check  # the instance attribute shadows the method

    # -- checks (called by pymavlink while it decodes a frame) ---------------------------
    def _check(self, msgbuf: bytearray, source_system: int, source_component: int) -> bool:
        key = self.codec.signing.secret_key
        digest = hashlib.sha256(key + bytes(msgbuf[:-_SIGNATURE_BYTES])).digest()
        if not hmac.compare_digest(digest[:_SIGNATURE_BYTES], bytes(msgbuf[-_SIGNATURE_BYTES:])):
            return self._refuse("bad_signature")
        if self._pymavlink_check(msgbuf, source_system, source_component):
            return True
        return self._refuse("replayed")

    def _refuse(self, kind: str) -> bool:
        self._failed = True
        self.rejected[kind] += 1
        return False

    def _unsigned(self, codec: mavlink.MAVLink, message_id: int) -> bool:
        if self._failed:  # pymavlink asks again after a failed check: already counted
            self._failed = False
            return False
        self.rejected["unsigned"] += 1
        return False

    # -- provisioning --------------------------------------------------------------------
    def setup(self, message: mavlink.MAVLink_message, sysid: int, armed: bool) -> str | None:
        """A SETUP_SIGNING for this vehicle: the STATUSTEXT answering it (None: not for us)."""
        if message.target_system not in (0, sysid):
            return None
        key = bytes(message.secret_key)
        if self.enabled:
            return "Signing: SETUP_SIGNING refused, key already set"
        if armed:
            return "Signing: SETUP_SIGNING refused while armed"
        if not any(key):
            return "Signing: not enabled (empty key)"
        self.enable(key, int(message.initial_timestamp))
        log.info("sysid %d: signing key set by SETUP_SIGNING", sysid)
        return "Signing: key set, unsigned input now refused"

    # -- reporting -----------------------------------------------------------------------
    def report(self, sim_s: float) -> str | None:
        """A STATUSTEXT (at most 50 characters) about refusals since the last report, at most
        every ``REPORT_INTERVAL_S`` simulated seconds; None when there is nothing to say."""
        if self.rejected == self._reported:
            return None
        if self._last_report_s is not None and sim_s - self._last_report_s < REPORT_INTERVAL_S:
            return None
        new = self.rejected - self._reported
        self._reported = self.rejected.copy()
        self._last_report_s = sim_s
        return (
            f"Signing: refused {new['unsigned']} unsigned, {new['bad_signature']} bad, "
            f"{new['replayed']} old"
        )


def deliver_setup_signing(link, autopilot, message, stamp) -> bool:
    """The sim's hook for SETUP_SIGNING (the link's codec and the autopilot's arming state
    meet here): True when ``message`` was one and is dealt with."""
    if message.get_type() != "SETUP_SIGNING":
        return False
    text = link.signing.setup(message, autopilot.sysid, autopilot.armed)
    if text is not None:
        autopilot.status_text(
            mavlink.MAV_SEVERITY_INFO if "key set" in text else mavlink.MAV_SEVERITY_WARNING, text
        )
    return True


def report_refusals(link, autopilot, stamp) -> None:
    """The sim's per-tick hook: tell the ground station about refused frames."""
    text = link.signing.report(stamp.sim_s)
    if text is not None:
        autopilot.status_text(mavlink.MAV_SEVERITY_WARNING, text)
