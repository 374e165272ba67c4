"""The real command line, run as a subprocess by the tests (`python -m robot_calib`)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def robot_calib(
    *args: str, cwd: Path | None = None, timeout: float | None = None
) -> subprocess.CompletedProcess[str]:
    """`robot-calib ARGS...` in `cwd`: exit status, stdout and stderr as text."""
    return subprocess.run(
        [sys.executable, "-m", "robot_calib", *args],
        capture_output=True,
        text=True,
        check=False,
        cwd=cwd,
        timeout=timeout,
    )
