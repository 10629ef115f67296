"""MAVLink 2 signing of the ground station's links, and the fleet key (pymavlink's signing).

The fleet key. The key file's rules (a passphrase on its first line, the key its SHA-256 as
MAVProxy's `signing setup PASSPHRASE` derives, owner-only) are `fleetwire.signing`'s, shared
with the vehicles. `gcs` creates a missing key file (`signing.key_file`, relative to the
mission file) with owner-only permissions and 64 random hex digits (256 bits); a key file that
group or others may read, an empty or short passphrase, or a missing folder is bad input (exit
2). Without `signing.key_file`, the simulated fleet gets a fresh key for the run
(`EphemeralKey`), written only to an owner-only file in a private temporary folder that the
vehicle processes read at start and that is removed at the end of the run.

The links. `FleetSigning.apply(link)` calls mavutil's `setup_signing` on each link (sign
everything sent, no unsigned input accepted) and makes every link of the fleet share ONE
signing state: one timestamp for the whole fleet, that never falls behind the wall clock
(`ClockedSigning`), so a frame captured on the link of one UAV and replayed to another, or
captured earlier, is older than what that UAV already heard. Incoming frames are
refused when unsigned, wrongly signed, or replayed (a timestamp not newer than the last one of
its stream (link id, system, component), or a new stream more than a minute old). Refused
frames never reach a driver and never count as "link alive" (the `Link` sees them as bad data).

One hardening over pymavlink 2.4.50 (`fleetwire.signing.SignatureCheck`, as the vehicles'):
the signature is compared before pymavlink checks and records the stream's timestamp, so one
forged frame with a future timestamp cannot make every later genuine frame look like a replay.

Refusals are counted per UAV and kind (`unsigned`, `bad_signature`, `replayed`) and written to
the recording's `/events` by `RejectionLog` (the first at once, then at most one summary per
UAV per second, and the remainder at the end of the run).
"""

from __future__ import annotations

import logging
import shutil
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from fleetwire.signing import LINK_ID as GCS_LINK_ID
from fleetwire.signing import (
    REJECTION_KINDS,
    ClockedSigning,
    KeyFileError,
    SignatureCheck,
    check_key,
    create_key_file,
    key_from_passphrase,
    read_key_file,
)
from gcs.errors import InputError
from gcs.transport.link import Link, mavutil

log = logging.getLogger(__name__)
mavlink = mavutil.mavlink

#: A UAV's refusals are summarised in the log at most this often (wall seconds).
REPORT_PERIOD_S = 1.0


@dataclass(frozen=True)
class FleetKey:
    """The fleet's signing key and where it lives (`path`; `created` if this run made it)."""

    key: bytes = field(repr=False)
    path: Path
    created: bool = False
    ephemeral: bool = False


def load_or_create_key(
    path: Path, source: Path | None = None, key_path: str = "signing.key_file"
) -> FleetKey:
    """Read the key file at `path`, creating it (owner-only, 256 random bits) if missing.

    Bad input (`InputError`, exit 2): a missing folder, a path that is not a regular file, a file
    group or others may access, an unreadable file, an empty or short passphrase.
    """
    path = Path(path)
    created = False
    if not path.exists():
        if not path.parent.is_dir():
            raise InputError(source, key_path, f"a file in an existing folder, got {path}")
        try:
            create_key_file(path)
        except OSError as error:
            raise InputError(
                source, key_path, f"a writable key file ({error.strerror}: {path})"
            ) from None
        created = True
        log.info("created the fleet key file %s", path)
    try:
        key = read_key_file(path)
    except KeyFileError as error:
        hint = " (delete the file to get a random one)" if error.kind == "passphrase" else ""
        raise InputError(source, key_path, error.expected + hint) from None
    return FleetKey(key, path.resolve(), created=created)


