"""Read MCAP bags (profile `ros2`): messages as raw CDR with receive times, topics, QoS.

Records come from the `mcap` library: header and summary (topics, counts, metadata index)
through its seeking reader, messages in file order through its stream reader. A bag whose
writer was killed has no summary or footer; `BagReader(path, allow_truncated=True)` reads
it up to the last complete record: every closed chunk, nothing of the chunk that was open.
Bad input raises BagError with a one-line message naming the file.
"""

from __future__ import annotations

import functools
import os
import struct
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.reader import FOOTER_SIZE, make_reader
from mcap.records import Channel, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import MAGIC_SIZE, StreamReader
from mcap_ros2.decoder import DecoderFactory

from robot_calib.bag.ros2_formats import (
    METADATA_KEY,
    METADATA_NAME,
    PROFILE,
    QosProfile,
    qos_profiles_from_yaml,
)
from robot_calib.errors import BagError, TruncatedBagError

MAGIC = b"\x89MCAP0\r\n"
_CORRUPT = (McapError, ValueError, KeyError, IndexError, EOFError, struct.error)
"""What mcap raises on a malformed file."""


@dataclass(frozen=True)
class TopicInfo:
    """One topic (MCAP channel) of a bag.

    offered_qos: the publishers' offered profiles recorded with it (may be empty).
    type_hash: 'RIHS01_…' or '' when the recorder did not know it.
    definition: the schema's text (for `ros2msg`, the message definition), '' if none.
    """

    topic: str
    type_name: str
    message_count: int
    offered_qos: tuple[QosProfile, ...]
    type_hash: str
    schema_encoding: str
    message_encoding: str
    definition: str = ""


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: raw CDR bytes and times [ns since the Unix epoch].

    log_time_ns / publish_time_ns: receive time (the contract stores it in both).
    `decode()` gives a message object with the type's fields (mcap_ros2 dynamic type).
    """

    topic: str
    type_name: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    sequence: int = 0
    _decoder: Callable[[bytes], Any] | None = field(default=None, repr=False, compare=False)

    def decode(self) -> Any:
        """The message decoded from its CDR bytes with the bag's own schema."""
        if self._decoder is None:
            raise BagError(f"{self.topic}: message has no decoder attached")
        return self._decoder(self.data)


class _ExactReads:
    """A binary file whose short reads raise EndOfFile.

    mcap's ReadDataStream only notices an empty read; a record cut by a crash would come
    back short (a partial message, a chunk failing its CRC) instead of ending the file.
    """

    def __init__(self, file: IO[bytes]) -> None:
        self._file = file
        self.seek, self.tell, self.seekable = file.seek, file.tell, file.seekable

    def read(self, size: int = -1) -> bytes:
        data = self._file.read(size)
        if size > 0 and len(data) < size:
            raise EndOfFile()
        return data


