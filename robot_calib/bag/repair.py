"""Repair a recording whose writer was killed: copy every complete message into a new bag.

A writer killed by SIGKILL, a power loss or a closed terminal leaves an MCAP file without
summary or footer; its closed chunks are intact, the chunk it held open is lost.
`repair_bag` reads what survived (`BagReader(..., allow_truncated=True)`) and writes it
again with `BagWriter`, so the output is the contract's bag (msgs_doc/specification.md section 1):
indexed, with the same topics, types, message definitions, offered QoS, type hashes,
receive/publish times, sequence numbers and ROS distro. An intact bag is copied the same
way. The output is written to a temporary file beside it and renamed at the end: it is
complete or absent, never half-written; neither the input nor an existing file is ever
overwritten.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path

from robot_calib.bag.mcap_reader import BagReader
from robot_calib.bag.mcap_writer import BagWriter
from robot_calib.bag.ros2_formats import MESSAGE_ENCODING
from robot_calib.errors import EXISTS, BagError, InputError


@dataclass(frozen=True)
class RepairReport:
    """What `repair_bag` recovered.

    recovered: messages copied per topic (every topic of the source, in channel order).
    source_complete: True if the source was closed properly (nothing needed repair).
    bytes_lost: bytes after the source's last complete record [B] (a record cut by the
    crash, usually 0: a killed writer held its open chunk in memory); 0 for a complete bag.
    messages_lost: 0 for a complete source; None for a truncated one, whose open chunk
    (at most `chunk_size` bytes or `max_chunk_age` seconds of messages) is not in the file,
    so how many it held is unknown.
    """

    source: Path
    output: Path
    recovered: dict[str, int]
    source_complete: bool
    bytes_lost: int
    messages_lost: int | None

    @property
    def total(self) -> int:
        """Messages copied in total."""
        return sum(self.recovered.values())

    def summary(self) -> str:
        """'OUT: recovered N messages (/topic=n, ...) of a truncated recording' (one line)."""
        per_topic = ", ".join(f"{topic}={n}" for topic, n in self.recovered.items())
        text = f"{self.output}: recovered {self.total} messages ({per_topic})"
        if self.source_complete:
            return text + "; the recording was complete"
        text += " of a truncated recording"
        if self.bytes_lost:
            text += f" ({self.bytes_lost} bytes of a record cut by the crash dropped)"
        return text


def repair_bag(source: Path, output: Path, force: bool = False) -> RepairReport:
    """Copy every complete message of the bag `source` into the new bag `output`.

    Raises InputError if `output` is `source`, exists (unless `force`: then it is replaced
    whole, at the final rename) or has no folder; BagError if
    `source` is not a readable ros2 MCAP bag or holds no complete message. Nothing is
    written then.

    Returns
    -------
    report : RepairReport
        Messages recovered per topic, whether the source was complete, what was lost.
    """
    source, output = Path(source), Path(output)
    _check_output(source, output, force)
    with BagReader(source, allow_truncated=True) as reader:
        if reader.message_count == 0:
            raise BagError(
                f"{source}: no complete message to recover (its writer stopped before the "
                "first chunk was written)"
            )
        for info in reader.topics.values():
            if info.message_encoding != MESSAGE_ENCODING:
                raise BagError(
                    f"{source}: topic {info.topic} has message encoding "
                    f"{info.message_encoding!r}, not {MESSAGE_ENCODING!r}"
                )
        tmp = output.with_name(f".{output.name}.{os.getpid()}.tmp")
        distro = _ros_distro(reader)
        # BagWriter never overwrites: an existing `tmp` is an error, and not ours to remove;
        # one it created and could not start (a full disk at the header) is removed
        existed = tmp.exists() or tmp.is_symlink()
        try:
            writer = BagWriter(tmp, ros_distro=distro, file_name=output.name)
        except BaseException:
            if not existed:
                with contextlib.suppress(OSError):
                    tmp.unlink()
            raise
        try:
            with writer:
                for info in reader.topics.values():
                    writer.add_topic(
                        info.topic,
                        info.type_name,
                        offered_qos=info.offered_qos,
                        type_hash=info.type_hash,
                        definition=(info.schema_encoding, info.definition)
                        if info.schema_encoding
                        else None,  # no schema recorded: the installed definition
                    )
                for m in reader.messages():
                    writer.write(m.topic, m.data, m.log_time_ns, m.publish_time_ns, m.sequence)
                recovered = writer.counts
            if force:
                os.replace(tmp, output)  # the repair replaces it whole, never in part
            else:
                _rename_new(tmp, output)
        except BaseException:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise
        return RepairReport(
            source=source,
            output=output,
            recovered=recovered,
            source_complete=reader.complete,
            bytes_lost=source.stat().st_size - reader.complete_bytes,
            messages_lost=0 if reader.complete else None,
        )


def _check_output(source: Path, output: Path, force: bool = False) -> None:
    """The output must be a new file (an existing one only with `force`, never a folder) in
    an existing folder, never the source (not even with `force`)."""
    if output.exists() or output.is_symlink():
        if source.exists() and output.resolve() == source.resolve():
            raise InputError(f"{output}: is the bag to repair; will not overwrite it")
        if output.is_dir():
            raise InputError(f"{output}: is a folder; give a file name for the repaired bag")
        if not force:
            raise InputError(f"{output}: {EXISTS}")
    if not output.parent.is_dir():
        raise InputError(f"{output.parent}: no such folder for the repaired bag")


def _rename_new(tmp: Path, output: Path) -> None:
    """Move `tmp` to `output` unless `output` appeared meanwhile (a hard link fails on an
    existing name, where a rename would replace it)."""
    try:
        os.link(tmp, output)
    except FileExistsError:
        raise InputError(f"{output}: exists; will not overwrite it") from None
    except OSError:  # a file system without hard links
        if output.exists():
            raise InputError(f"{output}: exists; will not overwrite it") from None
        os.replace(tmp, output)
        return
    tmp.unlink()


def _ros_distro(reader: BagReader) -> str:
    """The source's `ros_distro` from its rosbag2 metadata ('' if it recorded none)."""
    text = reader.rosbag2_metadata()
    if text is None:
        return ""
    import yaml  # PyYAML, as for the QoS profiles

    try:
        metadata = yaml.safe_load(text)
    except yaml.YAMLError:
        return ""
    if isinstance(metadata, dict) and "rosbag2_bagfile_information" in metadata:
        metadata = metadata["rosbag2_bagfile_information"]
    distro = metadata.get("ros_distro") if isinstance(metadata, dict) else None
    return distro if isinstance(distro, str) else ""
