"""Layering by imports: the core (measurement model, identification, diagnosis, pipeline)
never loads a file format or ROS, and each command line verb loads only what it uses
(checked in a fresh interpreter, through `sys.modules`; timings live in
benchmarks/bench_startup.py)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("mcap", "mcap_ros2", "rosbags", "rclpy", "scipy", "matplotlib")


def loaded_after(code: str) -> set[str]:
    """The heavy top-level packages in sys.modules after running `code` in a new process."""
    tops = "sorted({m.split('.')[0] for m in sys.modules})"
    probe = f"{code}\nimport json, sys\nprint(json.dumps({tops}))"
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    return set(json.loads(out.strip().splitlines()[-1])) & set(HEAVY)


@pytest.mark.parametrize(
    "module",
    [
        "robot_calib.measurements",
        "robot_calib.identify.calibrate",
        "robot_calib.diagnose.diagnosis",
        "robot_calib.diagnose.report",
        "robot_calib.pipeline",
        "robot_calib.bag",
    ],
)
def test_the_core_imports_no_file_format_nor_ros(module: str) -> None:
    assert not loaded_after(f"import {module}") & {"mcap", "mcap_ros2", "rosbags", "rclpy"}


def test_diagnose_does_not_import_the_simulator() -> None:
    probe = "import robot_calib.diagnose.diagnosis, robot_calib.diagnose.report, sys\n"
    probe += "print([m for m in sys.modules if m.startswith('robot_calib.sim')])"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True).stdout  # fmt: skip
    assert out.strip() == "[]"


def test_help_and_reading_a_parameter_file_stay_light() -> None:
    """`--help` and `predict`'s path (the CLI, the light PARAMS.json reader, POINTS.csv)
    import no solver, file format, plotting or ROS."""
    assert not loaded_after("import robot_calib.cli as c; c.build_parser()")
    assert not loaded_after(
        "import robot_calib.identify.params_file, robot_calib.predict, robot_calib.cli"
    )
