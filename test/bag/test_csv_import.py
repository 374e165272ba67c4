"""`robot-calib import`: measurement CSVs into contract bags (read back by rosbags too), the
options of real exports, bad rows reported by line, and the UR5 laser-tracker dataset
calibrated through the same path as simulated data."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli
from rosbags.highlevel import AnyReader

from robot_calib.accuracy import accuracy
from robot_calib.bag.csv_format import PRESETS, CsvFormat
from robot_calib.bag.csv_import import read_measurement_csv
from robot_calib.bag.read import read_recording
from robot_calib.identify.calibrate import calibrate
from robot_calib.kinematics.loader import load_robot

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "datasets" / "ur5_jacobi2025"
GRID = DATA / "3D_UR5_uncalibrated_grid_cleaned.csv"
RANDOM = DATA / "3D_UR5_uncalibrated_random_cleaned.csv"


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return cli(*args)


def test_ur5_dataset_calibrates_far_below_nominal(tmp_path: Path) -> None:
    bags = {}
    for name, csv in (("grid", GRID), ("random", RANDOM)):
        bags[name] = tmp_path / f"{name}.mcap"
        proc = run(
            "import",
            str(csv),
            "--preset",
            "ur5_jacobi2025",
            "--robot",
            "ur5",
            "-o",
            str(bags[name]),
        )
        assert proc.returncode == 0, proc.stderr
        assert "0 bad rows" in proc.stdout
    with AnyReader([bags["grid"]]) as reader:  # the contract's bag, read independently
        assert {c.topic: c.msgcount for c in reader.connections} == {
            "/joint_states": 1000,
            "/laser_tracker/point": 1000,
        }
    robot = load_robot("ur5")
    grid = read_recording([bags["grid"]], robot)
    test = read_recording([bags["random"]], robot)
    # The imported point is target - dif in metres, the joints in radians.
    table = read_measurement_csv(GRID, PRESETS["ur5_jacobi2025"])
    np.testing.assert_allclose(grid.points, table.points)
    raw = np.genfromtxt(GRID, delimiter=",", names=True)
    assert grid.points[0, 0] == pytest.approx((raw["x_t"][0] - raw["x_dif"][0]) / 1e3)
    assert grid.poses.q[0, 1] == pytest.approx(np.radians(raw["joint_2"][0]))

    short = grid.poses.subset(slice(0, 1000, 2))  # a short calibration: every other pose
    sub = type(grid)(grid.sources, short, grid.points[::2], (), grid.bag_index[::2])
    nominal = accuracy(test.points, calibrate(sub, robot, "nominal").predict(test.poses))
    geometric = accuracy(test.points, calibrate(sub, robot, "geometric").predict(test.poses))
    assert geometric.absolute_mean_mm < 0.15 < nominal.absolute_mean_mm
    assert geometric.absolute_mean_mm < 0.3 * nominal.absolute_mean_mm


def test_csv_options_and_bad_rows(tmp_path: Path) -> None:
    csv = tmp_path / "export.csv"
    rows = [
        "0,5;0,1;0,2;0,3;0,4;0,5;0,6;1250,5;20,0;-300,25",  # t; q1..q6 rad; x,y,z mm
        "1,0;0,1;0,2;0,3;0,4;0,5;0,6;1251,5;20,0;-300,25",
        "2,0;0,1;oops;0,3;0,4;0,5;0,6;1252,5;20,0;-300,25",
        "3,0;0,1;0,2",
    ]
    csv.write_text("\n".join(rows) + "\n")
    fmt = CsvFormat(
        joints=("1", "2", "3", "4", "5", "6"),
        point=("7", "8", "9"),
        time="0",
        separator=";",
        decimal_comma=True,
        angle_unit="rad",
        length_unit="mm",
        header=False,
    )
    table = read_measurement_csv(csv, fmt)
    assert len(table.q) == 2 and [line for line, _ in table.bad_rows] == [3, 4]
    np.testing.assert_allclose(table.points[1], [1.2515, 0.020, -0.30025])
    np.testing.assert_allclose(table.time, [0.5, 1.0])
    out = tmp_path / "export.mcap"
    proc = run(
        "import",
        str(csv),
        "--joints",
        "1,2,3,4,5,6",
        "--point",
        "7,8,9",
        "--time",
        "0",
        "--sep",
        ";",
        "--decimal-comma",
        "--angle-unit",
        "rad",
        "--length-unit",
        "mm",
        "--no-header",
        "-o",
        str(out),
    )
    assert proc.returncode == 0, proc.stderr
    assert f"{csv}:3: column 2 'oops' is not a number: row skipped" in proc.stderr
    assert f"{csv}:4: 3 fields" in proc.stderr
    rec = read_recording([out], load_robot("kr5_sixx_r650"))
    assert len(rec) == 2 and rec.poses.time[1] == pytest.approx(0.5)

    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\nx,y\n")
    proc = run(
        "import",
        str(bad),
        "--joints",
        "a,b,c,d,e,f",
        "--point",
        "a,b,c",
        "-o",
        str(tmp_path / "bad.mcap"),
    )
    assert proc.returncode == 2 and "bad.csv: no column 'c'" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and not (tmp_path / "bad.mcap").exists()
