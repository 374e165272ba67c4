"""The compensated commands as a JOINTS.csv (msgs_doc/compensate.md): q1..qJ [rad],
dir1..dirJ (the approach directions the compensation assumed), then the calibrated model's
remaining error_mm and error_urad, the iterations and a `status` per row: `ok`,
`large_change` (a joint moved by more than LARGE_CHANGE_DEG: check before sending),
`position_only` (near a singularity, solved for the tool position alone: its orientation
is off by error_urad), `beyond_limits`, or
`not_reached`, whose q columns are `nan` so that no script sends them to a robot.
`predict` and `compensate --joints` read the file back (they ignore the extra columns)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robot_calib.atomic import write_text_atomic
from robot_calib.compensation.solve import SINGULAR_CHANGE_DEG
from robot_calib.ik import IKSolution
from robot_calib.kinematics.frames import Array

LARGE_CHANGE_DEG = SINGULAR_CHANGE_DEG  # a calibration corrects by mrad: larger is suspect


def row_status(
    result: IKSolution, start: Array, within_limits: NDArray[np.bool_] | None = None
) -> list[str]:
    """Per row: `not_reached`, `beyond_limits`, `large_change` (a joint moved by more than
    LARGE_CHANGE_DEG from `start` (n, J) [rad], the nominal commands or solution) or `ok`."""
    change = np.degrees(np.abs(result.q - start)).max(axis=1)
    within = np.ones(len(change), dtype=bool) if within_limits is None else within_limits
    point = (
        np.zeros(len(change), dtype=bool) if result.position_only is None else result.position_only
    )
    return [
        "not_reached"
        if not ok
        else "beyond_limits"
        if not inside
        else "large_change"
        if big > LARGE_CHANGE_DEG
        else "position_only"
        if alone
        else "ok"
        for ok, inside, big, alone in zip(result.converged, within, change, point)
    ]


def write_compensated_csv(
    path: str | Path, result: IKSolution, direction: Array, status: list[str]
) -> None:
    """Write `result` (readings (n, J) [rad], errors, iterations) with the approach
    directions (n, J) (+1/-1) and each row's `status` (`row_status`) to `path`,
    atomically; the readings of a `not_reached` row are written as nan."""
    n_joints = result.q.shape[1]
    header = [
        *(f"q{j + 1}" for j in range(n_joints)),
        *(f"dir{j + 1}" for j in range(n_joints)),
        "error_mm",
        "error_urad",
        "iterations",
        "status",
    ]
    rows = [",".join(header)]
    for k in range(len(result.q)):
        q = result.q[k] if status[k] != "not_reached" else np.full(n_joints, np.nan)
        rows.append(
            ",".join(
                [
                    *(repr(float(v)) for v in q),
                    *(str(int(d)) for d in direction[k]),
                    f"{result.error_m[k] * 1e3:.6f}",
                    f"{result.error_rad[k] * 1e6:.3f}",
                    str(int(result.iterations[k])),
                    status[k],
                ]
            )
        )
    write_text_atomic(path, "\n".join(rows) + "\n")
