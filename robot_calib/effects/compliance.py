"""compliance: elastic joint deflection proportional to the gravity torque on that joint.

theta_j += c_j * tau_j(q), with tau_j the torque of gravity about joint j's axis from the
robot's (approximate) mass model, evaluated on the nominal kinematics: it depends on the
whole pose, not only on q_j. Parameter `complianceJ` [rad/(N m)] = c_j.
Base z is up; gravity is -z of the base frame (CONTRACT.md).
"""

from __future__ import annotations

import numpy as np

from robot_calib.effects.base import JointOffsetEffect
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.dh import DHTable, chain
from robot_calib.kinematics.frames import Array
from robot_calib.poses import Poses

GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2 in the robot base frame


def gravity_torques(robot: RobotDescription, q: Array) -> Array:
    """Gravity torque about every joint axis, shape (n, J) [N m], for readings q (n, J) [rad].

    tau_j = z_{j-1} . sum_{i >= j} (c_i - o_{j-1}) x (m_i g), with c_i the centre of mass
    of link i (moved by joint i), all on the nominal kinematics.
    """
    dh = DHTable(robot.theta + q, robot.d, robot.a, robot.alpha, robot.beta)
    frames = chain(dh)  # (n, J + 1, 4, 4)
    com = np.einsum("njab,jb->nja", frames[:, 1:, :3, :3], robot.link_com) + frames[:, 1:, :3, 3]
    force = robot.link_mass[:, None] * GRAVITY  # (J, 3)
    n, n_joints = q.shape
    tau = np.zeros((n, n_joints))
    for j in range(n_joints):
        axis, origin = frames[:, j, :3, 2], frames[:, j, :3, 3]
        moment = np.cross(com[:, j:] - origin[:, None, :], force[j:]).sum(axis=1)
        tau[:, j] = np.einsum("na,na->n", axis, moment)
    return tau


class Compliance(JointOffsetEffect):
    name = "compliance"
    unit = "rad/(N m)"

    def signal(self, robot: RobotDescription, poses: Poses) -> Array:
        return gravity_torques(robot, poses.q)
