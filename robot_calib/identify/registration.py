"""A first tracker pose for a model that has none: the rigid transform that best maps the
model's predicted points (base frame) onto the measured ones (Kabsch / Horn), then the
frames (tracker pose, target offset) refined by least squares with the geometry held.
"""

from __future__ import annotations

import numpy as np

from robot_calib.identify.fit import FitResult, fit_model
from robot_calib.kinematics.frames import Array, matrix_to_rpy
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import BASE_ROTATION, BASE_TRANSLATION, KinematicModel
from robot_calib.poses import Poses

REASON_FRAMES_ONLY = "held: only the tracker pose and target offset are fitted in this model"


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
    model: KinematicModel, params: ParameterVector, poses: Poses, points: Array
) -> ParameterVector:
    """`params` with base2tracker set by a rigid fit of the predicted onto the measured points."""
    at_origin = params.with_values({k: 0.0 for k in BASE_TRANSLATION + BASE_ROTATION})
    predicted = model.target_points(at_origin, poses)
    rotation, translation = rigid_transform(predicted, points)
    roll, pitch, yaw = matrix_to_rpy(rotation)
    updates = dict(zip(BASE_TRANSLATION, translation))
    updates.update(dict(zip(BASE_ROTATION, (roll, pitch, yaw))))
    return params.with_values(updates)


def fit_frames(
    model: KinematicModel, params: ParameterVector, poses: Poses, points: Array
) -> FitResult:
    """Fit only the tracker pose and the target offset, the rest held at `params`."""
    start = initial_frames(model, params, poses, points)
    held = [p.name for p in start.parameters if p.group != "frames" and p.free]
    return fit_model(model, start.fixed(held, REASON_FRAMES_ONLY), poses, points)
