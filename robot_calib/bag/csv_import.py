"""Measurements exported by tracker software (CSV) into a bag of the contract, so real data
takes exactly the path of simulated data (msgs_doc/specification.md section 2, `import`).

A row is one measurement pose: joint angles and the measured target point (optionally as a
commanded point plus a difference column, as some exports give it), optionally a time;
further targets' points, a 6-DoF probe's orientation (quaternion or roll-pitch-yaw columns)
and the tracker's stated standard deviations may follow (msgs_doc/import.md).
Columns are named (header) or 0-based indices; separator and decimal comma are options;
units deg/rad and mm/m are converted to SI. Bad rows are counted and reported with their
line numbers, never dropped silently. In the bag, poses are stamped in row order (`time`
column, else 1 s apart) and each point carries its joint state's stamp.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from robot_calib.atomic import staged_outputs
from robot_calib.bag.mcap_writer import BagWriter
from robot_calib.bag.ros2_formats import typestore
from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.measurements.recording import COPY_RESOLUTION, copies
from robot_calib.messages import (
    JOINT_STATE_TYPE,
    JOINT_STATES_TOPIC,
    POINT_TOPIC,
    POINT_TYPE,
    POSE_COV_TYPE,
    POSE_TYPE,
    QUATERNION_TOLERANCE,
    TEMPERATURE_TOPIC,
    TEMPERATURE_TYPE,
    TRACKER_FRAME,
    ns_to_sec_nanosec,
    pose_covariance,
    pose_topic,
    target_topic,
)
from robot_calib.poses import beyond_reach

ANGLE_UNITS = {"deg": np.pi / 180.0, "rad": 1.0}
LENGTH_UNITS = {"mm": 1e-3, "m": 1.0}
# stated standard deviations: trackers often give micrometres and microradians/millidegrees
SIGMA_LENGTH_UNITS = {**LENGTH_UNITS, "um": 1e-6}
SIGMA_ANGLE_UNITS = {**ANGLE_UNITS, "mdeg": np.pi / 180e3, "urad": 1e-6}
# plausible medians of stated standard deviations [m], [rad]: outside, a unit mix-up is
# likelier (um read as mm, urad as rad, mdeg as deg): a warning, not an error
PLAUSIBLE_SIGMA = {"position": (1e-7, 1e-3), "orientation": (1e-7, 2e-2)}
START_NS = 1_700_000_000_000_000_000  # stamp of the first pose when the CSV has no time
STEP_NS = 1_000_000_000
# a time column whose first value is at least this [s] (March 1973 on) is absolute time,
# Unix epoch seconds: written as it is (two halves of one file keep their own stamps)
EPOCH_MIN_S = 1e8


SixDof = tuple[Array, Array]  # rotation (n, 3, 3) and sigma (n, 2) [m, rad] of one target


def target_label(name: str) -> str:
    """'the first target' ('') or 'target NAME', for messages."""
    return "the first target" if not name else f"target {name}"


@dataclass(frozen=True)
class OrientationColumns:
    """Where a 6-DoF probe's orientation (the probe frame in the tracker frame) is in a CSV.

    kind 'quaternion': columns x, y, z, w of a unit quaternion; kind 'rpy': roll, pitch, yaw
    with R = Rz(yaw) Ry(pitch) Rx(roll) (`kinematics.frames.rpy_to_matrix`), in the
    format's orientation unit. target: '' the first target, else a further target's NAME.
    """

    target: str
    kind: str  # 'quaternion' | 'rpy'
    columns: tuple[str, ...]

    @property
    def option(self) -> str:
        """How the command line spells it: '--orientation[-rpy] [NAME:]C,C,...'."""
        flag = "--orientation" if self.kind == "quaternion" else "--orientation-rpy"
        return f"{flag} {self.target + ':' if self.target else ''}{','.join(self.columns)}"


@dataclass(frozen=True)
class SigmaColumns:
    """Where a target's stated standard deviations are in a CSV: `position` (per coordinate,
    in the format's sigma unit) and optionally `orientation` (per axis, in its sigma angle
    unit); an empty cell: not stated at that pose. target as in OrientationColumns."""

    target: str
    position: str
    orientation: str | None = None

    @property
    def option(self) -> str:
        """How the command line spells it: '--sigma [NAME:]SP[,SR]'."""
        columns = self.position + (f",{self.orientation}" if self.orientation else "")
        return f"--sigma {self.target + ':' if self.target else ''}{columns}"


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
    temperature: str | None = None  # a temperature column [deg C], onto /temperature
    # further targets measured at each pose: (NAME, (x, y, z) columns), each onto
    # /laser_tracker/NAME/point (msgs_doc/targets.md); an empty cell: not measured there
    targets: tuple[tuple[str, tuple[str, str, str]], ...] = ()
    # 6-DoF probes (msgs_doc/six_dof.md): orientation columns and stated standard deviations
    # per target ('' the first), at most one of each per target
    orientations: tuple[OrientationColumns, ...] = ()
    sigmas: tuple[SigmaColumns, ...] = ()
    orientation_unit: str | None = None  # of roll-pitch-yaw columns (None: angle_unit)
    sigma_unit: str | None = None  # position sigma: mm|m|um (None: length_unit)
    sigma_angle_unit: str | None = None  # orientation sigma: deg|rad|mdeg|urad (None: as rpy)
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
    """q (n, J) [rad], points (n, 3) [m], time (n,) [s] or None; bad_rows: (line, why);
    warnings: labelled 'warning: ...' lines about the whole file (e.g. units);
    temperature (n,) [deg C] or None; extra_points {NAME: (n, 3) [m], NaN where that
    target was not measured} of the further targets; six_dof {NAME ('' the first target):
    (rotation (n, 3, 3) in the tracker frame, NaN where no orientation was measured, sigma
    (n, 2) [m, rad], NaN where none was stated)} of the targets given orientation or
    standard deviation columns."""

    q: Array
    points: Array
    time: Array | None
    bad_rows: tuple[tuple[int, str], ...]
    warnings: tuple[str, ...] = ()
    temperature: Array | None = None
    extra_points: Mapping[str, Array] = field(default_factory=dict)
    six_dof: Mapping[str, SixDof] = field(default_factory=dict)
    lines: tuple[int, ...] = ()  # the file line of each row


def check_no_copies(paths: Sequence[str | Path], tables: Sequence[ImportedTable]) -> None:
    """InputError when a CSV is given twice, or a row repeats an earlier row's joint
    readings and point (to 1 nrad / 1 nm, `copies`: the same measurement, not the tracker
    measuring again), in one file or across the files; names the first copy and how many."""
    seen: dict[Path, str] = {}
    for path in paths:
        key = Path(path).resolve()
        if key in seen:
            raise InputError(f"{path}: given twice (as {seen[key]}): its rows would be "
                             "imported twice; give each CSV once")  # fmt: skip
        seen[key] = str(path)
    if not tables:
        return
    q = np.concatenate([t.q for t in tables])
    points = np.concatenate([t.points for t in tables])
    if all(t.time is not None for t in tables):  # rows logged at other times: kept
        q = np.column_stack([q, np.concatenate([t.time for t in tables if t.time is not None])])
    copied = copies(q, points)
    if not copied.any():
        return
    where = [f"{p}:{line}" for p, t in zip(paths, tables)
             for line in (t.lines or range(1, len(t.q) + 1))]  # fmt: skip
    k = int(np.flatnonzero(copied)[0])
    rows = np.round(np.column_stack([q, points]) / COPY_RESOLUTION)
    first = int(np.flatnonzero((rows[:k] == rows[k]).all(axis=1))[0])
    raise InputError(
        f"{where[k]}: the same joint readings and point as {where[first]} (to 1 nrad / 1 nm; "
        f"{int(copied.sum())} of {len(copied)} rows are such copies): a tracker measuring "
        "again never repeats a point exactly; give each measurement once"
    )


MAX_TRACKER_RANGE_M = 50.0  # beyond a laser tracker's range: millimetres read as metres
MIN_TRACKER_RANGE_M = 0.05  # nearer than the tracker head allows: metres read as mm


def _column(ref: str, header: list[str] | None, path: Path) -> int:
    if ref.isdigit():
        return int(ref)
    if header is None:
        raise InputError(f"{path}: column {ref!r} by name needs a header row (or give an index)")
    if ref not in header:
        raise InputError(f"{path}: no column {ref!r} (header: {', '.join(header)})")
    if header.count(ref) > 1:
        at = [k for k, h in enumerate(header) if h == ref]
        raise InputError(
            f"{path}: the header has {len(at)} columns named {ref!r} (0-based {at}): which "
            "one is meant is unknown; rename one or give the column by index"
        )
    return header.index(ref)


def _check_distinct_columns(
    path: Path, refs: list[str], cols: list[int], header: list[str] | None
) -> None:
    """InputError when two of the columns given (--joints, --point, --dif, --time,
    --temperature, --target) are one column of the file: one number read as two."""
    for k, col in enumerate(cols):
        if col in cols[:k]:
            other = refs[cols.index(col)]
            raise InputError(
                f"{path}: column {_column_label(refs[k], col, header)!r} is given twice (as "
                f"{other!r} and {refs[k]!r} in --joints/--point/--dif/--time/--temperature/"
                "--target): each value needs its own column"
            )


def counted(n: int, noun: str) -> str:
    """'1 bad row', '3 bad rows'."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _column_label(ref: str, col: int, header: list[str] | None) -> str:
    """How a message names a column: as referenced, with its header name for an index."""
    if ref.isdigit() and header is not None and header[col] != ref:
        return f"{ref} ({header[col]})"
    return ref


