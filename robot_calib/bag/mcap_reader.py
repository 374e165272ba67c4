"""Read MCAP bags (profile `ros2`): messages as raw CDR with receive times, topics, QoS.

A closed bag is read through its summary (topics, counts) and then record by record. A bag
whose writer was killed has no summary or footer; `BagReader(path, allow_truncated=True)`
reads it record by record up to the last complete record: every closed chunk, nothing of
the chunk that was open. Bad input raises BagError with a one-line message naming the file.
"""

from __future__ import annotations

import functools
import io
import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    Footer,
    Header,
    Message,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
)
from mcap.stream_reader import breakup_chunk
from mcap_ros2.decoder import DecoderFactory

from robot_calib.bag.ros2_formats import (
    METADATA_KEY,
    METADATA_NAME,
    PROFILE,
    QosProfile,
    qos_profiles_from_yaml,
)
from robot_calib.errors import BagError

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = 9  # opcode (1) + length (8)
_FOOTER_BODY = 20  # summary_start (8) + summary_offset_start (8) + summary_crc (4)


@dataclass(frozen=True)
class TopicInfo:
    """One topic (MCAP channel) of a bag.

    offered_qos: the publishers' offered profiles recorded with it (may be empty).
    type_hash: 'RIHS01_…' or '' when the recorder did not know it.
    """

    topic: str
    type_name: str
    message_count: int
    offered_qos: tuple[QosProfile, ...]
    type_hash: str
    schema_encoding: str
    message_encoding: str


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


