"""Spinning an in-process executor until something has happened (the ROS tests' loop)."""

from __future__ import annotations

import time
from collections.abc import Callable

from rclpy.executors import Executor


def spin_until(executor: Executor, condition: Callable[[], bool], timeout_s: float = 20.0) -> None:
    """Spin `executor` in 10 ms steps until `condition()`; AssertionError after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        executor.spin_once(timeout_sec=0.01)
