"""Effects: additions to the kinematic model, one module per contract name, and their registry.

Everything outside this package reaches effects through the registry, never by name:
`make_effect(name, joints, **options)` builds one, `parse_effect('backlash:4')` reads the
text form and `effect_from_dict` the file form; `vocabulary()` lists the contract's effects.
A new effect is one new module in this package whose class is decorated with
`@register_effect`: every module here is imported (`discover_effects`) when the package is.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import fields
from typing import Any, get_origin, get_type_hints

from robot_calib.effects.base import EFFECTS, Contribution, Effect, register_effect
from robot_calib.errors import InputError, check_keys
from robot_calib.kinematics.description import RobotDescription
from robot_calib.poses import Poses


def discover_effects() -> tuple[str, ...]:
    """Import every module of this package (every folder of its `__path__`), so that each
    registers its effect; returns the registered names in registry order."""
    for info in pkgutil.iter_modules(__path__):
        if info.name != "base":
            importlib.import_module(f"{__name__}.{info.name}")
    return tuple(EFFECTS)


discover_effects()

from robot_calib.effects.backlash import Backlash  # noqa: E402 - the seed's effects, below
from robot_calib.effects.eccentricity import Eccentricity  # noqa: E402


@contextmanager
def registered(cls: type[Effect]) -> Iterator[type[Effect]]:
    """The registry with `cls` added for the duration of a `with` block (tests, plug-ins
    tried out): everything that loops over the registry sees it, then it is gone."""
    register_effect(cls)
    try:
        yield cls
    finally:
        EFFECTS.pop(cls.name, None)


def vocabulary() -> tuple[str, ...]:
    """Names of the contract's effects (section 3) the identifier and the ladder may use."""
    return tuple(name for name, cls in EFFECTS.items() if cls.in_vocabulary)


def effect_class(name: str) -> type[Effect]:
    """The registered class called `name`; InputError listing the known names otherwise."""
    if name not in EFFECTS:
        raise InputError(f"unknown effect {name!r} (known: {', '.join(EFFECTS)})")
    return EFFECTS[name]


def option_types(cls: type[Effect]) -> dict[str, type]:
    """The options of an effect class (dataclass fields besides `joints`) and their types."""
    hints = get_type_hints(cls)
    return {f.name: hints[f.name] for f in fields(cls) if f.name != "joints"}


def _option_value(kind: Any, raw: str) -> Any:  # noqa: ANN401 - an option's type
    """An option's value from its text: a tuple option (joint_harmonics' orders) from
    '11,27', anything else by its type."""
    if get_origin(kind) is tuple:
        return tuple(int(v) for v in raw.split(","))  # '11,,27' fails here: no silent gap
    return kind(raw)


def make_effect(name: str, joints: tuple[int, ...] | list[int] = (), **options: Any) -> Effect:
    """The effect called `name` (contract vocabulary or simulator-only) on `joints` (1-based).

    Returns
    -------
    effect : Effect
        An instance of the registered class of `name` (a frozen dataclass) with `joints`
        and `options`. Raises InputError for an unknown name or option, or bad values.
    """
    cls = effect_class(name)
    check_keys(options, tuple(option_types(cls)), f"effect {name!r}", what="option")
    try:
        return cls(joints=tuple(int(j) for j in joints), **options)
    except (TypeError, ValueError) as exc:
        raise InputError(f"effect {name!r}: bad joints/options {options} ({exc})") from None


def parse_effect(text: str, n_joints: int, **defaults: Any) -> Effect:
    """An effect from its text form `name[:J,J,..][:option=value]` (`Effect.spec`), e.g.
    'backlash:4', 'eccentricity:6:order=3', 'thermal_drift'. Without joints a per-joint
    effect is on every joint 1..n_joints; `defaults` give options not in the text (only
    those the effect has, e.g. order=2 applies to eccentricity, not to backlash).

    Returns
    -------
    effect : Effect
        As `make_effect`; its `spec` gives the text form back. Raises InputError for text
        that names no effect or has bad joints or options.
    """
    name, *parts = text.split(":")
    cls = effect_class(name)
    types = option_types(cls)
    options = {k: v for k, v in defaults.items() if k in types}
    joints: list[int] = []
    given: set[str] = set()
    try:
        for part in parts:
            if "=" in part:
                key, raw = part.split("=", 1)
                check_keys([key], tuple(types), text, what="option")
                if key in given:
                    raise InputError(f"{text}: option {key!r} given twice")
                given.add(key)
                options[key] = _option_value(types[key], raw)
            else:
                joints += [int(j) for j in part.split(",") if j]
    except ValueError:
        raise InputError(
            f"{text}: expected EFFECT[:J,J][:option=value], e.g. backlash:4"
        ) from None
    if not joints and cls.per_joint:
        joints = list(range(1, n_joints + 1))
    bad = [j for j in joints if not 1 <= j <= n_joints]
    if bad:
        raise InputError(f"{text}: joints {bad} outside 1..{n_joints}")
    return make_effect(name, joints, **options)


def effect_from_dict(record: Mapping[str, Any]) -> Effect:
    """An effect from its PARAMS.json / world-file record (`Effect.to_dict`).

    Returns
    -------
    effect : Effect
        As `make_effect` of the record's name, joints and options. Raises InputError for a
        record without a name, or as `make_effect`.
    """
    if not isinstance(record, Mapping) or "name" not in record:
        raise InputError(f"an effect is a mapping with a name, got {record!r}")
    record = dict(record)
    name, joints = record.pop("name"), record.pop("joints", [])
    return make_effect(name, joints or (), **record)


def seed_runout(n_joints: int) -> Effect:
    """The seed paper's measured runout of the real KR5 (Tables 5-6): eccentricity of
    order 1 on every joint (its simulator defaults are those tables)."""
    return Eccentricity(joints=tuple(range(1, n_joints + 1)), order=1)


def seed_effects(n_joints: int) -> tuple[Effect, ...]:
    """The seed paper's unmodelled effects of the real KR5: runout on every joint
    (`seed_runout`) and joint-4 backlash (the seed reports about 250 um of play)."""
    return (seed_runout(n_joints), Backlash(joints=(4,)))


#: The effects of the main job's simulated robot (`robot-calib run`): joint-4 backlash.
MAIN_JOB_EFFECTS = (Backlash(joints=(4,)).spec,)


def ladder_candidates(robot: RobotDescription, poses: Poses) -> list[Effect]:
    """Every candidate of every vocabulary effect for these poses, joint by joint (in
    registry order, i.e. by module name, within a joint), effects of no joint last."""
    out: list[Effect] = []
    for name in vocabulary():
        out += EFFECTS[name].ladder_candidates(robot, poses)
    return sorted(out, key=lambda e: min(e.joints) if e.joints else robot.n_joints + 1)


__all__ = [
    "EFFECTS",
    "Contribution",
    "Effect",
    "effect_class",
    "effect_from_dict",
    "MAIN_JOB_EFFECTS",
    "ladder_candidates",
    "make_effect",
    "parse_effect",
    "register_effect",
    "registered",
    "discover_effects",
    "seed_effects",
    "seed_runout",
    "vocabulary",
]
