"""The compensated commands as a JOINTS.csv (msgs_doc/compensate.md): q1..qJ [rad],
dir1..dirJ (the approach directions the compensation assumed), then the calibrated model's
remaining error_mm and error_urad and the iterations; `predict` and `compensate --joints`
read it back (they ignore the last three columns)."""

from __future__ import annotations

from pathlib import Path

from robot_calib.atomic import write_text_atomic
from robot_calib.ik import IKSolution
from robot_calib.kinematics.frames import Array


def write_compensated_csv(path: str | Path, result: IKSolution, direction: Array) -> None:
    """Write `result` (readings (n, J) [rad], errors, iterations) with the approach
    directions (n, J) (+1/-1) to `path`, atomically."""
    n_joints = result.q.shape[1]
    header = [*(f"q{j + 1}" for j in range(n_joints)), *(f"dir{j + 1}" for j in range(n_joints)),
              "error_mm", "error_urad", "iterations"]  # fmt: skip
    rows = [",".join(header)]
    for k in range(len(result.q)):
        rows.append(",".join([*(repr(float(v)) for v in result.q[k]),
                              *(str(int(d)) for d in direction[k]),
                              f"{result.error_m[k] * 1e3:.6f}", f"{result.error_rad[k] * 1e6:.3f}",
                              str(int(result.iterations[k]))]))  # fmt: skip
    write_text_atomic(path, "\n".join(rows) + "\n")
