"""thermal_drift: link lengths that grow with time since the start of the recording.

Warm-up expands the structure: every a_j and d_j is scaled by (1 + rate * t), with t the
time since the first measurement of the recording (msgs_doc/specification.md). Over a recording
of tens
of minutes the warm-up exponential is close to this linear start. It belongs to no joint.
Parameter `thermal_drift_rate` [1/s].
"""

from __future__ import annotations

import numpy as np

from robot_calib.effects.base import Contribution, Effect, register_effect
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

DEFAULT_RATE = 3e-7  # 1/s: 0.03 % strain per 1000 s of warm-up
DRAW_RANGE = (2e-7, 6e-7)  # 1/s, blind tests


@register_effect
class ThermalDrift(Effect):
    name = "thermal_drift"
    per_joint = False

    @property
    def parameter(self) -> str:
        return f"{self.name}_rate"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [Parameter(self.parameter, "1/s", 0.0, group=self.name)]

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        jac = poses.time[:, None].astype(float)
        return Contribution(
            length_strain=jac[:, 0] * params[self.parameter], length_strain_jac=jac
        )

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        return {self.parameter: DEFAULT_RATE}

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        effect = cls()
        return effect, {effect.parameter: float(rng.uniform(*DRAW_RANGE))}

    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """Only when the poses span some time (a drift needs a clock)."""
        return [cls()] if np.ptp(poses.time) > 0 else []
