"""Shared plumbing of the nodes: declared parameters with descriptions, and the standalone
`main` loop (rclpy.init, spin, clean shutdown on Ctrl-C / external shutdown, exit codes)."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any, TypeVar

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from robot_calib.errors import RobotCalibError

T = TypeVar("T")
N = TypeVar("N", bound=Node)


def declare(node: Node, name: str, default: T, description: str) -> T:
    """Declare a ROS parameter with a description (units in the text) and return its value."""
    node.declare_parameter(name, default, ParameterDescriptor(description=description))
    return node.get_parameter(name).value  # type: ignore[no-any-return]


def run_standalone(factory: Callable[[], N], args: list[str] | None,
                   until_done: bool = False, on_stop: Callable[[N], Any] | None = None) -> None:
    """Run one node alone (`ros2 run robot_calib <node>` / console script).

    until_done: stop once `node.done` is true (after a short linger so reliable readers
    receive the last messages). on_stop: called once when the node stops, before shutdown.
    Bad input from the node's constructor: one line on stderr, exit status 2.
    """
    rclpy.init(args=args)
    node: N | None = None
    status = 0
    try:
        node = factory()
        start = getattr(node, "start_timer", None)
        if start is not None:
            start()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok() and not (until_done and getattr(node, "done", False)):
            executor.spin_once(timeout_sec=0.1)
        if until_done:
            for _ in range(20):  # linger: let readers take the last messages
                executor.spin_once(timeout_sec=0.05)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RobotCalibError as exc:
        print(f"{factory.__name__}: error: {exc}", file=sys.stderr)
        status = exc.exit_status
    finally:
        if node is not None:
            if on_stop is not None:
                on_stop(node)
            node.destroy_node()
        rclpy.try_shutdown()
    if status:
        sys.exit(status)
