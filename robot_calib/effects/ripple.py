"""joint_ripple (simulator only, NOT in the contract's vocabulary): a periodic joint-angle
error theta_j += A_j sin(k q_j + phi_j), e.g. a k-th harmonic of a gear or encoder.

Blind tests use it as "an effect the model does not know". Parameters per joint:
`ripple_sinJ`, `ripple_cosJ` [rad] (A sin(phi) and A cos(phi) of the harmonic `order`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.effects.base import Contribution, Effect
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses


@dataclass(frozen=True)
class JointRipple(Effect):
    name = "joint_ripple"
    in_vocabulary = False
    order: int = 3

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [
            Parameter(f"ripple_{kind}{j}", "rad", 0.0, group=self.name)
            for j in self.joints
            for kind in ("cos", "sin")
        ]

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        n, n_joints = poses.q.shape
        jac = np.zeros((n, n_joints, 2 * len(self.joints)))
        for k, j in enumerate(self.joints):
            angle = self.order * poses.q[:, j - 1]
            # A sin(k q + phi) = A cos(phi) sin(k q) + A sin(phi) cos(k q)
            jac[:, j - 1, 2 * k] = np.sin(angle)
            jac[:, j - 1, 2 * k + 1] = np.cos(angle)
        return Contribution(joint_offset=jac @ self.values(robot, params), joint_offset_jac=jac)