def _row_numbers(
    fields: list[str], names: list[str], n_required: int, decimal_comma: bool
) -> tuple[list[float], str]:
    """The numbers of one row's cells (NaN for an empty optional cell) and why the row is
    bad ('' when it is not): the required columns (the first `n_required`) that are empty
    or not finite, else the cells that are not numbers, named by column."""
    numbers, empty, not_number, not_finite = [], [], [], []
    for k, (cell, name) in enumerate(zip(fields, names)):
        if not cell:
            numbers.append(np.nan)
            if k < n_required:
                empty.append(name)
            continue
        try:
            value = float(cell.replace(".", "").replace(",", ".") if decimal_comma else cell)
        except ValueError:
            not_number.append(f"{name} {cell!r}")
            value = np.nan
        else:
            if k < n_required and not np.isfinite(value):
                not_finite.append(f"{name} {cell!r}")
        numbers.append(value)
    for bad, what in ((empty, "empty"), (not_number, "not a number"), (not_finite, "not finite")):
        if bad:
            one = len(bad) == 1
            return numbers, f"{'column' if one else 'columns'} {', '.join(bad)} " + (
                f"{'is' if one else 'are'} {what}"
            )
    return numbers, ""


SEPARATORS = {";": "';'", "\t": "tab", ",": "','", "|": "'|'", " ": "' '"}  # as --sep spells them


