"""The Universal Robots calibration file (the `kinematics` YAML of ur_description's
`kinematics_params`, the file ur_calibration writes and ur_robot_driver reads).

Each entry (shoulder, upper_arm, forearm, wrist_1, wrist_2, wrist_3) is a joint's origin
in its parent link frame as ur_description's URDF macro uses it: x, y, z [m] and roll,
pitch, yaw [rad] (fixed-axis XYZ), the joint turning about its child frame's z; the
shoulder's parent is ``base_link_inertia``, the controller's base frame (DH frame 0).

With link rows ``Rz(theta_j + q_j) Tz(d_j) Tx(a_j) Rx(alpha_j) Ry(beta_j)`` and a turn
about z commuting with a shift along z: joint 1's origin is ``Rz(theta_1) Tz(d_1)`` and joint
j's ``Tx(a_{j-1}) Rx(alpha_{j-1}) Ry(beta_{j-1}) Rz(theta_j) Tz(d_j)``; what remains of the
last row (``Tx(a_6) Rx(alpha_6)``, fixed at their nominal 0 for a point target) must be
the identity, wrist_3_link being the flange (tool0). The nominal UR DH table gives
ur_description's default_kinematics.yaml. `hash` names this calibration; the driver only
warns that it is not the robot controller's own calibration hash.
"""

from __future__ import annotations

import hashlib
from typing import TYPE_CHECKING

import numpy as np
import yaml

from robot_calib.errors import param
from robot_calib.export.base import (
    Exporter,
    ExportError,
    correction_lines,
    effect_lines,
    joint_signs,
    rpy,
)
from robot_calib.kinematics.frames import Array, rot_x, rot_y, rot_z

if TYPE_CHECKING:
    from robot_calib.identify.calibration import Calibration

ENTRIES = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
UR_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
_IDENTITY_TOLERANCE = 1e-12  # [m, rad]: the last row's remainder must vanish


def _transform(rotation: Array, translation: Array) -> Array:
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = translation
    return out


def joint_origins(cal: Calibration) -> Array:
    """The six joint origins (6, 4, 4), each in its parent link frame (see the module)."""
    model, params = cal.model, cal.parameters
    robot = model.robot
    is_ur = robot.joint_names == UR_JOINTS or robot.name.startswith("ur")
    if not is_ur or robot.n_joints != len(ENTRIES):
        raise ExportError(
            f"robot {robot.name} is not a Universal Robots arm: the UR calibration file is "
            f"only for UR robots (use {param('format', 'urdf')} or {param('format', 'dh')})"
        )
    signs = joint_signs(cal, "the UR calibration file")
    if np.any(signs != 1.0) or robot.reading_offset is not None:
        raise ExportError(
            f"robot {robot.name}: a reading_to_joint sign or offset has no place in the UR "
            f"calibration file (use {param('format', 'urdf')})"
        )
    table = model.dh_table(params, np.zeros((1, robot.n_joints)))
    theta, d, a, alpha, beta = (
        np.asarray(getattr(table, f)).reshape(-1) for f in ("theta", "d", "a", "alpha", "beta")
    )
    head = [_transform(rot_z([theta[j]])[0], np.array([0.0, 0.0, d[j]])) for j in range(6)]
    tail = [
        _transform(rot_x([alpha[j]])[0] @ rot_y([beta[j]])[0], np.array([a[j], 0.0, 0.0]))
        for j in range(6)
    ]
    if np.abs(tail[5] - np.eye(4)).max() > _IDENTITY_TOLERANCE:
        raise ExportError(
            "a6, alpha6 and beta6 must be 0 for the UR calibration file (wrist_3_link is the "
            f"flange): got {a[5]} m, {alpha[5]} rad, {beta[5]} rad"
        )
    return np.array([head[0]] + [tail[j - 1] @ head[j] for j in range(1, 6)])


def render(cal: Calibration, source: str) -> str:
    """The UR calibration YAML text of calibration `cal` read from `source`."""
    origins = joint_origins(cal)
    kinematics: dict[str, object] = {}
    for name, origin in zip(ENTRIES, origins):
        roll, pitch, yaw = (v + 0.0 for v in rpy(origin[:3, :3]))  # no -0.0
        x, y, z = (float(v) + 0.0 for v in origin[:3, 3])
        kinematics[name] = {"x": x, "y": y, "z": z, "roll": roll, "pitch": pitch, "yaw": yaw}
    digest = hashlib.sha256(np.ascontiguousarray(origins).tobytes()).hexdigest()[:16]
    kinematics["hash"] = f"calib_robot_calib_{digest}"
    comments = [
        f"Universal Robots calibration of {cal.model.robot.name}, written by robot-calib export",
        f"from {source} (model {cal.name}); ur_robot_driver: kinematics_params_file:=THIS",
    ]
    effects = effect_lines(cal)
    if effects:
        comments.append("Effects identified that this file cannot hold:")
        comments += [f"  {line}" for line in effects]
    comments += correction_lines(cal)
    body = yaml.safe_dump({"kinematics": kinematics}, sort_keys=False)
    return "".join(f"# {c}\n" for c in comments) + body


EXPORTER = Exporter("ur", ".yaml", "the Universal Robots calibration YAML (UR robots)", render)
