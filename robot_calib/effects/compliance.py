"""compliance: elastic joint deflection proportional to the gravity torque on that joint.

theta_j += c_j * tau_j(q), with tau_j the torque of gravity about joint j's axis from the
robot's (approximate) mass model, evaluated on the nominal kinematics: it depends on the
whole pose, not only on q_j. Parameter `complianceJ` [rad/(N m)] = c_j.
Base z is up; gravity is -z of the base frame (msgs_doc/specification.md).
"""

from __future__ import annotations

import numpy as np

from robot_calib.effects.base import Effect, JointOffsetEffect, register_effect
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.poses import Poses

GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2 in the robot base frame
#: a joint whose gravity torque never exceeds this [N m] deflects by less than the noise at
#: any realistic compliance (the KR5 without payload: up to 41 N m on joint 2, 13 N m on
#: joint 3, 0.34 N m on joints 4-5)
SIGNIFICANT_TORQUE_NM = 5.0
#: below this torque range over the measured poses [N m] a compliance cannot be seen
VISIBLE_TORQUE_RANGE_NM = 1e-3
VISIBLE_POSES = 10000  # poses the visibility is judged on at most


def gravity_torques(robot: RobotDescription, q: Array) -> Array:
    """Gravity torque about every joint axis, shape (n, J) [N m], for readings q (n, J) [rad].

    tau_j = z_{j-1} . sum_{i >= j} (c_i - o_{j-1}) x (m_i g), with c_i the centre of mass
    of link i (moved by joint i), all on the nominal kinematics (the robot's joint
    variables of q).
    """
    frames = robot.nominal_frames(q)  # (n, J + 1, 4, 4)
    com = np.einsum("njab,jb->nja", frames[:, 1:, :3, :3], robot.link_com) + frames[:, 1:, :3, 3]
    force = robot.link_mass[:, None] * GRAVITY  # (J, 3)
    n, n_joints = q.shape
    tau = np.zeros((n, n_joints))
    for j in range(n_joints):
        axis, origin = frames[:, j, :3, 2], frames[:, j, :3, 3]
        moment = np.cross(com[:, j:] - origin[:, None, :], force[j:]).sum(axis=1)
        tau[:, j] = np.einsum("na,na->n", axis, moment)
    return tau


def gravity_joints(robot: RobotDescription) -> tuple[int, ...]:
    """Joints (1-based) on which gravity puts a torque worth a deflection: more than
    SIGNIFICANT_TORQUE_NM somewhere among 500 poses spread over the joint limits."""
    rng = np.random.default_rng(0)  # a fixed spread of poses, not a random draw
    q = rng.uniform(robot.limits[:, 0], robot.limits[:, 1], size=(500, robot.n_joints))
    peak = np.abs(gravity_torques(robot, q)).max(axis=0)
    return tuple(int(j) + 1 for j in np.flatnonzero(peak > SIGNIFICANT_TORQUE_NM))


def visible_gravity_joints(robot: RobotDescription, poses: Poses) -> list[int]:
    """Joints (1-based) whose gravity torque varies over `poses` by more than
    VISIBLE_TORQUE_RANGE_NM: the ladder's gravity candidates (else nothing to see). Over at
    most VISIBLE_POSES of them (evenly spaced): a range of 1e-3 N m shows in any of them."""
    step = max(1, len(poses) // VISIBLE_POSES)
    tau = gravity_torques(robot, poses.q[::step])
    return [
        j for j in range(1, robot.n_joints + 1) if np.ptp(tau[:, j - 1]) > VISIBLE_TORQUE_RANGE_NM
    ]


@register_effect
class Compliance(JointOffsetEffect):
    name = "compliance"
    signature_family = "gravity"
    unit = "rad/(N m)"
    default_magnitude = 2.0e-5
    draw_range = (1e-5, 4e-5)

    def signal(self, robot: RobotDescription, poses: Poses) -> Array:
        return gravity_torques(robot, poses.q)

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        """Only joints with a significant gravity torque (`gravity_joints`)."""
        return super().draw(robot, rng, int(rng.choice(gravity_joints(robot))))

    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """Joints whose gravity torque varies over the poses (else nothing to see)."""
        return [cls(joints=(j,)) for j in visible_gravity_joints(robot, poses)]
