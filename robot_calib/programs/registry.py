"""The robot-program languages by name and by file suffix."""

from __future__ import annotations

from pathlib import Path

from robot_calib.errors import InputError, param
from robot_calib.programs import fanuc_tp, krl, rapid, urscript
from robot_calib.programs.language import Language


def language_names() -> tuple[str, ...]:
    return tuple(_registry())


def language_for(path: str | Path, name: str | None = None) -> Language:
    """The language `name`, else the one reading `path`'s suffix; InputError naming the
    file when neither gives one."""
    languages = _registry()
    if name is not None:
        if name not in languages:
            raise InputError(f"{param('language', name)}: expected one of {sorted(languages)}")
        return languages[name]
    suffix = Path(path).suffix.lower()
    for language in languages.values():
        if suffix in language.suffixes:
            return language
    known = ", ".join(f"{s} ({lang.title})" for lang in languages.values() for s in lang.suffixes)
    raise InputError(
        f"{path}: no robot-program language reads {suffix or 'a file without a suffix'} "
        f"(known: {known}); name one with {param('language', '...')}"
    )


def _registry() -> dict[str, Language]:
    return {m.LANGUAGE.name: m.LANGUAGE for m in (krl, rapid, fanuc_tp, urscript)}


#: the makers of the built-in robots, by the start of the description's name
VENDORS = (
    ("kr", "KUKA"),
    ("irb", "ABB"),
    ("m20ia", "FANUC"),
    ("r2000", "FANUC"),
    ("ur", "Universal Robots"),
    ("gp", "Yaskawa"),
)


def check_robot(language: Language, robot: str, source: str) -> None:
    """InputError naming `source` (the calibration) when its robot is a built-in one of
    another maker than the language's (a program for a KUKA compensated with an ABB's
    calibration); robots of other names are not checked."""
    vendor = next((v for prefix, v in VENDORS if robot.lower().startswith(prefix)), None)
    if vendor is not None and vendor != language.vendor:
        raise InputError(
            f"{source}: a calibration of robot {robot} ({vendor}), not of the "
            f"{language.vendor} robot that runs {language.title} programs"
        )
