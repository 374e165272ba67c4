"""The numeric CSV tables of joint commands and points that `predict` and `compensate` read
and write (msgs_doc/specification.md section 2).

JOINTS.csv: header q1..qJ [rad], optional leading column t [s] and optional dir1..dirJ (+1/-1);
without dir columns the directions follow the row order, without t the time is 0. A reading
beyond any reading of its joint in rad (degrees, most likely; `poses.beyond_reach`, the
check `import` makes) is refused, naming its line and column.
POINTS.csv: header x,y,z [m], one row per input row, in the laser_tracker frame.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from robot_calib.atomic import write_text_atomic
from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array
from robot_calib.poses import Poses, beyond_reach

TEMPERATURE_COLUMN = "temp_c"  # JOINTS.csv: the robot's temperature [deg C], optional


@dataclass(frozen=True)
class CsvTable:
    """A CSV file of numbers with a header: table (n, C) of the rows that are not blank,
    `lines` (n,) their line numbers in the file (for messages), `header` (C,) stripped."""

    path: Path
    header: tuple[str, ...]
    table: Array
    lines: tuple[int, ...]

    def has(self, name: str) -> bool:
        return name in self.header

    def column(self, name: str) -> Array:
        """(n,) the values of column `name` (which must be in the header)."""
        return self.table[:, self.header.index(name)]

    def columns(self, names: list[str]) -> Array:
        """(n, len(names)) the values of `names` (all in the header)."""
        return self.table[:, [self.header.index(c) for c in names]]

    def all_or_none(self, names: list[str]) -> bool:
        """True when every column of `names` is in the header, False when none is;
        InputError naming the file when only some are."""
        given = [c for c in names if c in self.header]
        if given and len(given) != len(names):
            raise InputError(f"{self.path}: give all of {names} or none (got {given})")
        return bool(given)


def read_csv_table(path: str | Path, what: str, expected: str) -> CsvTable:
    """The numbers of a CSV file with a header row (`what`: 'joints', 'targets' for
    messages; `expected`: the header it should have, for the empty-file message). Blank
    lines are skipped; a repeated column, a row of another length, a field that is not a
    finite number raise InputError naming the file and line."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such {what} file")
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:  # -sig: Excel's BOM
            rows = list(csv.reader(handle))
    except UnicodeDecodeError:
        raise InputError(
            f"{path}: not a text CSV file (not UTF-8; a bag or a spreadsheet? expected "
            f"header {expected})"
        ) from None
    except (OSError, csv.Error) as exc:
        raise InputError(f"{path}: cannot read as CSV ({exc})") from None
    if not rows:
        raise InputError(f"{path}: empty file (expected header {expected})")
    header = [h.strip() for h in rows[0]]
    if len(header) == 1 and ";" in header[0]:
        raise InputError(
            f"{path}: one column {header[0]!r}: separated by ';'? use ',' "
            f"(expected header {expected})"
        )
    repeated = sorted({h for h in header if header.count(h) > 1})
    if repeated:
        raise InputError(f"{path}: columns {repeated} given more than once (header {header})")
    values, lines = [], []
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise InputError(f"{path}:{line}: {len(row)} fields, header has {len(header)}")
        try:
            values.append([float(c) for c in row])
        except ValueError:
            raise InputError(f"{path}:{line}: not a number in {row}") from None
        lines.append(line)
    if not values:
        raise InputError(f"{path}: no poses")
    table = np.array(values)
    if not np.all(np.isfinite(table)):
        bad = lines[int(np.flatnonzero(~np.isfinite(table).all(axis=1))[0])]
        raise InputError(f"{path}:{bad}: value not finite")
    return CsvTable(path, tuple(header), table, tuple(lines))


def joint_columns(
    table: CsvTable, n_joints: int, limits: Array | None, required: bool
) -> tuple[Array | None, Array | None]:
    """The readings q1..qJ (n, J) [rad] and directions dir1..dirJ (n, J) (+1/-1) of a
    table, each None where its columns are absent (q only where not `required`). Columns of
    joints beyond the robot's, some but not all of a group, a reading beyond any reading of
    its joint in rad (degrees, most likely; `limits` (J, 2) [rad]) or a direction other
    than +-1 raise InputError naming the file (and line and column)."""
    path, header = table.path, list(table.header)
    q_cols = [f"q{j}" for j in range(1, n_joints + 1)]
    dir_cols = [f"dir{j}" for j in range(1, n_joints + 1)]
    extra = [h for h in header if re.fullmatch(r"(q|dir)\d+", h) and h not in q_cols + dir_cols]
    if extra:
        raise InputError(
            f"{path}: columns {extra} beyond the robot's {n_joints} joints (header {header})"
        )
    missing = [c for c in q_cols if c not in header]
    if required and missing:
        raise InputError(f"{path}: header lacks {missing} (got {header})")
    q = table.columns(q_cols) if table.all_or_none(q_cols) else None
    if q is not None:
        beyond, reach = beyond_reach(q, limits)
        if beyond.any():
            k, j = (int(i) for i in np.argwhere(beyond)[0])
            raise InputError(
                f"{path}:{table.lines[k]}: column {q_cols[j]} (field "
                f"{header.index(q_cols[j]) + 1}) = {q[k, j]:g} is beyond any reading of joint "
                f"{j + 1} in rad (|q| <= {reach[j]:.2f}): degrees? q1..qJ take rad"
            )
    direction = table.columns(dir_cols) if table.all_or_none(dir_cols) else None
    if direction is not None and not np.all(np.abs(direction) == 1.0):
        raise InputError(f"{path}: dir columns must be +1 or -1")
    return q, direction


def read_joints_csv(path: str | Path, n_joints: int, limits: Array | None = None) -> Poses:
    """Poses of a JOINTS.csv; a bad header or row raises InputError naming file and line,
    and a reading beyond any reading of its joint in rad (`poses.beyond_reach` with the
    robot's `limits` (J, 2) [rad]: degrees, most likely) names its line and column too."""
    table = read_csv_table(path, "joints", f"q1..q{n_joints}")
    q, direction = joint_columns(table, n_joints, limits, required=True)
    assert q is not None  # required
    time = table.column("t") if table.has("t") else None
    poses = Poses.from_readings(q, direction, time)
    if table.has(TEMPERATURE_COLUMN):  # for models that follow the temperature
        poses = replace(poses, temperature=table.column(TEMPERATURE_COLUMN))
    return poses


def write_points_csv(points: Array, path: str | Path, quaternions: Array | None = None) -> None:
    """POINTS.csv with header x,y,z [m] (and qx,qy,qz,qw: a 6-DoF probe's frame in the
    tracker frame, when `quaternions` (n, 4) are given), written atomically (temporary
    file + rename)."""
    text = io.StringIO(newline="")
    writer = csv.writer(text)
    writer.writerow(["x", "y", "z"] + ([] if quaternions is None else ["qx", "qy", "qz", "qw"]))
    rows = points if quaternions is None else np.hstack([points, quaternions])
    writer.writerows([[repr(float(v)) for v in p] for p in rows])
    write_text_atomic(path, text.getvalue())
