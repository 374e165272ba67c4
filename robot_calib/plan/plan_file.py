"""PLAN.yaml: a capture plan, the poses to visit in order (msgs_doc/plan.md).

Written by `robot-calib plan`; read by `simulate --plan`, `run --plan` (through
`sim.plans.make_plan`) and any capture program, always through `load_plan`, which checks a
file whole and raises a one-line InputError naming the file and the problem (not found,
not YAML, missing or unknown keys, another robot, wrong joint count or names, non-finite
readings, readings outside the joint limits).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robot_calib.errors import InputError, check_keys
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array

FORMAT = "robot_calib plan 1"
REQUIRED_KEYS = ("format", "robot", "joint_names", "poses")
KNOWN_KEYS = (*REQUIRED_KEYS, "model", "units", "speed_fraction", "design", "predicted")
POSE_UNIT = "rad"
DEFAULT_SPEED_FRACTION = 0.1  # of each joint's max speed, as the built-in `random` plan


@dataclass(frozen=True)
class PlanFile:
    """A PLAN.yaml file as read: `q` (n, J) the readings to visit, in order [rad];
    `speed_fraction` of each joint's max speed for the moves [1]; `model` the model it was
    planned for ('' when not given); `robot` the robot reference; `joint_names` (J,)."""

    path: str
    robot: str
    joint_names: tuple[str, ...]
    model: str
    q: Array
    speed_fraction: float


def is_plan_file(name: str | Path) -> bool:
    """True when a `--plan` value names a PLAN.yaml file (suffix .yaml or .yml) rather
    than a built-in plan."""
    return Path(name).suffix.lower() in (".yaml", ".yml")


def _document(path: str | Path) -> dict[str, Any]:
    """The PLAN.yaml mapping, its keys checked; InputError (one line) otherwise."""
    where = str(path)
    if not Path(path).is_file():
        raise InputError(f"{where}: no such plan file")
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise InputError(f"{where}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{where}: a plan file is a mapping (msgs_doc/plan.md)")
    missing = [k for k in REQUIRED_KEYS if k not in doc]
    if missing:
        raise InputError(f"{where}: missing key(s) {', '.join(missing)} (msgs_doc/plan.md)")
    check_keys(doc, KNOWN_KEYS, where)
    return doc


def planned_robot(path: str | Path) -> str:
    """The robot reference PLAN.yaml `path` was planned for (its `robot`)."""
    return str(_document(path)["robot"])


def load_plan(path: str | Path, robot: RobotDescription) -> PlanFile:
    """The plan of PLAN.yaml `path` for `robot`, checked whole.

    Parameters
    ----------
    path : the file.
    robot : the robot the plan will run on: the file's `robot` must be its reference
        (`RobotDescription.reference`), its `joint_names` its joint names, every reading
        within its joint limits.

    Returns
    -------
    plan : PlanFile
        q : ndarray, shape (n, J) — readings [rad], in visiting order.

    Raises InputError (one line naming `path`) on any problem.
    """
    where = str(path)
    doc = _document(path)
    if doc["format"] != FORMAT:
        raise InputError(f"{where}: format {doc['format']!r}, expected {FORMAT!r}")
    if str(doc["robot"]) != robot.reference():
        raise InputError(f"{where}: planned for robot {doc['robot']}, not for {robot.reference()}")
    units = doc.get("units") or {}
    if not isinstance(units, dict) or units.get("poses", POSE_UNIT) != POSE_UNIT:
        raise InputError(f"{where}: units.poses must be {POSE_UNIT} (got {units!r})")
    names = doc["joint_names"]
    n_joints = robot.n_joints
    if not isinstance(names, list) or len(names) != n_joints:
        raise InputError(f"{where}: joint_names must list the robot's {n_joints} joints")
    if tuple(map(str, names)) != robot.joint_names:
        raise InputError(
            f"{where}: joint_names {names} are not the robot's {list(robot.joint_names)}"
        )
    q = _readings(doc["poses"], n_joints, where)
    robot.check_joints(q, where)  # the one check of limits and units (JointLimitError)
    speed = doc.get("speed_fraction", DEFAULT_SPEED_FRACTION)
    if isinstance(speed, bool) or not isinstance(speed, int | float) or not 0 < speed <= 1:
        raise InputError(f"{where}: speed_fraction must be a number in (0, 1], got {speed!r}")
    return PlanFile(
        where,
        str(doc["robot"]),
        tuple(map(str, names)),
        str(doc.get("model", "")),
        q,
        float(speed),
    )


def _readings(rows: Any, n_joints: int, where: str) -> Array:  # noqa: ANN401 - YAML
    """The poses of a plan file as an (n, J) array [rad], else InputError."""
    if not isinstance(rows, list) or not rows:
        raise InputError(f"{where}: poses must be a non-empty list of readings [rad]")
    for k, row in enumerate(rows):
        if not isinstance(row, list) or len(row) != n_joints:
            got = len(row) if isinstance(row, list) else type(row).__name__
            raise InputError(f"{where}: pose {k} has {got} readings, the robot {n_joints}")
        if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in row):
            raise InputError(f"{where}: pose {k}: readings must be numbers [rad], got {row}")
    q = np.array(rows, dtype=float)
    bad = ~np.isfinite(q)
    if bad.any():
        row = int(np.argwhere(bad)[0][0])
        raise InputError(f"{where}: pose {row}: non-finite reading(s) {rows[row]}")
    return q


def plan_text(
    robot: RobotDescription,
    model: str,
    q: Array,
    speed_fraction: float,
    design: dict[str, Any],
    predicted: dict[str, Any],
) -> str:
    """The PLAN.yaml text of readings `q` (n, J) [rad] in visiting order for `robot`, the
    `model` they were planned for, how (`design`) and what they promise (`predicted`);
    each pose row carries its readings in degrees as a comment, for people."""
    head = {
        "format": FORMAT,
        "robot": robot.reference(),
        "joint_names": list(robot.joint_names),
        "model": model,
        "units": {"poses": POSE_UNIT, "lengths": "m", "angles": "rad"},
        "speed_fraction": float(speed_fraction),
        "design": design,
        "predicted": predicted,
    }
    rows = [
        f"- [{', '.join(repr(float(v)) for v in row)}]  # deg: "
        + ", ".join(f"{v:.3f}" for v in np.degrees(row))
        for row in np.asarray(q, dtype=float)
    ]
    comment = (
        f"# robot_calib capture plan (msgs_doc/plan.md): {len(rows)} poses of {robot.name} "
        f"for {model}; visit them in the order listed\n"
    )
    body = yaml.safe_dump(head, sort_keys=False, width=99)
    return comment + body + "poses:  # readings [rad], visiting order\n" + "\n".join(rows) + "\n"
