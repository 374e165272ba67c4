"""The single forward model: robot + tracker/target frames (+ effects) -> target points.

Simulation, identification and diagnosis all call `KinematicModel`. Points are
predicted in the laser-tracker frame:

    p_in_tracker = base2tracker * flange2base(q) * target_in_flange

Parameter layout (names are the public vocabulary of PARAMS.json):
  thetaJ, dJ, aJ, alphaJ [rad, m, m, rad] for every joint, betaJ [rad] for Hayati joints;
  base2tracker_x/y/z [m], base2tracker_roll/pitch/yaw [rad] (Rz(yaw) Ry(pitch) Rx(roll));
  target_x/y/z [m] in the flange frame (DH frame 6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.dh import DHTable, chain, point_derivatives
from robot_calib.kinematics.frames import Array, rot_x, rot_y, rot_z
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

BASE_TRANSLATION = ("base2tracker_x", "base2tracker_y", "base2tracker_z")
BASE_ROTATION = ("base2tracker_roll", "base2tracker_pitch", "base2tracker_yaw")
TARGET = ("target_x", "target_y", "target_z")
DH_UNITS = {"theta": "rad", "d": "m", "a": "m", "alpha": "rad", "beta": "rad"}

REASON_HAYATI = "dropped: axes {j} and {k} nominally parallel, Hayati beta{j} used instead"
REASON_BASE = "redundant with base2tracker (rotation about and shift along joint 1's axis)"
REASON_TARGET = "redundant with the target offset (a point target on the last link)"


def geometric_parameters(
    robot: RobotDescription,
    base2tracker: tuple[float, float, float, float, float, float] = (0.0,) * 6,
    target_in_flange: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> ParameterVector:
    """The nominal geometric parameter vector of `robot`.

    base2tracker : (x, y, z [m], roll, pitch, yaw [rad]) of the robot base in the tracker.
    target_in_flange : target centre in the flange frame [m].
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
    for name, value in zip(TARGET, target_in_flange):
        params.append(Parameter(name, "m", float(value), group="frames"))
    return ParameterVector(params)


@dataclass(frozen=True)
class KinematicModel:
    """Forward model and analytic Jacobian for one robot description."""

    robot: RobotDescription

    def dh_table(self, params: ParameterVector, q: Array) -> DHTable:
        """DH/Hayati values of every pose, (n, J) each, from parameters and readings q (n, J)."""
        n = self.robot.n_joints
        row = {
            field: np.array(
                [
                    params.get(f"{field}{j}", getattr(self.robot, field)[j - 1])
                    for j in range(1, n + 1)
                ]
            )
            for field in DH_UNITS
        }
        return DHTable(
            theta=row["theta"][None, :] + q,
            d=row["d"][None, :],
            a=row["a"][None, :],
            alpha=row["alpha"][None, :],
            beta=row["beta"][None, :],
        )

    @staticmethod
    def base2tracker(params: ParameterVector) -> Array:
        """Robot base pose in the tracker frame, shape (4, 4)."""
        roll, pitch, yaw = (params[k] for k in BASE_ROTATION)
        out = np.eye(4)
        out[:3, :3] = rot_z([yaw])[0] @ rot_y([pitch])[0] @ rot_x([roll])[0]
        out[:3, 3] = [params[k] for k in BASE_TRANSLATION]
        return out

    def flange2base(self, params: ParameterVector, poses: Poses) -> Array:
        """Flange (DH frame J) poses in the robot base frame, shape (n, 4, 4)."""
        return chain(self.dh_table(params, poses.q))[:, -1]

    def target_points(self, params: ParameterVector, poses: Poses) -> Array:
        """Predicted target centres in the tracker frame, shape (n, 3) [m]."""
        return self._evaluate(params, poses, with_jacobian=False)[0]

    def jacobian(self, params: ParameterVector, poses: Poses) -> tuple[Array, Array]:
        """Points (n, 3) [m] and d points / d parameters, shape (n, 3, P), full vector order."""
        points, jac = self._evaluate(params, poses, with_jacobian=True)
        assert jac is not None
        return points, jac

    def _evaluate(
        self, params: ParameterVector, poses: Poses, with_jacobian: bool
    ) -> tuple[Array, Array | None]:
        dh = self.dh_table(params, poses.q)
        frames = chain(dh)
        target = np.array([params[k] for k in TARGET])
        flange = frames[:, -1]
        p_in_base = flange[:, :3, :3] @ target + flange[:, :3, 3]
        b2t = self.base2tracker(params)
        rot = b2t[:3, :3]
        points = p_in_base @ rot.T + b2t[:3, 3]
        if not with_jacobian:
            return points, None

        n = len(poses)
        jac = np.zeros((n, 3, len(params)))
        deriv = point_derivatives(dh, frames, p_in_base)
        for j in range(1, self.robot.n_joints + 1):
            for field in DH_UNITS:
                name = f"{field}{j}"
                if name in params:
                    jac[:, :, params.index(name)] = getattr(deriv, field)[:, :, j - 1] @ rot.T
        for axis, name in enumerate(BASE_TRANSLATION):
            jac[:, axis, params.index(name)] = 1.0
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
            jac[:, :, params.index(name)] = np.cross(axis_vec, lever)
        flange_in_tracker = rot @ flange[:, :3, :3]  # (n, 3, 3)
        for axis, name in enumerate(TARGET):
            jac[:, :, params.index(name)] = flange_in_tracker[:, :, axis]
        return points, jac
