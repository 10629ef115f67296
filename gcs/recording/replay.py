"""`gcs log replay`: re-emit the MAVLink of a recording with its original timing (or faster).

The recording holds every MAVLink frame exchanged, raw, on `/mavlink/<n>/rx` (what UAV n sent
to the ground station) and `/mavlink/<n>/tx` (what the ground station sent it). Replaying the
`rx` frames to a ground-control program (MAVProxy, QGroundControl: `udpout:127.0.0.1:14550`)
shows it the fleet as it flew. Frames are sent byte for byte (signatures included), one
datagram per frame, in log-time order, the gaps between them divided by `rate`.
"""

from __future__ import annotations

import base64
import logging
import re
import time
from collections.abc import Callable
from dataclasses import dataclass

from fleetline.errors import FleetlineError
from gcs.errors import InputError
from gcs.recording.logreader import Recording
from gcs.transport.link import GCS_SYSTEM_ID, open_connection

log = logging.getLogger(__name__)

_MAVLINK_TOPIC = re.compile(r"^/mavlink/(\d+)/(rx|tx)$")


@dataclass(frozen=True)
class RecordedFrame:
    """One MAVLink frame as recorded: log time (ns), UAV, direction, raw bytes."""

    log_time_ns: int
    uav: int
    direction: str
    raw: bytes


class ReplayError(FleetlineError):
    """Sending failed (an unresolvable host, a closed TCP peer...) after `sent` frames."""

    def __init__(self, sent: int, error: Exception) -> None:
        self.sent = sent
        self.error = error
        super().__init__(f"{error} (after {sent} frames)")


@dataclass(frozen=True)
class ReplayStats:
    """What a replay sent."""

    frames: int
    bytes: int
    recorded_s: float  # log-time span of the frames
    wall_s: float  # how long sending took


def mavlink_topics(recording: Recording, directions: tuple[str, ...]) -> list[str]:
    """The `/mavlink/<n>/<direction>` topics of a recording, for the directions asked."""
    return [
        topic
        for topic in recording.topics
        if (match := _MAVLINK_TOPIC.match(topic)) and match.group(2) in directions
    ]


def recorded_frames(
    recording: Recording, directions: tuple[str, ...] = ("rx",), uavs: set[int] | None = None
) -> list[RecordedFrame]:
    """The recorded frames of the chosen directions (and UAVs), in log-time order (ties keep
    the order of the file)."""
    frames = []
    for topic in mavlink_topics(recording, directions):
        match = _MAVLINK_TOPIC.match(topic)
        uav, direction = int(match.group(1)), match.group(2)
        if uavs is not None and uav not in uavs:
            continue
        for log_time, message in recording.messages(topic):
            frames.append(RecordedFrame(log_time, uav, direction, base64.b64decode(message["raw"])))
    frames.sort(key=lambda f: f.log_time_ns)
    return frames


def open_output(url: str):
    """A pymavlink connection to send to (any mavutil connection string); bad one: exit 2."""
    try:
        return open_connection(url, GCS_SYSTEM_ID)
    except OSError as error:
        expected = "a MAVLink connection string such as udpout:127.0.0.1:14550"
        raise InputError(None, "--to", f"{expected} ({url}: {error})") from None


def replay(
    frames: list[RecordedFrame],
    connection,
    rate: float = 1.0,
    *,
    monotonic: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> ReplayStats:
    """Send `frames` through `connection` (a pymavlink connection), keeping their recorded
    spacing divided by `rate`. Waiting is on the wall clock: this is what replay is for.
    Raises `ReplayError` if a frame cannot be sent."""
    if not frames:
        return ReplayStats(0, 0, 0.0, 0.0)
    first = frames[0].log_time_ns
    began = monotonic()
    sent = sent_bytes = 0
    for frame in frames:
        due = began + (frame.log_time_ns - first) / 1e9 / rate
        delay = due - monotonic()
        if delay > 0:
            sleep(delay)
        try:
            connection.write(frame.raw)
        except (OSError, OverflowError) as error:
            raise ReplayError(sent, error) from None
        sent += 1
        sent_bytes += len(frame.raw)
    span = (frames[-1].log_time_ns - first) / 1e9
    log.info("replayed %d frames (%.1f s recorded)", len(frames), span)
    return ReplayStats(len(frames), sent_bytes, span, monotonic() - began)
