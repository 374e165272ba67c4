"""Elementary rigid transforms, batched over a leading axis.

Every function returns homogeneous matrices of shape (n, 4, 4) (or rotations (n, 3, 3))
for angle/length arrays of shape (n,). Angles in rad, lengths in m.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]
IntArray = NDArray[np.integer]  # indices, nanosecond stamps


def _cos_sin(angle: ArrayLike) -> tuple[Array, Array]:
    a = np.asarray(angle, dtype=float)
    return np.cos(a), np.sin(a)


def rot_x(angle: ArrayLike) -> Array:
    """Rotations about x, shape (n, 3, 3), for `angle` of shape (n,) [rad]."""
    c, s = _cos_sin(angle)
    out = np.zeros((*c.shape, 3, 3))
    out[..., 0, 0] = 1.0
    out[..., 1, 1], out[..., 1, 2] = c, -s
    out[..., 2, 1], out[..., 2, 2] = s, c
    return out


def rot_y(angle: ArrayLike) -> Array:
    """Rotations about y, shape (n, 3, 3), for `angle` of shape (n,) [rad]."""
    c, s = _cos_sin(angle)
    out = np.zeros((*c.shape, 3, 3))
    out[..., 1, 1] = 1.0
    out[..., 0, 0], out[..., 0, 2] = c, s
    out[..., 2, 0], out[..., 2, 2] = -s, c
    return out


def rot_z(angle: ArrayLike) -> Array:
    """Rotations about z, shape (n, 3, 3), for `angle` of shape (n,) [rad]."""
    c, s = _cos_sin(angle)
    out = np.zeros((*c.shape, 3, 3))
    out[..., 2, 2] = 1.0
    out[..., 0, 0], out[..., 0, 1] = c, -s
    out[..., 1, 0], out[..., 1, 1] = s, c
    return out


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> Array:
    """Rotation Rz(yaw) Ry(pitch) Rx(roll), shape (3, 3) (fixed-axis XYZ, as ROS's RPY)."""
    return rot_z(np.array([yaw]))[0] @ rot_y(np.array([pitch]))[0] @ rot_x(np.array([roll]))[0]


def matrix_to_rpy(rotation: Array) -> tuple[float, float, float]:
    """Inverse of `rpy_to_matrix` for a (3, 3) rotation; pitch in [-pi/2, pi/2]."""
    pitch = float(np.arcsin(np.clip(-rotation[2, 0], -1.0, 1.0)))
    roll = float(np.arctan2(rotation[2, 1], rotation[2, 2]))
    yaw = float(np.arctan2(rotation[1, 0], rotation[0, 0]))
    return roll, pitch, yaw


def skew(v: Array) -> Array:
    """The cross-product matrix [v]x (3, 3) of a vector v (3,): [v]x w = v x w."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rotvec_to_matrix(rotvec: Array) -> Array:
    """Rotation (3, 3) of a rotation vector (3,) [rad] (axis times angle; Rodrigues). Here,
    not through scipy, because `predict` keeps its imports light."""
    theta = float(np.linalg.norm(rotvec))
    k = skew(np.asarray(rotvec, dtype=float))
    if theta < 1e-12:
        return np.eye(3) + k
    return np.eye(3) + np.sin(theta) / theta * k + (1.0 - np.cos(theta)) / theta**2 * (k @ k)


def rotvec_left_jacobian(rotvec: Array) -> Array:
    """J (3, 3) with exp([r + dr]x) = exp([J dr]x) exp([r]x) to first order: column k is
    the small rotation [rad] (frame of the rotated vectors) per unit change of r_k.
    Regular for |r| < 2 pi: no gimbal lock, unlike roll-pitch-yaw."""
    theta = float(np.linalg.norm(rotvec))
    k = skew(np.asarray(rotvec, dtype=float))
    if theta < 1e-8:
        return np.eye(3) + 0.5 * k
    a = (1.0 - np.cos(theta)) / theta**2
    b = (theta - np.sin(theta)) / theta**3
    return np.eye(3) + a * k + b * (k @ k)


def homogeneous(rotation: Array, translation: Array) -> Array:
    """Stack rotations (..., 3, 3) and translations (..., 3) into (..., 4, 4) transforms."""
    shape = np.broadcast_shapes(rotation.shape[:-2], translation.shape[:-1])
    out = np.zeros(shape + (4, 4))
    out[..., :3, :3] = rotation
    out[..., :3, 3] = translation
    out[..., 3, 3] = 1.0
    return out


def transform_points(a2b: Array, p_in_a: Array) -> Array:
    """Apply transforms a2b (..., 4, 4) to points p_in_a (..., 3); returns p_in_b (..., 3)."""
    return np.einsum("...ij,...j->...i", a2b[..., :3, :3], p_in_a) + a2b[..., :3, 3]
