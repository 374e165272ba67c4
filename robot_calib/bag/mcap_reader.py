"""Read MCAP bags (profile `ros2`): messages as raw CDR with receive times, topics, QoS.

Why one module: `BagReader` and its bulk path (`channel_messages`: chunks parsed here,
`_ChannelTable`, `_ExactReads`) read one file through one summary and must agree on what is
corrupt (the bulk path gives None where mcap's reader would raise, and the caller falls
back); apart, the bulk path would reach into the reader's private state.

Records come from the `mcap` library: header and summary (topics, counts, metadata index)
through its seeking reader, messages in file order through its stream reader. A bag whose
writer was killed has no summary or footer; `BagReader(path, allow_truncated=True)` reads
it up to the last complete record: every closed chunk, nothing of the chunk that was open.
Bad input raises BagError with a one-line message naming the file.

`BagReader.channel_messages` reads a complete bag's messages of some topics in bulk: the
chunks decompressed with mcap's own codecs and their records parsed here, every message of a
channel in arrays (times, file order, payloads back to back) for `bulk_decode`. It checks
what mcap's stream reader checks (CRCs, record bounds, known channels) and gives None where
anything is off, so that the caller falls back to `messages()` and its errors.
"""

from __future__ import annotations

import functools
import io
import os
import struct
import zlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import numpy as np
import numpy.typing as npt
from mcap import records as _records
from mcap import stream_reader as _stream_reader
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.opcode import Opcode
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
_CORRUPT = (McapError, ValueError, KeyError, IndexError, EOFError, struct.error, MemoryError)
"""What mcap raises on a malformed file (MemoryError: a length beyond memory, e.g. a chunk
to decompress to more bytes than there are, read whole by mcap)."""
_LARGE_READ = 1 << 20
"""Reads above this size [B] are checked against the bytes left in the file first."""


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


@dataclass(frozen=True)
class ChannelMessages:
    """The messages of one channel in file order, as arrays (`BagReader.channel_messages`).

    index: each message's position among all the bag's messages in file order (to merge
    channels); log_time_ns, publish_time_ns, sequence as recorded; payload: the messages'
    CDR bytes back to back, message i at payload[offsets[i]:offsets[i + 1]].
    """

    channel: Channel
    schema: Schema | None
    index: npt.NDArray[np.int64]
    log_time_ns: npt.NDArray[np.uint64]
    publish_time_ns: npt.NDArray[np.uint64]
    sequence: npt.NDArray[np.uint32]
    payload: npt.NDArray[np.uint8]
    offsets: npt.NDArray[np.int64]
    decode: Callable[[bytes], Any] = field(repr=False, compare=False)
    """mcap_ros2's decoder of the channel (BagError when it cannot decode)."""

    def __len__(self) -> int:
        return len(self.index)

    @property
    def topic(self) -> str:
        return self.channel.topic

    def data(self, i: int) -> bytes:
        """Message i's CDR bytes."""
        return self.payload[self.offsets[i] : self.offsets[i + 1]].tobytes()

    def fixed(self) -> npt.NDArray[np.uint8] | None:
        """The payloads as rows (n, size) when all have the same size (n > 0), else None."""
        sizes = np.diff(self.offsets)
        if len(sizes) == 0 or sizes.min() != sizes.max():
            return None
        return self.payload.reshape(len(sizes), int(sizes[0]))


class _Fallback(Exception):
    """Something `channel_messages` does not read itself: the caller reads `messages()`."""


_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = np.dtype(
    {
        "names": ["length", "channel", "sequence", "log_time", "publish_time"],
        "formats": ["<u8", "<u2", "<u4", "<u8", "<u8"],
        "offsets": [1, 9, 11, 15, 23],
        "itemsize": 31,
    }
)
"""A message record's opcode, length, channel id, sequence, log and publish time."""
_RECORD_SIZE_LIMIT = 4 * 2**30  # mcap's stream reader's default
_TOP_LEVEL: dict[int, Any] = {
    Opcode.ATTACHMENT: _records.Attachment,
    Opcode.ATTACHMENT_INDEX: _records.AttachmentIndex,
    Opcode.CHANNEL: _records.Channel,
    Opcode.CHUNK: _records.Chunk,
    Opcode.CHUNK_INDEX: _records.ChunkIndex,
    Opcode.DATA_END: _records.DataEnd,
    Opcode.FOOTER: _records.Footer,
    Opcode.HEADER: _records.Header,
    Opcode.MESSAGE_INDEX: _records.MessageIndex,
    Opcode.METADATA: _records.Metadata,
    Opcode.METADATA_INDEX: _records.MetadataIndex,
    Opcode.SCHEMA: _records.Schema,
    Opcode.STATISTICS: _records.Statistics,
    Opcode.SUMMARY_OFFSET: _records.SummaryOffset,
}
"""Records mcap's stream reader parses outside chunks (besides messages), by opcode."""


