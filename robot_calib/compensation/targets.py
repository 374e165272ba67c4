"""TARGETS.csv: the positions (and orientations) the tool should reach (msgs_doc/compensate.md).

Header x,y,z (the tool point, in m or, with unit 'mm', mm), optional qx,qy,qz,qw (a unit
quaternion, x, y, z, w: the tool frame's orientation; without it a target is a position
only), optional q1..qJ [rad] (seed readings: where to start the nominal inverse
kinematics, e.g. the taught pose), and the optional columns of JOINTS.csv: t [s],
dir1..dirJ (+1/-1, approach directions) and temp_c [deg C]. The frame ('base' or
'tracker') is the caller's: `goals_in_base` puts them into the robot base frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robot_calib.csv_tables import TEMPERATURE_COLUMN, joint_columns, read_csv_table
from robot_calib.errors import InputError, param
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements.recording import MAX_COORDINATE_M, implausible_values
from robot_calib.messages import QUATERNION_TOLERANCE
from robot_calib.model import KinematicModel

FRAMES = ("base", "tracker")
UNITS = {"m": 1.0, "mm": 1e-3}  # --unit of the x,y,z columns -> m
POSITION_COLUMNS = ["x", "y", "z"]
QUATERNION_COLUMNS = ["qx", "qy", "qz", "qw"]


@dataclass(frozen=True)
class Targets:
    """The rows of a TARGETS.csv, in SI units.

    position : shape (n, 3), the tool point [m], in the file's frame
    rotation : shape (n, 3, 3) or None, the tool frame's orientation in the file's frame
        (None: position-only targets)
    seed : shape (n, J) or None, readings to start the nominal inverse kinematics from [rad]
    direction : shape (n, J) or None, approach directions +1/-1 (None: from the row order
        of the commands found)
    time : shape (n,), seconds since the start [s] (0 without a t column)
    temperature : shape (n,) or None, the robot's temperature [deg C]
    lines : shape (n,), each row's line in the file (for messages)
    """

    position: Array
    rotation: Array | None
    seed: Array | None
    direction: Array | None
    time: Array
    temperature: Array | None
    lines: tuple[int, ...]

    def __len__(self) -> int:
        return len(self.position)


def read_targets_csv(
    path: str | Path, n_joints: int, limits: Array | None = None, unit: str = "m"
) -> Targets:
    """The targets of a TARGETS.csv (module docstring); `unit` of x,y,z: 'm' or 'mm'.
    A bad header, row, quaternion (norm not 1) or seed reading (degrees?) raises
    InputError naming the file and line."""
    if unit not in UNITS:
        raise InputError(f"unit {unit!r}: expected one of {sorted(UNITS)}")
    table = read_csv_table(path, "targets", "x,y,z[,qx,qy,qz,qw][,q1..qJ]")
    missing = [c for c in POSITION_COLUMNS if not table.has(c)]
    if missing:
        raise InputError(f"{table.path}: header lacks {missing} (got {list(table.header)})")
    rotation = None
    if table.all_or_none(QUATERNION_COLUMNS):
        quaternion = table.columns(QUATERNION_COLUMNS)
        norm = np.linalg.norm(quaternion, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > QUATERNION_TOLERANCE)
        if bad.size:
            k = int(bad[0])
            raise InputError(
                f"{table.path}:{table.lines[k]}: quaternion qx,qy,qz,qw "
                f"{quaternion[k].tolist()} has norm {norm[k]:.6g}, not 1"
            )
        from scipy.spatial.transform import Rotation  # scipy only where orientations are read

        rotation = Rotation.from_quat(quaternion / norm[:, None]).as_matrix()
    seed, direction = joint_columns(table, n_joints, limits, required=False)
    position = table.columns(POSITION_COLUMNS) * UNITS[unit]
    beyond = implausible_values(position, MAX_COORDINATE_M)
    if beyond.size:
        k = int(beyond[0])
        raise InputError(
            f"{table.path}:{table.lines[k]}: target x,y,z {position[k].tolist()} m is beyond "
            f"+-{MAX_COORDINATE_M:g} m from the frame's origin (a corrupt value?)"
        )
    return Targets(
        position=position,
        rotation=rotation,
        seed=seed,
        direction=direction,
        time=table.column("t") if table.has("t") else np.zeros(len(table.table)),
        temperature=table.column(TEMPERATURE_COLUMN) if table.has(TEMPERATURE_COLUMN) else None,
        lines=table.lines,
    )


def goals_in_base(
    targets: Targets, frame: str, model: KinematicModel, params: ParameterVector
) -> Array:
    """The targets as tool frames in the robot base frame, shape (n, 4, 4) [m]: from the
    'base' frame as they are, from the 'tracker' frame through the calibration's
    base2tracker. Position-only targets get the identity orientation (not used)."""
    if frame not in FRAMES:
        raise InputError(f"frame {frame!r}: expected one of {FRAMES}")
    goal = np.tile(np.eye(4), (len(targets), 1, 1))
    goal[:, :3, 3] = targets.position
    if targets.rotation is not None:
        goal[:, :3, :3] = targets.rotation
    if frame == "tracker":
        goal = np.linalg.inv(model.base2tracker(params)) @ goal
    return goal


REACH_MARGIN = 1.5  # targets beyond this x the robot's longest possible reach: units?


def check_reach(
    goal2base: Array,
    model: KinematicModel,
    source: str | Path,
    unit: str = "m",
    frame: str = "base",
) -> None:
    """InputError naming `source` when every goal (n, 4, 4) [m] lies beyond REACH_MARGIN x
    the robot's reach (the sum of its link lengths |a| + |d| and the first target's
    offset): targets in mm read as m, or in the tracker frame read as base, never reach.
    `unit`, `frame`: what the targets were read as (the message suggests the others)."""
    robot = model.robot
    reach = float(np.sum(np.abs(robot.a)) + np.sum(np.abs(robot.d)))
    distance = np.linalg.norm(goal2base[:, :3, 3], axis=1)
    if len(distance) and np.all(distance > REACH_MARGIN * reach + 0.5):
        raise InputError(
            f"{source}: every target is out of robot {robot.name}'s reach (median "
            f"{np.median(distance):.4g} m from its base, reach about {reach:.2f} m): targets in "
            f"another unit ({param('unit', 'mm' if unit == 'm' else 'm')}) or frame "
            f"({param('frame', 'tracker' if frame == 'base' else 'base')})?"
        )
