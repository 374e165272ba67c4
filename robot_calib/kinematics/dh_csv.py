"""A DH table as a CSV file: one row per joint, standard or modified (Craig) convention.

Vendors and papers print their tables with a column per DH value; a CSV of that table is a
robot description (`--robot arm.csv`, msgs_doc/robots.md "DH tables as CSV"). The header
names the convention and the units, so nothing is guessed:

- standard DH: columns `theta`, `d`, `a`, `alpha`; modified DH (row i: alpha_{i-1},
  a_{i-1}, theta_i, d_i): `alpha_prev` and `a_prev` (also written `alpha_{i-1}`,
  `alpha(i-1)`, `alpha_i-1`) in place of `alpha` and `a`;
- every angle and length column carries its unit, as `a [mm]`, `a (mm)` or `a_mm` (m, mm;
  deg, rad); a missing unit is an error, not a guess;
- optional: `name`, `min` and `max` (the joint's limits, an angle unit), `mass` (kg) and
  `com_x`, `com_y`, `com_z` (the centre of mass in the row's DH frame, a length unit);
- lines starting with `#` are comments; the robot's name is the file's stem.

The table becomes the mapping of a robot YAML file (`description.parse_robot`), so a CSV
is checked and converted exactly as the same table written in YAML.
"""

from __future__ import annotations

import csv
import io
import math
import re
from typing import Any

from robot_calib.errors import RobotDescriptionError

ANGLE_UNITS = {"deg": math.pi / 180.0, "°": math.pi / 180.0, "rad": 1.0}
LENGTH_UNITS = {"m": 1.0, "mm": 1e-3}
MASS_UNITS = {"kg": 1.0}
_UNIT = "|".join(sorted({*ANGLE_UNITS, *LENGTH_UNITS, *MASS_UNITS}, key=len, reverse=True))
_HEADER = re.compile(rf"(.+?)(?:\[([^\]]+)\]|\(({_UNIT})\)|_({_UNIT}))?")
_PREVIOUS = re.compile(r"(alpha|a)_?(?:\{i-1\}|\(i-1\)|i-1|prev)")
#: each column's kind of unit (None: no unit)
COLUMNS: dict[str, dict[str, float] | None] = {
    "name": None,
    "theta": ANGLE_UNITS,
    "d": LENGTH_UNITS,
    "a": LENGTH_UNITS,
    "alpha": ANGLE_UNITS,
    "alpha_prev": ANGLE_UNITS,
    "a_prev": LENGTH_UNITS,
    "min": ANGLE_UNITS,
    "max": ANGLE_UNITS,
    "mass": MASS_UNITS,
    "com_x": LENGTH_UNITS,
    "com_y": LENGTH_UNITS,
    "com_z": LENGTH_UNITS,
}


def _column(header: str, where: str) -> tuple[str, float]:
    """A header cell -> (column key, factor to SI); RobotDescriptionError for an unknown
    column or a missing or wrong unit."""
    text = header.strip().lower().replace(" ", "")
    match = _HEADER.fullmatch(text)
    if not text or match is None:
        raise RobotDescriptionError(f"{where}: an empty column name (a trailing comma?)")
    key, unit = match.group(1), match.group(2) or match.group(3) or match.group(4)
    previous = _PREVIOUS.fullmatch(key)
    key = f"{previous.group(1)}_prev" if previous else key
    if key not in COLUMNS:
        import difflib

        close = difflib.get_close_matches(key, COLUMNS, n=1)
        if close:
            raise RobotDescriptionError(
                f"{where}: column {header.strip()!r}: did you mean {close[0]!r}?"
            )
        known = ", ".join(COLUMNS)
        raise RobotDescriptionError(
            f"{where}: column {header.strip()!r} is none of {known} (with a unit, e.g. 'a [mm]')"
        )
    units = COLUMNS[key]
    if units is None:
        return key, 1.0
    if unit is None and units is MASS_UNITS:
        return key, 1.0
    if unit not in units:
        given = f"unit {unit!r}" if unit else "no unit"
        raise RobotDescriptionError(
            f"{where}: column {header.strip()!r} has {given}: write "
            f"it as '{key} [{' or '.join(_shown(units))}]'"
        )
    return key, units[unit]