def _check_separator(path: Path, fmt: CsvFormat, line: int, row: list[str]) -> None:
    """InputError when the first row (`line`, the header unless fmt.header is False) is one
    column holding another common separator: the file is split by that one (--sep)."""
    found = {sep: row[0].count(sep) for sep in SEPARATORS if sep != fmt.separator}
    sep = max(found, key=lambda k: found[k])
    if found[sep]:
        first = "the header" if fmt.header else "the first row"
        raise InputError(
            f"{path}:{line}: {first} is one column containing {found[sep]} {SEPARATORS[sep]} "
            f"(separator {SEPARATORS.get(fmt.separator, repr(fmt.separator))}): give --sep "
            f"{SEPARATORS[sep]}"
        )


def _is_number(cell: str, fmt: CsvFormat) -> bool:
    """True when `cell` reads as a number (with the file's decimal mark)."""
    text = cell.strip().replace(",", ".") if fmt.decimal_comma else cell.strip()
    try:
        float(text)
    except ValueError:
        return False
    return True


def _check_decimal_mark(path: Path, fmt: CsvFormat, cells: list[tuple[int, str]]) -> None:
    """InputError when --decimal-comma meets numbers written with a decimal point (it would
    read '1.5' as 15), or numbers with a decimal comma come without it."""
    commas = [(line, c) for line, c in cells if "," in c]
    points = [(line, c) for line, c in cells if "." in c]
    if fmt.decimal_comma and points and not commas:
        line, cell = points[0]
        raise InputError(
            f"{path}:{line}: --decimal-comma, but the numbers have a decimal point "
            f"({cell!r}); drop --decimal-comma"
        )
    if not fmt.decimal_comma and commas and fmt.separator != ",":
        line, cell = commas[0]
        raise InputError(
            f"{path}:{line}: number {cell!r} has a decimal comma; add --decimal-comma"
        )


def _unit_checks(
    path: Path, fmt: CsvFormat, table: Array, lines: list[int], limits: Array | None
) -> tuple[NDArray[np.bool_], list[tuple[int, str]], list[str]]:
    """Per-column unit sanity of the rows read (table in the file's units): a joint column
    in rad beyond any joint reading (`poses.beyond_reach`) looks like degrees,
    a point in m beyond a tracker's range looks like millimetres, one in mm nearer than
    MIN_TRACKER_RANGE_M looks like metres. When most rows look so, InputError naming the
    column; when a few do, they are rows in mixed units: bad rows.

    Returns
    -------
    keep : ndarray of bool, shape (n,)
        Rows in consistent units.
    bad : list of (line, why)
        The rows in mixed units.
    warnings : list of str
        'warning: ...' lines (joint columns in deg that all look like radians).
    """
    n_j = len(fmt.joints)
    bad_mask = np.zeros(len(table), dtype=bool)
    why = [""] * len(table)
    q = table[:, :n_j]
    if fmt.angle_unit == "rad":
        beyond, reach = beyond_reach(q, limits)
        for j in range(n_j):
            if beyond[:, j].mean() > 0.5:
                raise InputError(
                    f"{path}: joint column {fmt.joints[j]!r} reaches "
                    f"{np.abs(q[:, j]).max():.1f}, beyond any joint reading in rad "
                    f"(|q| <= {reach[j]:.1f}): the angles look like degrees; give "
                    "--angle-unit deg"
                )
        for k in np.flatnonzero(beyond.any(axis=1)):
            j = int(np.flatnonzero(beyond[k])[0])
            bad_mask[k] = True
            why[k] = (f"joint column {fmt.joints[j]!r} = {q[k, j]:g} looks like degrees "
                      "(the other rows: rad)")  # fmt: skip
    points = table[:, n_j : n_j + 3]
    if fmt.dif:
        points = points + fmt.dif_sign * table[:, n_j + 3 : n_j + 6]
    dist_m = np.linalg.norm(points, axis=1) * LENGTH_UNITS[fmt.length_unit]
    columns = "/".join(fmt.point)
    if fmt.length_unit == "m":
        far, other, hint = dist_m > MAX_TRACKER_RANGE_M, "millimetres", "--length-unit mm"
    else:
        far, other, hint = dist_m < MIN_TRACKER_RANGE_M, "metres", "--length-unit m"
    if far.mean() > 0.5:
        raise InputError(
            f"{path}: point columns {columns} are {np.median(dist_m):.3g} m from the tracker "
            f"read as {fmt.length_unit}: they look like {other}; give {hint}"
        )
    for k in np.flatnonzero(far & ~bad_mask):
        bad_mask[k] = True
        why[k] = (f"point {columns} {dist_m[k]:.3g} m from the tracker looks like {other} "
                  f"(the other rows: {fmt.length_unit})")  # fmt: skip
    warnings = []
    if fmt.angle_unit == "deg" and len(q) > 1:
        span = np.ptp(q, axis=0)
        if np.all(np.abs(q) <= 2 * np.pi) and span.max() > 0.5:
            warnings.append(
                f"warning: {path}: every joint column stays within +-{2 * np.pi:.2f} while "
                "read as degrees: they look like radians (--angle-unit rad?)"
            )
    bad = [(lines[k], why[k]) for k in np.flatnonzero(bad_mask)]
    return ~bad_mask, bad, warnings


