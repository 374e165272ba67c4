"""How a measurement CSV is read (`CsvFormat`: its columns, units, separator; the presets
of known exports) and what reading it gives (`ImportedTable`); the units it understands
(msgs_doc/import.md). Plain data: the reading itself is `csv_import`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from robot_calib.bag.write import SixDof
from robot_calib.errors import param
from robot_calib.kinematics.frames import Array

ANGLE_UNITS = {"deg": np.pi / 180.0, "rad": 1.0}
LENGTH_UNITS = {"mm": 1e-3, "m": 1.0}
# stated standard deviations: trackers often give micrometres and microradians/millidegrees
SIGMA_LENGTH_UNITS = {**LENGTH_UNITS, "um": 1e-6}
SIGMA_ANGLE_UNITS = {**ANGLE_UNITS, "mdeg": np.pi / 180e3, "urad": 1e-6}
# plausible medians of stated standard deviations [m], [rad]: outside, a unit mix-up is
# likelier (um read as mm, urad as rad, mdeg as deg): a warning, not an error
PLAUSIBLE_SIGMA = {"position": (1e-7, 1e-3), "orientation": (1e-7, 2e-2)}


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
        """How messages name it: `orientation[_rpy]='[NAME:]C,C,...'` (`errors.param`)."""
        name = "orientation" if self.kind == "quaternion" else "orientation_rpy"
        return param(name, f"{self.target + ':' if self.target else ''}{','.join(self.columns)}")


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
        """How messages name it: `sigma='[NAME:]SP[,SR]'` (`errors.param`)."""
        columns = self.position + (f",{self.orientation}" if self.orientation else "")
        return param("sigma", f"{self.target + ':' if self.target else ''}{columns}")


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
    # the names among `targets` that are reference reflectors (--reference; msgs_doc/
    # references.md): read like targets, named as references in messages
    references: tuple[str, ...] = ()
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


def with_overrides(fmt: CsvFormat, **changes: Any) -> CsvFormat:
    """A copy of `fmt` with the given (non-None) fields replaced."""
    return replace(fmt, **{k: v for k, v in changes.items() if v is not None})


def target_word(fmt: CsvFormat, name: str) -> str:
    """'target NAME' or 'reference NAME' (a --reference), for messages."""
    return f"{'reference' if name in fmt.references else 'target'} {name}"
