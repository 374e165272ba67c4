# ruff: noqa: E402 - the BLAS thread setting must precede the numpy import
"""The UR5 laser-tracker dataset (datasets/ur5_jacobi2025) through the whole pipeline:
import the CSVs into bags, calibrate on the 1000 grid poses, diagnose (hold-out: the 20
random poses), score every model on the 20 random poses.

    .venv/bin/python scripts/ur5_table.py [--dif-sign -1|1]

Prints a Markdown table (absolute error and the seed's pairwise criterion, mean and max,
mm) and the fit times.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see robot_calib/__init__.py

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from robot_calib.accuracy import accuracy
from robot_calib.bag.csv_format import PRESETS, with_overrides
from robot_calib.bag.csv_import import read_measurement_csv
from robot_calib.bag.read import read_recording
from robot_calib.bag.write import write_measurement_bag
from robot_calib.diagnosis.diagnosis import diagnose
from robot_calib.identify.calibrate import calibrate
from robot_calib.kinematics.loader import load_robot

DATA = Path(__file__).resolve().parents[1] / "datasets" / "ur5_jacobi2025"
GRID, RANDOM = "3D_UR5_uncalibrated_grid_cleaned.csv", "3D_UR5_uncalibrated_random_cleaned.csv"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--dif-sign", type=float, default=-1.0, choices=(-1.0, 1.0))
    args = parser.parse_args()
    robot = load_robot("ur5")
    fmt = with_overrides(PRESETS["ur5_jacobi2025"], dif_sign=args.dif_sign)
    with tempfile.TemporaryDirectory() as tmp:
        bags = {}
        for name in (GRID, RANDOM):
            table = read_measurement_csv(DATA / name, fmt)
            bags[name] = Path(tmp) / f"{name}.mcap"
            write_measurement_bag(bags[name], table.q, table.points, robot.joint_names)
        grid = read_recording([bags[GRID]], robot)
        test = read_recording([bags[RANDOM]], robot)
    dif = read_measurement_csv(DATA / RANDOM, with_overrides(fmt, dif_sign=0.0))
    commanded = np.linalg.norm(test.points - dif.points, axis=1) * 1e3
    rows = [
        (
            "as commanded (dataset's own base/TCF set-up): mean abs |dif|",
            f"{commanded.mean():.4f}",
            f"{commanded.max():.4f}",
            "-",
            "-",
            "-",
        )
    ]
    fits = {}
    for model in ("nominal", "geometric"):
        started = time.perf_counter()
        cal = calibrate(grid, robot, model)
        fits[model] = (cal, time.perf_counter() - started)
    started = time.perf_counter()
    diagnosis, ladder = diagnose(grid, robot, test)
    diag_time = time.perf_counter() - started
    picked = ladder.rungs[-1]
    models = [
        ("nominal (tracker pose + tool fitted)", *fits["nominal"]),
        ("geometric", *fits["geometric"]),
    ]
    if picked.model != "geometric":
        models.append((f"diagnosis pick: {picked.model}", picked.calibration, float("nan")))
    for label, cal, seconds in models:
        acc = accuracy(test.points, cal.predict(test.poses))
        rows.append(
            (
                label,
                f"{acc.absolute_mean_mm:.4f}",
                f"{acc.absolute_max_mm:.4f}",
                f"{acc.pairwise_mean_mm:.4f}",
                f"{acc.pairwise_max_mm:.4f}",
                "-" if np.isnan(seconds) else f"{seconds:.2f}",
            )
        )
    print(
        "| model (calibrated on 1000 grid poses) | abs mean | abs max | seed mean | seed max "
        "| fit [s] |"
    )
    print("|---|---|---|---|---|---|")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    dom = None if diagnosis.dominant_effect is None else diagnosis.dominant_effect.to_dict()
    print(
        f"\ndominant effect: {dom}; diagnosis {diag_time:.1f} s; "
        f"free parameters (geometric): {int(fits['geometric'][0].parameters.free.sum())}"
    )
    print(f"note: {diagnosis.unexplained.note}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