def read_measurement_csv(
    path: str | Path, fmt: CsvFormat, limits: Array | None = None
) -> ImportedTable:
    """Rows of a measurement CSV in SI units; unreadable rows are listed, not dropped.

    A row whose field count differs from the header's (or, without a header, from most
    rows') is a bad row, so a '1,5' cell in a comma CSV cannot shift the columns; a row in
    other units than the rest is a bad row; a file whose numbers or units contradict `fmt`
    (decimal mark, deg/rad, mm/m) raises InputError naming the column. `limits` (J, 2)
    [rad]: the robot's joint limits, for the degrees check (default: |q| <= 2 pi).
    Orientation and standard deviation columns (fmt.orientations, fmt.sigmas) may be empty
    (not measured, not stated); a bad cell in them is an InputError naming its line
    (`_six_dof_columns`).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such CSV file")
    if fmt.angle_unit not in ANGLE_UNITS or fmt.length_unit not in LENGTH_UNITS:
        raise InputError(
            f"units must be deg|rad and mm|m, got {fmt.angle_unit}, {fmt.length_unit}"
        )
    _check_six_dof_format(path, fmt)
    if len(fmt.separator) != 1:
        raise InputError(f"{path}: separator {fmt.separator!r}: one character (--sep tab: a tab)")
    spaced = fmt.separator == " "  # a run of spaces (aligned columns) is one separator
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            text = (line.lstrip(" ") for line in handle) if spaced else handle
            rows = list(csv.reader(text, delimiter=fmt.separator, skipinitialspace=spaced))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path}: not a readable CSV ({exc})") from None
    numbered = [
        (line, row) for line, row in enumerate(rows, start=1) if any(c.strip() for c in row)
    ]
    if not numbered:
        raise InputError(f"{path}: the file is empty (no header, no rows)")
    header = [h.strip() for h in numbered[0][1]] if fmt.header else None
    if header is not None and len(header) > 1 and all(_is_number(h, fmt) for h in header):
        raise InputError(
            f"{path}:{numbered[0][0]}: the header row is all numbers ({', '.join(header[:3])}"
            f"{', ...' if len(header) > 3 else ''}): a measurement, not column names; give "
            "--no-header (columns by 0-based index) or add a header row"
        )
    body = numbered[1:] if fmt.header else numbered
    if not body:
        raise InputError(f"{path}: no rows after the header (the file holds only a header)")
    if header is not None:
        n_fields, of = len(header), "the header has"
    else:
        counts = np.bincount([len(row) for _, row in body])
        n_fields, of = int(counts.argmax()), "most rows have"
    if n_fields == 1:
        _check_separator(path, fmt, *numbered[0])
    refs = (
        list(fmt.joints) + list(fmt.point) + list(fmt.dif or ()) + ([fmt.time] if fmt.time else [])
        + ([fmt.temperature] if fmt.temperature else [])
    )  # fmt: skip
    n_required = len(refs)  # the further targets' cells may be empty (not measured)
    refs += [c for _, triple in fmt.targets for c in triple]
    n_optional = len(refs)  # then the 6-DoF columns: orientations, then sigmas, in fmt order
    refs += [c for o in fmt.orientations for c in o.columns]
    refs += [c for s in fmt.sigmas for c in (s.position, s.orientation) if c]
    cols = [_column(r, header, path) for r in refs]
    _check_distinct_columns(path, refs[:n_optional], cols[:n_optional], header)
    if max(cols) >= n_fields:
        raise InputError(f"{path}: no column {max(cols)} ({of} {counted(n_fields, 'field')})")
    cells: list[tuple[int, str]] = []
    raw, bad, lines = [], [], []
    for line, row in body:
        if len(row) != n_fields:
            bad.append((line, f"{len(row)} fields, {of} {n_fields}"))
            continue
        fields = [row[c].strip() for c in cols]
        cells += [(line, f) for f in fields]
        raw.append(fields)
        lines.append(line)
    _check_decimal_mark(path, fmt, cells)
    names = [_column_label(r, c, header) for r, c in zip(refs, cols)]
    values, kept_lines, filled = [], [], []
    for line, fields in zip(lines, raw):
        numbers, why = _row_numbers(fields, names, n_required, fmt.decimal_comma)
        if why:
            bad.append((line, why))
            continue
        values.append(numbers)
        kept_lines.append(line)
        filled.append([bool(f) for f in fields[n_optional:]])  # empty 6-DoF cell: none
    if not values:
        line, why = min(bad)
        which = "the only row" if len(bad) == 1 else f"the first of {len(bad)} bad rows"
        raise InputError(f"{path}:{line}: {why} ({which}: no usable row)")
    table = np.array(values)
    keep, mixed, warnings = _unit_checks(path, fmt, table, kept_lines, limits)
    bad = sorted(bad + mixed)
    table, lines = table[keep], [line for line, k in zip(kept_lines, keep) if k]
    given = np.array(filled, dtype=bool)[keep]  # (n, 6-DoF columns)
    n_j = len(fmt.joints)
    q = table[:, :n_j] * ANGLE_UNITS[fmt.angle_unit]
    points = table[:, n_j : n_j + 3]
    if fmt.dif:
        points = points + fmt.dif_sign * table[:, n_j + 3 : n_j + 6]
    points = points * LENGTH_UNITS[fmt.length_unit]
    after = n_j + 3 + (3 if fmt.dif else 0)  # the optional columns follow, in this order
    time = table[:, after] if fmt.time else None
    temperature = table[:, after + (1 if fmt.time else 0)] if fmt.temperature else None
    extra = {
        name: table[:, n_required + 3 * k : n_required + 3 * k + 3] * LENGTH_UNITS[fmt.length_unit]
        for k, (name, _) in enumerate(fmt.targets)
    }
    for (name, columns), xyz in zip(fmt.targets, extra.values()):
        if set(columns) == set(fmt.point):
            raise InputError(f"{path}: --target {name} names the --point columns {columns}")
        dist_m = np.linalg.norm(xyz[np.isfinite(xyz).all(axis=1)], axis=1)
        if len(dist_m) and not MIN_TRACKER_RANGE_M <= np.median(dist_m) <= MAX_TRACKER_RANGE_M:
            raise InputError(
                f"{path}: target {name} columns {'/'.join(columns)} are "
                f"{np.median(dist_m):.3g} m from the tracker read as {fmt.length_unit} "
                f"(the --point columns' unit): another unit, or not point columns?"
            )
        partial = np.isnan(xyz).any(axis=1) & ~np.isnan(xyz).all(axis=1)
        if partial.any():
            k = int(np.flatnonzero(partial)[0])
            raise InputError(
                f"{path}:{lines[k]}: target {name} has some of its x, y, z cells empty: a "
                "target is measured whole or not at all"
            )
    if time is not None and np.any(np.diff(time) <= 0):
        k = int(np.flatnonzero(np.diff(time) <= 0)[0]) + 1
        raise InputError(
            f"{path}:{lines[k]}: time {time[k]:g} s does not increase (previous row: "
            f"{time[k - 1]:g} s); rows must be in measurement order"
        )
    measured: dict[str, NDArray[np.bool_]] = {"": np.ones(len(table), dtype=bool)}
    for name, xyz in extra.items():
        measured[name] = np.asarray(np.isfinite(xyz).all(axis=1), dtype=bool)
    six_dof, more = _six_dof_columns(path, fmt, table[:, n_optional:], given, lines, measured)
    return ImportedTable(
        q, points, time, tuple(bad), (*warnings, *more), temperature, extra, six_dof,
        tuple(lines),
    )  # fmt: skip


def _check_six_dof_format(path: Path, fmt: CsvFormat) -> None:
    """InputError (naming `path`) when the 6-DoF columns of `fmt` name a target that is not
    among fmt.targets, give one target two orientations (or both kinds) or two sigma
    specifications, have the wrong number of columns, give an orientation standard
    deviation without an orientation, or a unit is not understood."""
    for unit, known, option in (
        (fmt.orientation_unit, ANGLE_UNITS, "--orientation-unit"),
        (fmt.sigma_unit, SIGMA_LENGTH_UNITS, "--sigma-unit"),
        (fmt.sigma_angle_unit, SIGMA_ANGLE_UNITS, "--sigma-angle-unit"),
    ):
        if unit is not None and unit not in known:
            raise InputError(f"{path}: {option} {unit}: expected one of {'|'.join(known)}")
    names = [name for name, _ in fmt.targets]
    known_targets = ", ".join(names) or "none given"
    oriented: dict[str, OrientationColumns] = {}
    specs: list[OrientationColumns | SigmaColumns] = [*fmt.orientations, *fmt.sigmas]
    for spec in specs:
        if spec.target and spec.target not in names:
            raise InputError(
                f"{path}: {spec.option}: no target {spec.target} among the --target names "
                f"({known_targets}); without NAME: the first target"
            )
    for o in fmt.orientations:
        n_columns = 4 if o.kind == "quaternion" else 3
        if o.kind not in ("quaternion", "rpy") or len(o.columns) != n_columns:
            raise InputError(f"{path}: {o.option}: expected {n_columns} columns")
        if o.target in oriented:
            raise InputError(
                f"{path}: {oriented[o.target].option} and {o.option}: one orientation per "
                f"target ({target_label(o.target)})"
            )
        oriented[o.target] = o
    stated: set[str] = set()
    for sig in fmt.sigmas:
        if sig.target in stated:
            raise InputError(f"{path}: {sig.option}: {target_label(sig.target)} given twice")
        stated.add(sig.target)
        if sig.orientation and sig.target not in oriented:
            raise InputError(
                f"{path}: {sig.option}: an orientation standard deviation, but no "
                f"--orientation or --orientation-rpy for {target_label(sig.target)}"
            )


def _six_dof_columns(
    path: Path, fmt: CsvFormat, table: Array, given: NDArray[np.bool_], lines: list[int],
    measured: Mapping[str, NDArray[np.bool_]],
) -> tuple[dict[str, SixDof], list[str]]:  # fmt: skip
    """Rotations and stated standard deviations of the targets with 6-DoF columns.

    Parameters
    ----------
    table : shape (n, C), the 6-DoF columns in the file's units, in the order of
        fmt.orientations then fmt.sigmas (NaN where a cell is empty)
    given : shape (n, C), which of those cells are not empty
    lines : the rows' line numbers (n,)
    measured : {target: shape (n,)}, whether the target's point was measured in the row

    Returns
    -------
    six_dof : {target: (rotation (n, 3, 3), sigma (n, 2) [m, rad])}, NaN where none
    warnings : 'warning: ...' lines (standard deviations of implausible size)

    Every cell error is an InputError naming `path` and the line (`_orientation`, `_sigma`).
    """
    n = len(table)
    out: dict[str, SixDof] = {}
    start = 0
    for o in fmt.orientations:
        span = slice(start, start + len(o.columns))
        start = span.stop
        rotation = _orientation(path, fmt, o, table[:, span], given[:, span], lines,
                                measured[o.target])  # fmt: skip
        out[o.target] = (rotation, np.full((n, 2), np.nan))
    warnings = []
    for sig in fmt.sigmas:
        rotation = out.get(sig.target, (np.full((n, 3, 3), np.nan), None))[0]
        sigma = np.full((n, 2), np.nan)
        for kind in range(1 if sig.orientation is None else 2):
            cells, filled = table[:, start], given[:, start]
            start += 1
            sigma[:, kind], warning = _sigma(
                path, fmt, sig, kind, cells, filled, lines, measured[sig.target]
            )
            warnings += warning
        out[sig.target] = (rotation, sigma)
    return out, warnings


def _first_row(mask: Any) -> int | None:
    """The first row where `mask` (n,) of bool holds, None when none does."""
    rows = np.flatnonzero(mask)
    return int(rows[0]) if len(rows) else None


def _orientation(
    path: Path, fmt: CsvFormat, spec: OrientationColumns, cells: Array,
    filled: NDArray[np.bool_], lines: list[int], measured: NDArray[np.bool_],
) -> Array:  # fmt: skip
    """Rotations (n, 3, 3) of the orientation cells (n, 3 or 4) (NaN rows where all are
    empty: orientation not measured there). InputError FILE:LINE when some of a row's cells
    are empty, a row without the target's point has an orientation, a cell is not finite,
    a quaternion's norm is off 1 by more than QUATERNION_TOLERANCE, or roll-pitch-yaw read
    as rad go beyond 2 pi."""
    label, columns = target_label(spec.target), ",".join(spec.columns)
    whole = filled.all(axis=1)
    if (k := _first_row(filled.any(axis=1) & ~whole)) is not None:
        raise InputError(
            f"{path}:{lines[k]}: {label} has some of its orientation cells ({columns}) "
            "empty: an orientation is measured whole or not at all"
        )
    if (k := _first_row(whole & ~measured)) is not None:
        raise InputError(f"{path}:{lines[k]}: {label} has an orientation but no point (its "
                         "x, y, z cells are empty)")  # fmt: skip
    if (k := _first_row(whole & ~np.isfinite(cells).all(axis=1))) is not None:
        raise InputError(f"{path}:{lines[k]}: {label}'s orientation {columns} is not finite: "
                         f"{cells[k].tolist()}")  # fmt: skip
    rotation = np.full((len(cells), 3, 3), np.nan)
    if not whole.any():
        return rotation
    if spec.kind == "quaternion":
        norm = np.linalg.norm(cells, axis=1)
        if (k := _first_row(whole & (np.abs(norm - 1.0) > QUATERNION_TOLERANCE))) is not None:
            raise InputError(
                f"{path}:{lines[k]}: quaternion {columns} (x, y, z, w) of {label} has norm "
                f"{norm[k]:.6g}, not 1: not a rotation (a column mix-up?)"
            )
        rotation[whole] = Rotation.from_quat(cells[whole]).as_matrix()
        return rotation
    unit = fmt.orientation_unit or fmt.angle_unit
    beyond = whole & (np.abs(cells) > 2 * np.pi).any(axis=1)
    if unit == "rad" and (k := _first_row(beyond)) is not None:
        raise InputError(
            f"{path}:{lines[k]}: roll-pitch-yaw {columns} of {label} = {cells[k].tolist()} "
            "go beyond 2 pi read as rad: they look like degrees; give --orientation-unit deg"
        )
    # lowercase 'xyz': extrinsic (fixed axes) x, then y, then z, i.e. R = Rz Ry Rx
    rotation[whole] = Rotation.from_euler("xyz", cells[whole] * ANGLE_UNITS[unit]).as_matrix()
    return rotation


def _sigma(
    path: Path, fmt: CsvFormat, spec: SigmaColumns, kind: int, cells: Array,
    filled: NDArray[np.bool_], lines: list[int], measured: NDArray[np.bool_],
) -> tuple[Array, list[str]]:  # fmt: skip
    """Standard deviations (n,) in SI of the cells (n,) of spec's position (kind 0) or
    orientation (kind 1) column (NaN where empty: not stated), and a warning when their
    median is implausible for a tracker. InputError FILE:LINE when a cell is not a finite
    number > 0 or a row without the target's point states one."""
    what = ("position", "orientation")[kind]
    column = (spec.position, spec.orientation)[kind]
    label = target_label(spec.target)
    if (k := _first_row(filled & ~measured)) is not None:
        raise InputError(f"{path}:{lines[k]}: {label} has a {what} standard deviation "
                         f"({column}) but no point (its x, y, z cells are empty)")  # fmt: skip
    with np.errstate(invalid="ignore"):
        wrong = filled & ~(np.isfinite(cells) & (cells > 0))
    if (k := _first_row(wrong)) is not None:
        raise InputError(
            f"{path}:{lines[k]}: {what} standard deviation {column} of {label} is "
            f"{cells[k]:g}: need a finite number > 0 (an empty cell: not stated)"
        )
    if kind == 0:
        unit = fmt.sigma_unit or fmt.length_unit
        scale, si = SIGMA_LENGTH_UNITS[unit], "m"
    else:
        unit = fmt.sigma_angle_unit or fmt.orientation_unit or fmt.angle_unit
        scale, si = SIGMA_ANGLE_UNITS[unit], "rad"
    sigma = np.where(filled, cells * scale, np.nan)
    low, high = PLAUSIBLE_SIGMA[what]
    median = float(np.median(sigma[filled])) if filled.any() else low
    if low <= median <= high:
        return sigma, []
    option = "--sigma-unit" if kind == 0 else "--sigma-angle-unit"
    return sigma, [
        f"warning: {path}: {what} standard deviations {column} of {label} have a median of "
        f"{median:.3g} {si} read as {unit}, outside the plausible {low:g}..{high:g} {si}: "
        f"another unit? ({option})"
    ]