class _Truncated(Exception):
    """The data ends inside a record."""


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
        except (McapError, ValueError, KeyError, IndexError, EOFError) as exc:
            self._file.close()
            raise BagError(f"{self.path}: corrupt MCAP file: {exc}") from None

    def _open(self, allow_truncated: bool) -> None:
        self._size = os.fstat(self._file.fileno()).st_size
        self._file.seek(0)
        if self._file.read(len(MAGIC)) != MAGIC:
            raise BagError(f"{self.path}: not an MCAP file (no MCAP magic at the start)")
        records = self._records(len(MAGIC), self._size)
        try:
            opcode, body = next(records)
        except (StopIteration, _Truncated):
            raise BagError(f"{self.path}: truncated MCAP file (no complete header)") from None
        if opcode != Opcode.HEADER:
            raise BagError(f"{self.path}: MCAP file does not start with a header record")
        header = Header.read(_stream(body))
        self.profile: str = header.profile
        self.library: str = header.library
        if self.profile != PROFILE:
            raise BagError(f"{self.path}: MCAP profile {self.profile!r} is not {PROFILE!r}")
        self._data_start = len(MAGIC) + _RECORD_HEAD + len(body)
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._counts: dict[int, int] = {}
        self._metadata_indexes: list[MetadataIndex] = []
        self._decoders = DecoderFactory()
        footer = self._footer()
        self.complete: bool = footer is not None
        """True if the file was closed properly (footer present)."""
        self.has_summary: bool = footer is not None and footer.summary_start != 0
        """True if the file has a summary section (statistics and indexes)."""
        if footer is None:
            if not allow_truncated:
                raise BagError(
                    f"{self.path}: truncated MCAP file (no footer: its writer did not close "
                    "it); open with allow_truncated=True to read its complete chunks"
                )
            self._data_end = self._size
            self._scan_topics()
        elif footer.summary_start == 0:
            self._data_end = self._size - len(MAGIC) - _RECORD_HEAD - _FOOTER_BODY
            self._scan_topics()
        else:
            self._data_end = footer.summary_start
            self._read_summary(footer.summary_start)
        self.topics: dict[str, TopicInfo] = self._topic_infos()
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
        try:
            for record in self._data_records():
                if not isinstance(record, Message):
                    continue
                channel = self._channels.get(record.channel_id)
                if channel is None:
                    raise BagError(f"{self.path}: message on unknown channel {record.channel_id}")
                if wanted is not None and channel.topic not in wanted:
                    continue
                schema = self._schemas.get(channel.schema_id)
                yield BagMessage(
                    topic=channel.topic,
                    type_name=schema.name if schema is not None else "",
                    log_time_ns=record.log_time,
                    publish_time_ns=record.publish_time,
                    data=bytes(record.data),
                    sequence=record.sequence,
                    _decoder=functools.partial(self._decode, channel.id),
                )
        except (McapError, ValueError, KeyError, IndexError, EOFError) as exc:
            raise BagError(f"{self.path}: corrupt MCAP data: {exc}") from None

    def rosbag2_metadata(self) -> str | None:
        """The last `rosbag2` metadata record's `serialized_metadata` (YAML text), if any."""
        found: str | None = None
        try:
            if self.has_summary and self._metadata_indexes:
                for index in self._metadata_indexes:
                    if index.name != METADATA_NAME:
                        continue
                    self._file.seek(index.offset + _RECORD_HEAD)
                    body = self._file.read(index.length - _RECORD_HEAD)
                    found = Metadata.read(_stream(body)).metadata.get(METADATA_KEY, found)
                return found
            for opcode, body in self._records(self._data_start, self._data_end):
                if opcode == Opcode.METADATA:
                    metadata = Metadata.read(_stream(body))
                    if metadata.name == METADATA_NAME:
                        found = metadata.metadata.get(METADATA_KEY, found)
        except _Truncated:
            pass
        except (McapError, ValueError, KeyError, EOFError) as exc:
            raise BagError(f"{self.path}: corrupt MCAP metadata: {exc}") from None
        return found

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

    def _records(self, start: int, end: int) -> Iterator[tuple[int, bytes]]:
        """(opcode, body) of the top-level records in [start, end); _Truncated at a record
        that does not fit. Seeks before every read, so several iterators may interleave."""
        position = start
        while position < end:
            self._file.seek(position)
            head = self._file.read(_RECORD_HEAD)
            if len(head) < _RECORD_HEAD:
                raise _Truncated
            opcode = head[0]
            length = int.from_bytes(head[1:], "little")
            if position + _RECORD_HEAD + length > end:
                raise _Truncated
            body = self._file.read(length)
            if len(body) < length:
                raise _Truncated
            position += _RECORD_HEAD + length
            yield opcode, body

    def _data_records(self) -> Iterator[Schema | Channel | Message | Metadata]:
        """Schemas, channels, messages (chunks opened) and metadata of the data section, in
        file order; a truncated file ends quietly after its last complete record."""
        try:
            for opcode, body in self._records(self._data_start, self._data_end):
                if opcode == Opcode.CHUNK:
                    chunk = Chunk.read(_stream(body))
                    for record in breakup_chunk(chunk, validate_crc=True):
                        if isinstance(record, Schema | Channel | Message):
                            yield record
                elif opcode == Opcode.MESSAGE:
                    yield Message.read(_stream(body), len(body))
                elif opcode == Opcode.SCHEMA:
                    yield Schema.read(_stream(body))
                elif opcode == Opcode.CHANNEL:
                    yield Channel.read(_stream(body))
                elif opcode == Opcode.METADATA:
                    yield Metadata.read(_stream(body))
                elif opcode in (Opcode.DATA_END, Opcode.FOOTER):
                    return
                elif opcode == 0 and not self.complete:
                    return  # zero fill after a crash: no record starts with opcode 0
        except _Truncated:
            if self.complete:
                raise BagError(f"{self.path}: record runs past the data section") from None

    def _footer(self) -> Footer | None:
        """The footer, or None if the file does not end with one (writer killed)."""
        footer_start = self._size - len(MAGIC) - _RECORD_HEAD - _FOOTER_BODY
        if footer_start < self._data_start:
            return None
        self._file.seek(footer_start)
        tail = self._file.read(_RECORD_HEAD + _FOOTER_BODY + len(MAGIC))
        if tail[-len(MAGIC) :] != MAGIC or tail[0] != Opcode.FOOTER:
            return None
        if int.from_bytes(tail[1:_RECORD_HEAD], "little") != _FOOTER_BODY:
            return None
        footer = Footer.read(_stream(tail[_RECORD_HEAD : _RECORD_HEAD + _FOOTER_BODY]))
        if footer.summary_start and not (self._data_start <= footer.summary_start <= footer_start):
            raise BagError(f"{self.path}: footer points outside the file")
        return footer

    def _read_summary(self, summary_start: int) -> None:
        footer_start = self._size - len(MAGIC) - _RECORD_HEAD - _FOOTER_BODY
        statistics: Statistics | None = None
        try:
            for opcode, body in self._records(summary_start, footer_start):
                if opcode == Opcode.SCHEMA:
                    schema = Schema.read(_stream(body))
                    self._schemas[schema.id] = schema
                elif opcode == Opcode.CHANNEL:
                    channel = Channel.read(_stream(body))
                    self._channels[channel.id] = channel
                elif opcode == Opcode.STATISTICS:
                    statistics = Statistics.read(_stream(body))
                elif opcode == Opcode.METADATA_INDEX:
                    self._metadata_indexes.append(MetadataIndex.read(_stream(body)))
        except _Truncated:
            raise BagError(f"{self.path}: summary section runs into the footer") from None
        if statistics is None or not self._channels:
            self._schemas.clear()
            self._channels.clear()
            self._scan_topics()  # a summary without statistics or channels: count by reading
            return
        self._counts = dict(statistics.channel_message_counts)

    def _scan_topics(self) -> None:
        """Schemas, channels and message counts by reading the data section."""
        counts: dict[int, int] = {}
        for record in self._data_records():
            if isinstance(record, Schema):
                self._schemas[record.id] = record
            elif isinstance(record, Channel):
                self._channels[record.id] = record
            elif isinstance(record, Message):
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
        self._counts = counts

    def _topic_infos(self) -> dict[str, TopicInfo]:
        infos: dict[str, TopicInfo] = {}
        for channel in self._channels.values():
            schema = self._schemas.get(channel.schema_id)
            try:
                qos = qos_profiles_from_yaml(channel.metadata.get("offered_qos_profiles", ""))
            except ValueError as exc:
                raise BagError(
                    f"{self.path}: topic {channel.topic}: bad offered_qos_profiles: {exc}"
                ) from None
            infos[channel.topic] = TopicInfo(
                topic=channel.topic,
                type_name=schema.name if schema is not None else "",
                message_count=self._counts.get(channel.id, 0),
                offered_qos=qos,
                type_hash=channel.metadata.get("topic_type_hash", ""),
                schema_encoding=schema.encoding if schema is not None else "",
                message_encoding=channel.message_encoding,
            )
        return infos

    def _decode(self, channel_id: int, data: bytes) -> Any:
        channel = self._channels[channel_id]
        schema = self._schemas.get(channel.schema_id)
        try:
            decoder = self._decoders.decoder_for(channel.message_encoding, schema)
            if decoder is None:
                raise BagError(
                    f"{self.path}: topic {channel.topic}: cannot decode encoding "
                    f"{channel.message_encoding!r} with schema "
                    f"{schema.encoding if schema else None!r}"
                )
            return decoder(data)
        except BagError:
            raise
        except Exception as exc:  # mcap_ros2 raises assorted errors on bad schemas/data
            raise BagError(
                f"{self.path}: topic {channel.topic}: cannot decode "
                f"{schema.name if schema else '?'}: {exc}"
            ) from None


def _stream(body: bytes) -> ReadDataStream:
    return ReadDataStream(io.BytesIO(body))
