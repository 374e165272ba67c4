"""How the benchmarks measure a `robot-calib` run: the program as a user starts it
(`python -m robot_calib ARGS`, the console script's `run`) in a child process, its wall
time, its CPU time (with the helper processes it forks and reaps: `forked.Aside`) and its
peak RSS from the kernel's accounting of that child (`os.wait4`): the largest of the
process and the helpers it reaped, not their sum (a helper shares the parent's pages
until either writes them)."""

from __future__ import annotations

import compileall
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import robot_calib

# the package's bytecode, as the README's set-up compiles it (an editable install has none,
# and with PYTHONDONTWRITEBYTECODE set every run compiled ~70 modules again: 0.15 s)
compileall.compile_dir(Path(robot_calib.__file__).parent, quiet=1)


@dataclass(frozen=True)
class Run:
    """One `robot-calib` run: wall and CPU [s], peak RSS [MiB], exit status, output."""

    wall_s: float
    cpu_s: float
    peak_mib: float
    status: int
    stdout: str
    stderr: str


def robot_calib(args: list[str]) -> Run:
    """`robot-calib ARGS` in a child process, measured (stdout/stderr collected)."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        started = time.perf_counter()
        child = subprocess.Popen([sys.executable, "-m", "robot_calib", *args], stdout=out,
                                 stderr=err, text=True)  # fmt: skip
        _, status, usage = os.wait4(child.pid, 0)  # reaped here: its own rusage
        wall = time.perf_counter() - started
        child.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        cpu = usage.ru_utime + usage.ru_stime
        return Run(wall, cpu, usage.ru_maxrss / 1024.0, child.returncode, out.read(), err.read())
