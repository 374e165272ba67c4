"""Decode a channel's CDR messages in bulk when they share one layout: numpy views instead
of mcap_ros2's per-message decoding, with the same values bit for bit.

The layout of the first message is walked from the schema exactly as mcap_ros2's decoder
walks it (its own parsed definitions, alignment relative to the 4-byte encapsulation
header, its `builtin_interfaces/Time` with an unsigned `sec`): every numeric field (and
numeric array) gets an offset and a dtype; every byte the decoder reads for anything else
(the encapsulation kind, string and sequence lengths, string characters, 1-byte fields) is
structure. When all payloads have the first one's size and structure bytes, every message
decodes along the same path, so its numeric fields are fixed-offset columns of the payload
rows (one structured dtype view). The first and last messages are also decoded by
mcap_ros2 and must agree. Anything else gives None: the caller decodes message by message.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from robot_calib.bag.mcap_reader import ChannelMessages

_NUMERIC = {
    "int16": "i2",
    "uint16": "u2",
    "int32": "i4",
    "uint32": "u4",
    "int64": "i8",
    "uint64": "u8",
    "float32": "f4",
    "float64": "f8",
}
"""Primitive types read as values (mcap_ros2 aligns each to its size); the 1-byte ones
(bool, byte, char, int8, uint8) count as structure."""
_ONE_BYTE = ("bool", "byte", "char", "int8", "uint8")


class _NotFixed(Exception):
    """The message's layout is not one this module decodes in bulk."""


@dataclass(frozen=True)
class Columns:
    """A channel's messages decoded in bulk.

    fields: {dotted path: values (n,) or (n, k) in native byte order}, for every numeric
    field ('header.stamp.sec', 'position', 'pose.orientation.w', ...; arrays of messages
    as 'name[i].field'); first: the first message as mcap_ros2 decodes it (its strings and
    sequences of strings are every message's).
    """

    fields: dict[str, npt.NDArray[Any]]
    first: Any

    def __len__(self) -> int:
        return len(next(iter(self.fields.values()))) if self.fields else 0


def _msgdefs(schema_name: str, text: str) -> dict[str, Any]:
    """The parsed definitions mcap_ros2's decoder uses for this schema."""
    from mcap_ros2._dynamic import TimeDefinition, _for_each_msgdef

    msgdefs: dict[str, Any] = {
        "builtin_interfaces/Time": TimeDefinition,
        "builtin_interfaces/Duration": TimeDefinition,
    }

    def handle(name: str, short_name: str, msgdef: Any) -> None:
        msgdefs[name] = msgdefs[short_name] = msgdef

    _for_each_msgdef(schema_name, text, handle)
    return msgdefs


class _Walk:
    """The layout of one message along mcap_ros2's `_read_complex_type`."""

    def __init__(self, data: bytes, msgdefs: dict[str, Any]) -> None:
        self.data, self.msgdefs = data, msgdefs
        self.offset = 4
        self.little = data[1] & 1 == 1
        self.structure: list[tuple[int, int]] = [(1, 2)]  # (start, end) byte ranges read
        self.fields: list[
            tuple[str, int, str, int]
        ] = []  # path, offset, dtype, count (-1: scalar)

    def _take(self, size: int) -> int:
        """Advance over `size` bytes aligned to `size` (CdrReader._unpack); their offset."""
        if size > 1:
            self.offset += -(self.offset - 4) % size
        start = self.offset
        self.offset += size
        if self.offset > len(self.data):
            raise _NotFixed("message shorter than its layout")
        return start

    def _uint32(self) -> int:
        start = self._take(4)
        self.structure.append((start, start + 4))
        return int.from_bytes(self.data[start : start + 4], "little" if self.little else "big")

    def _string(self) -> None:
        length = self._uint32()
        if length > 1:
            self.structure.append((self.offset, self.offset + length))
        self.offset += length
        if self.offset > len(self.data):
            raise _NotFixed("string beyond the message")

    def message(self, msgdef: Any, path: str) -> None:
        if len(msgdef.fields) == 0:
            start = self._take(1)
            self.structure.append((start, start + 1))
        for field in msgdef.fields:
            ftype, name = field.type, f"{path}{field.name}"
            fixed = ftype.is_fixed_size_array() and ftype.array_size is not None
            if not ftype.is_primitive_type():
                nested = self.msgdefs.get(f"{ftype.pkg_name}/{ftype.type}")
                if nested is None:
                    raise _NotFixed(f"no definition of {ftype.type}")
                if ftype.is_array:
                    count = ftype.array_size if fixed else self._uint32()
                    for i in range(count):
                        self.message(nested, f"{name}[{i}].")
                else:
                    self.message(nested, f"{name}.")
            elif ftype.type in _NUMERIC:
                code = _NUMERIC[ftype.type]
                size = int(code[1])
                if not ftype.is_array:
                    self.fields.append((name, self._take(size), code, -1))
                    continue
                count = ftype.array_size if fixed else self._uint32()
                first = self._take(size) if count else self.offset
                self.offset = first + size * count
                if self.offset > len(self.data):
                    raise _NotFixed("array beyond the message")
                self.fields.append((name, first, code, count))
            elif ftype.type in _ONE_BYTE:
                count = (
                    1 if not ftype.is_array else (ftype.array_size if fixed else self._uint32())
                )
                self.structure.append((self.offset, self.offset + count))
                self.offset += count
                if self.offset > len(self.data):
                    raise _NotFixed("bytes beyond the message")
            elif ftype.type == "string":
                for _ in range(
                    1 if not ftype.is_array else (ftype.array_size if fixed else self._uint32())
                ):
                    self._string()
            else:
                raise _NotFixed(f"type {ftype.type}")


