"""The one Effect interface: an addition to the kinematic model with its own parameters.

An effect changes the chain through up to three channels, each with its exact derivative
with respect to the effect's own parameters (so the identifier gets analytic Jacobians):

- joint_offset (n, J) [rad]: added to theta_j (backlash, compliance, encoder_scale, ripple);
- length_strain (n,) [1]: every a_j and d_j is scaled by (1 + strain) (thermal_drift);
- housing (n, J, 5): the error motions dx, dy, dz [m], ex, ey [rad] of each joint in its
  fixed housing frame, applied before the joint's rotation (eccentricity, seed eq. 10).

Everything specific to an effect lives on its class, so that adding an effect is one new
module registered in `robot_calib.effects`: its parameter names, its options (dataclass
fields besides `joints`, e.g. a Fourier `order`), its text form `name[:J,J][:option=value]`
(`spec`, parsed by `robot_calib.effects.parse_effect`), its PARAMS.json / world-file form
(`to_dict`), the simulator's default and random magnitudes (`default_values`, `draw`) and
the candidates the diagnosis ladder tries (`ladder_candidates`).

The simulator, the identifier and the diagnosis use the same objects: the simulator
evaluates them at the world's true parameter values, the identifier fits them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, TypeVar

import numpy as np

from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

HOUSING_ERRORS = ("dx", "dy", "dz", "ex", "ey")
E = TypeVar("E", bound="Effect")


@dataclass
class Contribution:
    """What one effect adds to the chain at n poses, with derivatives w.r.t. its parameters.

    joint_offset : (n, J) [rad], joint_offset_jac : (n, J, P_e)
    length_strain : (n,) [1], length_strain_jac : (n, P_e)
    housing : (n, J, 5) [m, m, m, rad, rad], housing_jac : (n, J, 5, P_e)
    A channel the effect does not use is None (both value and jac).

    housing_blocks : instead of housing_jac, the same derivatives in block form, when every
    housing error of a joint is one shared basis (n, T) times its own T coefficients: a list
    of (joint index 0..J-1, basis (n, T)), the effect's parameters ordered block by block,
    error by error (dx, dy, dz, ex, ey), term by term. The dense (n, J, 5, P_e) would be
    mostly zeros (eccentricity of order 3 on six joints: 140 MB at 2773 poses).
    """

    joint_offset: Array | None = None
    joint_offset_jac: Array | None = None
    length_strain: Array | None = None
    length_strain_jac: Array | None = None
    housing: Array | None = None
    housing_jac: Array | None = None
    housing_blocks: list[tuple[int, Array]] | None = None


#: The registry: effect name -> class, in the order the modules were imported (by name).
EFFECTS: dict[str, type[Effect]] = {}


def register_effect(cls: type[E]) -> type[E]:
    """Class decorator: add an effect class to the registry under `cls.name`."""
    if cls.name in EFFECTS and EFFECTS[cls.name] is not cls:
        raise ValueError(f"effect name {cls.name!r} already registered")
    EFFECTS[cls.name] = cls
    return cls


def _text(value: Any) -> str:  # noqa: ANN401 - an option's value
    """An option's value in the text form: a tuple of orders as '11,27'."""
    return ",".join(map(str, value)) if isinstance(value, tuple | list) else str(value)


def signed_uniform(rng: np.random.Generator, low: float, high: float) -> float:
    """A random value of random sign whose magnitude is uniform in [low, high)."""
    return float(rng.choice([-1.0, 1.0]) * rng.uniform(low, high))


