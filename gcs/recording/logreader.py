"""Reading a recording back: every record of an MCAP file, complete or cut short.

The file is read sequentially with `mcap`'s stream reader, so a recording whose writer was
killed (no summary, a last chunk cut at an arbitrary byte) yields everything before the cut
and says where it stopped (`Recording.truncated`). Protobuf messages (Foxglove's schemas) are
decoded with `mcap-protobuf-support`, JSON ones with `json`; decoding happens per topic, on
demand, so summarising a long log stays cheap.

A file that does not start with the MCAP magic is refused with `InputError` (exit 2).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import EndOfFile
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

from gcs.errors import InputError

#: The 8 bytes every MCAP file starts with.
MCAP_MAGIC = b"\x89MCAP0\r\n"

_UAV_TOPIC = re.compile(r"^/uav(\d+)/|^/mavlink/(\d+)/")


@dataclass
class TopicData:
    """One channel: its schema, encodings, the log time of every message and, for the topics
    kept, the messages as (log time ns, raw bytes)."""

    topic: str
    schema_name: str
    schema_encoding: str
    message_encoding: str
    times: list[int] = field(default_factory=list)
    messages: list[tuple[int, bytes]] = field(default_factory=list)
    kept: bool = True

    @property
    def count(self) -> int:
        return len(self.times)

    @property
    def first_ns(self) -> int | None:
        return min(self.times) if self.times else None

    @property
    def last_ns(self) -> int | None:
        return max(self.times) if self.times else None


@dataclass
class Recording:
    """What a recording holds. `messages(topic)` decodes one topic on demand."""

    path: Path
    profile: str
    topics: dict[str, TopicData]
    attachments: dict[str, bytes]
    metadata: dict[str, dict[str, str]]
    truncated: bool
    truncation: str | None  # why reading stopped early, for humans
    bytes_read: int  # bytes of complete records (the rest was cut or unreadable)
    size: int
    #: a chunk or the data section failed its CRC (a flipped byte): what, for humans; reading
    #: stopped there (None: every CRC held)
    damaged: str | None = None
    _decoders: dict[str, Callable[[bytes], Any]] = field(default_factory=dict, repr=False)

    # ----------------------------------------------------------------- summary
    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())

    @property
    def start_ns(self) -> int | None:
        firsts = [t.first_ns for t in self.topics.values() if t.first_ns is not None]
        return min(firsts) if firsts else None

    @property
    def end_ns(self) -> int | None:
        lasts = [t.last_ns for t in self.topics.values() if t.last_ns is not None]
        return max(lasts) if lasts else None

    @property
    def duration_s(self) -> float:
        start, end = self.start_ns, self.end_ns
        return 0.0 if start is None else (end - start) / 1e9

    @property
    def uavs(self) -> list[int]:
        """UAV numbers that have a topic (`/uav<n>/...`, `/mavlink/<n>/...`)."""
        found = set()
        for topic in self.topics:
            match = _UAV_TOPIC.match(topic)
            if match:
                found.add(int(match.group(1) or match.group(2)))
        return sorted(found)

    @property
    def mission_name(self) -> str | None:
        name = self.metadata.get("mission", {}).get("name")
        if name is None and "/plan" in self.topics and self.topics["/plan"].messages:
            name = self.first("/plan").get("name")
        return name

    @property
    def outcome(self) -> dict[str, Any] | None:
        """The `outcome` metadata, decoded (None: the GCS did not finish the recording)."""
        raw = self.metadata.get("outcome")
        if raw is None:
            return None
        return {key: json.loads(value) for key, value in raw.items()}

    @property
    def epoch_ns(self) -> int | None:
        """Unix ns at mission time 0 (from the `clock` metadata, else from a timed message)."""
        value = self.metadata.get("clock", {}).get("epoch_ns")
        if value not in (None, "None"):
            return int(value)
        for topic in ("/metrics", "/uav1/setpoint", "/speed"):
            for log_time, message in self.messages(topic):
                if isinstance(message.get("t"), int | float):
                    return log_time - round(message["t"] * 1e9)
        return None

    def mission_time(self, log_time_ns: int) -> float | None:
        epoch = self.epoch_ns
        return None if epoch is None else (log_time_ns - epoch) / 1e9

    # ----------------------------------------------------------------- messages
    def messages(self, topic: str) -> Iterator[tuple[int, Any]]:
        """(log time ns, decoded message) of `topic` in file order; nothing if absent."""
        data = self.topics.get(topic)
        if data is None:
            return iter(())
        decode = self._decoders.get(topic)
        if decode is None:
            return iter(())
        return ((log_time, decode(raw)) for log_time, raw in data.messages)

    def first(self, topic: str) -> Any:
        for _, message in self.messages(topic):
            return message
        return None

    def json_attachment(self, name: str) -> Any:
        data = self.attachments.get(name)
        return None if data is None else json.loads(data)


def _json_decoder(raw: bytes) -> Any:
    return json.loads(raw)


def read_recording(path: str | Path, keep: Callable[[str], bool] = lambda topic: True) -> Recording:  # noqa: C901 (over 15 branches: to split)
    """Read every record of `path`; keep the message bytes of the topics `keep` accepts
    (counts and times are kept for all). Raises `InputError` if it is not an MCAP file."""
    path = Path(path)
    try:
        handle = open(path, "rb")  # noqa: SIM115 - closed below, the reader streams from it
    except OSError as error:
        raise InputError(path, "", f"a readable MCAP file ({error.strerror or error})") from None
    with handle:
        magic = handle.read(len(MCAP_MAGIC))
        if magic != MCAP_MAGIC:
            raise InputError(path, "", "an MCAP file (it does not start with the MCAP magic)")
        handle.seek(0)
        size = path.stat().st_size
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        by_id: dict[int, TopicData] = {}
        topics: dict[str, TopicData] = {}
        attachments: dict[str, bytes] = {}
        metadata: dict[str, dict[str, str]] = {}
        profile = ""
        complete = False
        reason = None
        # CRCs checked: a flipped byte in a chunk dropped hundreds of messages unnoticed
        reader = StreamReader(handle, record_size_limit=size + 1, validate_crcs=True)
        damaged = None
        good = 0  # bytes of complete records read
        try:
            for record in reader.records:
                good = handle.tell()
                if isinstance(record, Message):
                    data = by_id.get(record.channel_id)
                    if data is None:
                        continue
                    data.times.append(record.log_time)
                    if data.kept:
                        data.messages.append((record.log_time, record.data))
                elif isinstance(record, Channel):
                    if record.id in channels:
                        continue
                    channels[record.id] = record
                    schema = schemas.get(record.schema_id)
                    data = topics.get(record.topic) or TopicData(
                        topic=record.topic,
                        schema_name=schema.name if schema else "",
                        schema_encoding=schema.encoding if schema else "",
                        message_encoding=record.message_encoding,
                        kept=keep(record.topic),
                    )
                    topics[record.topic] = data
                    by_id[record.id] = data
                elif isinstance(record, Schema):
                    schemas.setdefault(record.id, record)
                elif isinstance(record, Attachment):
                    attachments[record.name] = record.data
                elif isinstance(record, Metadata):
                    metadata[record.name] = dict(record.metadata)
                elif isinstance(record, Header):
                    profile = record.profile
                elif isinstance(record, Footer):
                    complete = True
        except CRCValidationError as error:  # a flipped byte: said, never skipped silently
            damaged = reason = f"damaged at byte {good}: {' '.join(str(error).split())}"
        except Exception as error:  # noqa: BLE001 - a cut file ends in EndOfFile, struct or zstd errors
            reason = _describe(error)
            if "corrupt" in reason.lower():  # zstd's checksum: damaged too
                damaged = f"damaged at byte {good}: {reason}"
    if not complete and reason is None:
        reason = "no footer (the writer did not finish)"
    recording = Recording(
        path=path,
        profile=profile,
        topics=topics,
        attachments=attachments,
        metadata=metadata,
        truncated=not complete,
        truncation=None if complete else reason,
        bytes_read=good,
        size=size,
        damaged=damaged,
    )
    protobuf = ProtobufDecoderFactory()
    for channel in channels.values():
        data = topics[channel.topic]
        if data.message_encoding == "json":
            recording._decoders[channel.topic] = _json_decoder
        else:
            decoder = protobuf.decoder_for(channel.message_encoding, schemas.get(channel.schema_id))
            if decoder is not None:
                recording._decoders[channel.topic] = decoder
    return recording


def _describe(error: Exception) -> str:
    if isinstance(error, EndOfFile):
        return "the file ends inside a record (cut short)"
    text = " ".join(str(error).split()) or "unreadable data"
    return f"{type(error).__name__}: {text}"
