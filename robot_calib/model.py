"""The single forward model: robot + effects + tracker/target frames -> target points.

Simulation, identification and diagnosis all call `KinematicModel`. Points are
predicted in the laser-tracker frame:

    p_in_tracker = base2tracker * flange2base(q) * target_in_flange

Readings enter the DH table only as the robot's joint variables
(`RobotDescription.joint_variables`: the readings themselves unless the robot declares a
`reading_to_joint` mapping); effects stay functions of the readings (msgs_doc/specification.md).

Parameter layout (names are the public vocabulary of PARAMS.json):
  thetaJ, dJ, aJ, alphaJ [rad, m, m, rad] for every joint, betaJ [rad] for Hayati joints;
  base2tracker_x/y/z [m], base2tracker_roll/pitch/yaw [rad] (Rz(yaw) Ry(pitch) Rx(roll));
  target_x/y/z [m] in the flange frame (DH frame 6); with several targets on the flange
  (msgs_doc/targets.md) each further target NAME has its own target_NAME_x/y/z, all sharing
  the tracker pose. Which target a measurement is of is `Poses.target` (an index into the
  model's `targets`).
  A 6-DoF probe (msgs_doc/six_dof.md) at target NAME also has the orientation of its frame
  in the flange frame: target_rx/ry/rz or target_NAME_rx/ry/rz [rad], a rotation vector
  (axis times angle: no gimbal lock, unlike roll-pitch-yaw, for any probe turned by less
  than 360 deg), for the targets in the model's `oriented`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from robot_calib.effects.base import Contribution, Effect
from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.dh import DHTable, chain, point_derivatives
from robot_calib.kinematics.frames import (
    Array,
    IntArray,
    matrix_to_rpy,
    rot_x,
    rot_y,
    rot_z,
    rotvec_left_jacobian,
    rotvec_to_matrix,
)
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import PRIMARY_TARGET, Poses

BASE_TRANSLATION = ("base2tracker_x", "base2tracker_y", "base2tracker_z")
BASE_ROTATION = ("base2tracker_roll", "base2tracker_pitch", "base2tracker_yaw")
TARGET = ("target_x", "target_y", "target_z")
DH_UNITS = {"theta": "rad", "d": "m", "a": "m", "alpha": "rad", "beta": "rad"}
#: poses per block where a whole chain would be held only to keep a part of it
CHAIN_BLOCK_POSES = 5000

REASON_HAYATI = "dropped: axes {j} and {k} nominally parallel, Hayati beta{j} used instead"
REASON_BASE = "redundant with base2tracker (rotation about and shift along joint 1's axis)"
REASON_TARGET = "redundant with the target offset (a point target on the last link)"


def target_parameters(name: str) -> tuple[str, str, str]:
    """Names of the x, y, z offset parameters of target `name` ('' = the contract's single
    target: target_x/y/z; else target_NAME_x/y/z)."""
    if name == PRIMARY_TARGET:
        return TARGET
    return (f"target_{name}_x", f"target_{name}_y", f"target_{name}_z")


def tool_rotation_parameters(name: str) -> tuple[str, str, str]:
    """Names of the rotation-vector parameters (x, y, z [rad]) of 6-DoF target `name`'s
    frame in the flange frame (target_rx/ry/rz for the first target)."""
    stem = "target" if name == PRIMARY_TARGET else f"target_{name}"
    return (f"{stem}_rx", f"{stem}_ry", f"{stem}_rz")


def geometric_parameters(
    robot: RobotDescription,
    base2tracker: tuple[float, float, float, float, float, float] = (0.0,) * 6,
    target_in_flange: tuple[float, float, float] = (0.0, 0.0, 0.0),
    targets: tuple[str, ...] = (PRIMARY_TARGET,),
    offsets: Mapping[str, tuple[float, float, float]] | None = None,
    oriented: tuple[str, ...] = (),
) -> ParameterVector:
    """The nominal geometric parameter vector of `robot`.

    base2tracker : (x, y, z [m], roll, pitch, yaw [rad]) of the robot base in the tracker.
    target_in_flange : the first target's centre in the flange frame [m].
    targets : the names of the targets measured (the first is the one of
      `target_in_flange`); offsets : the others' centres in the flange frame [m] (default
      that of the first); oriented : the targets measured by 6-DoF probes, whose frame's
      orientation in the flange frame is a parameter too (nominal: the flange's).
    Parameters that a point target and a free tracker pose can never separate are fixed,
    each with its reason (the data-driven identifiability check comes on top).
    """
    n = robot.n_joints
    params: list[Parameter] = []
    for j in range(1, n + 1):
        for field in ("theta", "d", "a", "alpha", "beta"):
            if field == "beta" and not robot.hayati[j - 1]:
                continue
            reason = ""
            if field == "d" and robot.hayati[j - 1]:
                reason = REASON_HAYATI.format(j=j, k=j + 1)
            elif j == 1 and field in ("theta", "d"):
                reason = REASON_BASE
            elif j == n and field in ("theta", "d", "a", "alpha"):
                reason = REASON_TARGET
            nominal = float(getattr(robot, field)[j - 1])
            params.append(Parameter(f"{field}{j}", DH_UNITS[field], nominal, not reason, reason))
    for name, value in zip(BASE_TRANSLATION + BASE_ROTATION, base2tracker):
        unit = "m" if name in BASE_TRANSLATION else "rad"
        params.append(Parameter(name, unit, float(value), group="frames"))
    for k, target in enumerate(targets):
        xyz = target_in_flange if k == 0 else (offsets or {}).get(target, target_in_flange)
        for name, value in zip(target_parameters(target), xyz):
            params.append(Parameter(name, "m", float(value), group="frames"))
    for target in oriented:
        for name in tool_rotation_parameters(target):
            params.append(Parameter(name, "rad", 0.0, group="frames"))
    return ParameterVector(params)


def absorb_base_offsets(robot: RobotDescription, params: ParameterVector) -> ParameterVector:
    """The same geometry with theta1 and d1 at their nominal values, their deviations moved
    into base2tracker (a turn about and shift along axis 1 commute with joint 1). Use it to
    compare a simulated world's truth with identified parameters, which keep them nominal."""
    d_theta = params["theta1"] - robot.theta[0]
    d_d = params["d1"] - robot.d[0]
    shift = np.eye(4)
    shift[:3, :3] = rot_z([d_theta])[0]
    shift[2, 3] = d_d
    frame = KinematicModel.base2tracker(params) @ shift
    roll, pitch, yaw = matrix_to_rpy(frame[:3, :3])
    updates = dict(zip(BASE_TRANSLATION, frame[:3, 3]))
    updates.update(zip(BASE_ROTATION, (roll, pitch, yaw)))
    updates.update({"theta1": float(robot.theta[0]), "d1": float(robot.d[0])})
    return params.with_values(updates)


@dataclass(frozen=True)
class Chain:
    """The kinematic chain of a model at n poses, effects applied.

    dh : effective DH/Hayati values, (n, J) each; frames : (n, J + 1, 4, 4) frame j in the
    robot base (0 = base, J = flange); errors : (n, J, 4, 4) housing error transforms or None;
    housing : (n, J, 5) housing error motions [m, m, m, rad, rad] or None;
    contributions : one per effect, in the model's order; rows : the geometric DH/Hayati rows
    (J,) each, before effects; scale : (n, 1) length scale 1 + strain [1].
    """

    dh: DHTable
    frames: Array
    errors: Array | None
    housing: Array | None
    contributions: list[Contribution]
    rows: dict[str, Array]
    scale: Array


def housing_transforms(housing: Array) -> Array:
    """Error transforms T(dx, dy, dz) Rx(ex) Ry(ey) (seed eq. 10), shape (n, J, 4, 4),
    from error motions `housing` (n, J, 5) [m, m, m, rad, rad]."""
    n, j, _ = housing.shape
    flat = housing.reshape(-1, 5)
    out = np.zeros((n * j, 4, 4))
    out[:, :3, :3] = rot_x(flat[:, 3]) @ rot_y(flat[:, 4])
    out[:, :3, 3] = flat[:, :3]
    out[:, 3, 3] = 1.0
    return out.reshape(n, j, 4, 4)


class PointCorrection(Protocol):
    """What corrects a model's points: a learned correction's predicted residual (n, 3)
    [m] at poses (`identify.correction_structured.LearnedCorrection`)."""

    def predict(self, poses: Poses) -> Array: ...


def corrected(points: Array, poses: Poses, correction: PointCorrection | None) -> Array:
    """`points` (n, 3) [m, tracker frame] at `poses` (the model's, or its residuals) less
    the residual the learned `correction` predicts there: the hybrid model's (`points` when
    there is none). The one place a learned correction is applied to points."""
    return points if correction is None else points - correction.predict(poses)


class Calibrated(Protocol):
    """What applying a calibration takes: its model, its parameters and its learned
    correction (None: the model alone). `identify.calibration.Calibration` is one, as loaded
    from PARAMS.json by every front end."""

    @property
    def model(self) -> KinematicModel: ...

    @property
    def parameters(self) -> ParameterVector: ...

    @property
    def correction(self) -> PointCorrection | None: ...


@dataclass(frozen=True)
class KinematicModel:
    """Forward model and analytic Jacobian: a robot description plus effects, measured at
    the targets `targets` (names; measurement i is of target `poses.target[i]`)."""

    robot: RobotDescription
    effects: tuple[Effect, ...] = ()
    targets: tuple[str, ...] = (PRIMARY_TARGET,)
    oriented: tuple[str, ...] = ()  # targets measured by 6-DoF probes (a subset of targets)

    def __post_init__(self) -> None:
        unknown = [t for t in self.oriented if t not in self.targets]
        if unknown:
            raise InputError(f"6-DoF targets {unknown} are not among the targets {self.targets}")
        for effect in self.effects:
            bad = [j for j in effect.joints if not 1 <= j <= self.robot.n_joints]
            if bad:
                raise InputError(
                    f"effect {effect.name}: joints {bad} outside 1..{self.robot.n_joints}"
                )

    def parameters(
        self,
        base2tracker: tuple[float, float, float, float, float, float] = (0.0,) * 6,
        target_in_flange: tuple[float, float, float] = (0.0, 0.0, 0.0),
        offsets: Mapping[str, tuple[float, float, float]] | None = None,
    ) -> ParameterVector:
        """Nominal geometric parameters followed by every effect's (nominal 0); the first
        target at `target_in_flange`, the others at `offsets` (default: the same) [m]."""
        params = geometric_parameters(
            self.robot, base2tracker, target_in_flange, self.targets, offsets, self.oriented
        )
        for effect in self.effects:
            params = params.concat(ParameterVector(effect.parameters(self.robot)))
        return params

    def with_effects(self, *effects: Effect) -> KinematicModel:
        """The same robot with `effects` added."""
        return replace(self, effects=self.effects + tuple(effects))

    def with_targets(
        self, targets: tuple[str, ...], oriented: tuple[str, ...] = ()
    ) -> KinematicModel:
        """The same robot and effects measured at the targets named `targets`, those of
        `oriented` by 6-DoF probes."""
        return replace(self, targets=tuple(targets), oriented=tuple(oriented))

    def tool_rotations(self, params: ParameterVector) -> Array:
        """Every target's frame in the flange frame, shape (T, 3, 3), `targets` order
        (identity for targets not in `oriented`)."""
        out = np.tile(np.eye(3), (len(self.targets), 1, 1))
        for name in self.oriented:
            rotvec = np.array([params[k] for k in tool_rotation_parameters(name)])
            out[self.targets.index(name)] = rotvec_to_matrix(rotvec)
        return out

    def probe_orientations(self, params: ParameterVector, poses: Poses) -> Array:
        """Predicted probe frames in the tracker frame, shape (n, 3, 3) (columns: the
        probe's x, y, z axes): base2tracker * flange2base(q) * tool rotation."""
        tools = self.tool_rotations(params)[poses.target_index]
        return self.flange_rotations(params, poses) @ tools

    def flange_rotations(self, params: ParameterVector, poses: Poses) -> Array:
        """The flange's orientation in the tracker frame, shape (n, 3, 3): base2tracker's
        rotation * flange2base(q)'s (effects included)."""
        return self.base2tracker(params)[:3, :3] @ self.flange2base(params, poses)[:, :3, :3]

    def orientation_jacobian(self, params: ParameterVector, poses: Poses) -> tuple[Array, Array]:
        """Probe frames (n, 3, 3) as `probe_orientations` and their small rotation per unit
        change of each parameter, omega (n, 3, P) [rad per parameter unit], tracker frame.

        Every parameter moves the flange as a rigid body, so a point's Jacobian is
        v + omega x p: the Jacobians at the probe's point and at points a unit along its
        frame's x and y axes differ by omega x w_x and omega x w_y, from which omega
        follows; the tool rotation's own columns are added analytically."""
        n = len(poses)
        tool = self.tool_rotations(params)[poses.target_index]  # (n, 3, 3) flange frame
        _, jac0 = self._evaluate(params, poses, True)
        _, jac_x = self._evaluate(params, poses, True, shift=tool[:, :, 0])
        _, jac_y = self._evaluate(params, poses, True, shift=tool[:, :, 1])
        assert jac0 is not None and jac_x is not None and jac_y is not None
        flange_in_tracker = self.flange_rotations(params, poses)  # (n, 3, 3)
        frames = flange_in_tracker @ tool
        w_x, w_y, w_z = frames[:, :, 0], frames[:, :, 1], frames[:, :, 2]
        d_x, d_y = jac_x - jac0, jac_y - jac0  # omega x w_x, omega x w_y (n, 3, P)

        def along(w: Array, d: Array) -> Array:
            return np.einsum("na,nap->np", w, d)

        omega = (
            along(w_z, d_y)[:, None, :] * w_x[:, :, None]
            - along(w_z, d_x)[:, None, :] * w_y[:, :, None]
            + along(w_y, d_x)[:, None, :] * w_z[:, :, None]
        )
        for name in self.oriented:
            rows = poses.target_index == self.targets.index(name)
            rotvec = np.array([params[k] for k in tool_rotation_parameters(name)])
            turns = rotvec_left_jacobian(rotvec)  # columns: flange-frame rotations
            for k, pname in enumerate(tool_rotation_parameters(name)):
                omega[rows, :, params.index(pname)] = flange_in_tracker[rows] @ turns[:, k]
        return frames, omega.reshape(n, 3, len(params))

    def target_offsets(self, params: ParameterVector) -> Array:
        """Every target's centre in the flange frame, shape (T, 3) [m], in `targets` order."""
        return np.array([[params[k] for k in target_parameters(t)] for t in self.targets])

    def _nominal_rows(self, params: ParameterVector) -> dict[str, Array]:
        n = self.robot.n_joints
        return {
            field: np.array(
                [
                    params.get(f"{field}{j}", getattr(self.robot, field)[j - 1])
                    for j in range(1, n + 1)
                ]
            )
            for field in DH_UNITS
        }

    def dh_table(self, params: ParameterVector, q: Array) -> DHTable:
        """Geometric DH/Hayati values (no effects), (n, J) each, for readings q (n, J); theta
        takes the robot's joint variables of q (`RobotDescription.joint_variables`)."""
        row = self._nominal_rows(params)
        theta = row["theta"] + self.robot.joint_variables(q)
        return DHTable(theta, row["d"], row["a"], row["alpha"], row["beta"])

    @staticmethod
    def base2tracker(params: ParameterVector) -> Array:
        """Robot base pose in the tracker frame, shape (4, 4)."""
        roll, pitch, yaw = (params[k] for k in BASE_ROTATION)
        out = np.eye(4)
        out[:3, :3] = rot_z([yaw])[0] @ rot_y([pitch])[0] @ rot_x([roll])[0]
        out[:3, 3] = [params[k] for k in BASE_TRANSLATION]
        return out

    def flange2base(self, params: ParameterVector, poses: Poses) -> Array:
        """Flange (DH frame J) poses in the robot base frame, with effects, shape (n, 4, 4);
        the chain computed CHAIN_BLOCK_POSES poses at a time (its every frame, (n, J + 1,
        4, 4), would be 7x the result)."""
        n = len(poses)
        if n <= CHAIN_BLOCK_POSES:
            return self._chain(params, poses).frames[:, -1]
        out = np.empty((n, 4, 4))
        for start in range(0, n, CHAIN_BLOCK_POSES):
            rows = slice(start, min(start + CHAIN_BLOCK_POSES, n))
            out[rows] = self._chain(params, poses.subset(rows)).frames[:, -1]
        return out

    def link_frames(self, params: ParameterVector, poses: Poses) -> Array:
        """Every DH frame in the robot base, effects applied, shape (n, J + 1, 4, 4)
        (0 = base, J = flange)."""
        return self._chain(params, poses).frames

    def joint_axes(self, params: ParameterVector, poses: Poses) -> tuple[Array, Array]:
        """Axis lines of every joint at `poses` in the tracker frame: origins (n, J, 3) [m]
        and unit directions (n, J, 3) (z of frame j-1; housing errors included)."""
        frames = self._chain(params, poses).frames[:, :-1]
        b2t = self.base2tracker(params)
        origins = frames[..., :3, 3] @ b2t[:3, :3].T + b2t[:3, 3]
        return origins, frames[..., :3, 2] @ b2t[:3, :3].T

    def target_points(
        self, params: ParameterVector, poses: Poses, correction: PointCorrection | None = None
    ) -> Array:
        """Predicted target centres in the tracker frame, shape (n, 3) [m] (CHAIN_BLOCK_POSES
        poses at a time: memory O(block) beyond the result); with a learned `correction`
        (the hybrid model, PARAMS.json `correction`) less the residual it predicts at
        `poses`: the one place a learned correction is applied to points."""
        n = len(poses)
        if n <= CHAIN_BLOCK_POSES:
            out = self._evaluate(params, poses, with_jacobian=False)[0]
        else:
            out = np.empty((n, 3))
            for start in range(0, n, CHAIN_BLOCK_POSES):
                rows = slice(start, min(start + CHAIN_BLOCK_POSES, n))
                out[rows] = self._evaluate(params, poses.subset(rows), with_jacobian=False)[0]
        return corrected(out, poses, correction)

    def jacobian(self, params: ParameterVector, poses: Poses) -> tuple[Array, Array]:
        """Points (n, 3) [m] and d points / d parameters, shape (n, 3, P), full vector order
        (a view of parameter-major storage: `jacobian_columns` gives columns contiguous)."""
        points, jac = self._evaluate(params, poses, with_jacobian=True)
        assert jac is not None
        return points, jac

    def jacobian_columns(
        self, params: ParameterVector, poses: Poses, columns: IntArray
    ) -> tuple[Array, Array]:
        """Points (n, 3) [m] and d points / d the parameters at `columns` (indices into the
        full vector), parameter-major: shape (len(columns), n, 3), each column's (n, 3)
        contiguous (what a column-major least-squares block copies fastest)."""
        points, jac = self.jacobian(params, poses)
        return points, jac.transpose(2, 0, 1)[columns]

    def _chain(self, params: ParameterVector, poses: Poses) -> Chain:
        """The chain at `poses` with every effect's contribution applied."""
        n, n_joints = poses.q.shape
        row = self._nominal_rows(params)
        contributions = [e.contribution(self.robot, params, poses) for e in self.effects]
        offset = np.zeros((n, n_joints))
        strain = np.zeros(n)
        housing = None
        for c in contributions:
            if c.joint_offset is not None:
                offset += c.joint_offset
            if c.length_strain is not None:
                strain += c.length_strain
            if c.housing is not None:
                housing = c.housing if housing is None else housing + c.housing
        scale = (1.0 + strain)[:, None]
        dh = DHTable(
            row["theta"] + self.robot.joint_variables(poses.q) + offset,
            row["d"] * scale,
            row["a"] * scale,
            row["alpha"],
            row["beta"],
        )
        errors = None if housing is None else housing_transforms(housing)
        return Chain(dh, chain(dh, errors), errors, housing, contributions, row, scale)

    def _evaluate(
        self,
        params: ParameterVector,
        poses: Poses,
        with_jacobian: bool,
        shift: Array | None = None,
    ) -> tuple[Array, Array | None]:
        """Points (n, 3) and, `with_jacobian`, d points / d parameters (n, 3, P); `shift`
        (n, 3) [m] moves each measurement's target by that much in the flange frame."""
        ch = self._chain(params, poses)
        dh, frames, errors, housing, row, scale = (
            ch.dh,
            ch.frames,
            ch.errors,
            ch.housing,
            ch.rows,
            ch.scale,
        )
        which = poses.target_index
        if len(which) and (which.min() < 0 or which.max() >= len(self.targets)):
            raise InputError(
                f"measurements of target {int(which.max())} but the model has "
                f"{len(self.targets)} target(s) {list(self.targets)}"
            )
        target = self.target_offsets(params)[which]  # (n, 3) flange frame
        if shift is not None:
            target = target + shift
        flange = frames[:, -1]
        p_in_base = np.einsum("nab,nb->na", flange[:, :3, :3], target) + flange[:, :3, 3]
        b2t = self.base2tracker(params)
        rot = b2t[:3, :3]
        points = p_in_base @ rot.T + b2t[:3, 3]
        if not with_jacobian:
            return points, None

        n = len(poses)
        # parameter-major: each column a contiguous (n, 3) plane written whole (writing
        # columns into an (n, 3, P) array strides through memory); returned as an
        # (n, 3, P) view, and whole to `jacobian_columns`
        jac_t = np.zeros((len(params), n, 3))
        deriv = point_derivatives(dh, frames, p_in_base, errors)
        for field in DH_UNITS:  # every joint's column of the field at once, (n, 3, J)
            joints = [j for j in range(self.robot.n_joints) if f"{field}{j + 1}" in params]
            if not joints:
                continue
            cols = getattr(deriv, field)[:, :, joints]
            if field in ("a", "d"):
                cols = cols * scale[:, :, None]  # the effective length is (1 + strain) * value
            index = [params.index(f"{field}{j + 1}") for j in joints]
            jac_t[index] = np.einsum("naj,ba->jnb", cols, rot)
        for axis, name in enumerate(BASE_TRANSLATION):
            jac_t[params.index(name), :, axis] = 1.0
        # Rotation R = Rz(yaw) Ry(pitch) Rx(roll): each angle turns about an axis of the
        # partially rotated frame, through the tracker-frame image of the base origin.
        roll, pitch, yaw = (params[k] for k in BASE_ROTATION)
        rz, ry = rot_z([yaw])[0], rot_y([pitch])[0]
        axes = {
            "base2tracker_roll": rz @ ry[:, 0],
            "base2tracker_pitch": rz[:, 1],
            "base2tracker_yaw": np.array([0.0, 0.0, 1.0]),
        }
        lever = p_in_base @ rot.T
        for name, axis_vec in axes.items():
            jac_t[params.index(name)] = np.cross(axis_vec, lever)
        flange_in_tracker = rot @ flange[:, :3, :3]  # (n, 3, 3)
        for k, name in enumerate(self.targets):
            rows = which == k
            for axis, pname in enumerate(target_parameters(name)):
                jac_t[params.index(pname), rows] = flange_in_tracker[rows, :, axis]

        d_housing = None
        if housing is not None:
            d_housing = _housing_derivatives(frames, housing, p_in_base)
        for effect, c in zip(self.effects, ch.contributions):
            cols = [params.index(name) for name in effect.parameter_names(self.robot)]
            d_eff = np.zeros((n, 3, len(cols)))
            if c.joint_offset_jac is not None:
                d_eff += np.einsum("naj,njp->nap", deriv.theta, c.joint_offset_jac)
            if c.length_strain_jac is not None:
                d_strain = deriv.a @ row["a"] + deriv.d @ row["d"]  # (n, 3)
                d_eff += d_strain[:, :, None] * c.length_strain_jac[:, None, :]
            if c.housing_jac is not None:
                assert d_housing is not None
                d_eff += np.einsum("najk,njkp->nap", d_housing, c.housing_jac)
            if c.housing_blocks is not None:  # (n, 3, 5, T) per joint, in parameter order
                assert d_housing is not None
                d_eff += np.concatenate(
                    [
                        (d_housing[:, :, j, :, None] * basis[:, None, None, :]).reshape(n, 3, -1)
                        for j, basis in c.housing_blocks
                    ],
                    axis=2,
                )
            jac_t[cols] = np.einsum("ab,nbp->pna", rot, d_eff)
        return points, jac_t.transpose(1, 2, 0)


def _housing_derivatives(frames: Array, housing: Array, p_in_base: Array) -> Array:
    """d p_in_base / d (dx, dy, dz, ex, ey) of every joint, shape (n, 3, J, 5), exact for
    E = T(dx, dy, dz) Rx(ex) Ry(ey) applied in housing frame j-1 (`frames[:, j-1]`)."""
    prev = frames[:, :-1]  # (n, J, 4, 4)
    rot_prev = prev[..., :3, :3]
    shifted = prev[..., :3, 3] + np.einsum("njab,njb->nja", rot_prev, housing[..., :3])
    lever = p_in_base[:, None, :] - shifted  # from the displaced tilt centre
    x_axis = rot_prev[..., :, 0]
    tilt_x = housing[..., 3:4]  # ey turns about y after Rx(ex): R_prev (0, cos ex, sin ex)
    y_axis = np.cos(tilt_x) * rot_prev[..., :, 1] + np.sin(tilt_x) * rot_prev[..., :, 2]
    out = np.empty(housing.shape[:2] + (3, 5))  # (n, J, 3, 5)
    out[..., :3] = rot_prev
    out[..., 3] = np.cross(x_axis, lever)
    out[..., 4] = np.cross(y_axis, lever)
    return np.moveaxis(out, 1, 2)  # (n, 3, J, 5)