def write_measurement_bag(
    output: str | Path, q: Array, points: Array, joint_names: tuple[str, ...],
    time: Array | None = None, force: bool = False, direction: Array | None = None,
    temperature: Array | None = None, extra_points: Mapping[str, Array] | None = None,
    six_dof: Mapping[str, SixDof] | None = None,
) -> dict[str, int]:  # fmt: skip
    """A contract bag: one JointState and one PointStamped per pose, stamped in row order
    (`time` [s]: absolute Unix time from EPOCH_MIN_S on, else from the first pose; without
    `time` 1 s apart; see `write_measurements`). Written
    under a temporary name and moved in when complete (an existing `output` is replaced
    only with `force`): a failure or Ctrl-C leaves nothing. Returns messages per topic."""
    output = Path(output)
    if time is None:
        start, offsets = START_NS, np.arange(len(q)) * STEP_NS
    elif len(time) and time[0] >= EPOCH_MIN_S:  # absolute Unix time: as it is
        start, offsets = 0, np.round(np.asarray(time) * 1e9).astype(np.int64)
    else:
        start, offsets = START_NS, np.round((time - time[0]) * 1e9).astype(np.int64)
    if np.any(np.diff(offsets) <= 0):
        raise InputError("time column must increase from row to row")
    with staged_outputs(output.parent, force) as stage:
        return write_measurements(
            stage / output.name, q, points, joint_names, start + offsets, direction,
            temperature, extra_points, six_dof,
        )  # fmt: skip


