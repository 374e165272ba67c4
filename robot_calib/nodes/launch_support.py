"""What the launch files in launch/ start, as data, and the one builder of their descriptions.

`ros2 launch robot_calib X.launch.py` runs a file that only calls `launch_description(X)`
with one of the specs below (SIM_GRAPH, CAPTURE, CALIBRATOR): the launch arguments with
their defaults, and per node its executable, its parameters (a constant, or a launch
argument's value) and when it starts. The boilerplate every file repeated is defined here
once: the `params_file` argument (the installed config/robot_calib.yaml, loaded first, the
arguments win), `output='screen'`, string parameters passed as text, and shutting the
launch down when a node ends. msgs_doc/launch.md documents the arguments.

The specs are plain data (test/nodes/test_launch_files.py checks them against the parameters
each node declares); `launch` and `launch_ros` are imported only inside
`launch_description`, so importing robot_calib never needs them (they come with a ROS 2
install, package.xml `exec_depend`, not with the wheels).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

PACKAGE = "robot_calib"
#: the parameters YAML every node of PACKAGE loads first (`params_file:=` to replace it)
PARAMS_FILE = "params_file"
PARAMS_YAML = ("config", "robot_calib.yaml")  # in share/robot_calib
RVIZ_CONFIG = ("rviz", "robot_calib.rviz")


@dataclass(frozen=True)
class ShareFile:
    """A file installed in share/robot_calib (folder, name)."""

    folder: str
    name: str


@dataclass(frozen=True)
class Argument:
    """A launch argument: its name, default (None: required; a ShareFile: that installed
    file's path) and description."""

    name: str
    default: str | ShareFile | None
    description: str


@dataclass(frozen=True)
class FromArgument:
    """A parameter set to a launch argument's value. `text`: passed as a string
    (`ParameterValue(..., value_type=str)`); else launch_ros reads the text as YAML, as
    `-p name:=value` does ('' would be null, which it refuses, and '0' an integer)."""

    argument: str
    text: bool = False


@dataclass(frozen=True)
class When:
    """A node's condition on a launch argument: `test` 'true' (the argument is true),
    'empty' (it is '') or 'given' (it is not '')."""

    argument: str
    test: str = "true"

    def __post_init__(self) -> None:
        if self.test not in ("true", "empty", "given"):
            raise ValueError(f"When({self.argument!r}, {self.test!r}): true, empty or given")


@dataclass(frozen=True)
class FileText:
    """A parameter set to the text of the file a launch argument names (`cat FILE`, as
    robot_state_publisher's robot_description is given)."""

    argument: str


Value = FromArgument | FileText | bool | int | float | str


@dataclass(frozen=True)
class NodeSpec:
    """One node a launch file starts. `parameters` come after the `params_file` YAML (nodes
    of PACKAGE only); `shutdown_after_s`: when this node exits, the launch shuts down after
    this many seconds (None: it does not), for `shutdown_reason`."""

    executable: str
    parameters: Mapping[str, Value] = field(default_factory=dict)
    package: str = PACKAGE
    when: When | None = None
    arguments: tuple[str | ShareFile, ...] = ()
    shutdown_after_s: float | None = None
    shutdown_reason: str = ""


@dataclass(frozen=True)
class LaunchSpec:
    """A launch file: its arguments (after `params_file`, declared first) and its nodes."""

    name: str
    arguments: tuple[Argument, ...]
    nodes: tuple[NodeSpec, ...]

    @property
    def all_arguments(self) -> tuple[Argument, ...]:
        """`params_file` and the launch file's own arguments, in declaration order."""
        params = Argument(
            PARAMS_FILE,
            ShareFile(*PARAMS_YAML),
            "parameters YAML of the nodes (the arguments below win)",
        )
        return (params, *self.arguments)


def _text(name: str) -> FromArgument:
    return FromArgument(name, text=True)


SIM_GRAPH = LaunchSpec(
    "sim_graph.launch.py",
    (
        Argument("plan", "paper-test3", "built-in plan or PLAN.yaml"),
        Argument("rate", "1.0", "time factor vs the plan's timing (<= 0: one pose per 5 ms)"),
        Argument("world", "", "world YAML ('' = built-in default)"),
        Argument("output", "run.mcap", "bag to write (must not exist)"),
        Argument(
            "wait_for_subscribers",
            "2",
            "/joint_states readers sim_robot waits for (recorder + sim_tracker; 3 with a "
            "live calibrator)",
        ),
    ),
    (
        NodeSpec("recorder", {"output": _text("output")}),
        NodeSpec("sim_tracker", {"world": _text("world"), "wait_for_subscribers": 1}),
        NodeSpec(
            "sim_robot",
            {
                "mode": "plan",
                "plan": _text("plan"),
                "rate": FromArgument("rate"),
                "world": _text("world"),
                "wait_for_subscribers": FromArgument("wait_for_subscribers"),
            },
            # after sim_robot exits, the last points reach the recorder before the shutdown
            # closes the bag
            shutdown_after_s=1.0,
            shutdown_reason="plan done",
        ),
    ),
)

CAPTURE = LaunchSpec(
    "capture.launch.py",
    (
        Argument("plan", None, "PLAN.yaml of robot-calib plan (or a built-in plan)"),
        Argument("output", None, "campaign bag .mcap (resumed if it exists)"),
        Argument(
            "controller",
            "joint_trajectory_controller",
            "commands go to /<controller>/joint_trajectory",
        ),
        Argument("robot", "", "built-in robot, YAML or URDF ('' = the PLAN.yaml's robot)"),
        Argument(
            "trigger_service", "", "std_srvs/Trigger of the tracker driver ('' = next point)"
        ),
        Argument("approach", "0", "approach side: +, -, 0 or per joint"),
        Argument("dry_run", "false", "log the moves, move nothing"),
        Argument(
            "record_raw", "false", "also record the raw /joint_states and /laser_tracker/point"
        ),
        Argument("raw_output", "raw.mcap", "bag of the raw streams"),
    ),
    (
        NodeSpec(
            "capture",
            {
                **{name: _text(name) for name in ("plan", "output", "controller", "robot")},
                "trigger_service": _text("trigger_service"),
                "approach": _text("approach"),
                "dry_run": FromArgument("dry_run"),
            },
            shutdown_after_s=0.0,
            shutdown_reason="capture ended",
        ),
        NodeSpec("recorder", {"output": _text("raw_output")}, when=When("record_raw")),
    ),
)

_CALIBRATOR_COMMON: dict[str, Value] = {
    "model": _text("model"),
    "robot": _text("robot"),
    "output": _text("output"),
    "diagnose": FromArgument("diagnose"),
    # the calibration written into the robot's URDF, and robot_state_publisher told of it
    "nominal_urdf": _text("urdf"),
    "robot_state_publisher": _text("state_publisher"),
}
STATE_PUBLISHER = "/robot_state_publisher"
CALIBRATOR = LaunchSpec(
    "calibrator.launch.py",
    (
        Argument(
            "bags", "", "YAML list of calibration bags, e.g. \"['run.mcap']\"; '' = live mode"
        ),
        Argument("model", "geometric", "model of the ladder to fit"),
        Argument("robot", "kr5_sixx_r650", "built-in robot, YAML, URDF"),
        Argument("output", "", "also write PARAMS.json here"),
        Argument("diagnose", "false", "also run the diagnosis"),
        Argument(
            "solve_after_idle_s",
            "0.0",
            "live: solve this long after the last point [s]; 0 = on request",
        ),
        Argument("rviz", "false", "start RViz with robot_calib.rviz"),
        Argument(
            "urdf",
            "",
            "the robot's URDF: robot_state_publisher starts on it and each "
            "plausible calibration is written into it and set as its robot_description "
            "(TF and RViz follow the calibration); '' = none",
        ),
        Argument(
            "state_publisher",
            STATE_PUBLISHER,
            "the robot_state_publisher node the calibrator updates ('' = none)",
        ),
    ),
    (
        # bag mode
        NodeSpec(
            "calibrator",
            {**_CALIBRATOR_COMMON, "bags": FromArgument("bags")},
            when=When("bags", "given"),
        ),
        # live mode (an empty list is no launch_ros parameter value: `bags` not passed)
        NodeSpec(
            "calibrator",
            {**_CALIBRATOR_COMMON, "solve_after_idle_s": FromArgument("solve_after_idle_s")},
            when=When("bags", "empty"),
        ),
        NodeSpec(
            "robot_state_publisher",
            {"robot_description": FileText("urdf")},
            package="robot_state_publisher",
            when=When("urdf", "given"),
        ),
        NodeSpec(
            "rviz2", package="rviz2", when=When("rviz"), arguments=("-d", ShareFile(*RVIZ_CONFIG))
        ),
    ),
)

SPECS = {spec.name: spec for spec in (SIM_GRAPH, CAPTURE, CALIBRATOR)}


def launch_description(spec: LaunchSpec) -> Any:  # noqa: ANN401 - a launch.LaunchDescription
    """The launch description of `spec` (launch and launch_ros: a ROS 2 install)."""
    # (mypy, run from the repository, takes its launch/ folder for the package `launch`)
    from launch import LaunchDescription  # type: ignore[attr-defined]
    from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler, TimerAction
    from launch.conditions import IfCondition
    from launch.event_handlers import OnProcessExit
    from launch.events import Shutdown
    from launch.substitutions import (
        Command,
        EqualsSubstitution,
        LaunchConfiguration,
        NotEqualsSubstitution,
        PathJoinSubstitution,
    )
    from launch_ros.actions import Node
    from launch_ros.parameter_descriptions import ParameterValue
    from launch_ros.substitutions import FindPackageShare

    def share(file: ShareFile) -> Any:  # noqa: ANN401 - a launch substitution
        return PathJoinSubstitution([FindPackageShare(PACKAGE), file.folder, file.name])

    def value(given: Value) -> Any:  # noqa: ANN401 - a launch substitution or a constant
        if isinstance(given, FileText):
            return ParameterValue(
                Command(["cat ", LaunchConfiguration(given.argument)]), value_type=str
            )
        if not isinstance(given, FromArgument):
            return given
        argument = LaunchConfiguration(given.argument)
        return ParameterValue(argument, value_type=str) if given.text else argument

    def condition(when: When) -> Any:  # noqa: ANN401 - a launch condition
        argument = LaunchConfiguration(when.argument)
        if when.test == "empty":
            return IfCondition(EqualsSubstitution(argument, ""))
        if when.test == "given":
            return IfCondition(NotEqualsSubstitution(argument, ""))
        return IfCondition(argument)

    entities: list[Any] = []
    for declared in spec.all_arguments:
        default = declared.default
        if isinstance(default, ShareFile):
            default = share(default)
        options: dict[str, Any] = {} if default is None else {"default_value": default}
        entities.append(
            DeclareLaunchArgument(declared.name, description=declared.description, **options)
        )
    handlers = []  # after every node, as the launch files had them
    for node in spec.nodes:
        options = {} if node.when is None else {"condition": condition(node.when)}
        parameters = {name: value(v) for name, v in node.parameters.items()}
        if node.package == PACKAGE:
            options["parameters"] = [LaunchConfiguration(PARAMS_FILE), parameters]
        elif parameters:
            options["parameters"] = [parameters]
        if node.arguments:
            options["arguments"] = [
                share(a) if isinstance(a, ShareFile) else a for a in node.arguments
            ]
        action = Node(
            package=node.package,
            executable=node.executable,
            output="screen",
            **options,
        )
        entities.append(action)
        if node.shutdown_after_s is not None:
            shutdown: Any = EmitEvent(event=Shutdown(reason=node.shutdown_reason))
            if node.shutdown_after_s > 0:
                shutdown = TimerAction(period=node.shutdown_after_s, actions=[shutdown])
            handlers.append(
                RegisterEventHandler(OnProcessExit(target_action=action, on_exit=[shutdown]))
            )
    return LaunchDescription(entities + handlers)