def _record_stream(body: bytes) -> ReadDataStream:
    """A record's content to parse with mcap's record classes; reading past it raises."""
    return ReadDataStream(_ExactReads(io.BytesIO(body)))  # type: ignore[arg-type]


def _uncompressed(chunk: Any) -> bytes:
    """A chunk's records, decompressed as mcap's stream reader does, CRC checked."""
    if chunk.compression == "zstd" and _stream_reader.zstandard is not None:
        data = _stream_reader.zstandard.decompress(chunk.data, chunk.uncompressed_size)
    elif chunk.compression == "lz4" and _stream_reader.lz4 is not None:
        data = _stream_reader.lz4.decompress(chunk.data)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise _Fallback(f"compression {chunk.compression!r}")
    if len(data) != chunk.uncompressed_size:
        raise _Fallback("uncompressed size")
    if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
        raise _Fallback("chunk CRC")
    return bytes(data)


class _ChannelTable:
    """Collects the messages of some channels, chunk by chunk (`BagReader.channel_messages`)."""

    def __init__(self, known: Iterable[int], wanted: Iterable[int]) -> None:
        self.known = np.array(sorted(known), dtype=np.int64)
        self.wanted = set(wanted)
        self.count = 0  # messages so far (all channels)
        self.pieces: dict[int, list[tuple[npt.NDArray[Any], ...]]] = {c: [] for c in self.wanted}

    def add_records(self, data: bytes) -> None:
        """The records of one chunk (or one message record outside chunks): messages
        collected, schema and channel records parsed as mcap's `breakup_chunk` does."""
        positions: list[int] = []
        append, head = positions.append, _RECORD_HEAD.unpack_from
        pos, end = 0, len(data)
        while pos < end:
            opcode, length = head(data, pos)
            after = pos + 9 + length
            if after > end:
                raise _Fallback("record beyond its chunk")
            if opcode == Opcode.MESSAGE:
                if length < 22:
                    raise _Fallback("short message record")
                append(pos)
            elif opcode == Opcode.SCHEMA or opcode == Opcode.CHANNEL:
                stream = _record_stream(data[pos + 9 : after])
                _TOP_LEVEL[opcode].read(stream)
                if stream.count != length:  # breakup_chunk reads on where the record's fields end
                    raise _Fallback("schema or channel record of another length")
            pos = after
        if not positions:
            return
        chunk = np.frombuffer(data, dtype=np.uint8)
        starts = np.array(positions, dtype=np.int64)
        heads = chunk[starts[:, None] + np.arange(_MESSAGE_HEAD.itemsize)].view(_MESSAGE_HEAD)
        heads = heads.reshape(-1)
        channel = heads["channel"].astype(np.int64)
        if not np.isin(channel, self.known).all():
            raise _Fallback("message on a channel not in the summary")
        index = self.count + np.arange(len(starts), dtype=np.int64)
        self.count += len(starts)
        for c in self.wanted.intersection(np.unique(channel).tolist()):
            mine = channel == c
            first = starts[mine] + _MESSAGE_HEAD.itemsize
            sizes = heads["length"][mine].astype(np.int64) - 22
            if sizes.min() == sizes.max():
                payload = chunk[first[:, None] + np.arange(sizes[0])].reshape(-1)
            else:
                skip = np.repeat(first - (np.cumsum(sizes) - sizes), sizes)
                payload = chunk[skip + np.arange(int(sizes.sum()))]
            self.pieces[c].append(
                (
                    index[mine],
                    heads["log_time"][mine],
                    heads["publish_time"][mine],
                    heads["sequence"][mine],
                    payload,
                    sizes,
                )
            )

    def channel(
        self, channel: Channel, schema: Schema | None, decode: Callable[[bytes], Any]
    ) -> ChannelMessages:
        pieces = self.pieces[channel.id]
        columns = [
            np.concatenate([p[k] for p in pieces]) if pieces else np.empty(0, dtype=dtype)
            for k, dtype in enumerate([np.int64, np.uint64, np.uint64, np.uint32, np.uint8])
        ]
        sizes = np.concatenate([p[5] for p in pieces]) if pieces else np.empty(0, np.int64)
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        index, log_time, publish_time, sequence, payload = columns
        return ChannelMessages(
            channel, schema, index, log_time, publish_time, sequence, payload, offsets, decode
        )


