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

from robot_calib.effects.base import (
    HOUSING_ERRORS,
    Contribution,
    Effect,
    check_order,
    register_effect,
    signed_uniform,
)
from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

DEG = np.pi / 180.0
#: Fourier orders the diagnosis ladder tries per joint
LADDER_ORDERS = (1, 2, 3)
#: blind tests: radial (dx, dy) [m] and tilt (ex, ey) [rad] order-1 amplitudes
DRAW_RADIAL_M = (0.05e-3, 0.2e-3)
DRAW_TILT_RAD = (0.1e-3, 0.5e-3)
#: the robot whose runout the seed paper measured (Tables 5-6): the simulator's default
SEED_ROBOT = "kr5_sixx_r650"

# Seed Tables 5-6: eccentricity offsets D and amplitudes A per joint, order dx, dy, dz [mm],
# ex, ey (read as deg: the tables label them "mm", which cannot be a tilt). Phases (Table 7)
# are all below 3e-4 rad, so the series is D + A cos(q).
SEED_TABLE5_D = [
    [-0.00894432, -0.00044766, -0.09097568, -2.8886e-05, 9.9299e-05],
    [0.00225915, -0.05434195, -0.00171799, -0.00027847, 0.00043006],
    [0.16801637, 0.00185002, -0.03888246, -0.00021782, -0.0004381],
    [0.00982289, 0.03792663, 0.00545861, 9.5836e-05, -0.00014458],
    [-0.00465192, 0.00250222, 0.31343338, 0.00324521, -0.00115391],
    [-0.03546433, -0.02386418, -0.13111638, 0.00084781, 0.00031983],
]
SEED_TABLE6_A = [
    [-0.09438893, -0.010266, -0.1214897, -0.0056238, 0.0062345],
    [-0.01861644, -0.11436569, -0.00977474, 0.02706514, -0.02377566],
    [0.14699369, -0.02192545, -0.00973498, 0.00430838, 0.02144104],
    [0.24364125, -0.00971577, -0.02075261, -0.01180938, 0.00267801],
    [-0.1641385, -0.02075231, 0.0408056, -0.00131996, -0.14413296],
    [0.00374365, 0.04081512, 0.02455266, 0.01901011, 0.04791811],
]


def fourier_basis(q: np.ndarray, order: int) -> np.ndarray:
    """Columns 1, cos q, sin q, ..., cos(K q), sin(K q) of angles q (n,) [rad]: (n, 1 + 2K)."""
    cols = [np.ones_like(q)]
    for k in range(1, order + 1):
        cols += [np.cos(k * q), np.sin(k * q)]
    return np.stack(cols, axis=-1)


def term_names(order: int) -> list[str]:
    """Fourier terms of one error motion: D, c1, s1, ..., cK, sK."""
    return ["D"] + [f"{kind}{k}" for k in range(1, order + 1) for kind in ("c", "s")]


@register_effect
@dataclass(frozen=True)
class Eccentricity(Effect):
    name = "eccentricity"
    order: int = 1

    def __post_init__(self) -> None:
        super().__post_init__()
        check_order(self, self.order)

    @staticmethod
    def term(joint: int, error: str, term: str) -> str:
        """Parameter name of one Fourier term, e.g. term(2, 'dx', 'c1') = 'ecc2_dx_c1'."""
        return f"ecc{joint}_{error}_{term}"

    @property
    def label(self) -> str:
        return f"eccentricity(order {self.order})[{','.join(map(str, self.joints))}]"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [
            Parameter(
                self.term(j, err, term), "m" if err[0] == "d" else "rad", 0.0, group=self.name
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
        coef = self.values(robot, params).reshape(len(self.joints), len(HOUSING_ERRORS), n_terms)
        housing = np.zeros((n, n_joints, len(HOUSING_ERRORS)))
        blocks = []
        for k, j in enumerate(self.joints):  # parameters: joint, error, term (`parameters`)
            basis = self.basis(poses.q[:, j - 1])  # (n, T): shared by the joint's 5 errors
            housing[:, j - 1, :] = basis @ coef[k].T
            blocks.append((j - 1, basis))
        return Contribution(housing=housing, housing_blocks=blocks)

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        """The seed's measured runout (Tables 5-6, order 1) of the KR5's joints."""
        if robot.name != SEED_ROBOT:
            raise InputError(
                f"eccentricity values must be given for robots other than the {SEED_ROBOT}"
            )
        values = {}
        for j in self.joints:
            for e, err in enumerate(HOUSING_ERRORS):
                scale = 1e-3 if err[0] == "d" else DEG
                values[self.term(j, err, "D")] = SEED_TABLE5_D[j - 1][e] * scale
                values[self.term(j, err, "c1")] = SEED_TABLE6_A[j - 1][e] * scale
        return values

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        """Order 1 on one joint: radial and tilt runout, random phase and sign."""
        values = {
            cls.term(joint, e, t): signed_uniform(rng, *DRAW_RADIAL_M)
            for e in ("dx", "dy")
            for t in ("c1", "s1")
        }
        values.update(
            {
                cls.term(joint, e, t): signed_uniform(rng, *DRAW_TILT_RAD)
                for e in ("ex", "ey")
                for t in ("c1", "s1")
            }
        )
        return cls(joints=(joint,), order=1), values

    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """Every joint at every order of LADDER_ORDERS."""
        return [
            cls(joints=(j,), order=k) for j in range(1, robot.n_joints + 1) for k in LADDER_ORDERS
        ]
