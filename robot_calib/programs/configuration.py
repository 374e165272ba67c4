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


def clear_of_singularities(
    robot: RobotDescription, q: Array, angle_deg: float, reach_m: float
) -> NDArray[np.bool_]:
    """(n,) readings q (n, J) [rad] at least `angle_deg` from the wrist singularity (axis 5
    at 0 or 180 deg) and from the stretched or folded elbow, with the wrist centre at
    least `reach_m` off axis 1 (the shoulder singularity)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    frames = robot.nominal_frames(q)
    wrist = frames[:, WRIST_FRAME, :3, 3]
    joint2, joint3 = frames[:, 1, :3, 3], frames[:, 2, :3, 3]
    upper, fore = joint3 - joint2, wrist - joint3
    sine = np.linalg.norm(np.cross(upper, fore), axis=1) / (
        np.linalg.norm(upper, axis=1) * np.linalg.norm(fore, axis=1)
    )
    least = np.sin(np.radians(angle_deg))
    return (
        (np.abs(np.sin(q[:, 4])) >= least)
        & (sine >= least)
        & (np.linalg.norm(wrist[:, :2], axis=1) >= reach_m)
    )
