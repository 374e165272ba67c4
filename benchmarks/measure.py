"""How the benchmarks measure a `robot-calib` run: the program as a user starts it
(`python -m robot_calib ARGS`, the console script's `run`) in a child process, its wall
time, its CPU time (with the helper processes it forks and reaps: `forked.Aside`,
`forked.Helper`), its peak RSS from the kernel's accounting of that child (`os.wait4`:
the largest of the process and the helpers it reaped, as `/usr/bin/time` reports it), and
the peak of the summed PSS of the whole process tree (proportional set size, sampled
every 0.1 s from /proc: pages shared by a process and its forked helpers counted once),
the memory the run takes from the machine."""

from __future__ import annotations

import compileall
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import robot_calib

# the package's bytecode, as the README's set-up compiles it (an editable install has none,
# and with PYTHONDONTWRITEBYTECODE set every run compiled ~70 modules again: 0.15 s)
compileall.compile_dir(Path(robot_calib.__file__).parent, quiet=1)


@dataclass(frozen=True)
class Run:
    """One `robot-calib` run: wall and CPU [s], peak RSS of its largest process and peak
    summed PSS of its process tree [MiB] (0 where /proc has none), exit status, output."""

    wall_s: float
    cpu_s: float
    peak_mib: float
    tree_mib: float
    status: int
    stdout: str
    stderr: str


def _tree(pid: int) -> list[int]:
    """`pid` and its descendants (Linux /proc)."""
    out = [pid]
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as file:
                for child in file.read().split():
                    out += _tree(int(child))
    except OSError:
        pass
    return out


def _pss_kib(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/smaps_rollup") as file:
            for line in file:
                if line.startswith("Pss:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def robot_calib(args: list[str]) -> Run:
    """`robot-calib ARGS` in a child process, measured (stdout/stderr collected)."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        started = time.perf_counter()
        child = subprocess.Popen(
            [sys.executable, "-m", "robot_calib", *args], stdout=out, stderr=err, text=True
        )
        peak_tree = [0]
        done = threading.Event()

        def sample() -> None:
            while not done.wait(0.1):
                peak_tree[0] = max(peak_tree[0], sum(_pss_kib(p) for p in _tree(child.pid)))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        _, status, usage = os.wait4(child.pid, 0)  # reaped here: its own rusage
        wall = time.perf_counter() - started
        done.set()
        sampler.join()
        child.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        cpu = usage.ru_utime + usage.ru_stime
        return Run(
            wall,
            cpu,
            usage.ru_maxrss / 1024.0,
            peak_tree[0] / 1024.0,
            child.returncode,
            out.read(),
            err.read(),
        )
