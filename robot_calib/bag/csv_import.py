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

The format (`csv_format`), the 6-DoF columns (`csv_six_dof`) and the writing of the bag
(`write`) are modules of their own.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robot_calib.bag.csv_format import (
    ANGLE_UNITS,
    LENGTH_UNITS,
    CsvFormat,
    ImportedTable,
    target_word,
)
from robot_calib.bag.csv_six_dof import check_six_dof_format, six_dof_columns
from robot_calib.bag.write import EPOCH_MIN_S
from robot_calib.errors import InputError, param
from robot_calib.kinematics.frames import Array
from robot_calib.measurements.recording import are_rereads, copied_rows, copies, pasted_block
from robot_calib.poses import beyond_reach

__all__ = [
    "ImportedTable",
    "check_no_copies",
    "counted",
    "joined_times",
    "read_measurement_csv",
]


def check_no_copies(paths: Sequence[str | Path], tables: Sequence[ImportedTable]) -> str:
    """InputError when a CSV is given twice, or the rows repeat themselves as a copy would:
    a block of MIN_PASTED_ROWS or more consecutive rows repeating earlier consecutive rows
    (in order or reversed), or more than MAX_REREAD_SHARE of the rows repeating an earlier
    row's joint readings and point exactly (to 1 nrad / 1 nm, `copies`), in one file or
    across the files; names the first copy and how many. Fewer, scattered exact repeats
    are re-reads of a still pose by a tracker whose export rounds (kept): returned as a
    note ('' when none)."""
    seen: dict[Path, str] = {}
    for path in paths:
        key = Path(path).resolve()
        if key in seen:
            raise InputError(
                f"{path}: given twice (as {seen[key]}): its rows would be "
                "imported twice; give each CSV once"
            )
        seen[key] = str(path)
    if not tables:
        return ""
    q = np.concatenate([t.q for t in tables])
    points = np.concatenate([t.points for t in tables])
    # not the time: a block pasted with new times is still a copy, a re-read at a later
    # time still a re-read (`are_rereads`)
    copied = copies(q, points)
    if not copied.any():
        return ""
    where = [
        f"{p}:{line}"
        for p, t in zip(paths, tables)
        for line in (t.lines or range(1, len(t.q) + 1))
    ]
    original = copied_rows(q, points)
    block = pasted_block(original)
    if are_rereads(original, len(copied)):
        k = min(original)
        return (
            f"note: {int(copied.sum())} of {len(copied)} rows repeat an earlier row's "
            f"joint readings and point exactly (first {where[k]} = {where[original[k]]}): "
            "kept as re-reads of a still pose (an export that rounds); they count as one "
            "pose in every fold and split"
        )
    k = min(original) if block is None else block[0]
    if block is not None:
        what = (
            f"rows {where[k]} .. {where[block[0] + block[1] - 1]} repeat rows from "
            f"{where[original[k]]} on, one by one ({block[1]} rows: a pasted block; a "
            "tracker measuring again never repeats a run of different points)"
        )
    else:
        what = (
            f"{where[k]}: the same joint readings and point as {where[original[k]]}, "
            "and more than half the rows repeat earlier ones exactly (a copied file: "
            "re-reads of a still pose coincide now and then, not mostly)"
        )
    raise InputError(
        f"{what} (to 1 nrad / 1 nm; {int(copied.sum())} of {len(copied)} rows are such "
        "copies); give each measurement once"
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
    --temperature, --target, --reference) are one column of the file: one number read as
    two."""
    for k, col in enumerate(cols):
        if col in cols[:k]:
            raise InputError(
                f"{path}: column {_column_label(refs[k], col, header)!r} is given twice (in "
                f"two of {', '.join(param(k) for k in COLUMN_OPTIONS)}): each value needs its own "
                "column"
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


SEPARATORS = {";": "';'", "\t": "tab", ",": "','", "|": "'|'", " ": "' '"}  # for people
# the format's options that each name columns of the file (CsvFormat's fields)
COLUMN_OPTIONS = ("joints", "point", "dif", "time", "temperature", "targets", "references")


def _check_separator(path: Path, fmt: CsvFormat, line: int, row: list[str]) -> None:
    """InputError when the first row (`line`, the header unless fmt.header is False) is one
    column holding another common separator: the file is split by that one (--sep)."""
    found = {sep: row[0].count(sep) for sep in SEPARATORS if sep != fmt.separator}
    sep = max(found, key=lambda k: found[k])
    if found[sep]:
        first = "the header" if fmt.header else "the first row"
        raise InputError(
            f"{path}:{line}: {first} is one column containing {found[sep]} {SEPARATORS[sep]} "
            f"(separator {SEPARATORS.get(fmt.separator, repr(fmt.separator))}): give "
            f"{param('separator', sep)}"
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
            f"{path}:{line}: {param('decimal_comma', True)}, but the numbers have a decimal "
            f"point ({cell!r}); drop it"
        )
    if not fmt.decimal_comma and commas and fmt.separator != ",":
        line, cell = commas[0]
        raise InputError(
            f"{path}:{line}: number {cell!r} has a decimal comma; add "
            f"{param('decimal_comma', True)}"
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
                    f"{param('angle_unit', 'deg')}"
                )
        for k in np.flatnonzero(beyond.any(axis=1)):
            j = int(np.flatnonzero(beyond[k])[0])
            bad_mask[k] = True
            why[k] = (
                f"joint column {fmt.joints[j]!r} = {q[k, j]:g} looks like degrees "
                "(the other rows: rad)"
            )
    points = table[:, n_j : n_j + 3]
    if fmt.dif:
        points = points + fmt.dif_sign * table[:, n_j + 3 : n_j + 6]
    dist_m = np.linalg.norm(points, axis=1) * LENGTH_UNITS[fmt.length_unit]
    columns = "/".join(fmt.point)
    if fmt.length_unit == "m":
        far, other, hint = dist_m > MAX_TRACKER_RANGE_M, "millimetres", param("length_unit", "mm")
    else:
        far, other, hint = dist_m < MIN_TRACKER_RANGE_M, "metres", param("length_unit", "m")
    if far.mean() > 0.5:
        raise InputError(
            f"{path}: point columns {columns} are {np.median(dist_m):.3g} m from the tracker "
            f"read as {fmt.length_unit}: they look like {other}; give {hint}"
        )
    for k in np.flatnonzero(far & ~bad_mask):
        bad_mask[k] = True
        why[k] = (
            f"point {columns} {dist_m[k]:.3g} m from the tracker looks like {other} "
            f"(the other rows: {fmt.length_unit})"
        )
    warnings = []
    if fmt.angle_unit == "deg" and len(q) > 1:
        span = np.ptp(q, axis=0)
        if np.all(np.abs(q) <= 2 * np.pi) and span.max() > 0.5:
            warnings.append(
                f"warning: {path}: every joint column stays within +-{2 * np.pi:.2f} while "
                f"read as degrees: they look like radians ({param('angle_unit', 'rad')}?)"
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
    (`csv_six_dof.six_dof_columns`).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such CSV file")
    if fmt.angle_unit not in ANGLE_UNITS or fmt.length_unit not in LENGTH_UNITS:
        raise InputError(
            f"units must be deg|rad and mm|m, got {fmt.angle_unit}, {fmt.length_unit}"
        )
    check_six_dof_format(path, fmt)
    if len(fmt.separator) != 1:
        raise InputError(
            f"{path}: {param('separator', fmt.separator)}: one character ('\\t': a tab)"
        )
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
            f"{param('header', False)} (columns by 0-based index) or add a header row"
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
        list(fmt.joints)
        + list(fmt.point)
        + list(fmt.dif or ())
        + ([fmt.time] if fmt.time else [])
        + ([fmt.temperature] if fmt.temperature else [])
    )
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
            option = param("references" if name in fmt.references else "targets")
            raise InputError(
                f"{path}: {option} {name} names the {param('point')} columns {columns}"
            )
        dist_m = np.linalg.norm(xyz[np.isfinite(xyz).all(axis=1)], axis=1)
        if len(dist_m) and not MIN_TRACKER_RANGE_M <= np.median(dist_m) <= MAX_TRACKER_RANGE_M:
            raise InputError(
                f"{path}: {target_word(fmt, name)} columns {'/'.join(columns)} are "
                f"{np.median(dist_m):.3g} m from the tracker read as {fmt.length_unit} "
                f"(the {param('point')} columns' unit): another unit, or not point columns?"
            )
        partial = np.isnan(xyz).any(axis=1) & ~np.isnan(xyz).all(axis=1)
        if partial.any():
            k = int(np.flatnonzero(partial)[0])
            raise InputError(
                f"{path}:{lines[k]}: {target_word(fmt, name)} has some of its x, y, z cells "
                "empty: a point is measured whole or not at all"
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
    six_dof, more = six_dof_columns(path, fmt, table[:, n_optional:], given, lines, measured)
    return ImportedTable(
        q,
        points,
        time,
        tuple(bad),
        (*warnings, *more),
        temperature,
        extra,
        six_dof,
        tuple(lines),
    )


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
