"""A private ROS 2 domain: a DDS domain id no other robot_calib process holds, claimed with
a file lock, for a graph that must see nobody else's topics (the offline simulation of
`simulate` and `run`, each test process).

Two processes on one DDS domain see each other's topics: a real robot's /joint_states, a
second simulation's /clock or a user's `sim_robot` on the default domain stalled the
offline simulation ("simulation stalled waiting for pose 124"). Fast DDS accepts domains
0-101 and 215-232; 0 is everybody's default, so it is never claimed. The lock is released
when its file handle is closed, or by the OS when the process ends (even killed).

A lock only keeps robot_calib processes apart; a foreign process may use any domain. So the
offline graph's context also starts with discovery off (`discovery_off`): its nodes match
each other in-process and nobody else (test_private_domain: two simulations at once with
foreign /joint_states and /clock publishers on domain 0 and on the domains they claim).
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from robot_calib.errors import RobotCalibError

DOMAINS = (*range(1, 102), *range(215, 233))
LOCK_DIR = Path(tempfile.gettempdir()) / "robot_calib_ros_domains"


def claim() -> tuple[int, IO[str]]:
    """The first domain of DOMAINS no process holds, and its locked file handle: the
    domain stays this process's while the handle is open."""
    LOCK_DIR.mkdir(exist_ok=True)
    for domain in DOMAINS:
        handle = open(LOCK_DIR / f"{domain}.lock", "w")  # noqa: SIM115 - held by the caller
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        return domain, handle
    raise RobotCalibError(f"no free ROS 2 domain: all {len(DOMAINS)} are held ({LOCK_DIR})")


DISCOVERY_VARIABLES = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF", "ROS_STATIC_PEERS": ""}
"""rcl reads these when a context is initialised: discovery OFF, no static peers, so the
context's participant matches its own nodes only (its endpoints match in-process) and no
other process's, even one on the same domain that holds no lock (a robot, a user's
`sim_robot`, `ROS_DOMAIN_ID=1` set by hand)."""


@contextmanager
def discovery_off() -> Iterator[None]:
    """While a context is initialised in the block (`rclpy.init`), rcl's discovery
    variables say OFF (`DISCOVERY_VARIABLES`); the environment is restored after."""
    saved = {name: os.environ.get(name) for name in DISCOVERY_VARIABLES}
    os.environ.update(DISCOVERY_VARIABLES)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


@contextmanager
def private_domain() -> Iterator[int]:
    """A domain id of `claim`, held for the duration of a `with` block."""
    domain, handle = claim()
    try:
        yield domain
    finally:
        handle.close()
