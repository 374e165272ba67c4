"""thermal_warmup: link lengths that grow as a first-order warm-up.

A robot switched on (or set moving) warms towards a steady state: every a_j and d_j is
scaled by 1 + A (1 - exp(-t / tau)), with t the time since the first measurement of the
recording, A the steady-state strain [1] and tau the time constant [s], both identified.
For t << tau it starts as `thermal_drift`'s line (rate A / tau); over a recording of a
few time constants it levels off, which a line cannot follow. It belongs to no joint.
Parameters `thermal_warmup_strain` [1] and `thermal_warmup_ln_tau` [1] = ln(tau / 1 s)
(nominal ln 1200: the start of a fit): the logarithm keeps tau > 0 however a fit moves
it (tau = exp(value) s).
"""

from __future__ import annotations

import numpy as np

from robot_calib.effects.base import Contribution, Effect, register_effect
from robot_calib.effects.thermal_drift import ThermalDrift
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

NOMINAL_TAU_S = 1200.0
DEFAULT_STRAIN = 3e-4  # 0.03 %: about 0.3 mm on a 1 m reach
DRAW_STRAIN = (2e-4, 5e-4)  # blind tests
DRAW_TAU_S = (300.0, 1200.0)
START_STRAIN = 1e-5  # where a fit starts (`fit_starts`)
FIT_START_TAUS_S = (200.0, 800.0, 3200.0)
LN_TAU_RANGE = (0.0, 14.0)  # tau 1 s .. 14 days: exp() kept finite wherever a fit wanders


@register_effect
class ThermalWarmup(Effect):
    name = "thermal_warmup"
    per_joint = False

    @property
    def names(self) -> tuple[str, str]:
        return f"{self.name}_strain", f"{self.name}_ln_tau"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        strain, ln_tau = self.names
        return [
            Parameter(strain, "1", 0.0, group=self.name),
            Parameter(ln_tau, "1", float(np.log(NOMINAL_TAU_S)), group=self.name),
        ]

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        strain_name, ln_tau_name = self.names
        ln_tau = float(np.clip(params[ln_tau_name], *LN_TAU_RANGE))
        amplitude, tau = params[strain_name], float(np.exp(ln_tau))
        t = poses.time.astype(float)
        decay = np.exp(-t / tau)
        # d/d ln tau = tau d/d tau = -A (t / tau) exp(-t / tau)
        jac = np.column_stack([1.0 - decay, -amplitude * (t / tau) * decay])
        return Contribution(length_strain=amplitude * (1.0 - decay), length_strain_jac=jac)

    def fit_starts(self, robot: RobotDescription) -> list[dict[str, float]]:
        """A small strain (at zero the time constant moves no point) at time constants
        spread over FIT_START_TAUS_S: the fit from each, the best kept."""
        strain, ln_tau = self.names
        return [{strain: START_STRAIN, ln_tau: float(np.log(tau))} for tau in FIT_START_TAUS_S]

    def supersedes(self, other: Effect, robot: RobotDescription) -> bool:
        """A warm-up holds thermal_drift's line (its start) too: it replaces it."""
        return isinstance(other, ThermalDrift) or super().supersedes(other, robot)

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        strain, ln_tau = self.names
        return {strain: DEFAULT_STRAIN, ln_tau: float(np.log(600.0))}

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        effect = cls()
        strain, ln_tau = effect.names
        return effect, {
            strain: float(rng.uniform(*DRAW_STRAIN)),
            ln_tau: float(np.log(rng.uniform(*DRAW_TAU_S))),
        }

    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """Only when the poses span some time (a warm-up needs a clock)."""
        return [cls()] if np.ptp(poses.time) > 0 else []
