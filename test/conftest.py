"""Test-process set-up: a private ROS_DOMAIN_ID (claimed with a file lock) and ROS_LOG_DIR.

Two processes on one DDS domain see each other's topics, so every pytest process (and
every xdist worker) claims a free domain before anything imports rclpy.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path

import pytest

import robot_calib  # noqa: F401 - first, so its one-BLAS-thread default precedes numpy

# Fast DDS accepts domains 0-101 and 215-232; 0 is everybody's default, so skip it.
_DOMAINS = [*range(1, 102), *range(215, 233)]
_LOCK_DIR = Path(tempfile.gettempdir()) / "robot_calib_ros_domains"
_held_lock = None


def _claim_domain() -> int:
    global _held_lock
    _LOCK_DIR.mkdir(exist_ok=True)
    for domain in _DOMAINS:
        handle = open(_LOCK_DIR / f"{domain}.lock", "w")  # noqa: SIM115 - held for the run
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _held_lock = handle  # released by the OS when this process exits
        return domain
    raise RuntimeError(f"no free ROS_DOMAIN_ID: all of {len(_DOMAINS)} are locked")


def pytest_configure(config) -> None:  # noqa: ANN001 - pytest hook signature
    os.environ["ROS_DOMAIN_ID"] = str(_claim_domain())
    log_dir = Path(tempfile.mkdtemp(prefix="robot_calib_roslog_"))
    os.environ["ROS_LOG_DIR"] = str(log_dir)


@pytest.fixture
def context():  # noqa: ANN201 - rclpy is imported lazily, after the domain is claimed
    """A private rclpy context, shut down after the test."""
    import rclpy
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)
