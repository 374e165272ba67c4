"""What `ros2 bag record -s mcap` (ROS 2 Jazzy, rosbag2 0.26) puts into an MCAP file.

ROS-free (stdlib only). Each format below follows the rosbag2 source that writes it:

- schema: `ros2msg` full text, rosbag2_cpp `LocalMessageDefinitionSource::get_full_text`:
  the type's .msg text, then per dependency (sorted, depth first, each once)
  `"\\n" + "=" * 80 + "\\nMSG: pkg/Type\\n" + its text` (`ros2idl` with `IDL:` when a
  type has no .msg file).
- channel metadata `offered_qos_profiles`: rosbag2_storage `serialize_rclcpp_qos_vector`
  (YAML::Dump of a sequence, metadata version 9: policy names as rmw strings, durations as
  {sec, nsec}); `topic_type_hash`: the RIHS01 type description hash.
- metadata record `rosbag2` with key `serialized_metadata`: YAML::Dump of the BagMetadata
  (rosbag2_storage yaml.hpp, version 9), written when the bag opens and again when it closes
  (`BagWriter` builds it).
"""

from __future__ import annotations

import json
import os
import re
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

PROFILE = "ros2"
MESSAGE_ENCODING = "cdr"
SCHEMA_ENCODING_MSG = "ros2msg"
SCHEMA_ENCODING_IDL = "ros2idl"
METADATA_NAME = "rosbag2"
METADATA_KEY = "serialized_metadata"

Duration = tuple[int, int]
"""An rmw_time_t: (sec, nsec)."""

DURATION_INFINITE: Duration = (9223372036, 854775807)  # RMW_DURATION_INFINITE
DURATION_UNSPECIFIED: Duration = (0, 0)  # RMW_DURATION_UNSPECIFIED

# rmw enum order (rmw/types.h); metadata version <= 8 stored these integers.
HISTORY = ("system_default", "keep_last", "keep_all", "unknown")
RELIABILITY = ("system_default", "reliable", "best_effort", "unknown", "best_available")
DURABILITY = ("system_default", "transient_local", "volatile", "unknown", "best_available")
LIVELINESS = (
    "system_default",
    "automatic",
    "manual_by_node",
    "manual_by_topic",
    "unknown",
    "best_available",
)

_POLICIES = {
    "history": HISTORY,
    "reliability": RELIABILITY,
    "durability": DURABILITY,
    "liveliness": LIVELINESS,
}
_DURATIONS = ("deadline", "lifespan", "liveliness_lease_duration")
_DELIMITER = "=" * 80 + "\n"
_PRIMITIVES = frozenset(
    ("bool", "byte", "char", "float32", "float64", "string")
    + tuple(f"{sign}int{bits}" for sign in ("", "u") for bits in (8, 16, 32, 64))
)
# Same patterns as local_message_definition_source.cpp.
_MSG_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_IDL_INCLUDE = re.compile(r'(?:^|\n)#include\s+(?:"|<)([a-zA-Z0-9_/]+)\.idl(?:"|>)')
_ROS_NAME = r"[a-zA-Z][a-zA-Z0-9_]*"
_TYPE_NAME = re.compile(rf"({_ROS_NAME})/(?:({_ROS_NAME})/)?({_ROS_NAME})\Z")
_MAX_DEPTH = 50


