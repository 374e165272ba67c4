"""CDR bytes of the simulation's own messages without rclpy's per-message conversion, and a
decoder of JointState: what `robot-calib simulate` sends through its graph 100k times.

rclpy publishes a Python message by converting it to C and serialising it (~40 us for a
JointState); the bytes here are built with `struct` from a template (~2 us) and published
as they are (`Publisher.publish(bytes)`: rclpy's raw path, the same bytes on the wire).
An encoder's bytes can be checked against the message they stand for (`check`: rclpy
deserialises them into that message); a caller falls back to the messages if they differ.
On the wire they are the bytes rclpy's own publishing sends (padding zeroed; test_cdr
compares what a subscriber receives both ways; `serialize_message` itself leaves its
padding and a few trailing bytes uninitialised, so it is no reference).

Layout (XCDR1, little endian, as Fast DDS writes it): a 4-byte encapsulation header
(00 01 00 00), then each field aligned to its size relative to the end of that header;
strings as uint32 length (including the NUL) + bytes + NUL; sequences as uint32 count +
elements.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any

from rclpy.serialization import deserialize_message

ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR, little endian


def _string(text: str, offset: int) -> tuple[bytes, int]:
    """A CDR string at payload offset `offset` (alignment padding first): bytes, new offset."""
    pad = -offset % 4
    raw = text.encode("utf-8") + b"\x00"
    out = b"\x00" * pad + struct.pack("<I", len(raw)) + raw
    return out, offset + len(out)


class JointStateEncoder:
    """sensor_msgs/JointState of fixed joint `names`, empty frame_id, positions only: the
    messages sim_robot publishes. `encode(sec, nanosec, positions)` -> CDR bytes."""

    def __init__(self, names: Sequence[str]) -> None:
        self.names = tuple(names)
        offset = 8  # stamp (int32 sec, uint32 nanosec)
        frame, offset = _string("", offset)
        body = frame + b"\x00" * (-offset % 4)
        offset += -offset % 4
        body += struct.pack("<I", len(self.names))
        offset += 4
        for name in self.names:
            text, offset = _string(name, offset)
            body += text
        body += b"\x00" * (-offset % 4)
        offset += -offset % 4
        body += struct.pack("<I", len(self.names))  # position count
        offset += 4
        pad = -offset % 8 if self.names else 0
        self._prefix = body + b"\x00" * pad
        offset += pad + 8 * len(self.names)
        # velocity and effort: empty sequences (uint32 count 0 each, 4-aligned)
        self._suffix = b"\x00" * (-offset % 4) + struct.pack("<II", 0, 0)
        self._head = struct.Struct("<4siI")
        self._doubles = struct.Struct(f"<{len(self.names)}d")

    def encode(self, sec: int, nanosec: int, positions: Sequence[float]) -> bytes:
        return b"".join(
            (
                self._head.pack(ENCAPSULATION, sec, nanosec),
                self._prefix,
                self._doubles.pack(*positions),
                self._suffix,
            )
        )

    def decode(self, data: bytes) -> tuple[int, int, tuple[float, ...]] | None:
        """(sec, nanosec, positions) of bytes laid out as `encode`'s (these names in this
        order, empty frame_id, no velocity or effort); None for any other JointState."""
        head, prefix, suffix = self._head.size, self._prefix, self._suffix
        end = head + len(prefix) + self._doubles.size
        if (
            len(data) != end + len(suffix)
            or data[:4] != ENCAPSULATION
            or data[head : head + len(prefix)] != prefix
            or data[end:] != suffix
        ):
            return None
        _, sec, nanosec = self._head.unpack_from(data)
        return sec, nanosec, self._doubles.unpack_from(data, head + len(prefix))

    def message(self, sec: int, nanosec: int, positions: Sequence[float]) -> Any:  # noqa: ANN401
        """The JointState the bytes of `encode` stand for."""
        from sensor_msgs.msg import JointState

        msg = JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        msg.name = list(self.names)
        msg.position = [float(p) for p in positions]
        return msg

    def check(self, sec: int, nanosec: int, positions: Sequence[float]) -> bool:
        """rclpy reads the bytes of `encode` as `message`."""
        msg = self.message(sec, nanosec, positions)
        return _reads_as(self.encode(sec, nanosec, positions), msg)


class PointStampedEncoder:
    """geometry_msgs/PointStamped in frame `frame_id`: `encode(sec, nanosec, x, y, z)`."""

    def __init__(self, frame_id: str) -> None:
        self.frame_id = frame_id
        frame, offset = _string(frame_id, 8)
        self._frame = frame + b"\x00" * (-offset % 8)
        self._head = struct.Struct("<4siI")
        self._point = struct.Struct("<3d")

    def encode(self, sec: int, nanosec: int, x: float, y: float, z: float) -> bytes:
        return b"".join(
            (
                self._head.pack(ENCAPSULATION, sec, nanosec),
                self._frame,
                self._point.pack(x, y, z),
            )
        )

    def message(self, sec: int, nanosec: int, x: float, y: float, z: float) -> Any:  # noqa: ANN401
        """The PointStamped the bytes of `encode` stand for."""
        from geometry_msgs.msg import Point, PointStamped
        from std_msgs.msg import Header

        msg = PointStamped(header=Header(frame_id=self.frame_id), point=Point(x=x, y=y, z=z))
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        return msg

    def check(self, sec: int, nanosec: int, x: float, y: float, z: float) -> bool:
        """rclpy reads the bytes of `encode` as `message`."""
        return _reads_as(self.encode(sec, nanosec, x, y, z), self.message(sec, nanosec, x, y, z))


class ClockEncoder:
    """rosgraph_msgs/Clock: `encode(sec, nanosec)`."""

    def __init__(self) -> None:
        self._struct = struct.Struct("<4siI")

    def encode(self, sec: int, nanosec: int) -> bytes:
        return self._struct.pack(ENCAPSULATION, sec, nanosec)

    def message(self, sec: int, nanosec: int) -> Any:  # noqa: ANN401
        """The Clock the bytes of `encode` stand for."""
        from rosgraph_msgs.msg import Clock

        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = sec, nanosec
        return msg

    def check(self, sec: int, nanosec: int) -> bool:
        """rclpy reads the bytes of `encode` as `message`."""
        return _reads_as(self.encode(sec, nanosec), self.message(sec, nanosec))


_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")


def decode_joint_state(data: bytes) -> tuple[int, int, list[str], tuple[float, ...]] | None:
    """(sec, nanosec, names, positions) of a JointState's CDR bytes (little endian XCDR1);
    None for anything else (big endian, truncated, malformed): decode those with rclpy."""
    try:
        if data[:4] != ENCAPSULATION:
            return None
        view = memoryview(data)[4:]
        sec, nanosec = _STAMP.unpack_from(view, 0)
        (length,) = _U32.unpack_from(view, 8)
        offset = 12 + length  # frame_id
        offset += -offset % 4
        (count,) = _U32.unpack_from(view, offset)
        offset += 4
        names = []
        for _ in range(count):
            offset += -offset % 4
            (length,) = _U32.unpack_from(view, offset)
            if length == 0 or offset + 4 + length > len(view):
                return None
            names.append(bytes(view[offset + 4 : offset + 3 + length]).decode("utf-8"))
            offset += 4 + length
        offset += -offset % 4
        (n_positions,) = _U32.unpack_from(view, offset)
        offset += 4
        if n_positions:
            offset += -offset % 8
        if offset + 8 * n_positions > len(view):
            return None
        positions = struct.unpack_from(f"<{n_positions}d", view, offset)
    except (struct.error, UnicodeDecodeError, IndexError):
        return None
    return sec, nanosec, names, positions


def _reads_as(data: bytes, msg: Any) -> bool:  # noqa: ANN401 - any ROS message
    """rclpy deserialises `data` into a message equal to `msg`."""
    try:
        return bool(deserialize_message(data, type(msg)) == msg)
    except Exception:  # noqa: BLE001 - any failure to read them: not the message
        return False