class EphemeralKey:
    """A fresh key for one run of the simulated fleet, in an owner-only file of a private
    temporary folder (the vehicles read it at start); `close()` removes both."""

    def __init__(self) -> None:
        self.folder = Path(tempfile.mkdtemp(prefix="fleetline-key-"))  # mode 0700
        path = self.folder / "fleet.key"
        passphrase = create_key_file(path)
        self.fleet_key = FleetKey(key_from_passphrase(passphrase), path, True, ephemeral=True)

    def close(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


class FleetSigning:
    """Signs the links of one fleet with one shared signing state; counts the refusals."""

    def __init__(
        self, key: bytes, on_reject: Callable[[int, str, int | None], None] | None = None
    ) -> None:
        check_key(key)
        self.key = key
        self.on_reject = on_reject
        self.rejected: dict[int, Counter] = {}  # UAV id -> Counter(kind)
        self._state = None  # the shared pymavlink MAVLinkSigning
        self._checks: dict[int, SignatureCheck] = {}  # id(codec) -> its check

    def apply(self, link: Link, uav: int) -> None:
        """Sign `link` (UAV `uav`): pymavlink's `setup_signing`, the shared state, the check."""
        link.setup_signing(
            self.key,
            sign_outgoing=True,
            allow_unsigned_callback=self._unsigned,
            link_id=GCS_LINK_ID,
        )
        if self._state is None:
            self._state = ClockedSigning(link.mav.signing)
        link.mav.signing = self._state
        self.rejected.setdefault(uav, Counter())

        def refused(kind: str, source: int | None, message_id: int | None, uav=uav) -> None:
            self.rejected[uav][kind] += 1
            if self.on_reject is not None:
                self.on_reject(uav, kind, message_id)

        self._checks[id(link.mav)] = SignatureCheck(link.mav, refused)

    def _unsigned(self, mav, message_id: int) -> bool:
        check = self._checks.get(id(mav))
        return False if check is None else check.unsigned(mav, message_id)

    def totals(self) -> dict[str, dict[str, int]]:
        """Refused frames per UAV and kind (run JSON)."""
        return {
            str(uav): {kind: int(counts[kind]) for kind in REJECTION_KINDS}
            for uav, counts in sorted(self.rejected.items())
        }


def message_name(message_id: int | None) -> str:
    """A message id's name (`#id` when unknown)."""
    if message_id is None:
        return "?"
    kind = mavlink.mavlink_map.get(message_id)
    return kind.msgname if kind is not None else f"#{message_id}"


class RejectionLog:
    """Writes refused frames to the recording's `/events`, summarised per UAV.

    `event(level, text, wall)` is the recorder's; `monotonic` the runtime's wall clock.
    """

    def __init__(
        self,
        event: Callable[..., None],
        monotonic: Callable[[], float] = time.monotonic,
        period_s: float = REPORT_PERIOD_S,
    ) -> None:
        self._event = event
        self._monotonic = monotonic
        self.period_s = period_s
        self._pending: dict[int, Counter] = {}
        self._types: dict[int, Counter] = {}
        self._last: dict[int, float] = {}

    def __call__(self, uav: int, kind: str, message_id: int | None) -> None:
        self._pending.setdefault(uav, Counter())[kind] += 1
        self._types.setdefault(uav, Counter())[message_name(message_id)] += 1
        now = self._monotonic()
        last = self._last.get(uav)
        if last is None or now - last >= self.period_s:
            self._write(uav, now)

    def flush(self) -> None:
        """Write what is not yet reported (end of the run)."""
        now = self._monotonic()
        for uav in sorted(self._pending):
            self._write(uav, now)

    def _write(self, uav: int, now: float) -> None:
        counts = self._pending.pop(uav, None)
        types = self._types.pop(uav, Counter())
        if not counts:
            return
        self._last[uav] = now
        what = ", ".join(f"{counts[k]} {k.replace('_', ' ')}" for k in REJECTION_KINDS if counts[k])
        names = ", ".join(name for name, _ in types.most_common(4))
        text = f"UAV {uav} link: refused {what} frame(s) ({names})"
        self._event("warning", text, now, name="signing")
        log.warning("%s", text)


class RunSigning:
    """How one `gcs mission run` signs its MAVLink (built before anything starts: a bad key
    file is bad input).

    * `--insecure`: nothing is signed (said loudly: a console line and a log event);
    * `signing.key_file` set: that key (the file is created if missing), any backend;
    * else the simulated fleet gets a key of its own for this run (`EphemeralKey`), and SITL
      autopilots are not signed (their keys are provisioned by the user, see the README).
    """

    def __init__(self, mission, *, insecure: bool, simulated: bool) -> None:
        self.insecure = insecure
        self.fleet_key: FleetKey | None = None
        self.fleet: FleetSigning | None = None
        self._ephemeral: EphemeralKey | None = None
        self._rejections: RejectionLog | None = None
        if insecure:
            return
        if mission.signing.key_file is not None:
            self.fleet_key = load_or_create_key(mission.signing.key_file, mission.source)
        elif simulated:
            self._ephemeral = EphemeralKey()
            self.fleet_key = self._ephemeral.fleet_key
        if self.fleet_key is not None:
            self.fleet = FleetSigning(self.fleet_key.key)

    @property
    def enabled(self) -> bool:
        return self.fleet is not None

    def notice(self) -> tuple[str, str]:
        """(level, text) of what the run does about signing: a console line and a log event."""
        if self.insecure:
            return (
                "warning",
                "--insecure: MAVLink is NOT signed: any process that can reach the vehicles' "
                "ports can command the fleet",
            )
        if self.fleet_key is None:
            return (
                "warning",
                "MAVLink is not signed: set signing.key_file (and provision the autopilots with "
                "it) to sign it",
            )
        if self.fleet_key.ephemeral:
            return "info", "MAVLink 2 signed with a key made for this run"
        made = " (created)" if self.fleet_key.created else ""
        return "info", f"MAVLink 2 signed with the key of {self.fleet_key.path}{made}"

    def vehicle_args(self) -> tuple[str, ...]:
        """`vehicles sim` arguments that give the simulated vehicles the key."""
        if self.fleet_key is None:
            return ()
        return ("--signing-key-file", str(self.fleet_key.path))

    def record_to(self, event: Callable[..., None]) -> None:
        """Write refused frames to the recording (`recorder.event`)."""
        if self.fleet is not None:
            self._rejections = RejectionLog(event)
            self.fleet.on_reject = self._rejections

    def apply(self, link: Link, uav: int) -> None:
        if self.fleet is not None:
            self.fleet.apply(link, uav)

    def summary(self) -> dict:
        """The run JSON's `signing` object (reporting what is still pending to the log)."""
        if self._rejections is not None:
            self._rejections.flush()
        key = None
        if self.fleet_key is not None:
            key = "per-run" if self.fleet_key.ephemeral else str(self.fleet_key.path)
        return {
            "enabled": self.enabled,
            "insecure": self.insecure,
            "key": key,
            "refused": self.fleet.totals() if self.fleet is not None else {},
        }

    def close(self) -> None:
        """Remove the run's own key (idempotent)."""
        if self._ephemeral is not None:
            self._ephemeral.close()
