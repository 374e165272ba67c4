"""What a model can absorb, and how a joint-angle error moves the measured points: the two
pieces every residual signature needs (`signatures.joint_terms`, `frequency.joint_spectra`).

A joint-angle error e_j moves each measured point along m_j = axis_j x (point - origin_j)
[m/rad]; a signature's column is m_j times a signal of the pose. What a refit of the model
would absorb is the span of its free parameters' Jacobian columns: a signature counts only
for what is left of its column once that span is projected off, and a column that keeps
less than MIN_LEFT of its norm is collinear with the model (its coefficient would be noise
amplified without bound). A joint whose measured points sit within MIN_LEVER_M of its axis
cannot show an angle error at all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.identify.fit import blocked_jacobian
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses

#: a joint-angle error is observable only through a target at least this far from the
#: joint's axis: at 5 um of tracker noise, 5 mm of lever leaves 1 mrad of angle noise (a
#: target 0.2 mm from the axis would turn noise into 25 mrad of "harmonics")
MIN_LEVER_M = 5e-3
#: a signature column keeping less than this of its norm after the model's own columns are
#: projected off is collinear with the model: skipped (else "harmonics" of 3.6e15 urad)
MIN_LEFT = 1e-3


@dataclass(frozen=True)
class ModelSpan:
    """motion : (n, J, 3) [m/rad] how each joint's angle error moves each measured point,
    tracker frame; basis : (3n, p) orthonormal basis of the model's free columns (rows
    3i..3i+2 for point i, in the units the Jacobian was divided by); lever_m : (J,) the
    median distance [m] of the points from each joint's axis (|m_j|)."""

    motion: Array
    basis: Array
    lever_m: Array

    def project_off(self, columns: Array) -> Array:
        """`columns` (3n, ...) minus their part in the model's span (a new array)."""
        flat = columns.reshape(len(columns), -1)
        return (flat - self.basis @ (self.basis.T @ flat)).reshape(columns.shape)


def model_span(
    model: KinematicModel,
    params: ParameterVector,
    poses: Poses,
    predicted: Array,
    scale: float = 1.0,
) -> ModelSpan:
    """The span of `model`'s free parameters at `params` on `poses`, its Jacobian divided
    by `scale` (e.g. the noise [m]), and the joints' motion at the `predicted` points
    (n, 3) [m, tracker frame]."""
    motion, lever = joint_motion(model, params, poses, predicted)
    _, jac = blocked_jacobian(model, params, poses)
    nuisance = jac[:, :, params.free].reshape(3 * len(jac), -1) / scale
    del jac
    basis = np.linalg.qr(nuisance)[0] if nuisance.shape[1] else np.zeros((len(nuisance), 0))
    return ModelSpan(motion, basis, lever)


def joint_motion(
    model: KinematicModel, params: ParameterVector, poses: Poses, predicted: Array
) -> tuple[Array, Array]:
    """How each joint's angle error moves each of the `predicted` points (n, 3) [m,
    tracker frame]: motion (n, J, 3) [m/rad] = axis_j x (point - origin_j), and each
    joint's lever (J,) [m], the median of |motion_j| over the points."""
    origins, axes = model.joint_axes(params, poses)
    motion = np.cross(axes, predicted[:, None, :] - origins)
    return motion, np.median(np.linalg.norm(motion, axis=2), axis=0)