def write_measurements(
    path: Path, q: Array, points: Array, joint_names: tuple[str, ...], stamps_ns: IntArray,
    direction: Array | None = None, temperature: Array | None = None,
    extra_points: Mapping[str, Array] | None = None, six_dof: Mapping[str, SixDof] | None = None,
) -> dict[str, int]:  # fmt: skip
    """Write a contract bag at `path` directly (callers stage it): per pose i a JointState
    (readings q (n, J) [rad] of `joint_names`) and a PointStamped (points (n, 3) [m],
    tracker frame), both stamped stamps_ns[i] [ns] (non-decreasing). `direction` (n, J)
    +1/-1: each joint's approach direction, written as the sign of the JointState velocity
    (the contract's direct form), so that a subset of poses keeps the directions they were
    measured with. `temperature` (n,) [deg C]: a sensor_msgs/Temperature per pose on
    TEMPERATURE_TOPIC, stamped as the pose (side data, msgs_doc/temperature.md; NaN: none
    at that pose).
    `extra_points` {NAME: (n, 3) [m]}: further targets measured at the same poses, each on
    /laser_tracker/NAME/point stamped as its pose (a NaN row: not measured at that pose;
    msgs_doc/targets.md). `six_dof` {NAME: (rotation (n, 3, 3), sigma (n, 2))}: what a 6-DoF
    probe measured at target NAME besides its point, written beside the point as a pose on
    /laser_tracker/(NAME/)pose: a PoseWithCovarianceStamped where standard deviations are
    stated, else a PoseStamped (msgs_doc/six_dof.md). Returns messages per topic."""
    if len(joint_names) != q.shape[1]:
        raise InputError(f"{q.shape[1]} joint columns for a robot with {len(joint_names)} joints")
    store = typestore(JOINT_STATE_TYPE, POINT_TYPE, TEMPERATURE_TYPE, POSE_TYPE, POSE_COV_TYPE)
    types = store.types
    poses = _pose_writers(store, six_dof or {})
    with BagWriter(path) as writer:
        writer.add_topic(JOINT_STATES_TOPIC, JOINT_STATE_TYPE)
        writer.add_topic(POINT_TOPIC, POINT_TYPE)
        if temperature is not None:
            writer.add_topic(TEMPERATURE_TOPIC, TEMPERATURE_TYPE)
        extra = {  # a target never measured here gets no topic (an empty one says nothing)
            target_topic(k): np.asarray(v, dtype=float)
            for k, v in (extra_points or {}).items()
            if np.isfinite(v).all(axis=1).any()
        }
        for topic in extra:
            writer.add_topic(topic, POINT_TYPE)
        for pose in poses:
            writer.add_topic(pose.topic, pose.type_name)
        velocities = np.zeros((len(q), 0)) if direction is None else np.asarray(direction)
        for k, (qi, pi, stamp_ns, vi) in enumerate(zip(q, points, stamps_ns, velocities)):
            stamp = types["builtin_interfaces/msg/Time"](*ns_to_sec_nanosec(int(stamp_ns)))
            serialized = joint_state_cdr(store, int(stamp_ns), joint_names, qi, vi)
            writer.write(JOINT_STATES_TOPIC, serialized, int(stamp_ns))
            for topic, xyz in ((POINT_TOPIC, pi), *((t, v[k]) for t, v in extra.items())):
                if not np.all(np.isfinite(xyz)):
                    continue  # this target not measured at this pose
                writer.write(topic, point_cdr(store, int(stamp_ns), xyz), int(stamp_ns) + 1)
            for pose in poses:
                xyz = points[k] if not pose.name else extra_points_of(extra_points, pose.name, k)
                pose_cdr = pose.serialize(k, xyz, stamp)
                if pose_cdr is not None:
                    writer.write(pose.topic, pose_cdr, int(stamp_ns) + 1)
            if temperature is not None and np.isfinite(temperature[k]):  # side data
                msg = types[TEMPERATURE_TYPE](
                    header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
                    temperature=float(temperature[k]), variance=0.0,
                )  # fmt: skip
                temperature_cdr = store.serialize_cdr(msg, TEMPERATURE_TYPE)
                writer.write(TEMPERATURE_TOPIC, temperature_cdr, int(stamp_ns) + 2)
        writer.close()
        return writer.counts


