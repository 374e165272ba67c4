"""eccentricity: joint runout as in the seed paper (section 6, eq. 10-17).

For each joint j, the five error motions e = dx, dy, dz [m] (radial, axial) and ex, ey [rad]
(tilt) of the rotating axis, in the joint's fixed housing frame, are Fourier series of the
reading q_j:

    e(q) = D + sum_{k=1..K} (C_k cos(k q) + S_k sin(k q))

The seed's form D + A cos(q + phi) (order 1, 3 x 5 x 6 = 90 parameters) is the same series:
A = hypot(C1, S1), phi = atan2(-S1, C1); the linear form keeps the fit linear in each term.
Parameter names: `eccJ_<err>_D`, `eccJ_<err>_cK`, `eccJ_<err>_sK`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.effects.base import HOUSING_ERRORS, Contribution, Effect
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses


def fourier_basis(q: np.ndarray, order: int) -> np.ndarray:
    """Columns 1, cos q, sin q, ..., cos(K q), sin(K q) of angles q (n,) [rad]: (n, 1 + 2K)."""
    cols = [np.ones_like(q)]
    for k in range(1, order + 1):
        cols += [np.cos(k * q), np.sin(k * q)]
    return np.stack(cols, axis=-1)


def term_names(order: int) -> list[str]:
    """Fourier terms of one error motion: D, c1, s1, ..., cK, sK."""
    return ["D"] + [f"{kind}{k}" for k in range(1, order + 1) for kind in ("c", "s")]


@dataclass(frozen=True)
class Eccentricity(Effect):
    name = "eccentricity"
    order: int = 1

    @property
    def label(self) -> str:
        return f"eccentricity(order {self.order})[{','.join(map(str, self.joints))}]"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [
            Parameter(
                f"ecc{j}_{err}_{term}", "m" if err[0] == "d" else "rad", 0.0, group=self.name
            )
            for j in self.joints
            for err in HOUSING_ERRORS
            for term in term_names(self.order)
        ]

    def basis(self, q: np.ndarray) -> np.ndarray:
        """Fourier basis of readings q (n,) [rad]: shape (n, 1 + 2K) = 1, cos q, sin q, ..."""
        return fourier_basis(q, self.order)

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        n, n_joints = poses.q.shape
        n_terms = 1 + 2 * self.order
        per_joint = len(HOUSING_ERRORS) * n_terms
        jac = np.zeros((n, n_joints, len(HOUSING_ERRORS), per_joint * len(self.joints)))
        for k, j in enumerate(self.joints):
            basis = self.basis(poses.q[:, j - 1])
            for e in range(len(HOUSING_ERRORS)):
                start = k * per_joint + e * n_terms
                jac[:, j - 1, e, start : start + n_terms] = basis
        return Contribution(housing=jac @ self.values(robot, params), housing_jac=jac)
