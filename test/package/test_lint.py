"""ruff lint and format (line length 99, as ament_flake8) over the package and tests."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
RUFF = Path(sys.executable).with_name("ruff")


def test_ruff_check() -> None:
    result = subprocess.run(
        [str(RUFF), "check", "robot_calib", "test", "scripts", "benchmarks", "launch"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stdout[-3000:]


def test_ruff_format() -> None:
    result = subprocess.run(
        [str(RUFF), "format", "--check", "robot_calib", "test", "scripts", "benchmarks", "launch"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stdout[-3000:]
