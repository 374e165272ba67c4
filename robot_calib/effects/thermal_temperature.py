"""thermal_temperature: link lengths that follow the robot's measured temperature.

Where a recording carries the robot's temperature (the side topic /temperature,
msgs_doc/temperature.md; `import --temperature`), thermal expansion is a function of it,
not of time: every a_j and d_j is scaled by 1 + alpha (T - T_REF_C), with alpha the
structure's effective expansion coefficient [1/K] (steel 12e-6, aluminium 23e-6). The
constant part alpha (T_REF_C - mean T) is a length change the geometry absorbs; what the
effect adds is the change with the temperature over the recording, warm-up and cool-down
alike (which a time-based drift cannot follow). It belongs to no joint, and is a ladder
candidate only where every measurement has a temperature and it varies; a model with it
meeting measurements without one is an error (never a prediction at 20 deg C).
Parameter `thermal_temperature_alpha` [1/K].
"""

from __future__ import annotations

import numpy as np

from robot_calib.effects.base import Contribution, Effect, register_effect
from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

T_REF_C = 20.0  # deg C: the reference temperature of the nominal lengths
DEFAULT_ALPHA = 2.0e-5  # 1/K: an aluminium-and-steel arm
DRAW_ALPHA = (1.2e-5, 3.0e-5)
VISIBLE_SPAN_K = 0.1  # a temperature spanning less than this over the poses shows nothing


@register_effect
class ThermalTemperature(Effect):
    name = "thermal_temperature"
    per_joint = False

    @property
    def parameter(self) -> str:
        return f"{self.name}_alpha"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [Parameter(self.parameter, "1/K", 0.0, group=self.name)]

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        """(T - T_REF_C) scales the lengths. InputError for poses without a temperature
        (a bag without /temperature, a JOINTS.csv without `temp_c`): predicting as if at
        T_REF_C would be silently wrong."""
        if poses.temperature is None or not np.all(np.isfinite(poses.temperature)):
            raise InputError(
                f"{self.name}: the model follows the robot's temperature, but "
                f"{'some' if poses.temperature is not None else 'these'} measurements have "
                "none (a bag without /temperature, a JOINTS.csv without a temp_c column)"
            )
        jac = (np.asarray(poses.temperature, dtype=float) - T_REF_C)[:, None]
        return Contribution(
            length_strain=jac[:, 0] * params[self.parameter], length_strain_jac=jac
        )

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        return {self.parameter: DEFAULT_ALPHA}

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        """A random coefficient (the world needs a temperature profile: the blind harness
        gives it one)."""
        effect = cls()
        return effect, {effect.parameter: float(rng.uniform(*DRAW_ALPHA))}

    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """Only where every measurement has a temperature and it varies."""
        temperature = poses.temperature
        if temperature is None or not np.all(np.isfinite(temperature)):
            return []
        if np.ptp(temperature) < VISIBLE_SPAN_K:
            return []
        return [cls()]
