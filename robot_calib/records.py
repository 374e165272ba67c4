"""Typed result records: frozen dataclasses that turn into the JSON documents of msgs_doc/
and back, so code reads attributes and only files hold nested dicts.

`Record.to_dict()` is `dataclasses.asdict` (field names are the JSON keys);
`Record.from_dict(data)` rebuilds nested records, lists and optionals from the field types.
Keys a record does not know are ignored on reading (documents are extended, never broken).
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar, get_args, get_origin, get_type_hints

from robot_calib.errors import InputError

R = TypeVar("R", bound="Record")


def _build(hint: Any, value: Any) -> Any:
    """`value` read from JSON as the type `hint` (records, lists, tuples, optionals)."""
    if value is None:
        return None
    origin = get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        options = [a for a in get_args(hint) if a is not type(None)]
        return _build(options[0], value) if len(options) == 1 else value
    if origin in (list, tuple):
        args = get_args(hint)
        item = args[0] if args else Any
        built = [_build(item, v) for v in value]
        return built if origin is list else tuple(built)
    if isinstance(hint, type) and issubclass(hint, Record):
        return hint.from_dict(value)
    if hint is float and isinstance(value, int):
        return float(value)
    return value


class Record:
    """Mixin for frozen dataclasses that are (parts of) a JSON document."""

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready mapping of this record (nested records become mappings)."""
        return dataclasses.asdict(self)  # type: ignore[call-overload]

    @classmethod
    def from_dict(cls: type[R], data: Mapping[str, Any]) -> R:
        """The record of a mapping written by `to_dict` (InputError when a field lacks)."""
        if not isinstance(data, Mapping):
            raise InputError(f"{cls.__name__}: expected a mapping, got {type(data).__name__}")
        hints = get_type_hints(cls)
        values = {}
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if f.name in data:
                values[f.name] = _build(hints[f.name], data[f.name])
            elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise InputError(f"{cls.__name__}: missing {f.name!r}")
        return cls(**values)
