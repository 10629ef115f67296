"""Let other ground-station tools watch a live mission: `gcs mission run --out URL`.

As MAVProxy's `--out`: every message a UAV sends the ground station is copied, byte for byte,
to each output (QGroundControl listens on `udpout:127.0.0.1:14550`, MAVProxy on
`--master=udpin:...`), so the tool sees every UAV under its own system id. What a tool sends
back goes to the UAV it names (`target_system`; 0 or none: every UAV), byte for byte too:

* **Never more authority than the tool has.** The ground station does not sign what it
  forwards: on a signed fleet a tool's commands reach the autopilots with the tool's own
  signature (or none) and are refused unless the tool holds the fleet's key.
* **Never the ground station's heartbeat.** A tool's HEARTBEAT is not forwarded: autopilots
  take any GCS heartbeat as a sign that their ground station lives, and one from QGroundControl
  would hide this station's loss from their failsafe.
* `--out-readonly`: nothing from the tools is forwarded (counted in `dropped`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from gcs.transport.link import open_connection

log = logging.getLogger(__name__)

#: A tool's messages read per output per loop turn at most (a flood never starves the flight).
MAX_MESSAGES_PER_POLL = 1_000


@dataclass
class ForwardCounters:
    """Traffic through the outputs."""

    to_tools: int = 0  # messages copied from the UAVs to the outputs
    to_uavs: int = 0  # messages of the tools forwarded to UAVs
    dropped: int = 0  # messages of the tools not forwarded (read-only, heartbeats, no such UAV)


class Forwarder:
    """The outputs of one run (see the module docstring). `urls` are pymavlink connection
    strings (bad one: `OSError` naming it). The live loop waits on `filenos()` and calls
    `poll(index, uav_links)` when output `index` is readable; the links' capture hook calls
    `from_uav(raw)` for every message a UAV sent."""

    def __init__(self, urls: list[str], *, readonly: bool = False) -> None:
        self.urls = list(urls)
        self.readonly = readonly
        self.counters = ForwardCounters()
        self._outputs = []
        try:
            for url in self.urls:
                try:
                    self._outputs.append(open_connection(url, source_system=255))
                except OSError as error:
                    raise OSError(f"{url}: {error}") from None
        except BaseException:
            self.close()
            raise

    def filenos(self) -> list[int]:
        return [output.fd for output in self._outputs]

    def from_uav(self, raw: bytes) -> None:
        """Copy one message a UAV sent to every output (a full socket buffer drops it)."""
        for output in self._outputs:
            try:
                output.write(raw)
            except OSError as error:  # a tool that went away: it may come back
                log.debug("forward to %s failed: %s", output.address, error)
        self.counters.to_tools += 1

    def poll(self, index: int, uav_links: dict[int, object]) -> None:
        """Read what output `index`'s tool sent and forward it to the UAVs it names
        (`uav_links`: system id -> link with `write_raw(bytes)`)."""
        output = self._outputs[index]
        for _ in range(MAX_MESSAGES_PER_POLL):
            try:
                message = output.recv_msg()
            except OSError as error:
                log.debug("receive on %s failed: %s", self.urls[index], error)
                return
            except Exception as error:  # noqa: BLE001 - pymavlink raises bare errors on garbage
                log.debug("undecodable data from %s: %s", self.urls[index], error)
                continue
            if message is None:
                return
            kind = message.get_type()
            if self.readonly or kind in ("HEARTBEAT", "BAD_DATA") or kind.startswith("UNKNOWN_"):
                self.counters.dropped += 1
                continue
            target = getattr(message, "target_system", 0)
            links = list(uav_links.values()) if target == 0 else [uav_links.get(target)]
            raw = bytes(message.get_msgbuf())
            sent = False
            for link in links:
                if link is not None:
                    link.write_raw(raw)
                    sent = True
            if sent:
                self.counters.to_uavs += 1
            else:
                self.counters.dropped += 1

    def close(self) -> None:
        for output in self._outputs:
            try:
                output.close()
            except OSError:  # pragma: no cover
                pass
        self._outputs = []
