"""Where an arm's posture sits among the inverse kinematics' solutions, as the vendors'
configuration data encode it: is the wrist centre in front of axis 1 or behind it
(reaching over backwards), is the elbow on the side it has at a reference pose, is the
wrist flipped (the sign of axis 5), and how many turns axes 1, 4 and 6 are from zero.

The first two are geometry of the nominal model (the controller's), measured against a
reference pose the vendor documents (KUKA's home, ABB's and FANUC's zero position), so
that the same function serves every arm whatever its DH sign conventions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array

WRIST_FRAME = 4  # the DH frame whose origin is the wrist centre (axes 4, 5, 6 meet there)


@dataclass(frozen=True)
class Posture:
    """Each row's posture.

    degrees : shape (n, J), the readings [deg]
    front : shape (n,), the wrist centre on the side of axis 1 it has at the reference
        pose (in front of the robot)
    elbow : shape (n,), the elbow on the side it has at the reference pose
    """

    degrees: Array
    front: NDArray[np.bool_]
    elbow: NDArray[np.bool_]


def _sides(robot: RobotDescription, q: Array) -> tuple[Array, Array]:
    """(n,) signed distances: the wrist centre along axis 1's forward direction (DH x of
    frame 1, horizontal) [m], and the elbow's turn, (joint 3 - joint 2) x (wrist - joint 3)
    along joint 3's axis [m^2]."""
    frames = robot.nominal_frames(np.atleast_2d(q))
    wrist = frames[:, WRIST_FRAME, :3, 3]
    forward = frames[:, 1, :3, 0].copy()
    forward[:, 2] = 0.0
    ahead = np.einsum("ni,ni->n", wrist[:, :2], forward[:, :2])
    joint2, joint3 = frames[:, 1, :3, 3], frames[:, 2, :3, 3]
    turn = np.cross(joint3 - joint2, wrist - joint3)
    return ahead, np.einsum("ni,ni->n", turn, frames[:, 2, :3, 2])


def posture(robot: RobotDescription, q: Array, reference_deg: tuple[float, ...]) -> Posture:
    """The posture of readings q (n, J) [rad] against the reference pose [deg]."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    ahead, turn = _sides(robot, q)
    ref_ahead, ref_turn = _sides(robot, np.radians(np.asarray(reference_deg))[None])
    return Posture(
        np.degrees(q),
        np.sign(ahead) == np.sign(ref_ahead[0]),
        np.sign(turn) == np.sign(ref_turn[0]),
    )


#: the lever the Jacobian's rotation rows are scaled by [m]: a rotation counts as the
#: motion it gives half a metre out
ROTATION_LEVER_M = 0.5


def singular_margin(robot: RobotDescription, q: Array) -> Array:
    """(n,) how far readings q (n, J) [rad] are from a singularity of the nominal arm [m]:
    the smallest singular value of the flange's Jacobian, position rows [m/rad] and rotation
    rows x ROTATION_LEVER_M (0 at a singularity: the wrist's, the elbow's stretched or
    folded, the shoulder's; ~0.1 m at a typical pose of a 1.5 m arm)."""
    frames = robot.nominal_frames(np.atleast_2d(np.asarray(q, dtype=float)))
    flange = frames[:, -1, :3, 3]
    axes, origins = frames[:, :-1, :3, 2], frames[:, :-1, :3, 3]
    jacobian = np.concatenate(
        [np.cross(axes, flange[:, None] - origins), ROTATION_LEVER_M * axes], axis=2
    )
    return np.linalg.svd(jacobian, compute_uv=False)[:, -1]


def matches(found: tuple[int, ...], wanted: tuple[int, ...]) -> bool:
    """A configuration equals the wanted one where that gives a value (-1: not given)."""
    return all(w < 0 or f == w for f, w in zip(found, wanted))