@dataclass(frozen=True)
class QosProfile:
    """One offered QoS profile as rosbag2 records it (rmw policy names, durations (sec, nsec)).

    Publishers discovered through DDS report history `unknown` and depth 0 (the depth is not
    part of discovery), so a recorded profile says nothing reliable about the history.
    """

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline: Duration = DURATION_UNSPECIFIED
    lifespan: Duration = DURATION_UNSPECIFIED
    liveliness: str = "system_default"
    liveliness_lease_duration: Duration = DURATION_UNSPECIFIED
    avoid_ros_namespace_conventions: bool = False

    def to_dict(self) -> dict[str, Any]:
        """The YAML mapping, keys in rosbag2's order (the fields' order)."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        return values | {key: dict(zip(("sec", "nsec"), values[key])) for key in _DURATIONS}

    @classmethod
    def from_dict(cls, item: dict[str, Any]) -> QosProfile:
        """Parse one profile (metadata v9 names or v<=8 integers); ValueError if malformed."""
        try:
            values = {f.name: item[f.name] for f in fields(cls)}
            values |= {key: _policy(values[key], names) for key, names in _POLICIES.items()}
            values |= {key: _duration(values[key]) for key in _DURATIONS}
            values["depth"] = int(values["depth"])
            key = "avoid_ros_namespace_conventions"
            return cls(**values | {key: bool(values[key])})
        except (KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"malformed QoS profile {item!r}: {exc!r}") from None


def _policy(value: Any, names: Sequence[str]) -> str:
    if isinstance(value, bool):
        raise ValueError(f"bad QoS policy value {value!r}")
    if isinstance(value, int):
        return names[value]
    value = str(value).lower()
    if value not in names:
        raise ValueError(f"unknown QoS policy {value!r} (known: {', '.join(names)})")
    return value


def _duration(value: dict[str, Any]) -> Duration:
    return int(value["sec"]), int(value["nsec"])


def duration_from_ns(ns: int) -> Duration:
    """Integer nanoseconds -> (sec, nsec); 2**63 - 1 ns gives DURATION_INFINITE."""
    return ns // 1_000_000_000, ns % 1_000_000_000


def qos_profiles_to_yaml(profiles: Iterable[QosProfile]) -> str:
    """Channel metadata `offered_qos_profiles`: YAML::Dump of the sequence (no final newline)."""
    return dump_yaml([p.to_dict() for p in profiles])


def qos_profiles_from_yaml(text: str) -> tuple[QosProfile, ...]:
    """Parse `offered_qos_profiles` (either metadata version); ValueError if malformed."""
    import yaml  # PyYAML; imported here so the writer needs no YAML parser

    if not text.strip():
        return ()
    try:
        items = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"offered_qos_profiles is not YAML: {exc}") from None
    if items is None:
        return ()
    if not isinstance(items, list):
        raise ValueError(f"offered_qos_profiles is not a sequence: {items!r}")
    return tuple(QosProfile.from_dict(item) for item in items)


# --- YAML as yaml-cpp's YAML::Dump writes it (block style, indented sequences) ------------
# Not rosbags' emitter (ruamel.yaml): it sorts keys, writes '' and null, does not indent
# sequences under a key and puts an empty list on the key's line; the bytes would change.

_PLAIN = re.compile(r"[A-Za-z_/][A-Za-z0-9_./\-]*\Z")
_YAML_WORDS = frozenset(("true", "false", "yes", "no", "on", "off", "y", "n", "null", "~"))


def _scalar(value: Any) -> str:
    if value is None:
        return "~"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    text = str(value)
    if _PLAIN.match(text) and text.lower() not in _YAML_WORDS:
        return text
    return json.dumps(text)  # a JSON string is a valid double-quoted YAML scalar


def _block(value: Any, indent: int) -> list[str]:
    pad = " " * indent
    lines: list[str] = []
    if isinstance(value, dict):
        for key, item in value.items():
            if isinstance(item, dict | list) and not item:
                lines += [f"{pad}{key}:", f"{pad}  {'{}' if isinstance(item, dict) else '[]'}"]
            elif isinstance(item, dict | list):
                lines += [f"{pad}{key}:", *_block(item, indent + 2)]
            else:
                lines.append(f"{pad}{key}: {_scalar(item)}")
        return lines
    if isinstance(value, list):
        for item in value:
            if isinstance(item, dict) and item:
                inner = _block(item, indent + 2)
                lines += [f"{pad}- {inner[0][indent + 2 :]}", *inner[1:]]
            elif isinstance(item, dict | list):
                raise ValueError(f"cannot dump {item!r} inside a sequence")
            else:
                lines.append(f"{pad}- {_scalar(item)}")
        return lines
    return [f"{pad}{_scalar(value)}"]


def dump_yaml(value: Any) -> str:
    """Block-style YAML as yaml-cpp's YAML::Dump emits it, without a final newline."""
    if isinstance(value, dict | list) and not value:
        return "{}" if isinstance(value, dict) else "[]"
    return "\n".join(_block(value, 0))


# --- message definitions and type hashes from the installed interface files ----------------
# The definition text is not rosbags' generate_msgdef: that one is rebuilt from the parsed
# fields (no comments or blank lines, another dependency order), rosbag2 stores the files.


def interface_prefixes() -> list[Path]:
    """Install prefixes searched for share/<pkg>/msg/*.msg: AMENT_PREFIX_PATH, then sys.prefix.

    sys.prefix covers the ROS 2 wheels installed into a virtualenv (they ship share/ there).
    """
    paths = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return [*paths, Path(sys.prefix)]


def _split_type(type_name: str) -> tuple[str, str, str]:
    """'pkg/msg/Type' or 'pkg/Type' -> (pkg, namespace, Type); ValueError otherwise."""
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise ValueError(f"invalid ROS type name {type_name!r} (want pkg/msg/Type)")
    package, namespace, name = match.groups()
    return package, namespace or "msg", name


def _share_dir(package: str, prefixes: Sequence[Path]) -> Path | None:
    """The package's share directory, as the ament index would find it."""
    marker = Path("share/ament_index/resource_index/packages") / package
    for prefix in prefixes:
        if (prefix / marker).is_file():
            return prefix / "share" / package
    for prefix in prefixes:  # an install without ament index markers
        if (prefix / "share" / package).is_dir():
            return prefix / "share" / package
    return None


