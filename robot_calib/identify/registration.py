"""A first tracker pose and target offset for a model that has neither: found globally,
then the frames refined by least squares with the geometry held.

measured_i = R (flange_p_i + flange_R_i t) + b is bilinear in the unknowns: for a fixed
rotation R it is linear in the target offset t and the translation b, and for a fixed t
the best R, b is a rigid fit (Kabsch / Horn). Alternating the two from t = 0 reaches the
global solution in a few steps whatever the start, also for targets far from the flange
(0.3 m on large robots), where a rigid fit with t = 0 alone leaves 100 mm. A 6-DoF
probe's frame in the flange frame follows in closed form (`initial_tool_rotations`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from robot_calib.identify.fit import FitResult, fit_model
from robot_calib.kinematics.frames import Array, matrix_to_rpy
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import (
    BASE_ROTATION,
    BASE_TRANSLATION,
    KinematicModel,
    target_parameters,
    tool_rotation_parameters,
)
from robot_calib.poses import Poses

REASON_FRAMES_ONLY = "held: only the tracker pose and target offset are fitted in this model"
ALTERNATIONS = 50  # rigid fit <-> linear target offset; converges in a handful


def rigid_transform(source: Array, target: Array) -> tuple[Array, Array]:
    """Rotation (3, 3) and translation (3,) minimising |R source_i + t - target_i|^2 over
    point sets (n, 3) (Kabsch, with reflection guard)."""
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    h = (source - cs).T @ (target - ct)
    u, _, vt = np.linalg.svd(h)
    sign = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rotation = vt.T @ np.diag([1.0, 1.0, sign]) @ u.T
    return rotation, ct - rotation @ cs


def initial_frames(
    model: KinematicModel,
    params: ParameterVector,
    poses: Poses,
    points: Array,
    iterations: int = ALTERNATIONS,
) -> ParameterVector:
    """`params` with base2tracker and the target offset found globally for the geometry in
    `params`: alternately the rigid fit of the predicted onto the measured points (n, 3)
    [m] and the linear least squares of the target offsets (one per target of the model)
    and translation for that rotation, until the offsets move by less than 1 nm."""
    at_origin = params.with_values({k: 0.0 for k in BASE_TRANSLATION + BASE_ROTATION})
    flange = model.flange2base(at_origin, poses)  # (n, 4, 4), robot base frame
    flange_rot, flange_pos = flange[:, :3, :3], flange[:, :3, 3]
    offsets = model.target_offsets(params)  # (T, 3), one per target, flange frame
    which = poses.target_index  # (n,)
    n, n_targets = len(points), len(offsets)
    for _ in range(iterations):
        in_base = flange_pos + np.einsum("nab,nb->na", flange_rot, offsets[which])
        rotation, translation = rigid_transform(in_base, points)
        design = np.zeros((n, 3, 3 * n_targets + 3))  # d measured / d (t_1..t_T, b)
        for k in range(n_targets):
            rows = which == k
            design[rows, :, 3 * k : 3 * k + 3] = rotation @ flange_rot[rows]
        design[:, :, -3:] = np.eye(3)
        rhs = points - flange_pos @ rotation.T
        solution = np.linalg.lstsq(
            design.reshape(-1, design.shape[-1]), rhs.reshape(-1), rcond=None
        )[0]
        found: Array = np.asarray(solution[:-3], dtype=float).reshape(n_targets, 3)
        moved = float(np.linalg.norm(found - offsets))
        offsets = found
        if moved < 1e-9:
            break
    in_base = flange_pos + np.einsum("nab,nb->na", flange_rot, offsets[which])
    rotation, translation = rigid_transform(in_base, points)
    roll, pitch, yaw = matrix_to_rpy(rotation)
    updates = dict(zip(BASE_TRANSLATION, translation))
    updates.update(dict(zip(BASE_ROTATION, (roll, pitch, yaw))))
    for name, xyz in zip(model.targets, offsets):
        updates.update(dict(zip(target_parameters(name), xyz)))
    return initial_tool_rotations(model, params.with_values(updates), poses)


def initial_tool_rotations(
    model: KinematicModel, params: ParameterVector, poses: Poses
) -> ParameterVector:
    """`params` with the frame of every 6-DoF target of `model` (its `oriented`) in the
    flange frame found in closed form for the geometry and tracker pose in `params`: the
    mean rotation (scipy `Rotation.mean`) of predicted flange^T * measured probe frame."""
    if not model.oriented or poses.rotation is None:
        return params
    flange_in_tracker = model.flange_rotations(params, poses)
    updates: dict[str, float] = {}
    for name in model.oriented:
        rows = poses.oriented & (poses.target_index == model.targets.index(name))
        if not rows.any():
            continue
        tool = np.transpose(flange_in_tracker[rows], (0, 2, 1)) @ poses.rotation[rows]
        rotvec = Rotation.from_matrix(tool).mean().as_rotvec()  # |angle| <= pi
        updates.update(zip(tool_rotation_parameters(name), map(float, rotvec)))
    return params.with_values(updates)


def fit_frames(
    model: KinematicModel, params: ParameterVector, poses: Poses, points: Array
) -> FitResult:
    """Fit only the tracker pose and the target offset, the rest held at `params`."""
    start = initial_frames(model, params, poses, points)
    held = [p.name for p in start.parameters if p.group != "frames" and p.free]
    return fit_model(model, start.fixed(held, REASON_FRAMES_ONLY), poses, points)