class _ExactReads:
    """A binary file whose short reads raise EndOfFile.

    mcap's ReadDataStream only notices an empty read; a record cut by a crash would come
    back short (a partial message, a chunk failing its CRC) instead of ending the file.
    """

    def __init__(self, file: IO[bytes]) -> None:
        self._file = file
        self.seek, self.tell, self.seekable = file.seek, file.tell, file.seekable

    def read(self, size: int = -1) -> bytes:
        if size > _LARGE_READ and size > _bytes_left(self._file):
            raise EndOfFile()  # a record longer than the file (a corrupt length): never allocated
        data = self._file.read(size)
        if size > 0 and len(data) < size:
            raise EndOfFile()
        return data


def _bytes_left(file: IO[bytes]) -> int:
    """Bytes from the position of `file` to its end now (a live bag grows)."""
    try:
        return os.fstat(file.fileno()).st_size - file.tell()
    except (OSError, io.UnsupportedOperation, AttributeError):  # in memory: reads are short
        return 1 << 62


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

    def channel_messages(self, topics: Iterable[str]) -> dict[int, ChannelMessages] | None:
        """The messages of `topics` in bulk: {channel id: its messages in file order} for
        every channel of those topics, read in one pass. None when the bag is not one this
        reads itself (truncated, a compression mcap cannot open, a CRC or record that does
        not check out, a message on a channel or schema the summary lacks): then
        `messages()` reads it, with its errors."""
        if not self.complete:
            return None
        names = set(topics)
        wanted = {c.id: c for c in self._channels.values() if c.topic in names}
        if any(c.schema_id not in self._schemas for c in wanted.values()):
            return None
        table = _ChannelTable(self._channels, wanted)
        try:
            with open(self.path, "rb") as stream:
                self._read_all(stream, table)
        except Exception:  # anything off: `messages()` reads the bag and says what
            return None
        return {
            c.id: table.channel(c, schema, functools.partial(self._decode, c, schema))
            for c in wanted.values()
            for schema in [self._schemas.get(c.schema_id)]
        }

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
                    raise BagError(
                        f"{self.path}: corrupt MCAP data: a record runs past the end of "
                        "the file (a corrupt length)"
                    ) from None
            except _CORRUPT as exc:
                raise BagError(f"{self.path}: corrupt MCAP data: {exc}") from None

    @staticmethod
    def _read_all(stream: IO[bytes], table: _ChannelTable) -> None:
        """Every record of a complete bag from the start into `table`, checked as mcap's
        stream reader (validate_crcs=True) checks them; _Fallback (or mcap's errors) where
        it would raise or read on differently."""

        def read(size: int) -> bytes:
            data = stream.read(size)
            if len(data) != size:
                raise _Fallback("file ends in a record")
            return data

        crc = zlib.crc32(read(MAGIC_SIZE))
        if crc != zlib.crc32(MAGIC):
            raise _Fallback("magic")
        while True:
            head = read(9)
            opcode, length = _RECORD_HEAD.unpack(head)
            if length > _RECORD_SIZE_LIMIT:
                raise _Fallback("record length limit")
            if length > _LARGE_READ and length > _bytes_left(stream):
                raise _Fallback("record beyond the end of the file")
            body = read(length)
            if opcode == Opcode.MESSAGE:
                table.add_records(head + body)
            elif opcode == Opcode.MESSAGE_INDEX:  # MessageIndex.read, without its records
                (records_length,) = struct.unpack_from("<I", body, 2)
                if 6 + -(-records_length // 16) * 16 > length:
                    raise _Fallback("message index beyond its record")
            elif opcode in _TOP_LEVEL:
                record_stream = _record_stream(body)
                record = _TOP_LEVEL[opcode].read(record_stream)
                if opcode == Opcode.CHUNK:
                    table.add_records(_uncompressed(record))
                elif opcode == Opcode.DATA_END and record.data_section_crc not in (0, crc):
                    raise _Fallback("data section CRC")
                elif opcode == Opcode.FOOTER:
                    if read(MAGIC_SIZE) != MAGIC:
                        raise _Fallback("magic after the footer")
                    return
            crc = zlib.crc32(body, zlib.crc32(head, crc))

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
