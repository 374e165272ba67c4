"""thermal_warmup: link lengths that grow as a first-order warm-up.

A robot switched on (or set moving) warms towards a steady state: every a_j and d_j is
scaled by 1 + A (1 - exp(-t / tau)), with t the time since the first measurement of the
recording, A the steady-state strain [1] and tau the time constant [s], both identified.
For t << tau it starts as `thermal_drift`'s line (rate A / tau); over a recording of a
few time constants it levels off, which a line cannot follow. It belongs to no joint.
Parameters `thermal_warmup_strain` [1] and `thermal_warmup_tau` [s] (nominal 1200 s, the
start of the fit; with no strain the time constant is not identifiable and stays there).
"""

from __future__ import annotations

import numpy as np

from robot_calib.effects.base import Contribution, Effect, register_effect
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

NOMINAL_TAU_S = 1200.0
DEFAULT_STRAIN = 3e-4  # 0.03 %: about 0.3 mm on a 1 m reach
DRAW_STRAIN = (2e-4, 5e-4)  # blind tests
DRAW_TAU_S = (300.0, 1200.0)
MIN_TAU_S = 1.0  # the fit never takes the time constant below this
START_STRAIN = 1e-5  # where a fit starts (`fit_start`)


@register_effect
class ThermalWarmup(Effect):
    name = "thermal_warmup"
    per_joint = False

    @property
    def names(self) -> tuple[str, str]:
        return f"{self.name}_strain", f"{self.name}_tau"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        strain, tau = self.names
        return [
            Parameter(strain, "1", 0.0, group=self.name),
            Parameter(tau, "s", NOMINAL_TAU_S, group=self.name),
        ]

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        strain_name, tau_name = self.names
        amplitude, tau = params[strain_name], max(params[tau_name], MIN_TAU_S)
        t = poses.time.astype(float)
        rise = 1.0 - np.exp(-t / tau)
        jac = np.column_stack([rise, -amplitude * t / tau**2 * np.exp(-t / tau)])
        return Contribution(length_strain=amplitude * rise, length_strain_jac=jac)

    def fit_start(self, robot: RobotDescription) -> dict[str, float]:
        """A small strain: at zero the time constant moves no point (and would be fixed)."""
        return {self.names[0]: START_STRAIN}

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        strain, tau = self.names
        return {strain: DEFAULT_STRAIN, tau: 600.0}

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        effect = cls()
        strain, tau = effect.names
        return effect, {strain: float(rng.uniform(*DRAW_STRAIN)),
                        tau: float(rng.uniform(*DRAW_TAU_S))}  # fmt: skip

    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """Only when the poses span some time (a warm-up needs a clock)."""
        return [cls()] if np.ptp(poses.time) > 0 else []
