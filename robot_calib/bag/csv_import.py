"""Measurements exported by tracker software (CSV) into a bag of the contract, so real data
takes exactly the path of simulated data (CONTRACT.md section 2, `import`).

A row is one measurement pose: joint angles and the measured target point (optionally as a
commanded point plus a difference column, as some exports give it), optionally a time.
Columns are named (header) or 0-based indices; separator and decimal comma are options;
units deg/rad and mm/m are converted to SI. Bad rows are counted and reported with their
line numbers, never dropped silently. In the bag, poses are stamped in row order (`time`
column, else 1 s apart) and each point carries its joint state's stamp.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from robot_calib.bag.mcap_writer import BagWriter
from robot_calib.bag.ros2_formats import typestore
from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array
from robot_calib.messages import (
    JOINT_STATE_TYPE,
    JOINT_STATES_TOPIC,
    POINT_TOPIC,
    POINT_TYPE,
    TRACKER_FRAME,
    ns_to_sec_nanosec,
)

ANGLE_UNITS = {"deg": np.pi / 180.0, "rad": 1.0}
LENGTH_UNITS = {"mm": 1e-3, "m": 1.0}
START_NS = 1_700_000_000_000_000_000  # stamp of the first pose when the CSV has no time
STEP_NS = 1_000_000_000


@dataclass(frozen=True)
class CsvFormat:
    """How to read a measurement CSV. Column references are header names or 0-based indices.

    point = point columns + dif_sign * dif columns (when `dif` is given), in `length_unit`.
    """

    joints: tuple[str, ...]
    point: tuple[str, str, str]
    dif: tuple[str, str, str] | None = None
    dif_sign: float = 1.0
    time: str | None = None
    separator: str = ","
    decimal_comma: bool = False
    angle_unit: str = "rad"
    length_unit: str = "m"
    header: bool = True
    robot: str | None = None  # the robot the format belongs to (default for --robot)


# ur5_jacobi2025 (datasets/ur5_jacobi2025/README.md): `x_t..z_t` the commanded target [mm],
# `x_dif..z_dif` "the difference or residual error between the target position and the
# actual achieved position" [mm], joints in degrees. Read literally, dif = target - actual,
# so actual = target - dif (dif_sign -1); `--dif-sign +1` takes the other reading. Fit
# quality cannot decide it (the other sign fits as well with other geometric parameters).
PRESETS = {
    "ur5_jacobi2025": CsvFormat(
        joints=tuple(f"joint_{j}" for j in range(1, 7)),
        point=("x_t", "y_t", "z_t"),
        dif=("x_dif", "y_dif", "z_dif"),
        dif_sign=-1.0,
        angle_unit="deg",
        length_unit="mm",
        robot="ur5",
    )
}


@dataclass(frozen=True)
class ImportedTable:
    """q (n, J) [rad], points (n, 3) [m], time (n,) [s] or None; bad_rows: (line, why)."""

    q: Array
    points: Array
    time: Array | None
    bad_rows: tuple[tuple[int, str], ...]


def _column(ref: str, header: list[str] | None, path: Path) -> int:
    if ref.isdigit():
        return int(ref)
    if header is None:
        raise InputError(f"{path}: column {ref!r} by name needs a header row (or give an index)")
    if ref not in header:
        raise InputError(f"{path}: no column {ref!r} (header: {', '.join(header)})")
    return header.index(ref)


def read_measurement_csv(path: str | Path, fmt: CsvFormat) -> ImportedTable:
    """Rows of a measurement CSV in SI units; unreadable rows are listed, not dropped."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such CSV file")
    if fmt.angle_unit not in ANGLE_UNITS or fmt.length_unit not in LENGTH_UNITS:
        raise InputError(
            f"units must be deg|rad and mm|m, got {fmt.angle_unit}, {fmt.length_unit}"
        )
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            rows = list(csv.reader(handle, delimiter=fmt.separator))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path}: not a readable CSV ({exc})") from None
    header = [h.strip() for h in rows[0]] if fmt.header and rows else None
    first_line = 2 if fmt.header else 1
    body = rows[1:] if fmt.header else rows
    refs = (
        list(fmt.joints) + list(fmt.point) + list(fmt.dif or ()) + ([fmt.time] if fmt.time else [])
    )
    cols = [_column(r, header, path) for r in refs]
    values, bad, lines = [], [], []
    for line, row in enumerate(body, start=first_line):
        if not row or all(not c.strip() for c in row):
            continue
        try:
            fields = [row[c].strip() for c in cols]
        except IndexError:
            bad.append((line, f"{len(row)} fields, need column {max(cols)}"))
            continue
        if fmt.decimal_comma:
            fields = [f.replace(".", "").replace(",", ".") for f in fields]
        try:
            numbers = [float(f) for f in fields]
        except ValueError:
            bad.append((line, f"not a number in {fields}"))
            continue
        if not np.all(np.isfinite(numbers)):
            bad.append((line, "value not finite"))
            continue
        values.append(numbers)
        lines.append(line)
    if not values:
        raise InputError(f"{path}: no usable rows ({len(bad)} bad)")
    table = np.array(values)
    n_j = len(fmt.joints)
    q = table[:, :n_j] * ANGLE_UNITS[fmt.angle_unit]
    points = table[:, n_j : n_j + 3]
    if fmt.dif:
        points = points + fmt.dif_sign * table[:, n_j + 3 : n_j + 6]
    points = points * LENGTH_UNITS[fmt.length_unit]
    time = table[:, -1] if fmt.time else None
    if time is not None and np.any(np.diff(time) <= 0):
        k = int(np.flatnonzero(np.diff(time) <= 0)[0]) + 1
        raise InputError(
            f"{path}:{lines[k]}: time {time[k]:g} s does not increase (previous row: "
            f"{time[k - 1]:g} s); rows must be in measurement order"
        )
    return ImportedTable(q, points, time, tuple(bad))


