"""The calibrator's parameters (msgs_doc/calibrator.md, "Parameters"): declared read-only
with their descriptions, checked once at start, handed to the node as one typed value."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from rclpy.node import Node

from robot_calib.errors import InputError
from robot_calib.flows import DEFAULT_ROBOT
from robot_calib.identify import DEFAULT_ECC_ORDER, DEFAULT_MODEL
from robot_calib.identify.calibrate import parse_model
from robot_calib.kinematics.description import RobotDescription, with_joint_names
from robot_calib.kinematics.loader import load_robot
from robot_calib.measurements import PAIR_TOLERANCE_S
from robot_calib.nodes._common import declare, parameter_number
from robot_calib.nodes.calibrator_live import FIRST_TARGET, LiveTargets, live_targets

DEFAULT_QOS_DEPTH = 10000
PUBLISH_CHOICES = ("fitted", "best")  # parameter `publish`


@dataclass(frozen=True)
class CalibratorParameters:
    """The calibrator's parameters as read and checked (names as the parameters', `model`
    as `model_spec`; `robot` loaded, with `joint_names` applied; `targets` of live mode)."""

    bags: list[str]
    model_spec: str
    ecc_order: int
    robot: RobotDescription
    pair_tolerance: float
    output: str
    solve_after_idle_s: float
    residual_scale: float
    learned_correction: bool
    diagnose: bool
    publish: str
    holdout_bags: list[str]
    publish_robot_description: bool
    nominal_urdf: str
    robot_state_publisher: str
    base_frame: str
    qos_depth: int
    targets: LiveTargets


#: parameters that may change while the node runs (`ros2 param set`): checked as at start
#: and taking effect from the next solve; the others are read once (a robot, its topics and
#: bags are the node's configuration: change them by restarting, or cleanup + configure)
RUN_TIME = frozenset(
    {
        "model",
        "ecc_order",
        "pair_tolerance",
        "output",
        "solve_after_idle_s",
        "residual_scale",
        "learned_correction",
        "diagnose",
        "publish",
        "holdout_bags",
        "publish_robot_description",
        "nominal_urdf",
        "robot_state_publisher",
        "base_frame",
    }
)

_SPECS: tuple[tuple[str, object, str], ...] = (
    ("bags", [], "calibration bags (.mcap) to solve at start; empty: live topics"),
    ("model", DEFAULT_MODEL, "model to identify, e.g. geometric, geometric+eccentricity"),
    ("ecc_order", DEFAULT_ECC_ORDER, "Fourier order of the eccentricity effect [1]"),
    ("robot", DEFAULT_ROBOT, "built-in robot name, robot YAML, DH table CSV or URDF file"),
    (
        "joint_names",
        [],
        "JointState names of joints 1..J in order, if not the robot's own; empty: the robot's",
    ),
    (
        "pair_tolerance",
        PAIR_TOLERANCE_S,
        "a point pairs with the joint state nearest in header.stamp within this [s]",
    ),
    ("output", "", "also write each result to this PARAMS.json path ('' = no file)"),
    (
        "solve_after_idle_s",
        0.0,
        "live mode: solve when no new point arrived for this long after the last one "
        "[s, wall time]; 0 = only on ~/solve",
    ),
    (
        "residual_scale",
        100.0,
        "residual lines in ~/markers are drawn this many times their length [1]",
    ),
    (
        "learned_correction",
        False,
        "also learn a correction of the model's residuals (a Gaussian process: the hybrid "
        "model, PARAMS.json correction), which predict, score and compensate apply",
    ),
    (
        "diagnose",
        False,
        "also run the sim-to-real gap diagnosis and publish ~/diagnosis (+ _summary)",
    ),
    (
        "publish",
        "fitted",
        "which model the result topics and robot_description carry: 'fitted' (the "
        "parameter model) or 'best' (the diagnosis's chosen model; needs diagnose)",
    ),
    (
        "holdout_bags",
        [],
        "hold-out bags: each result scored on them (/diagnostics) and the diagnosis's "
        "(empty: none; the diagnosis then k-fold CV)",
    ),
    (
        "publish_robot_description",
        True,
        "publish each plausible result as a calibrated URDF on robot_description",
    ),
    (
        "nominal_urdf",
        "",
        "the URDF to write the calibration into for robot_description ('' = the robot's "
        "own URDF when `robot` is one, else the calibrated chain alone)",
    ),
    (
        "robot_state_publisher",
        "",
        "a robot_state_publisher node (e.g. /robot_state_publisher) whose robot_description "
        "each plausible result sets, so TF follows the calibration ('' = none)",
    ),
    (
        "base_frame",
        "base_link",
        "the robot's base frame: the parent of the static transform to laser_tracker",
    ),
    (
        "qos_depth",
        DEFAULT_QOS_DEPTH,
        "live mode: history depth of the topic subscriptions [messages]",
    ),
    ("targets", [], "live mode: further targets NAME whose /laser_tracker/NAME/point to take too"),
    (
        "six_dof_targets",
        [],
        f"live mode: targets with a 6-DoF probe whose /laser_tracker/(NAME/)pose to take "
        f"('{FIRST_TARGET}' = the first target, /laser_tracker/pose)",
    ),
)


PARAMETER_NAMES = tuple(name for name, _, _ in _SPECS)


def declare_parameters(node: Node) -> CalibratorParameters:
    """Declare the calibrator's parameters on `node` (those of RUN_TIME writable, the rest
    read-only) and read and check them (`checked_parameters`)."""
    values = {
        name: declare(
            node,
            name,
            default,
            description
            + (" (run-time: takes effect from the next solve)" if name in RUN_TIME else ""),
            read_only=name not in RUN_TIME,
        )
        for name, default, description in _SPECS
    }
    return checked_parameters(node.get_name(), values)


def checked_parameters(
    name: str, values: dict[str, object], robot: RobotDescription | None = None
) -> CalibratorParameters:
    """The parameters `values` (by name) checked: InputError naming the node `name` (or the
    file) for a bad value, an unknown robot or model, a missing folder. `robot`: the one
    already loaded (a change at run time keeps it), else loaded from `robot`."""
    v = {**values}
    for key in ("pair_tolerance", "solve_after_idle_s", "residual_scale"):
        v[key] = _number(name, key, v[key])
    for key in ("ecc_order", "qos_depth"):
        if isinstance(v[key], bool) or not isinstance(v[key], int):
            raise InputError(f"{name}: parameter {key!r} must be a whole number, not {v[key]!r}")
    model_spec, ecc_order = str(v["model"]), int(v["ecc_order"])  # type: ignore[call-overload]
    if robot is None:
        robot = load_robot(str(v["robot"]))
        joint_names = list(v["joint_names"])  # type: ignore[call-overload]
        if joint_names:
            robot = with_joint_names(robot, joint_names)
    pair_tolerance = float(v["pair_tolerance"])  # type: ignore[arg-type]
    solve_after_idle_s = float(v["solve_after_idle_s"])  # type: ignore[arg-type]
    residual_scale = float(v["residual_scale"])  # type: ignore[arg-type]
    qos_depth = int(v["qos_depth"])  # type: ignore[call-overload]
    publish, diagnose = str(v["publish"]), bool(v["diagnose"])
    nominal_urdf, output = str(v["nominal_urdf"]), str(v["output"])
    if ecc_order < 1:
        raise InputError(f"{name}: parameter 'ecc_order' must be >= 1")
    parse_model(model_spec, robot, ecc_order)  # a bad model fails now
    if pair_tolerance <= 0:
        raise InputError(f"{name}: parameter 'pair_tolerance' must be > 0 [s]")
    if solve_after_idle_s < 0:
        raise InputError(f"{name}: parameter 'solve_after_idle_s' must be >= 0 [s]")
    if residual_scale <= 0:
        raise InputError(f"{name}: parameter 'residual_scale' must be > 0")
    if publish not in PUBLISH_CHOICES:
        raise InputError(
            f"{name}: parameter 'publish' must be one of "
            f"{', '.join(PUBLISH_CHOICES)}, got {publish!r}"
        )
    if publish == "best" and not diagnose:
        raise InputError(
            f"{name}: parameter 'publish' best publishes the diagnosis's model: "
            "set diagnose to true as well"
        )
    if qos_depth < 1:
        raise InputError(f"{name}: parameter 'qos_depth' must be >= 1")
    if nominal_urdf and not Path(nominal_urdf).is_file():
        raise InputError(f"{nominal_urdf}: no such nominal URDF (parameter nominal_urdf)")
    if output and not Path(output).parent.is_dir():
        raise InputError(f"{output}: no such folder for the parameter file")
    targets = live_targets(name, list(v["targets"]), list(v["six_dof_targets"]))  # type: ignore[call-overload]
    return CalibratorParameters(
        bags=list(v["bags"]),  # type: ignore[call-overload]
        model_spec=model_spec,
        ecc_order=ecc_order,
        robot=robot,
        pair_tolerance=pair_tolerance,
        output=output,
        solve_after_idle_s=solve_after_idle_s,
        residual_scale=residual_scale,
        learned_correction=bool(v["learned_correction"]),
        diagnose=diagnose,
        publish=publish,
        holdout_bags=list(v["holdout_bags"]),  # type: ignore[call-overload]
        publish_robot_description=bool(v["publish_robot_description"]),
        nominal_urdf=nominal_urdf,
        robot_state_publisher=str(v["robot_state_publisher"]),
        base_frame=str(v["base_frame"]) or "base_link",
        qos_depth=qos_depth,
        targets=targets,
    )


def _number(name: str, key: str, value: object) -> float:
    """A float parameter's value (`parameter_number`) that is finite, else InputError."""
    number = parameter_number(name, key, value)
    if not math.isfinite(number):
        raise InputError(f"{name}: parameter {key!r} must be finite, not {value!r}")
    return number
