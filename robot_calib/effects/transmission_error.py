"""transmission_error: a joint-angle error periodic in the joint's reading.

Harmonic drives and gear trains turn the output by slightly more or less than the reading
says, periodically over a turn: theta_j += sum_{k=1..K} (C_k cos(k q_j) + S_k sin(k q_j)),
with q_j the reading (k = 2 dominates a harmonic drive, k = 1 is an encoder mounted off
centre, higher k a gear's tooth ripple seen at the joint). Unlike eccentricity's runout,
which moves the axis (housing error motions), this turns the link about the axis only.
The constant term is theta_j's own (not repeated here). Parameters
`teJ_cK`, `teJ_sK` [rad].
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
from robot_calib.effects.eccentricity import fourier_basis
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

#: Fourier orders the diagnosis ladder tries per joint (order K holds harmonics 1..K):
#: up to a gear's 6th harmonic
LADDER_ORDERS = (1, 2, 3, 4, 6)
DEFAULT_AMPLITUDE = 1.5e-4  # rad, the 2nd harmonic of a harmonic drive (about 0.5 arcmin)
DRAW_RANGE = (1e-4, 4e-4)  # rad, blind tests: one harmonic of order 1..3


@register_effect
@dataclass(frozen=True)
class TransmissionError(Effect):
    name = "transmission_error"
    order: int = 2

    def __post_init__(self) -> None:
        super().__post_init__()
        check_order(self, self.order)

    @staticmethod
    def term(joint: int, kind: str, k: int) -> str:
        """Parameter name, e.g. term(4, 's', 2) = 'te4_s2'."""
        return f"te{joint}_{kind}{k}"

    @property
    def label(self) -> str:
        return f"transmission_error(order {self.order})[{','.join(map(str, self.joints))}]"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [
            Parameter(self.term(j, kind, k), "rad", 0.0, group=self.name)
            for j in self.joints
            for k in range(1, self.order + 1)
            for kind in ("c", "s")
        ]

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        n, n_joints = poses.q.shape
        per_joint = 2 * self.order
        jac = np.zeros((n, n_joints, per_joint * len(self.joints)))
        for i, j in enumerate(self.joints):
            # fourier_basis: 1, cos q, sin q, ..., cos Kq, sin Kq; the constant is theta_j
            jac[:, j - 1, i * per_joint : (i + 1) * per_joint] = fourier_basis(
                poses.q[:, j - 1], self.order
            )[:, 1:]
        return Contribution(joint_offset=jac @ self.values(robot, params), joint_offset_jac=jac)

    def harmonic_orders(self, joint: int) -> frozenset[int]:
        return frozenset(range(1, self.order + 1)) if joint in self.joints else frozenset()

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        """A harmonic drive's 2nd harmonic on every joint of the effect."""
        return {self.term(j, "s", 2): DEFAULT_AMPLITUDE for j in self.joints if self.order >= 2}

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        """One harmonic of random order 1..3, amplitude and phase, on `joint`."""
        order = int(rng.integers(1, 4))
        amplitude, phase = signed_uniform(rng, *DRAW_RANGE), rng.uniform(0.0, 2.0 * np.pi)
        return cls(joints=(joint,), order=order), {
            cls.term(joint, "c", order): float(amplitude * np.sin(phase)),
            cls.term(joint, "s", order): float(amplitude * np.cos(phase)),
        }

    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """Every joint at every order of LADDER_ORDERS."""
        return [
            cls(joints=(j,), order=k) for j in range(1, robot.n_joints + 1) for k in LADDER_ORDERS
        ]