def _interface_file(type_name: str, suffix: str, prefixes: Sequence[Path]) -> Path | None:
    package, namespace, name = _split_type(type_name)
    share = _share_dir(package, prefixes)
    if share is None:
        return None
    path = share / namespace / f"{name}{suffix}"
    return path if path.is_file() else None


class DefinitionNotFoundError(LookupError):
    """No interface file (.msg / .idl) for a type under the searched prefixes."""


def _dependencies(text: str, package: str, fmt: str) -> list[str]:
    if fmt == SCHEMA_ENCODING_IDL:
        return sorted(set(_IDL_INCLUDE.findall(text)))
    deps = set()
    for field_type in _MSG_FIELD_TYPE.findall(text):
        if field_type in _PRIMITIVES:
            continue
        deps.add(field_type if "/" in field_type else f"{package}/{field_type}")
    return sorted(deps)  # std::set<std::string> order


def message_definition(type_name: str, prefixes: Sequence[Path] | None = None) -> tuple[str, str]:
    """(schema encoding, full definition text) of a ROS type, as rosbag2 stores the schema.

    type_name: 'pkg/msg/Type'. Reads the .msg files (falling back to .idl) installed under
    `prefixes` (default `interface_prefixes()`). Raises DefinitionNotFoundError.
    """
    prefixes = interface_prefixes() if prefixes is None else list(prefixes)
    suffixes = {SCHEMA_ENCODING_MSG: ".msg", SCHEMA_ENCODING_IDL: ".idl"}
    header = {SCHEMA_ENCODING_MSG: "MSG: ", SCHEMA_ENCODING_IDL: "IDL: "}

    def full_text(fmt: str) -> str:
        seen: set[str] = set()

        def append(name: str, depth: int) -> str:
            if depth <= 0:
                raise DefinitionNotFoundError(f"recursion too deep resolving {type_name}")
            path = _interface_file(name, suffixes[fmt], prefixes)
            if path is None:
                raise DefinitionNotFoundError(f"no {suffixes[fmt]} file for {name}")
            text = path.read_text(encoding="utf-8")
            result = text
            for dep in _dependencies(text, _split_type(name)[0], fmt):
                if dep not in seen:
                    seen.add(dep)
                    result += "\n" + _DELIMITER + header[fmt] + dep + "\n"
                    result += append(dep, depth - 1)
            return result

        body = append(type_name, _MAX_DEPTH)
        if fmt == SCHEMA_ENCODING_IDL:
            body = _DELIMITER + header[fmt] + type_name + "\n" + body
        return body

    try:
        return SCHEMA_ENCODING_MSG, full_text(SCHEMA_ENCODING_MSG)
    except DefinitionNotFoundError as msg_error:
        try:
            return SCHEMA_ENCODING_IDL, full_text(SCHEMA_ENCODING_IDL)
        except DefinitionNotFoundError:
            searched = ", ".join(str(p) for p in prefixes)
            raise DefinitionNotFoundError(f"{msg_error} (searched {searched})") from None


def typestore(*type_names: str) -> Typestore:
    """A rosbags typestore with these types ('pkg/msg/Type') and their dependencies, parsed
    from the definitions `message_definition` gives (what a bag's schema holds): CDR and
    RIHS01 hashes are those of the installed interfaces, not of rosbags' bundled copy of
    the distro. Raises DefinitionNotFoundError, or ValueError for a text it cannot parse."""
    from rosbags.typesys import (
        Stores,
        TypesysError,
        get_types_from_idl,
        get_types_from_msg,
        get_typestore,
    )

    store = get_typestore(Stores.EMPTY)
    for type_name in type_names:
        encoding, text = message_definition(type_name)
        try:
            if encoding == SCHEMA_ENCODING_MSG:
                store.register(get_types_from_msg(text, type_name))
            else:  # sections "IDL: pkg/msg/Type\n<idl>", each after a delimiter line
                for section in text.split(_DELIMITER)[1:]:
                    store.register(get_types_from_idl(section.split("\n", 1)[1]))
        except TypesysError as exc:
            raise ValueError(f"cannot parse the definition of {type_name}: {exc}") from None
    return store


def type_description_hash(type_name: str) -> str:
    """'RIHS01_<hex>' of a type (rosbags' `hash_rihs01` of `typestore(type_name)`), '' if
    its definition is not installed. Equals the hash rclpy reports as
    `TopicEndpointInfo.topic_type_hash` (rosidl's share/<pkg>/msg/<Type>.json)."""
    try:
        return typestore(type_name).hash_rihs01(type_name)
    except (DefinitionNotFoundError, ValueError, OSError):
        return ""
