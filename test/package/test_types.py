"""mypy (pinned in requirements.txt) over the package, with the pyproject [tool.mypy] config."""

from __future__ import annotations

import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_mypy_clean() -> None:
    # The default .mypy_cache (in the repo, git-ignored) keeps reruns to a few seconds.
    result = subprocess.run(
        [sys.executable, "-m", "mypy", "robot_calib"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, (result.stdout + result.stderr)[-5000:]


def test_mypy_pinned() -> None:
    pins = [
        line.strip()
        for line in (REPO / "requirements.txt").read_text().splitlines()
        if line.startswith("mypy==")
    ]
    assert pins == [f"mypy=={version('mypy')}"]