def joint_state_cdr(
    store: Any, stamp_ns: int, joint_names: tuple[str, ...], q: Array, velocity: Array
) -> bytes:
    """A sensor_msgs/JointState as CDR bytes: readings q (J,) [rad] of `joint_names`,
    `velocity` (J,) [rad/s] (or its signs; empty: none), stamped stamp_ns [ns]."""
    types = store.types
    stamp = types["builtin_interfaces/msg/Time"](*ns_to_sec_nanosec(stamp_ns))
    js = types[JOINT_STATE_TYPE](
        header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
        name=list(joint_names), position=np.asarray(q, dtype=float),
        velocity=np.asarray(velocity, dtype=float), effort=np.empty(0),
    )  # fmt: skip
    return bytes(store.serialize_cdr(js, JOINT_STATE_TYPE))


def point_cdr(store: Any, stamp_ns: int, xyz: Array) -> bytes:
    """A geometry_msgs/PointStamped in the tracker frame as CDR bytes: xyz (3,) [m],
    stamped stamp_ns [ns]."""
    types = store.types
    stamp = types["builtin_interfaces/msg/Time"](*ns_to_sec_nanosec(stamp_ns))
    pt = types[POINT_TYPE](
        header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=TRACKER_FRAME),
        point=types["geometry_msgs/msg/Point"](*map(float, xyz)),
    )
    return bytes(store.serialize_cdr(pt, POINT_TYPE))