def write_measurement_bag(
    output: str | Path, q: Array, points: Array, joint_names: tuple[str, ...],
    time: Array | None = None,
) -> dict[str, int]:  # fmt: skip
    """A contract bag: one JointState and one PointStamped per pose, stamped in row order
    (`time` [s] from the first pose, else 1 s apart). Returns messages per topic."""
    if len(joint_names) != q.shape[1]:
        raise InputError(f"{q.shape[1]} joint columns for a robot with {len(joint_names)} joints")
    offsets = (np.arange(len(q)) * STEP_NS if time is None
               else np.round((time - time[0]) * 1e9).astype(np.int64))  # fmt: skip
    if np.any(np.diff(offsets) <= 0):
        raise InputError("time column must increase from row to row")
    store = typestore(JOINT_STATE_TYPE, POINT_TYPE)
    types = store.types
    with BagWriter(output) as writer:
        writer.add_topic(JOINT_STATES_TOPIC, JOINT_STATE_TYPE)
        writer.add_topic(POINT_TOPIC, POINT_TYPE)
        for qi, pi, offset in zip(q, points, offsets):
            stamp_ns = START_NS + int(offset)
            stamp = types["builtin_interfaces/msg/Time"](*ns_to_sec_nanosec(stamp_ns))
            js = types[JOINT_STATE_TYPE](
                header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
                name=list(joint_names), position=qi, velocity=np.empty(0), effort=np.empty(0),
            )  # fmt: skip
            writer.write(JOINT_STATES_TOPIC, store.serialize_cdr(js, JOINT_STATE_TYPE), stamp_ns)
            pt = types[POINT_TYPE](
                header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=TRACKER_FRAME),
                point=types["geometry_msgs/msg/Point"](*map(float, pi)),
            )
            writer.write(POINT_TOPIC, store.serialize_cdr(pt, POINT_TYPE), stamp_ns + 1)
        return writer.counts


def with_overrides(fmt: CsvFormat, **changes: Any) -> CsvFormat:
    """A copy of `fmt` with the given (non-None) fields replaced."""
    return replace(fmt, **{k: v for k, v in changes.items() if v is not None})