class BagReader:
    """A bag opened for reading. Use as a context manager or call `close()`.

    allow_truncated: read a bag without footer/summary (killed writer) up to its last
    complete record instead of raising BagError. `complete` tells which one was opened.
    """

    def __init__(self, path: str | os.PathLike[str], *, allow_truncated: bool = False) -> None:
        self.path = Path(path)
        try:
            self._file = open(self.path, "rb")  # noqa: SIM115 - closed by close()
        except OSError as exc:
            raise BagError(f"{self.path}: cannot open: {exc.strerror}") from None
        try:
            self._open(allow_truncated)
        except BagError:
            self._file.close()
            raise
        except _CORRUPT as exc:
            self._file.close()
            raise BagError(f"{self.path}: corrupt MCAP file: {exc}") from None

    def _open(self, allow_truncated: bool) -> None:
        try:
            self._reader = make_reader(_ExactReads(self._file))  # type: ignore[arg-type]
        except (InvalidMagic, EndOfFile):
            raise BagError(f"{self.path}: not an MCAP file (no MCAP magic at the start)") from None
        try:
            header = self._reader.get_header()
        except EndOfFile:
            raise BagError(f"{self.path}: truncated MCAP file (no complete header)") from None
        except McapError:
            raise BagError(f"{self.path}: MCAP file does not start with a header record") from None
        self.profile: str = header.profile
        self.library: str = header.library
        if self.profile != PROFILE:
            raise BagError(f"{self.path}: MCAP profile {self.profile!r} is not {PROFILE!r}")
        size = self._file.seek(0, os.SEEK_END)
        self._file.seek(size - MAGIC_SIZE)
        self.complete: bool = size >= FOOTER_SIZE + 2 * MAGIC_SIZE and self._file.read() == MAGIC
        """True if the file was closed properly (footer present)."""
        if not self.complete and not allow_truncated:
            raise TruncatedBagError(
                f"{self.path}: truncated MCAP file (no footer: its writer did not close "
                "it); open with allow_truncated=True to read its complete chunks"
            )
        summary = self._reader.get_summary() if self.complete else None
        self.has_summary: bool = summary is not None
        """True if the file has a summary section (statistics and indexes)."""
        self._metadata_indexed = summary is not None and bool(summary.metadata_indexes)
        self._decoders = DecoderFactory()
        if summary is not None and summary.statistics is not None and summary.channels:
            schemas, channels = summary.schemas, summary.channels
            counts = dict(summary.statistics.channel_message_counts)
        else:  # no summary, or one without statistics or channels: count by reading
            schemas, channels, counts = {}, {}, {}
            for record in self._records():
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
        self._schemas, self._channels = schemas, channels
        self.complete_bytes: int = size if self.complete else self._complete_end
        """Bytes from the start to the end of the last complete record (the file size for a
        complete bag); what follows in a truncated bag is a record cut by the crash."""
        self.topics: dict[str, TopicInfo] = {
            channel.topic: self._topic_info(channel, counts.get(channel.id, 0))
            for channel in channels.values()
        }
        """Topic name -> TopicInfo, in channel order."""

    # --- public ---------------------------------------------------------------------------

    @property
    def counts(self) -> dict[str, int]:
        """Messages per topic."""
        return {name: info.message_count for name, info in self.topics.items()}

    @property
    def message_count(self) -> int:
        """Messages in the bag (in complete chunks, for a truncated bag)."""
        return sum(self.counts.values())

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
        """Messages in file order (the order the recorder received them), optionally of
        some topics only. Each call starts again at the beginning."""
        wanted = None if topics is None else set(topics)
        schemas, channels = dict(self._schemas), dict(self._channels)  # a live bag grows
        for record in self._records():
            if isinstance(record, Schema):
                schemas.setdefault(record.id, record)
            elif isinstance(record, Channel):
                channels.setdefault(record.id, record)
            elif isinstance(record, Message):
                channel = channels.get(record.channel_id)
                if channel is None:
                    raise BagError(f"{self.path}: message on unknown channel {record.channel_id}")
                if wanted is not None and channel.topic not in wanted:
                    continue
                schema = schemas.get(channel.schema_id)
                yield BagMessage(
                    topic=channel.topic,
                    type_name=schema.name if schema is not None else "",
                    log_time_ns=record.log_time,
                    publish_time_ns=record.publish_time,
                    data=bytes(record.data),
                    sequence=record.sequence,
                    _decoder=functools.partial(self._decode, channel, schema),
                )

    def rosbag2_metadata(self) -> str | None:
        """The last `rosbag2` metadata record's `serialized_metadata` (YAML text), if any."""
        try:
            records: Iterable[McapRecord] = (
                self._reader.iter_metadata() if self._metadata_indexed else self._records()
            )
            found = [
                r.metadata.get(METADATA_KEY)
                for r in records
                if isinstance(r, Metadata) and r.name == METADATA_NAME
            ]
        except _CORRUPT as exc:
            raise BagError(f"{self.path}: corrupt MCAP metadata: {exc}") from None
        return next((text for text in reversed(found) if text is not None), None)

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    # --- internals ------------------------------------------------------------------------

    def _records(self) -> Iterator[McapRecord]:
        """Every record from the start (chunks opened, CRCs checked), through a file handle
        of its own so that several iterations may interleave. In a truncated bag mcap's
        stream reader raises EndOfFile at the cut: the records end quietly there."""
        with open(self.path, "rb") as stream:
            self._complete_end = MAGIC_SIZE
            try:
                reader = StreamReader(_ExactReads(stream), validate_crcs=True)  # type: ignore[arg-type]
                for record in reader.records:  # a chunk's records come once it is read whole
                    self._complete_end = stream.tell()
                    yield record
            except EndOfFile:
                if self.complete:
                    raise BagError(f"{self.path}: corrupt MCAP data: ends in a record") from None
            except _CORRUPT as exc:
                raise BagError(f"{self.path}: corrupt MCAP data: {exc}") from None

    def _topic_info(self, channel: Channel, count: int) -> TopicInfo:
        schema = self._schemas.get(channel.schema_id)
        try:
            qos = qos_profiles_from_yaml(channel.metadata.get("offered_qos_profiles", ""))
        except ValueError as exc:
            raise BagError(
                f"{self.path}: topic {channel.topic}: bad offered_qos_profiles: {exc}"
            ) from None
        return TopicInfo(
            topic=channel.topic,
            type_name=schema.name if schema is not None else "",
            message_count=count,
            offered_qos=qos,
            type_hash=channel.metadata.get("topic_type_hash", ""),
            schema_encoding=schema.encoding if schema is not None else "",
            message_encoding=channel.message_encoding,
            definition=schema.data.decode("utf-8", "replace") if schema is not None else "",
        )

    def _decode(self, channel: Channel, schema: Schema | None, data: bytes) -> Any:
        """Decode with mcap_ros2 (its factory keeps one decoder per schema)."""
        try:
            decoder = self._decoders.decoder_for(channel.message_encoding, schema)
        except Exception as exc:  # mcap_ros2 raises assorted errors on bad schemas/data
            raise BagError(f"{self.path}: topic {channel.topic}: bad schema: {exc}") from None
        if decoder is None:
            raise BagError(
                f"{self.path}: topic {channel.topic}: cannot decode encoding "
                f"{channel.message_encoding!r} with schema "
                f"{schema.encoding if schema else None!r}"
            )
        try:
            return decoder(data)
        except Exception as exc:
            raise BagError(
                f"{self.path}: topic {channel.topic}: cannot decode "
                f"{schema.name if schema else '?'}: {exc}"
            ) from None
