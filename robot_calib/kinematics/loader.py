"""One name for every robot description: a built-in robot, a robot YAML file or a URDF.

The layers below it: `description` (the `RobotDescription` type and robot YAML files) and
`urdf` (a URDF chain converted into a `RobotDescription`); this module only dispatches
(and checks a YAML file's mass model, as `urdf` checks a URDF's: `masses`).
"""

from __future__ import annotations

from pathlib import Path

from robot_calib.errors import RobotDescriptionError
from robot_calib.kinematics.description import (
    ROBOTS_DIR,
    RobotDescription,
    available_robots,
    load_robot_yaml,
)
from robot_calib.kinematics.masses import checked_mass_model
from robot_calib.kinematics.urdf import (
    description_from_text,
    is_urdf_reference,
    load_urdf_reference,
)


def load_robot(name_or_path: str | Path) -> RobotDescription:
    """A built-in robot by name, a robot YAML file by path, a DH table as CSV (`PATH.csv`,
    kinematics/dh_csv.py) or a URDF (kinematics/urdf.py: `PATH.urdf` or
    `PATH.urdf#base_link=B&tip_link=T`). RobotDescriptionError naming the robot or file
    when it is unknown, missing or invalid."""
    if is_urdf_reference(name_or_path):
        return load_urdf_reference(name_or_path)
    path = Path(name_or_path)
    if path.suffix.lower() == ".csv":
        return load_dh_csv(path)
    if not path.suffix:
        path = ROBOTS_DIR / f"{name_or_path}.yaml"
        if not path.is_file():
            raise RobotDescriptionError(
                f"unknown robot {str(name_or_path)!r} (built-in: {', '.join(available_robots())}"
                "; or give a YAML file)"
            )
    return checked_mass_model(load_robot_yaml(path), str(path))


def load_dh_csv(path: Path) -> RobotDescription:
    """The description of a DH table CSV file (kinematics/dh_csv.py), its mass model
    checked; its `path` the file's absolute path."""
    if not path.is_file():
        raise RobotDescriptionError(f"{path}: no such robot description file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise RobotDescriptionError(f"{path}: not a text file ({exc.reason})") from None
    return description_from_text("csv", text, str(path.resolve()), str(path), quiet=False)