def _shown(units: dict[str, float]) -> list[str]:
    """The unit names to suggest (not the degree sign, which is the same as deg)."""
    return [u for u in units if u != "°"]


def dh_csv_mapping(text: str, name: str, source: str) -> dict[str, Any]:
    """The robot-YAML mapping (`description.parse_robot`) of a DH table CSV `text` (module
    docstring) named `name`; RobotDescriptionError naming `source` and the row."""
    lines = [
        line
        for line in text.lstrip("\ufeff").splitlines()
        if line.strip() and not line.lstrip().startswith("#")
    ]
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    if rows and len(rows[0]) == 1 and ";" in rows[0][0]:
        raise RobotDescriptionError(
            f"{source}: the columns are separated by ';': write the "
            "table with commas (and '.' decimals)"
        )
    if len(rows) < 3:
        raise RobotDescriptionError(f"{source}: a DH table needs a header and >= 2 joint rows")
    columns = [_column(h, f"{source}: header") for h in rows[0]]
    keys = [k for k, _ in columns]
    repeated = sorted({k for k in keys if keys.count(k) > 1})
    if repeated:
        raise RobotDescriptionError(f"{source}: header: column {repeated[0]!r} given twice")
    modified = "alpha_prev" in keys or "a_prev" in keys
    needed = ("theta", "d", "a_prev", "alpha_prev") if modified else ("theta", "d", "a", "alpha")
    missing = [k for k in needed if k not in keys]
    mixed = modified and ("a" in keys or "alpha" in keys)
    if missing or mixed:
        kind = "a modified-DH table" if modified else "a standard DH table"
        raise RobotDescriptionError(
            f"{source}: header: {kind} needs columns {', '.join(needed)}"
            + (f"; missing {', '.join(missing)}" if missing else "; not both a and a_prev")
        )
    if ("min" in keys) != ("max" in keys):
        raise RobotDescriptionError(f"{source}: header: limits need both min and max")
    com = [k for k in ("com_x", "com_y", "com_z") if k in keys]
    if com and len(com) < 3:
        raise RobotDescriptionError(
            f"{source}: header: a centre of mass needs com_x, com_y "
            f"and com_z; only {', '.join(com)} given"
        )
    joints = []
    for number, row in enumerate(rows[1:], start=1):
        where = f"{source}: joint {number}"
        if len(row) != len(columns):
            raise RobotDescriptionError(f"{where}: {len(row)} cells for {len(columns)} columns")
        values: dict[str, Any] = {}
        for (key, factor), cell in zip(columns, row):
            if key == "name":
                values[key] = cell.strip()
                continue
            try:
                values[key] = float(cell) * factor
            except ValueError:
                raise RobotDescriptionError(
                    f"{where}: {key}: {cell.strip()!r} is no number"
                ) from None
        joint = {
            "theta": values["theta"],
            "d": values["d"],
            "a": values["a_prev" if modified else "a"],
            "alpha": values["alpha_prev" if modified else "alpha"],
        }
        if "name" in values:
            joint["name"] = values["name"]
        if "min" in values:
            if not values["min"] < values["max"]:
                low, high = (row[keys.index(k)].strip() for k in ("min", "max"))
                raise RobotDescriptionError(f"{where}: min {low} is not below max {high}")
            joint["limits"] = [values["min"], values["max"]]
        if "mass" in values:
            joint["mass"] = values["mass"]
        if any(k in values for k in ("com_x", "com_y", "com_z")):
            joint["com"] = [values[f"com_{c}"] for c in "xyz"]
        joints.append(joint)
    return {
        "name": name,
        "source": f"DH table {source}",
        "angle_unit": "rad",
        "convention": "modified_dh" if modified else "dh",
        "joints": joints,
    }
