"""The one Effect interface: an addition to the kinematic model with its own parameters.

An effect changes the chain through up to three channels, each with its exact derivative
with respect to the effect's own parameters (so the identifier gets analytic Jacobians):

- joint_offset (n, J) [rad]: added to theta_j (backlash, compliance, encoder_scale, ripple);
- length_strain (n,) [1]: every a_j and d_j is scaled by (1 + strain) (thermal_drift);
- housing (n, J, 5): the error motions dx, dy, dz [m], ex, ey [rad] of each joint in its
  fixed housing frame, applied before the joint's rotation (eccentricity, seed eq. 10).

The simulator, the identifier and the diagnosis use the same objects: the simulator
evaluates them at the world's true parameter values, the identifier fits them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

HOUSING_ERRORS = ("dx", "dy", "dz", "ex", "ey")


@dataclass
class Contribution:
    """What one effect adds to the chain at n poses, with derivatives w.r.t. its parameters.

    joint_offset : (n, J) [rad], joint_offset_jac : (n, J, P_e)
    length_strain : (n,) [1], length_strain_jac : (n, P_e)
    housing : (n, J, 5) [m, m, m, rad, rad], housing_jac : (n, J, 5, P_e)
    A channel the effect does not use is None (both value and jac).
    """

    joint_offset: Array | None = None
    joint_offset_jac: Array | None = None
    length_strain: Array | None = None
    length_strain_jac: Array | None = None
    housing: Array | None = None
    housing_jac: Array | None = None


@dataclass(frozen=True)
class Effect(ABC):
    """Base of every effect. `joints` are 1-based joint numbers (empty: no joint)."""

    name: ClassVar[str]
    #: True for the contract's vocabulary (section 3); False for simulator-only effects
    #: that stand for "something the model does not know" in blind tests.
    in_vocabulary: ClassVar[bool] = True
    joints: tuple[int, ...] = field(default=())

    @abstractmethod
    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        """The effect's parameters (nominal 0 = effect absent), named uniquely."""

    @abstractmethod
    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        """Channels and their derivatives at `poses` for the values in `params`."""

    @property
    def label(self) -> str:
        """Human/JSON label, e.g. 'backlash[4]'."""
        joints = ",".join(str(j) for j in self.joints)
        return f"{self.name}[{joints}]" if joints else self.name

    def parameter_names(self, robot: RobotDescription) -> list[str]:
        return [p.name for p in self.parameters(robot)]

    def values(self, robot: RobotDescription, params: ParameterVector) -> Array:
        """Current values of this effect's parameters, shape (P_e,)."""
        return np.array([params[n] for n in self.parameter_names(robot)])


class JointOffsetEffect(Effect):
    """An effect that adds `theta_j += coefficient_j * signal_j(poses)`, linear in its
    one parameter per joint (backlash, encoder_scale, compliance)."""

    unit: ClassVar[str]

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        return [Parameter(f"{self.name}{j}", self.unit, 0.0, group=self.name) for j in self.joints]

    @abstractmethod
    def signal(self, robot: RobotDescription, poses: Poses) -> Array:
        """The per-unit signal of every joint, shape (n, J): offset = coefficient * signal."""

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        signal = self.signal(robot, poses)
        n, n_joints = signal.shape
        jac = np.zeros((n, n_joints, len(self.joints)))
        for k, j in enumerate(self.joints):
            jac[:, j - 1, k] = signal[:, j - 1]
        return Contribution(joint_offset=jac @ self.values(robot, params), joint_offset_jac=jac)
