"""capture's parameters (msgs_doc/capture.md, "Parameters"): declared read-only with their
descriptions, checked once at start (degrees at this edge, radians after), handed to the
node as one typed value."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rclpy.node import Node

from robot_calib.capture.moves import MoveRules, parse_approach
from robot_calib.errors import InputError
from robot_calib.flows import DEFAULT_ROBOT
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.loader import load_robot
from robot_calib.nodes._common import declare
from robot_calib.plan.plan_file import is_plan_file, planned_robot


@dataclass(frozen=True)
class CaptureParameters:
    """capture's parameters as read and checked: `robot` loaded, `joint_names` the
    controller's (default the robot's), `rules` the move rules in radians, `speed_rad_s`."""

    plan: str
    robot: RobotDescription
    joint_names: tuple[str, ...]
    output: Path
    controller: str
    tolerance: float  # position_tolerance [rad]
    settle_s: float  # settle_time [s]
    move_timeout: float  # [s]
    measure_timeout: float  # [s]
    trigger_service: str
    targets: list[str]
    rules: MoveRules
    speed_rad_s: float
    move_time: float  # [s]
    connect_timeout: float  # [s]
    trigger_retries: int
    dry_run: bool
    seed: int


def declare_parameters(node: Node) -> CaptureParameters:
    """Declare and read capture's parameters on `node`; InputError for a bad value, an
    unknown robot, joint names of the wrong count."""
    plan_name = declare(node, "plan", "paper-test3", "built-in plan name or PLAN.yaml path")
    robot_ref = declare(
        node,
        "robot",
        "",
        f"robot: built-in name, YAML or URDF (default: a PLAN.yaml's robot, else {DEFAULT_ROBOT})",
    )
    names = declare(
        node,
        "joint_names",
        [],
        "the controller's joint names in joint "
        "order, where they are not the robot's own (default: the robot's)",
    )
    output = Path(declare(node, "output", "", "campaign bag (.mcap; required)"))
    controller = declare(
        node,
        "controller",
        "joint_trajectory_controller",
        "controller name: commands on /<controller>/joint_trajectory",
    )
    tolerance = declare(
        node, "position_tolerance", 1e-4, "settled: every joint this close to the pose [rad]"
    )
    settle_s = declare(node, "settle_time", 0.5, "settled for this long [s]")
    move_timeout = declare(
        node, "move_timeout", 60.0, "a move not settled after this is skipped [s]"
    )
    measure_timeout = declare(
        node,
        "measure_timeout",
        5.0,
        "no point this long after settling: the pose is skipped [s]",
    )
    trigger = declare(
        node,
        "trigger_service",
        "",
        "std_srvs/Trigger service that makes the tracker measure ('' = take the next point)",
    )
    targets: list[str] = declare(
        node,
        "targets",
        [],
        "further targets' names (/laser_tracker/NAME/point; default: none)",
    )
    max_step = declare(node, "max_step", 90.0, "largest joint step of one move [deg]")
    approach = declare(
        node,
        "approach",
        "0",
        "approach side per joint: +, - or 0, one for all or comma-separated per joint",
    )
    overshoot = declare(node, "approach_overshoot", 1.0, "approach start before the pose [deg]")
    speed = declare(
        node,
        "speed",
        20.0,
        "joint speed of the moves [deg/s]: the trajectories' times (a joint_trajectory_"
        "controller follows the times it is given and has no speed limit of its own)",
    )
    move_time = declare(node, "move_time", 0.0, "every move takes at least this [s]")
    connect_timeout = declare(
        node,
        "connect_timeout",
        10.0,
        "no controller subscriber or no joint state this long at the start: error [s]",
    )
    trigger_retries = declare(
        node, "trigger_retries", 3, "trigger calls per pose while the tracker says no"
    )
    dry_run = declare(node, "dry_run", False, "log the moves; do not move or write")
    seed = declare(node, "seed", 0, "seed of the random plan")
    if not str(output) or output.suffix != ".mcap":
        raise InputError("parameter 'output' must name a .mcap bag")
    for name, value in (
        ("position_tolerance", tolerance),
        ("settle_time", settle_s),
        ("move_timeout", move_timeout),
        ("speed", speed),
        ("measure_timeout", measure_timeout),
        ("connect_timeout", connect_timeout),
    ):
        if not value > 0:
            raise InputError(f"parameter {name!r} must be > 0, not {value}")
    for name, value in (("max_step", max_step), ("approach_overshoot", overshoot)):
        if not (value > 0 if name == "max_step" else value >= 0):  # given in degrees
            bound = "> 0" if name == "max_step" else ">= 0"
            raise InputError(f"parameter {name!r} must be {bound} deg, not {value}")
    if not move_time >= 0 or trigger_retries < 1:
        raise InputError("parameters 'move_time' >= 0 and 'trigger_retries' >= 1")
    if not robot_ref:
        robot_ref = planned_robot(plan_name) if is_plan_file(plan_name) else DEFAULT_ROBOT
    robot = load_robot(robot_ref)
    joint_names = tuple(names) if names else robot.joint_names
    if len(joint_names) != robot.n_joints:
        raise InputError(f"parameter 'joint_names' needs {robot.n_joints} names")
    rules = MoveRules(
        np.radians(max_step), parse_approach(approach, robot.n_joints), np.radians(overshoot)
    )
    return CaptureParameters(
        plan=plan_name,
        robot=robot,
        joint_names=joint_names,
        output=output,
        controller=controller,
        tolerance=tolerance,
        settle_s=settle_s,
        move_timeout=move_timeout,
        measure_timeout=measure_timeout,
        trigger_service=trigger,
        targets=targets,
        rules=rules,
        speed_rad_s=float(np.radians(speed)),
        move_time=move_time,
        connect_timeout=connect_timeout,
        trigger_retries=trigger_retries,
        dry_run=dry_run,
        seed=seed,
    )
