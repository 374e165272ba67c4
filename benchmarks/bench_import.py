"""Import benchmark (target: a 2773-row, 20-column semicolon / decimal-comma
export with orientation and temperature imported in < 2 s).

    .venv/bin/python benchmarks/bench_import.py [--rows 2773] [--repeat 5]

Writes such an export (UR joint names in degrees, x/y/z in mm, a 6-DoF probe's orientation
as quaternion columns w, x, y, z, the tracker's standard deviations of position [um] and
orientation [urad], the distance, temperature, time, a status and an index column), then
times the whole `robot-calib import` process (median of --repeat runs; Python start and
imports included), which reads 17 of them (all but distance, status and index; the probe's
through --orientation and --sigma), and prints what the import printed: rows, orientations,
stated standard deviations and the bag's message counts (a PoseWithCovarianceStamped per
row on /laser_tracker/pose).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TARGET_S = 2.0
JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
COLUMNS = (
    *JOINTS,
    "X",
    "Y",
    "Z",
    "Q0",
    "QX",
    "QY",
    "QZ",
    "SP",
    "SR",
    "Dist",
    "Temp",
    "Time",
    "Status",
    "Index",
)


def export(path: Path, rows: int) -> None:
    """A 20-column export: semicolons, decimal commas, one header row."""
    rng = np.random.default_rng(0)
    q = rng.uniform(-170, 170, (rows, 6))
    xyz = rng.uniform(500, 2500, (rows, 3))
    quat = rng.normal(size=(rows, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    std = np.column_stack([rng.uniform(5, 20, rows), rng.uniform(20, 100, rows)])  # um, urad
    dist = np.linalg.norm(xyz, axis=1)
    temp = 21.0 + np.cumsum(rng.normal(0, 0.01, rows))
    lines = [";".join(COLUMNS)]
    for k in range(rows):
        values = (*q[k], *xyz[k], *quat[k], *std[k], dist[k], temp[k], 10.0 * k)
        cells = [f"{v:.6f}" for v in values]
        lines.append(";".join(c.replace(".", ",") for c in cells) + f";OK;{k}")
    path.write_text("\n".join(lines) + "\n")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=2773)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "export.csv"
        export(csv, args.rows)
        cmd = [
            sys.executable,
            "-m",
            "robot_calib",
            "import",
            str(csv),
            "--robot",
            "ur10",
            "--sep",
            ";",
            "--decimal-comma",
            "--angle-unit",
            "deg",
            "--length-unit",
            "mm",
            "--joints",
            ",".join(JOINTS),
            "--point",
            "X,Y,Z",
            "--time",
            "Time",
            "--temperature",
            "Temp",
            "--orientation",
            "QX,QY,QZ,Q0",
            "--sigma",
            "SP,SR",
            "--sigma-unit",
            "um",
            "--sigma-angle-unit",
            "urad",
            "-o",
            str(Path(tmp) / "out.mcap"),
            "--force",
        ]
        times, out = [], []
        for _ in range(args.repeat):
            started = time.perf_counter()
            proc = subprocess.run(cmd, capture_output=True, text=True, check=True)
            times.append(time.perf_counter() - started)
            out = [line.replace(tmp, "TMP") for line in proc.stdout.strip().splitlines()]
    median = statistics.median(times)
    print(f"export: {args.rows} rows x {len(COLUMNS)} columns, ';' and decimal comma")
    print(
        f"robot-calib import (whole process), median of {args.repeat}: {median:.3f} s "
        f"(min {min(times):.3f}, max {max(times):.3f}); target < {TARGET_S} s: "
        f"{'PASS' if median < TARGET_S else 'MISS'}"
    )
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
