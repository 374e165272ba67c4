"""joint_ripple (simulator only, NOT in the contract's vocabulary): a periodic joint-angle
error theta_j += A_j sin(k q_j + phi_j), e.g. a k-th harmonic of a gear or encoder.

Blind tests use it as "an effect the model does not know". Parameters per joint:
`ripple_sinJ`, `ripple_cosJ` [rad] (A sin(phi) and A cos(phi) of the harmonic `order`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.effects.base import (
    Contribution,
    Effect,
    check_order,
    register_effect,
    signed_uniform,
)
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

DEFAULT_AMPLITUDE = 3e-4  # rad
DRAW_RANGE = (2e-4, 5e-4)  # rad, blind tests


@register_effect
@dataclass(frozen=True)
class JointRipple(Effect):
    name = "joint_ripple"
    in_vocabulary = False
    order: int = 3

    def __post_init__(self) -> None:
        super().__post_init__()
        check_order(self, self.order)

    def _names(self, j: int) -> tuple[str, str]:
        """(cos, sin) parameter names of joint j."""
        return f"ripple_cos{j}", f"ripple_sin{j}"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [
            Parameter(name, "rad", 0.0, group=self.name)
            for j in self.joints
            for name in self._names(j)
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

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        return {self._names(j)[0]: DEFAULT_AMPLITUDE for j in self.joints}

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        effect = cls(joints=(joint,))
        cos_name, sin_name = effect._names(joint)
        return effect, {sin_name: signed_uniform(rng, *DRAW_RANGE), cos_name: 0.0}
