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

The key file's rules, the clocked timestamp and the hardening (pymavlink 2.4.50 records a
stream's timestamp before comparing the signature, so one forged frame with a far-future
timestamp would lock the real ground station out; the signature is compared first) are
``fleetwire.signing``'s, shared with the ground station.
"""

from __future__ import annotations

import logging
from collections import Counter

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from fleetwire.signing import (
    LINK_ID,
    ClockedSigning,
    KeyFileError,
    SignatureCheck,
    check_key,
    read_key_file,
)

#: The key file's error and reader are re-exported (the CLI's, and the tests').
__all__ = [
    "KeyFileError",
    "VehicleSigning",
    "deliver_setup_signing",
    "read_key_file",
    "report_refusals",
]

log = logging.getLogger(__name__)

REPORT_INTERVAL_S = 2.0


class VehicleSigning:
    """The signing state of one vehicle's codec: key, checks, refusal counters, reports."""

    def __init__(self, codec: mavlink.MAVLink, key: bytes | None = None) -> None:
        self.codec = codec
        self.rejected: Counter = Counter()
        self._reported: Counter = Counter()
        self._last_report_s: float | None = None
        if key is not None:
            self.enable(key)

    @property
    def enabled(self) -> bool:
        return self.codec.signing.secret_key is not None

    def enable(self, key: bytes, initial_timestamp: int = 0) -> None:
        """Sign from now on with ``key`` (as mavutil's ``setup_signing``): unsigned input is
        refused, the timestamp starts at the wall clock (or ``initial_timestamp`` if later)."""
        check_key(key)
        check = SignatureCheck(self.codec, self._refused)  # the signature before the timestamp
        signing = self.codec.signing = ClockedSigning()
        signing.secret_key = bytes(key)
        signing.sign_outgoing = True
        signing.link_id = LINK_ID
        signing.allow_unsigned_callback = check.unsigned
        signing.timestamp = int(initial_timestamp)  # the clock if later (ClockedSigning)

    def _refused(self, kind: str, source_system: int | None, message_id: int | None) -> None:
        self.rejected[kind] += 1

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
