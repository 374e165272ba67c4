"""`robot-calib predict`: target positions for given joint angles (CONTRACT.md section 2).

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
from dataclasses import replace
from pathlib import Path

import numpy as np

from robot_calib.atomic import write_text_atomic
from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array
from robot_calib.poses import Poses, beyond_reach

TEMPERATURE_COLUMN = "temp_c"  # JOINTS.csv: the robot's temperature [deg C], optional


def read_joints_csv(path: str | Path, n_joints: int, limits: Array | None = None) -> Poses:
    """Poses of a JOINTS.csv; a bad header or row raises InputError naming file and line,
    and a reading beyond any reading of its joint in rad (`poses.beyond_reach` with the
    robot's `limits` (J, 2) [rad]: degrees, most likely) names its line and column too."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such joints file")
    with path.open(newline="", encoding="utf-8-sig") as handle:  # -sig: Excel's BOM
        rows = list(csv.reader(handle))
    if not rows:
        raise InputError(f"{path}: empty file (expected header q1..q{n_joints})")
    header = [h.strip() for h in rows[0]]
    repeated = sorted({h for h in header if header.count(h) > 1})
    if repeated:
        raise InputError(f"{path}: columns {repeated} given more than once (header {header})")
    q_cols = [f"q{j}" for j in range(1, n_joints + 1)]
    dir_cols = [f"dir{j}" for j in range(1, n_joints + 1)]
    extra = [h for h in header if re.fullmatch(r"(q|dir)\d+", h) and h not in q_cols + dir_cols]
    if extra:
        raise InputError(
            f"{path}: columns {extra} beyond the robot's {n_joints} joints (header {header})"
        )
    missing = [c for c in q_cols if c not in header]
    if missing:
        raise InputError(f"{path}: header lacks {missing} (got {header})")
    has_dir = all(c in header for c in dir_cols)
    if not has_dir and any(c in header for c in dir_cols):
        raise InputError(f"{path}: give all of {dir_cols} or none")
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
    col = {name: k for k, name in enumerate(header)}
    q = table[:, [col[c] for c in q_cols]]
    beyond, reach = beyond_reach(q, limits)
    if beyond.any():
        k, j = (int(i) for i in np.argwhere(beyond)[0])
        raise InputError(
            f"{path}:{lines[k]}: column {q_cols[j]} (field {col[q_cols[j]] + 1}) = "
            f"{q[k, j]:g} is beyond any reading of joint {j + 1} in rad (|q| <= "
            f"{reach[j]:.2f}): degrees? JOINTS.csv takes rad"
        )
    direction = table[:, [col[c] for c in dir_cols]] if has_dir else None
    time = table[:, col["t"]] if "t" in col else None
    if direction is not None and not np.all(np.abs(direction) == 1.0):
        raise InputError(f"{path}: dir columns must be +1 or -1")
    poses = Poses.from_readings(q, direction, time)
    if TEMPERATURE_COLUMN in col:  # for models that follow the temperature
        poses = replace(poses, temperature=table[:, col[TEMPERATURE_COLUMN]])
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
