"""Write bags as `ros2 bag record -s mcap` (Jazzy) does: one MCAP file, profile `ros2`.

What the file holds (see `ros2_formats` for the rosbag2 sources of each format):
header profile `ros2`; one schema per type (`ros2msg` full definition text); one channel per
topic (message encoding `cdr`, metadata `offered_qos_profiles` and `topic_type_hash`);
messages in chunks with message indexes; a `rosbag2` metadata record written at open and
again at close; on close the summary (schemas, channels, statistics, chunk and metadata
indexes, summary offsets) and the footer.

Crash safety: the file is flushed to the operating system as soon as a chunk closes (at
`chunk_size` bytes, or when it is older than `max_chunk_age_s`, checked on every write and
by `flush_stale`); mcap's writer itself flushes only when asked. A killed writer loses at
most the open chunk; the rest stays readable with `BagReader(path, allow_truncated=True)`.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

from mcap.writer import CompressionType, Writer

from robot_calib import __version__
from robot_calib.bag.ros2_formats import (
    MESSAGE_ENCODING,
    METADATA_KEY,
    METADATA_NAME,
    PROFILE,
    DefinitionNotFoundError,
    QosProfile,
    dump_yaml,
    message_definition,
    qos_profiles_to_yaml,
    type_description_hash,
)
from robot_calib.errors import BagError

DEFAULT_CHUNK_SIZE = 128 * 1024  # bytes (uncompressed); rosbag2's own default is 768 KiB
DEFAULT_MAX_CHUNK_AGE_S = 1.0
_COMPRESSION = {
    "none": CompressionType.NONE,  # rosbag2's default (chunked, uncompressed)
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
}


@dataclass
class _Topic:
    channel_id: int
    type_name: str
    offered_qos: tuple[QosProfile, ...]
    type_hash: str
    count: int = 0


class BagWriter:
    """An MCAP bag being written. Never overwrites: an existing `path` raises BagError.

    path: the .mcap file to create. chunk_size: chunk size [bytes, uncompressed].
    max_chunk_age_s: a chunk open longer than this [s] is closed on the next `write` or
    `flush_stale`. compression: 'none' (rosbag2's default), 'zstd' or 'lz4' per chunk.
    fsync: also fsync each closed chunk (power-loss safety; costs a disk sync per chunk).
    ros_distro: recorded in the rosbag2 metadata (default: $ROS_DISTRO, else '').
    file_name: the file's name in the rosbag2 metadata (default: path's name; give the
    final name when writing to a temporary file that is renamed at the end).
    Use as a context manager or call `close()`; only a closed file has its summary.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        max_chunk_age_s: float = DEFAULT_MAX_CHUNK_AGE_S,
        compression: str = "none",
        fsync: bool = False,
        ros_distro: str | None = None,
        file_name: str | None = None,
    ) -> None:
        self.path = Path(path)
        self._file_name = self.path.name if file_name is None else file_name
        if compression not in _COMPRESSION:
            raise BagError(
                f"{self.path}: unknown compression {compression!r} "
                f"(use one of {', '.join(_COMPRESSION)})"
            )
        if chunk_size <= 0 or max_chunk_age_s <= 0:
            raise BagError(
                f"{self.path}: chunk_size ({chunk_size} B) and max_chunk_age_s "
                f"({max_chunk_age_s} s) must be positive"
            )
        try:  # mode "x": never overwrite
            self._file = open(self.path, "xb", opener=_create)  # noqa: SIM115 - close()
        except FileExistsError:
            raise BagError(f"{self.path}: already exists; not overwriting it") from None
        except OSError as exc:
            raise BagError(f"{self.path}: cannot create: {exc.strerror}") from None
        self._fsync = fsync
        self._max_chunk_age_ns = int(max_chunk_age_s * 1e9)
        self._ros_distro = os.environ.get("ROS_DISTRO", "") if ros_distro is None else ros_distro
        self._topics: dict[str, _Topic] = {}
        self._schema_ids: dict[str, int] = {}
        self._open_chunk_since: int | None = None  # monotonic ns of the open chunk's first msg
        self._first_log_ns: int | None = None
        self._last_log_ns: int | None = None
        self._closed = False
        self._writer = Writer(
            self._file, chunk_size=chunk_size, compression=_COMPRESSION[compression]
        )
        try:
            self._writer.start(
                profile=PROFILE, library=f"robot_calib {__version__} (mcap-python writer)"
            )
            self._write_metadata()  # rosbag2 writes its metadata when it opens the bag
            self._sync()
        except OSError as exc:
            self._abort()
            raise BagError(f"{self.path}: write failed: {exc.strerror}") from None

    # --- topics ---------------------------------------------------------------------------

    def add_topic(
        self,
        topic: str,
        type_name: str,
        *,
        offered_qos: Iterable[QosProfile] = (),
        type_hash: str | None = None,
        definition: tuple[str, str] | None = None,
    ) -> None:
        """Register a topic (one channel). A second call with the same type does nothing.

        type_name: 'pkg/msg/Type'. offered_qos: the publishers' offered profiles (recorded
        as the channel's `offered_qos_profiles`). type_hash: 'RIHS01_…' (default: from the
        installed type description, '' if none). definition: (schema encoding, text) if not
        to be read from the installed .msg files. BagError on a type conflict or an unknown
        type.
        """
        self._check_open()
        known = self._topics.get(topic)
        if known is not None:
            if known.type_name != type_name:
                raise BagError(
                    f"{self.path}: topic {topic} already recorded as {known.type_name}, "
                    f"not {type_name}"
                )
            return
        schema_id = self._schema_ids.get(type_name)
        if schema_id is None:
            if definition is None:
                try:
                    definition = message_definition(type_name)
                except (DefinitionNotFoundError, ValueError, OSError) as exc:
                    raise BagError(
                        f"{self.path}: no message definition for {type_name} "
                        f"(topic {topic}): {exc}"
                    ) from None
            encoding, text = definition
            schema_id = self._writer.register_schema(
                name=type_name, encoding=encoding, data=text.encode("utf-8")
            )
            self._schema_ids[type_name] = schema_id
        if type_hash is None:
            type_hash = type_description_hash(type_name)
        offered = tuple(offered_qos)
        channel_id = self._writer.register_channel(
            topic=topic,
            message_encoding=MESSAGE_ENCODING,
            schema_id=schema_id,
            metadata={
                "offered_qos_profiles": qos_profiles_to_yaml(offered),
                "topic_type_hash": type_hash,
            },
        )
        self._topics[topic] = _Topic(channel_id, type_name, offered, type_hash)

    def has_topic(self, topic: str) -> bool:
        """True once `add_topic(topic, …)` has been called."""
        return topic in self._topics

    # --- messages -------------------------------------------------------------------------

    def write(
        self,
        topic: str,
        data: bytes | bytearray | memoryview,
        log_time_ns: int,
        publish_time_ns: int | None = None,
        sequence: int = 0,
    ) -> None:
        """Append one CDR-serialised message of a registered topic.

        log_time_ns / publish_time_ns: receive time [ns since the Unix epoch]; publish time
        defaults to the log time (the contract records the receive time in both).
        sequence: the publisher's sequence number, if known (uint32).
        """
        self._check_open()
        entry = self._topics.get(topic)
        if entry is None:
            raise BagError(f"{self.path}: topic {topic} not added (call add_topic first)")
        log_time_ns = int(log_time_ns)
        publish = log_time_ns if publish_time_ns is None else int(publish_time_ns)
        before = self._file.tell()
        try:
            self._writer.add_message(
                channel_id=entry.channel_id,
                log_time=log_time_ns,
                data=bytes(data),
                publish_time=publish,
                sequence=int(sequence) & 0xFFFFFFFF,
            )
        except OSError as exc:
            raise BagError(f"{self.path}: write failed: {exc.strerror}") from None
        entry.count += 1
        if self._first_log_ns is None or log_time_ns < self._first_log_ns:
            self._first_log_ns = log_time_ns
        if self._last_log_ns is None or log_time_ns > self._last_log_ns:
            self._last_log_ns = log_time_ns
        if self._file.tell() != before:  # the message closed a chunk: it is on disk
            self._open_chunk_since = None
            self._sync()
        elif self._open_chunk_since is None:
            self._open_chunk_since = time.monotonic_ns()
        else:
            self.flush_stale()

    def flush_stale(self) -> bool:
        """Close the open chunk if it is older than max_chunk_age_s. True if it did."""
        if self._closed or self._open_chunk_since is None:
            return False
        if time.monotonic_ns() - self._open_chunk_since < self._max_chunk_age_ns:
            return False
        self.flush()
        return True

    def flush(self) -> None:
        """Close the open chunk now (if it holds messages) and hand it to the OS."""
        self._check_open()
        try:
            self._writer.flush()
        except OSError as exc:
            raise BagError(f"{self.path}: write failed: {exc.strerror}") from None
        self._open_chunk_since = None
        self._sync()

    # --- state ----------------------------------------------------------------------------

    @property
    def counts(self) -> dict[str, int]:
        """Messages written per topic (registered topics, in registration order)."""
        return {topic: entry.count for topic, entry in self._topics.items()}

    @property
    def message_count(self) -> int:
        """Messages written in total."""
        return sum(entry.count for entry in self._topics.values())

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Write the final rosbag2 metadata, the summary and the footer. Idempotent."""
        if self._closed:
            return
        try:
            self._writer.flush()
            self._write_metadata()
            self._writer.finish()
            self._sync(force=True)
        except OSError as exc:
            raise BagError(f"{self.path}: finalising failed: {exc.strerror}") from None
        finally:
            self._abort()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    # --- internals ------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise BagError(f"{self.path}: bag already closed")

    def _sync(self, force: bool = False) -> None:
        """Hand what is written to the OS (and to the disk with fsync or `force`)."""
        self._file.flush()
        if self._fsync or force:
            os.fsync(self._file.fileno())

    def _abort(self) -> None:
        if not self._closed:
            self._closed = True
            with contextlib.suppress(OSError):  # a failed flush was reported already
                self._file.close()

    def _write_metadata(self) -> None:
        """rosbag2's BagMetadata (version 9, keys in the order of its YAML encoder, yaml.hpp).

        Before any message the start is the largest int64 (its `nanoseconds::max()`)."""
        first, last = self._first_log_ns, self._last_log_ns
        start = {"nanoseconds_since_epoch": 2**63 - 1 if first is None else first}
        duration = {"nanoseconds": 0 if first is None or last is None else last - first}
        count = self.message_count
        topics = [
            {
                "topic_metadata": {
                    "name": topic,
                    "type": entry.type_name,
                    "serialization_format": MESSAGE_ENCODING,
                    "offered_qos_profiles": [p.to_dict() for p in entry.offered_qos],
                    "type_description_hash": entry.type_hash,
                },
                "message_count": entry.count,
            }
            for topic, entry in self._topics.items()
        ]
        metadata = {
            "version": 9,
            "storage_identifier": "mcap",
            "duration": duration,
            "starting_time": start,
            "message_count": count,
            "topics_with_message_count": topics,
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self._file_name],
            "files": [
                {
                    "path": self._file_name,
                    "starting_time": start,
                    "duration": duration,
                    "message_count": count,
                }
            ],
            "custom_data": None,
            "ros_distro": self._ros_distro,
        }
        self._writer.add_metadata(METADATA_NAME, {METADATA_KEY: dump_yaml(metadata)})


def _create(path: str, flags: int) -> int:
    """open()'s opener: a new bag is rw-r--r-- (before the umask), as before."""
    return os.open(path, flags, 0o644)
