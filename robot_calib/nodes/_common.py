"""Shared plumbing of the recorder and replay nodes: described parameters, type import,
QoS conversion, and the standalone `main` loop with SIGINT/SIGTERM/SIGHUP handling."""

from __future__ import annotations

import importlib
import re
import signal
import sys
from collections.abc import Callable, Sequence
from types import FrameType
from typing import Any, TypeVar

import rclpy
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy._rclpy_pybind11 import RCLError
from rclpy.exceptions import ParameterException, ParameterUninitializedException
from rclpy.executors import (
    Executor,
    ExternalShutdownException,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.signals import SignalHandlerOptions

from robot_calib.bag.ros2_formats import QosProfile, duration_from_ns
from robot_calib.errors import ELSEWHERE, KEYWORD, InputError, RobotCalibError, keyword_value

N = TypeVar("N", bound=Node)
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""Signals that stop a standalone node cleanly (SIGHUP: the terminal or SSH session closed)."""

_TYPES = {
    str: ParameterType.PARAMETER_STRING,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    bool: ParameterType.PARAMETER_BOOL,
    list: ParameterType.PARAMETER_STRING_ARRAY,  # the only array parameters here
}


#: the parameters the nodes of this process declared (`declare`): the core's keywords of
#: these are named as parameters, the others as the command line's (`in_ros_terms`)
_DECLARED: set[str] = set()


def declare(node: Node, name: str, default: Any, description: str, read_only: bool = True) -> Any:
    """Declare a typed ROS parameter with a description (units in the text), read-only
    unless `read_only` is False (a run-time parameter: the node validates changes), and
    return its value. A float parameter also takes an integer (`-p rate:=1`)."""
    _DECLARED.add(name)
    if isinstance(default, float):
        descriptor = ParameterDescriptor(
            description=description, read_only=read_only, dynamic_typing=True
        )
    else:
        descriptor = ParameterDescriptor(
            type=_TYPES[type(default)], description=description, read_only=read_only
        )
    try:
        if isinstance(default, list) and not default:  # an empty list has no inferable type
            node.declare_parameter(name, Parameter.Type.STRING_ARRAY, descriptor)
        else:
            node.declare_parameter(name, default, descriptor)
        value = node.get_parameter(name).value
    except ParameterUninitializedException:  # the empty-list default, not overridden
        return []
    except ParameterException as exc:  # e.g. `-p qos_depth:=many`
        hint = f" (a list: -p \"{name}:=['a.mcap']\")" if isinstance(default, list) else ""
        raise InputError(f"{node.get_name()}: parameter {name!r}: {exc}{hint}") from None
    if isinstance(default, float):
        return parameter_number(node.get_name(), name, value)
    return list(value) if isinstance(default, list) else value


def parameter_number(node_name: str, name: str, value: object) -> float:
    """A float parameter's value (an int too: `-p rate:=1`); InputError naming the node
    and the parameter for anything else (a bool, a string)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{node_name}: parameter {name!r} must be a number, not {value!r}")
    return float(value)


def overrides(
    values: dict[str, Any], parameter_overrides: Sequence[Parameter] | None
) -> list[Parameter]:
    """Keyword arguments that are not None, as parameter overrides (after any given ones)."""
    given = list(parameter_overrides or [])
    return given + [
        Parameter(name, value=value) for name, value in values.items() if value is not None
    ]


def message_class(type_name: str) -> type:
    """The Python class of 'pkg/msg/Type' (the package must be installed); InputError."""
    parts = type_name.split("/")
    if len(parts) != 3:
        raise InputError(f"bad message type name {type_name!r} (want pkg/msg/Type)")
    package, namespace, name = parts
    try:
        cls: type = getattr(importlib.import_module(f"{package}.{namespace}"), name)
    except (ImportError, AttributeError) as exc:
        raise InputError(f"message type {type_name} is not installed: {exc}") from None
    return cls


def qos_to_record(qos: QoSProfile) -> QosProfile:
    """An rclpy QoS profile as rosbag2 records it (rmw policy names, (sec, nsec))."""
    return QosProfile(
        history=qos.history.name.lower(),
        depth=int(qos.depth),
        reliability=qos.reliability.name.lower(),
        durability=qos.durability.name.lower(),
        deadline=duration_from_ns(qos.deadline.nanoseconds),
        lifespan=duration_from_ns(qos.lifespan.nanoseconds),
        liveliness=qos.liveliness.name.lower(),
        liveliness_lease_duration=duration_from_ns(qos.liveliness_lease_duration.nanoseconds),
        avoid_ros_namespace_conventions=bool(qos.avoid_ros_namespace_conventions),
    )


def in_ros_terms(text: object) -> str:
    """A core message in a node's terms: a keyword the core names (`errors.param`:
    `` `model='x'` ``) as the node's parameter of that name (parameter 'model' x), or,
    where no node here has that parameter, as the command line's option (`robot-calib
    calibrate --stream`: `errors.ELSEWHERE`) or in words (name=value)."""
    return KEYWORD.sub(_as_parameter, str(text))


def _as_parameter(match: re.Match[str]) -> str:
    if match.group(1) not in _DECLARED:
        name, text = match.group(1), match.group(2)
        return ELSEWHERE.get(name) or (name if text is None else f"{name}={text}")
    if match.group(2) is None:
        return f"parameter '{match.group(1)}'"
    value = keyword_value(match.group(2))
    if isinstance(value, bool):
        value = str(value).lower()  # as a ROS parameter is written: force:=true
    elif isinstance(value, list | tuple):
        value = ",".join(map(str, value))
    return f"parameter '{match.group(1)}' {value}"


def check_overrides(node: Node) -> None:
    """InputError for a parameter given on the command line (`-p name:=value`) that the
    node does not declare: a misspelt name would else be ignored without a word."""
    import difflib

    declared = set(node._parameters)  # noqa: SLF001 - rclpy keeps no public list of both
    given = set(getattr(node, "_parameter_overrides", {}))
    unknown = sorted(n for n in given - declared if not n.startswith("qos_overrides."))
    if unknown:
        close = difflib.get_close_matches(unknown[0], sorted(declared), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise InputError(
            f"parameter {unknown[0]!r} is not one of {node.get_name()}'s{hint}: "
            f"{', '.join(sorted(declared))}"
        )


def _unprefixed(name: str | None, exc: Exception) -> str:
    """The error in ROS terms without a leading 'NAME: ' that the line's prefix says."""
    return in_ros_terms(exc).removeprefix(f"{name}: ") if name else in_ros_terms(exc)


def ros_arguments_error(exc: Exception) -> str:
    """One line for rcl's refusal of the command line's ROS arguments: the rule it could not
    parse, and how an empty value is written."""
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    match = re.search(r"Couldn't parse parameter override rule: '([^']*)'", text)
    if match:
        rule = match.group(1).removeprefix("-p").strip()
        return (
            f"the ROS argument {match.group(1)!r} has no value: write an empty value "
            f"quoted, -p \"{rule}''\", or leave the parameter out (its default)"
        )
    return f"the ROS arguments could not be read ({text.split(', at ')[0]})"


def run_node(
    factory: Callable[[], N],
    args: Sequence[str] | None = None,
    *,
    done: Callable[[N], bool] | None = None,
    on_stop: Callable[[N], Any] | None = None,
    name: str | None = None,
    multithreaded: bool = False,
    left: Callable[[N], str | None] | None = None,
) -> int:
    """Run one node alone until SIGINT, SIGTERM, SIGHUP, external shutdown or `done(node)`.

    SIGINT, SIGTERM and SIGHUP (its terminal closed) only set a flag (Python handlers;
    rclpy's own handlers are not installed), so a callback is never interrupted half-way; the
    loop then stops, calls `on_stop(node)` (e.g. finalise a file), destroys the node and
    shuts rclpy down.
    Returns the exit status: 0, or 2 for bad input (one line on stderr: "NAME: error: …").
    multithreaded: spin a MultiThreadedExecutor, for a node whose long callbacks sit in
    their own callback group (the calibrator); otherwise one thread keeps callbacks ordered.
    left: what a signal left undone (None: nothing); when it says something the node was
    interrupted: "NAME: interrupted: <left>" on stderr and exit status 130, so an
    interrupted campaign never looks finished.
    """
    received: list[int] = []

    def stop(signum: int, frame: FrameType | None) -> None:
        received.append(signum)

    name = name or getattr(factory, "__name__", "node")
    try:
        rclpy.init(
            args=list(args) if args is not None else None,
            signal_handler_options=SignalHandlerOptions.NO,
        )
    except RCLError as exc:  # rcl could not read the --ros-args (e.g. `-p world:=`)
        print(f"{name}: error: {ros_arguments_error(exc)}", file=sys.stderr, flush=True)
        return InputError.exit_status
    previous = {sig: signal.signal(sig, stop) for sig in _STOP_SIGNALS}
    node: N | None = None
    executor: Executor | None = None
    status = 0
    try:
        node = factory()
        check_overrides(node)
        executor = MultiThreadedExecutor() if multithreaded else SingleThreadedExecutor()
        executor.add_node(node)
        while not received and rclpy.ok() and not (done is not None and done(node)):
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RobotCalibError as exc:
        print(f"{name}: error: {_unprefixed(name, exc)}", file=sys.stderr, flush=True)
        status = exc.exit_status
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=0)  # no new callbacks; a running one may finish
        if node is not None and getattr(node, "busy", False):
            print(
                f"{name}: stopping; the running solve ends first (Ctrl-C again to abort)",
                file=sys.stderr,
                flush=True,
            )
        try:
            if node is not None:
                if on_stop is not None:
                    on_stop(node)
                undone = left(node) if received and left is not None and status == 0 else None
                node.destroy_node()
                if undone:
                    print(f"{name}: interrupted: {undone}", file=sys.stderr, flush=True)
                    status = 130
        except RobotCalibError as exc:
            print(f"{name}: error: {_unprefixed(name, exc)}", file=sys.stderr, flush=True)
            status = exc.exit_status
        finally:
            rclpy.try_shutdown()
            for sig, handler in previous.items():
                signal.signal(sig, handler)
    return status
