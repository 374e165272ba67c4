"""gravity_compliance: elastic joint deflection under gravity with the mass distribution
identified, not assumed.

`compliance` multiplies one stiffness by the gravity torque of the robot's approximate
mass model (no payload unless given): a wrong mass model or an unknown payload leaves
structure behind. Here the torque's lumped regressors are fitted: the gravity torque about
joint j is linear in the first moments m_i c_i (in link i's frame) and masses m_i of the
links it carries (i >= j),

    tau_j = g sum_{i >= j} [ (R_i m_i c_i) . (u x z_{j-1}) + m_i (p_i - o_{j-1}) . (u x z_{j-1}) ]

with u the unit vector of gravity (-z of the base), R_i, p_i link i's frame and z_{j-1},
o_{j-1} joint j's axis, all on the nominal kinematics. A deflection theta_j += k_j tau_j is
then linear in the products k_j g m_i c_i [rad] and k_j g m_i [rad/m]: the parameters
`gcJ_L{i}_mx/my/mz` and `gcJ_L{i}_m` (a payload is part of the last link's). Combinations
the poses cannot separate are fixed by the identifiability analysis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.effects.base import Contribution, Effect, register_effect
from robot_calib.effects.compliance import (
    GRAVITY,
    Compliance,
    gravity_joints,
    visible_gravity_joints,
)
from robot_calib.kinematics.description import RobotDescription, with_payload
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

TERMS = ("mx", "my", "mz", "m")
ROUND_OFF = 1e-12  # [1], [m]: regressor values below this are geometry's zeros
DRAW_PAYLOAD_KG = (1.0, 5.0)  # blind tests: an unknown payload on the flange


def gravity_regressors(robot: RobotDescription, q: Array) -> Array:
    """R (n, J, J, 4): tau_j / g = sum_i R[:, j, i] . (m_i c_i (3, link frame), m_i) for
    readings q (n, J) [rad] on the nominal kinematics (zero for i < j); first three terms
    dimensionless, the last [m]."""
    frames = robot.nominal_frames(q)  # (n, J + 1, 4, 4)
    down = GRAVITY / np.linalg.norm(GRAVITY)
    n, n_joints = q.shape
    out = np.zeros((n, n_joints, n_joints, len(TERMS)))
    for j in range(n_joints):
        lever = np.cross(down, frames[:, j, :3, 2])  # u x z_{j-1}, (n, 3)
        origin = frames[:, j, :3, 3]
        for i in range(j, n_joints):
            link = frames[:, i + 1]
            out[:, j, i, :3] = np.einsum("nab,na->nb", link[:, :3, :3], lever)
            out[:, j, i, 3] = np.einsum("na,na->n", link[:, :3, 3] - origin, lever)
    # Terms that vanish by the geometry (a link axis perpendicular to the lever in every
    # pose) come out as round-off; exact zeros let the identifiability analysis fix them
    # instead of a fit blowing them up.
    out[np.abs(out) < ROUND_OFF] = 0.0
    return out


@register_effect
@dataclass(frozen=True)
class GravityCompliance(Effect):
    name = "gravity_compliance"
    signature_family = "gravity"

    @staticmethod
    def term(joint: int, link: int, term: str) -> str:
        """Parameter name, e.g. term(2, 5, 'mx') = 'gc2_L5_mx'."""
        return f"gc{joint}_L{link}_{term}"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [
            Parameter(self.term(j, i, t), "rad/m" if t == "m" else "rad", 0.0, group=self.name)
            for j in self.joints
            for i in range(j, robot.n_joints + 1)
            for t in TERMS
        ]

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        n, n_joints = poses.q.shape
        regressors = gravity_regressors(robot, poses.q)
        columns = [
            (j, i, k) for j in self.joints for i in range(j, n_joints + 1) for k in range(4)
        ]
        jac = np.zeros((n, n_joints, len(columns)))
        for c, (j, i, k) in enumerate(columns):
            jac[:, j - 1, c] = regressors[:, j - 1, i - 1, k]
        return Contribution(joint_offset=jac @ self.values(robot, params), joint_offset_jac=jac)

    def values_for(self, robot: RobotDescription, stiffness: float) -> dict[str, float]:
        """The parameters of `robot`'s mass model (payload included) deflecting every joint
        of the effect by `stiffness` [rad/(N m)] per N m: k g m_i c_i, k g m_i."""
        g = float(np.linalg.norm(GRAVITY))
        out = {}
        for j in self.joints:
            for i in range(j, robot.n_joints + 1):
                mass, centre = robot.link_mass[i - 1], robot.link_com[i - 1]
                moments = (*(mass * centre), mass)
                for t, value in zip(TERMS, moments):
                    out[self.term(j, i, t)] = float(stiffness * g * value)
        return out

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        """The robot's own mass model at `compliance`'s default stiffness."""
        return self.values_for(robot, Compliance.default_magnitude)

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        """A joint with a significant gravity torque, `compliance`'s stiffness range, and
        the mass model with an unknown payload (1-5 kg, centre up to 0.15 m off the flange)."""
        effect = cls(joints=(int(rng.choice(gravity_joints(robot))),))
        centre = rng.uniform(-0.05, 0.05, 3) + [0.0, 0.0, 0.1]
        payload = with_payload(robot, float(rng.uniform(*DRAW_PAYLOAD_KG)), centre.tolist())
        return effect, effect.values_for(payload, float(rng.uniform(*Compliance.draw_range)))

    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """Joints whose gravity torque varies over the poses (else nothing to see)."""
        return [cls(joints=(j,)) for j in visible_gravity_joints(robot, poses)]
