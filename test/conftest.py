"""Test-process set-up: a private ROS_DOMAIN_ID (claimed with a file lock) and ROS_LOG_DIR.

Two processes on one DDS domain see each other's topics, so every pytest process (and
every xdist worker) claims a free domain before anything imports rclpy.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

import robot_calib  # noqa: F401 - first, so its one-BLAS-thread default precedes numpy
from robot_calib.nodes.private_domain import claim

_held_lock = None


def _claim_domain() -> int:
    global _held_lock
    domain, _held_lock = claim()  # released by the OS when this process exits
    return domain


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
