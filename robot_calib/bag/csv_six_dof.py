"""The 6-DoF columns of a measurement CSV (msgs_doc/six_dof.md): a probe's orientation
(quaternion or roll-pitch-yaw) and the tracker's stated standard deviations, per target,
checked cell by cell (every error names FILE:LINE) and converted to rotations and SI
standard deviations for `csv_import.read_measurement_csv`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from robot_calib.bag.csv_format import (
    ANGLE_UNITS,
    PLAUSIBLE_SIGMA,
    SIGMA_ANGLE_UNITS,
    SIGMA_LENGTH_UNITS,
    CsvFormat,
    OrientationColumns,
    SigmaColumns,
    target_label,
)
from robot_calib.bag.write import SixDof
from robot_calib.errors import InputError, param
from robot_calib.kinematics.frames import Array
from robot_calib.messages import QUATERNION_TOLERANCE


def check_six_dof_format(path: Path, fmt: CsvFormat) -> None:
    """InputError (naming `path`) when the 6-DoF columns of `fmt` name a target that is not
    among fmt.targets, give one target two orientations (or both kinds) or two sigma
    specifications, have the wrong number of columns, give an orientation standard
    deviation without an orientation, or a unit is not understood."""
    for unit, known, option in (
        (fmt.orientation_unit, ANGLE_UNITS, "orientation_unit"),
        (fmt.sigma_unit, SIGMA_LENGTH_UNITS, "sigma_unit"),
        (fmt.sigma_angle_unit, SIGMA_ANGLE_UNITS, "sigma_angle_unit"),
    ):
        if unit is not None and unit not in known:
            raise InputError(f"{path}: {param(option, unit)}: expected one of {'|'.join(known)}")
    names = [name for name, _ in fmt.targets]
    known_targets = ", ".join(names) or "none given"
    oriented: dict[str, OrientationColumns] = {}
    specs: list[OrientationColumns | SigmaColumns] = [*fmt.orientations, *fmt.sigmas]
    for spec in specs:
        if spec.target and spec.target not in names:
            raise InputError(
                f"{path}: {spec.option}: no target {spec.target} among the targets of "
                f"{param('targets')} ({known_targets}); without NAME: the first target"
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
                f"{param('orientation')} or {param('orientation_rpy')} for "
                f"{target_label(sig.target)}"
            )


def six_dof_columns(
    path: Path,
    fmt: CsvFormat,
    table: Array,
    given: NDArray[np.bool_],
    lines: list[int],
    measured: Mapping[str, NDArray[np.bool_]],
) -> tuple[dict[str, SixDof], list[str]]:
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
        rotation = _orientation(
            path, fmt, o, table[:, span], given[:, span], lines, measured[o.target]
        )
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
    path: Path,
    fmt: CsvFormat,
    spec: OrientationColumns,
    cells: Array,
    filled: NDArray[np.bool_],
    lines: list[int],
    measured: NDArray[np.bool_],
) -> Array:
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
        raise InputError(
            f"{path}:{lines[k]}: {label} has an orientation but no point (its "
            "x, y, z cells are empty)"
        )
    if (k := _first_row(whole & ~np.isfinite(cells).all(axis=1))) is not None:
        raise InputError(
            f"{path}:{lines[k]}: {label}'s orientation {columns} is not finite: "
            f"{cells[k].tolist()}"
        )
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
            f"go beyond 2 pi read as rad: they look like degrees; give "
            f"{param('orientation_unit', 'deg')}"
        )
    # lowercase 'xyz': extrinsic (fixed axes) x, then y, then z, i.e. R = Rz Ry Rx
    rotation[whole] = Rotation.from_euler("xyz", cells[whole] * ANGLE_UNITS[unit]).as_matrix()
    return rotation


def _sigma(
    path: Path,
    fmt: CsvFormat,
    spec: SigmaColumns,
    kind: int,
    cells: Array,
    filled: NDArray[np.bool_],
    lines: list[int],
    measured: NDArray[np.bool_],
) -> tuple[Array, list[str]]:
    """Standard deviations (n,) in SI of the cells (n,) of spec's position (kind 0) or
    orientation (kind 1) column (NaN where empty: not stated), and a warning when their
    median is implausible for a tracker. InputError FILE:LINE when a cell is not a finite
    number > 0 or a row without the target's point states one."""
    what = ("position", "orientation")[kind]
    column = (spec.position, spec.orientation)[kind]
    label = target_label(spec.target)
    if (k := _first_row(filled & ~measured)) is not None:
        raise InputError(
            f"{path}:{lines[k]}: {label} has a {what} standard deviation "
            f"({column}) but no point (its x, y, z cells are empty)"
        )
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
    option = param("sigma_unit" if kind == 0 else "sigma_angle_unit")
    return sigma, [
        f"warning: {path}: {what} standard deviations {column} of {label} have a median of "
        f"{median:.3g} {si} read as {unit}, outside the plausible {low:g}..{high:g} {si}: "
        f"another unit? ({option})"
    ]