def _value(message: Any, path: str) -> Any:
    """The field at a dotted path ('a.b[2].c') of a decoded message."""
    for part in path.split("."):
        name, _, index = part.partition("[")
        message = getattr(message, name)
        if index:
            message = message[int(index[:-1])]
    return message


def _agrees(column: npt.NDArray[Any], value: Any) -> bool:
    """A bulk value equals mcap_ros2's (NaN equal to NaN)."""
    ours = np.asarray(column)
    theirs = np.asarray(value, dtype=ours.dtype)
    return ours.shape == theirs.shape and bool(
        np.all((ours == theirs) | (np.isnan(ours) & np.isnan(theirs)))
        if ours.dtype.kind == "f"
        else np.all(ours == theirs)
    )


_LAYOUTS: dict[tuple[str, str], dict[str, Any]] = {}


def decode_columns(messages: ChannelMessages) -> Columns | None:
    """The channel's messages decoded in bulk (`Columns`), or None when they do not share
    one layout (or the channel is not CDR with a `ros2msg` schema, or has no messages).
    The first and last are also decoded by mcap_ros2 (`messages.decode`) to check."""
    schema = messages.schema
    rows = messages.fixed()
    if (
        rows is None
        or schema is None
        or schema.encoding != "ros2msg"
        or messages.channel.message_encoding != "cdr"
        or rows.shape[1] < 4
    ):
        return None
    first_data = rows[0].tobytes()
    try:
        key = (schema.name, schema.data.decode())
        msgdefs = _LAYOUTS.get(key)
        if msgdefs is None:
            msgdefs = _LAYOUTS.setdefault(key, _msgdefs(*key))
        walk = _Walk(first_data, msgdefs)
        walk.message(msgdefs[schema.name], "")
    except Exception:  # a schema mcap_ros2 parses otherwise, or a layout not walked here
        return None
    size = rows.shape[1]
    structure = np.zeros(size, dtype=bool)
    for start, end in walk.structure:
        structure[start:end] = True
    shape = rows[:, structure]
    if not (shape == shape[0]).all():
        return None
    order = "<" if walk.little else ">"
    dtype = np.dtype(
        {
            "names": [f[0] for f in walk.fields],
            "formats": [
                order + f[2] if f[3] < 0 else (order + f[2], (f[3],)) for f in walk.fields
            ],
            "offsets": [f[1] for f in walk.fields],
            "itemsize": size,
        }
    )
    table = rows.view(dtype).reshape(-1)
    fields = {
        name: np.ascontiguousarray(table[name]).astype(table[name].dtype.newbyteorder("="))
        for name in dtype.names or ()
    }
    try:
        first = messages.decode(first_data)
        last = messages.decode(rows[-1].tobytes())
        if not all(
            _agrees(column[0], _value(first, name)) and _agrees(column[-1], _value(last, name))
            for name, column in fields.items()
        ):
            return None
    except Exception:  # BagError from the decoder: the caller's message-by-message reading says it
        return None
    return Columns(fields, first)
