"""joint_harmonics: a joint-angle error periodic in the joint's reading, at chosen orders.

Gear trains, strain-wave (harmonic) drives and encoder rings turn the output by slightly
more or less than the reading says, periodically: theta_j += sum over k in `orders` of
(C_k cos(k q_j) + S_k sin(k q_j)), q_j the reading [rad]. Unlike `transmission_error`
(every harmonic 1..K), the orders are any set of integers 1..MAX_ORDER, so that a gear
stage's 17th or 29th harmonic costs two parameters, not 58. What the orders usually mean:

- k = 1: an encoder or the output bearing mounted off centre (once per turn);
- k = 2: a strain-wave drive's elliptical wave generator (twice per turn);
- k = a gear ratio or tooth count of a stage (k cycles per output turn: a stage turning k
  times per output turn carries its own once-per-turn error at order k), or an encoder
  ring's pole count.

The orders of a real robot are found by a frequency scan of the residuals
(`robot_calib.diagnosis.frequency`), not guessed. Parameters `jhJ_cK`, `jhJ_sK` [rad]
(the constant term is theta_j's own). Over a partial turn of the joint the low orders are
nearly collinear with theta_j and the other geometry: the weak prior of every effect
amplitude (`robot_calib.identify.prior`) keeps them from trading radians with it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from robot_calib.effects.base import Contribution, Effect, register_effect, signed_uniform
from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

#: the highest order accepted (a gear stage of 256 teeth seen at the joint)
MAX_ORDER = 256
DEFAULT_AMPLITUDE = 1.0e-4  # rad per harmonic (about 0.3 arcmin)
DRAW_RANGE = (5e-5, 3e-4)  # rad, blind tests: each harmonic's amplitude
DRAW_ORDERS = (7, 60)  # blind tests: orders drawn in [low, high)


def meaning(order: int) -> str:
    """What a joint-angle harmonic of this order usually is, in a few words."""
    if order == 1:
        return "once per turn: an encoder or output bearing off centre"
    if order == 2:
        return "twice per turn: a strain-wave drive's wave generator"
    if order <= 6:
        return f"{order} per turn: a low-order transmission error (bearing, cam, shaft)"
    return (
        f"{order} per turn: a gear stage turning {order} x per output turn (its ratio), a "
        f"tooth count, or an encoder ring of {order} periods"
    )


@register_effect
@dataclass(frozen=True)
class JointHarmonics(Effect):
    name = "joint_harmonics"
    candidates_from_residuals = True
    orders: tuple[int, ...] = (2,)

    def __post_init__(self) -> None:
        super().__post_init__()
        raw: Any = self.orders
        if isinstance(raw, int | str):
            raw = (raw,)
        try:
            listed = [int(k) for k in raw]
        except (TypeError, ValueError):
            raise InputError(f"joint_harmonics: orders must be integers, got {raw!r}") from None
        orders = tuple(sorted(set(listed)))
        if len(orders) != len(listed):
            raise InputError(f"joint_harmonics: orders {listed} repeat an order")
        if not orders or any(isinstance(k, bool) for k in raw):
            raise InputError(f"joint_harmonics: orders must be integers >= 1, got {raw!r}")
        if orders[0] < 1 or orders[-1] > MAX_ORDER:
            raise InputError(f"joint_harmonics: orders {list(orders)} outside 1..{MAX_ORDER}")
        object.__setattr__(self, "orders", orders)

    def union(self, other: Effect, robot: RobotDescription) -> Effect | None:
        """Harmonics of the same joints: one effect of both sets of orders (two sets of
        aliases, neither covering the other, share their common orders' parameters)."""
        if isinstance(other, JointHarmonics) and other.joints == self.joints:
            return JointHarmonics(joints=self.joints, orders=tuple({*self.orders, *other.orders}))
        return super().union(other, robot)

    @staticmethod
    def term(joint: int, kind: str, k: int) -> str:
        """Parameter name, e.g. term(2, 's', 27) = 'jh2_s27'."""
        return f"jh{joint}_{kind}{k}"

    @property
    def label(self) -> str:
        orders = ",".join(map(str, self.orders))
        return f"joint_harmonics(orders {orders})[{','.join(map(str, self.joints))}]"

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [
            Parameter(self.term(j, kind, k), "rad", 0.0, group=self.name)
            for j in self.joints
            for k in self.orders
            for kind in ("c", "s")
        ]

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        n, n_joints = poses.q.shape
        per_joint = 2 * len(self.orders)
        jac = np.zeros((n, n_joints, per_joint * len(self.joints)))
        orders = np.asarray(self.orders, dtype=float)
        for i, j in enumerate(self.joints):
            angle = poses.q[:, j - 1, None] * orders  # (n, K)
            block = jac[:, j - 1, i * per_joint : (i + 1) * per_joint]
            block[:, 0::2] = np.cos(angle)
            block[:, 1::2] = np.sin(angle)
        return Contribution(joint_offset=jac @ self.values(robot, params), joint_offset_jac=jac)

    def harmonic_orders(self, joint: int) -> frozenset[int]:
        return frozenset(self.orders) if joint in self.joints else frozenset()

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        """DEFAULT_AMPLITUDE on the sine of every order of every joint."""
        return {self.term(j, "s", k): DEFAULT_AMPLITUDE for j in self.joints for k in self.orders}

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        """Two harmonics of random orders in DRAW_ORDERS, amplitudes and phases, on
        `joint`."""
        orders = tuple(sorted(rng.choice(np.arange(*DRAW_ORDERS), 2, replace=False).tolist()))
        values = {}
        for k in orders:
            amplitude, phase = signed_uniform(rng, *DRAW_RANGE), rng.uniform(0.0, 2.0 * np.pi)
            values[cls.term(joint, "c", k)] = float(amplitude * np.sin(phase))
            values[cls.term(joint, "s", k)] = float(amplitude * np.cos(phase))
        return cls(joints=(joint,), orders=orders), values

    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """None from the poses alone: the orders come from the residuals' frequency scan
        (`robot_calib.diagnosis.frequency`), which the ladder runs every round."""
        return []