def write_stream_bag(
    output: str | Path, js_ns: IntArray, q: Array, velocity: Array, point_ns: IntArray,
    points: Array, joint_names: tuple[str, ...], force: bool = False,
) -> dict[str, int]:  # fmt: skip
    """A contract bag of a stream (msgs_doc/stream.md): a JointState per js_ns (m,) [ns]
    (readings q (m, J) [rad], velocity (m, J) [rad/s]) and a PointStamped per point_ns
    (n,) [ns] (points (n, 3) [m], tracker frame), in stamp order, log time = stamp.
    Staged: nothing is left on failure (an existing `output` replaced only with `force`).
    Returns messages per topic."""
    output = Path(output)
    store = typestore(JOINT_STATE_TYPE, POINT_TYPE)
    messages = sorted(
        [(int(t), 0, k) for k, t in enumerate(js_ns)]
        + [(int(t), 1, k) for k, t in enumerate(point_ns)]
    )
    with staged_outputs(output.parent, force) as stage, BagWriter(stage / output.name) as writer:
        writer.add_topic(JOINT_STATES_TOPIC, JOINT_STATE_TYPE)
        writer.add_topic(POINT_TOPIC, POINT_TYPE)
        for stamp_ns, kind, k in messages:
            if kind == 0:
                cdr = joint_state_cdr(store, stamp_ns, joint_names, q[k], velocity[k])
                writer.write(JOINT_STATES_TOPIC, cdr, stamp_ns)
            else:
                writer.write(POINT_TOPIC, point_cdr(store, stamp_ns, points[k]), stamp_ns)
        writer.close()
        return writer.counts


def extra_points_of(extra_points: Mapping[str, Array] | None, name: str, k: int) -> Array:
    """Point k (3,) [m] of further target `name` (NaN when it has none)."""
    values = (extra_points or {}).get(name)
    return np.full(3, np.nan) if values is None else np.asarray(values[k], dtype=float)


@dataclass(frozen=True)
class _PoseWriter:
    """Serialises the 6-DoF messages of one target (`write_measurements`)."""

    name: str
    quat: Array  # (n, 4) x, y, z, w of the measured rotations, NaN rows: not measured
    sigma: Array  # (n, 2) [m, rad], NaN: not stated
    store: Any  # rosbags Typestore with the pose types

    @property
    def topic(self) -> str:
        return pose_topic(self.name)

    @property
    def type_name(self) -> str:
        return POSE_COV_TYPE if np.isfinite(self.sigma).any() else POSE_TYPE

    def serialize(self, k: int, xyz: Array, stamp: Any) -> bytes | None:
        """Row k's message (position xyz (3,) [m]), None when row k has neither a point,
        nor an orientation or stated accuracy."""
        oriented = bool(np.all(np.isfinite(self.quat[k])))
        if not np.all(np.isfinite(xyz)) or not (oriented or np.isfinite(self.sigma[k]).any()):
            return None
        t = self.store.types
        quat = self.quat[k] if oriented else [0.0, 0.0, 0.0, 1.0]
        pose = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](*map(float, xyz)),
            orientation=t["geometry_msgs/msg/Quaternion"](*map(float, quat)),
        )
        header = t["std_msgs/msg/Header"](stamp=stamp, frame_id=TRACKER_FRAME)
        if self.type_name == POSE_TYPE:
            msg = t[POSE_TYPE](header=header, pose=pose)
        else:
            cov = np.array(pose_covariance(self.sigma[k], oriented))
            msg = t[POSE_COV_TYPE](
                header=header,
                pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
            )
        return bytes(self.store.serialize_cdr(msg, self.type_name))


def _pose_writers(store: Any, six_dof: Mapping[str, SixDof]) -> list[_PoseWriter]:
    """One writer per target with any orientation or stated accuracy."""
    out = []
    for name, (rotation, sigma) in six_dof.items():
        rotation, sigma = np.asarray(rotation, dtype=float), np.asarray(sigma, dtype=float)
        oriented = np.isfinite(rotation).all(axis=(1, 2))
        if oriented.any() or np.isfinite(sigma).any():
            quat = np.full((len(rotation), 4), np.nan)
            if oriented.any():  # all at once: scipy's per-call overhead is most of the cost
                quat[oriented] = Rotation.from_matrix(rotation[oriented]).as_quat()
            out.append(_PoseWriter(name, quat, sigma, store))
    return out


def joined_times(times: Sequence[Array | None]) -> Array | None:
    """One time column [s] for the rows of several CSVs in order (None unless every file has
    one): absolute times (EPOCH_MIN_S on, every file) as they are, else each file from 0,
    1e6 s after the one before."""
    if not times or any(t is None for t in times):
        return None
    given = [t for t in times if t is not None]
    if all(len(t) and t[0] >= EPOCH_MIN_S for t in given):
        return np.concatenate(given)
    return np.concatenate([t - t[0] + k * 1e6 for k, t in enumerate(given)])


def with_overrides(fmt: CsvFormat, **changes: Any) -> CsvFormat:
    """A copy of `fmt` with the given (non-None) fields replaced."""
    return replace(fmt, **{k: v for k, v in changes.items() if v is not None})
