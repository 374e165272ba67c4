"""The runner the caller owns (robot_calib/parallel.py): the science's independent tasks give
the same results computed here (SEQUENTIAL, nothing installed: a library call) and in a
forked child (forked.FORKED, what the command line installs); the innermost choice holds."""

from __future__ import annotations

import os
import subprocess
import sys
from functools import partial
from pathlib import Path

from robot_calib import parallel


def square_with(box: parallel.Box[int], k: int) -> tuple[int, int]:
    return k * k + box.get(), os.getpid()


def run_tasks() -> tuple[list[int], set[int]]:
    """Three tasks aside, one waiting for a value found here meanwhile."""
    with parallel.mailbox() as box:
        tasks = [(k, partial(square_with, box, k)) for k in range(3)]
        with parallel.aside(tasks, mailbox=box) as results:
            box.put(10)
            got = [results.result(k) for k in range(3)]
    return [v for v, _ in got], {pid for _, pid in got}


# In a process of its own: pytest runs a thread, and a process with other Python threads
# never forks (`forked.can_fork`): the tasks would be computed here either way.
CHOICES = """
import os, sys
sys.path.insert(0, {here!r})
from test_parallel import run_tasks
from robot_calib import parallel
from robot_calib.forked import FORKED
def where():
    values, pids = run_tasks()
    return values, "here" if pids == {{os.getpid()}} else "child"
print(where())
with parallel.using(FORKED):
    print(where())
with parallel.using(FORKED), parallel.using(parallel.SEQUENTIAL):
    print(where())
print(where())
"""


def test_sequential_computes_here_and_forked_elsewhere_with_the_same_results() -> None:
    here, pids = run_tasks()  # nothing installed: SEQUENTIAL
    assert here == [10, 11, 14] and pids == {os.getpid()}
    code = CHOICES.format(here=str(Path(__file__).parent))
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.splitlines()
    assert out == [
        "([10, 11, 14], 'here')",  # nothing installed
        "([10, 11, 14], 'child')",  # FORKED: the same values from the child
        "([10, 11, 14], 'here')",  # the innermost choice holds
        "([10, 11, 14], 'here')",  # and none is installed after the blocks
    ]