@dataclass(frozen=True)
class Effect(ABC):
    """Base of every effect. `joints` are 1-based joint numbers (empty: no joint).

    Subclasses are frozen dataclasses: equal effects (same class, joints and options) are
    the same model term, so sets and `in` work on them.
    """

    name: ClassVar[str]
    #: True for the contract's vocabulary (section 3); False for simulator-only effects
    #: that stand for "something the model does not know" in blind tests.
    in_vocabulary: ClassVar[bool] = True
    #: False for effects that belong to no joint (their `joints` must be empty).
    per_joint: ClassVar[bool] = True
    #: True for effects whose ladder candidates come from the residuals (a frequency scan
    #: picks joint_harmonics' orders), not from the poses alone (`ladder_candidates`)
    candidates_from_residuals: ClassVar[bool] = False
    #: The per-joint signature family of the diagnosis this effect models on its joints
    #: (`robot_calib.diagnosis.signatures.SIGNATURE_FAMILIES`: "direction", "scale",
    #: "gravity"; "" none): the reports say a finding of that family on those joints is
    #: removed by a model with the effect. Joint-angle harmonics: `harmonic_orders`.
    signature_family: ClassVar[str] = ""
    joints: tuple[int, ...] = field(default=())

    def __post_init__(self) -> None:
        if not self.per_joint and self.joints:
            raise InputError(f"{self.name} belongs to no joint: give it no joints")
        if any(j < 1 for j in self.joints) or len(set(self.joints)) != len(self.joints):
            raise InputError(f"{self.name}: joints {list(self.joints)} must be distinct, >= 1")

    # -- the model ------------------------------------------------------------------------
    @abstractmethod
    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        """The effect's parameters (nominal 0 = effect absent), named uniquely."""

    @abstractmethod
    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        """Channels and their derivatives at `poses` for the values in `params`."""

    def parameter_names(self, robot: RobotDescription) -> list[str]:
        return [p.name for p in self.parameters(robot)]

    def values(self, robot: RobotDescription, params: ParameterVector) -> Array:
        """Current values of this effect's parameters, shape (P_e,)."""
        return np.array([params[n] for n in self.parameter_names(robot)])

    # -- names and files ------------------------------------------------------------------
    def options(self) -> dict[str, Any]:
        """The effect's options (its dataclass fields besides `joints`), e.g. {'order': 2}."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "joints"}

    @property
    def label(self) -> str:
        """Human/JSON label, e.g. 'backlash[4]'."""
        joints = ",".join(str(j) for j in self.joints)
        return f"{self.name}[{joints}]" if joints else self.name

    @property
    def spec(self) -> str:
        """The `--model` term, e.g. 'backlash:4', 'eccentricity:6:order=3', 'thermal_drift'
        (parsed back by `robot_calib.effects.parse_effect`)."""
        parts = [self.name]
        if self.joints:
            parts.append(",".join(str(j) for j in self.joints))
        parts += [f"{k}={_text(v)}" for k, v in self.options().items()]
        return ":".join(parts)

    def to_dict(self) -> dict[str, Any]:
        """The PARAMS.json / world-file record: name, joints and options
        (read back by `robot_calib.effects.effect_from_dict`)."""
        options = {k: list(v) if isinstance(v, tuple) else v for k, v in self.options().items()}
        return {"name": self.name, "joints": list(self.joints), **options}

    def covers(self, other: Effect, robot: RobotDescription) -> bool:
        """True when this effect's parameters include all of `other`'s (e.g. eccentricity
        of order 3 covers order 1 of the same joint): `other` adds nothing next to it."""
        if type(other) is not type(self):  # first: the names cost (the ladder asks 4000x)
            return False
        return set(other.parameter_names(robot)) <= set(self.parameter_names(robot))

    def union(self, other: Effect, robot: RobotDescription) -> Effect | None:
        """One effect holding this one's parameters and `other`'s, when one can (the
        ladder's screening fits every candidate as columns of one superset model): the one
        that covers the other, else None (default)."""
        if self.covers(other, robot):
            return self
        if other.covers(self, robot):
            return other
        return None

    def fit_starts(self, robot: RobotDescription) -> list[dict[str, float]]:
        """Values to start a fit from where the nominal ones would stall it: one fit per
        entry, the best kept (default: the nominal values only). An effect nonlinear in its
        parameters (thermal_warmup: its time constant moves no point at zero amplitude, and
        a fit from one time constant can slide off to another) gives several."""
        return [{}]

    def harmonic_orders(self, joint: int) -> frozenset[int]:
        """The orders k of joint-angle errors C cos(k q_j) + S sin(k q_j) of `joint` this
        effect already models (the frequency scan skips them): none by default."""
        return frozenset()

    def supersedes(self, other: Effect, robot: RobotDescription) -> bool:
        """True when a model with this effect needs no `other` besides (the ladder replaces
        `other` by it, and offers no `other` next to it): `covers`, or a physical
        relation an effect declares (thermal_warmup's start is thermal_drift's line)."""
        return self.covers(other, robot)

    def diagnosed_joints(self) -> tuple[int, ...]:
        """The joints a diagnosis may name for this effect (it names joints, not links):
        its own; an effect acting between two joints (link_bending) adds the other."""
        return self.joints

    # -- simulator ------------------------------------------------------------------------
    @abstractmethod
    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        """Realistic true values [SI] of the parameters for a simulated world."""

    @classmethod
    @abstractmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        """A random instance and realistic random true values [SI] for a blind test case;
        `joint` is a joint the caller drew at random (an effect may choose another)."""

    # -- diagnosis ------------------------------------------------------------------------
    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """The instances the diagnosis ladder tries on these poses: by default one per
        joint (or one for an effect of no joint)."""
        if not cls.per_joint:
            return [cls()]
        return [cls(joints=(j,)) for j in range(1, robot.n_joints + 1)]


def check_order(effect: Effect, order: int) -> None:
    """Raise InputError unless `order` is an integer >= 1 (Fourier orders)."""
    if isinstance(order, bool) or not isinstance(order, int) or order < 1:
        raise InputError(f"effect {effect.name!r}: order must be an integer >= 1, got {order!r}")


class JointOffsetEffect(Effect):
    """An effect that adds `theta_j += coefficient_j * signal_j(poses)`, linear in its
    one parameter per joint (backlash, encoder_scale, compliance), named `<name>J`."""

    unit: ClassVar[str]
    #: simulator default of the coefficient [unit]
    default_magnitude: ClassVar[float]
    #: range of a random coefficient for blind tests [unit], and whether its sign is random
    draw_range: ClassVar[tuple[float, float]]
    draw_signed: ClassVar[bool] = False

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

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        return {name: self.default_magnitude for name in self.parameter_names(robot)}

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        effect = cls(joints=(joint,))
        low, high = cls.draw_range
        value = signed_uniform(rng, low, high) if cls.draw_signed else rng.uniform(low, high)
        return effect, {effect.parameter_names(robot)[0]: float(value)}
