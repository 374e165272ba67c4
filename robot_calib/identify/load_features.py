"""The load features and the design matrix of the hybrid correction's structured part
(`identify.correction_structured`, whose docstring gives the model): the gravity loads of
every link frame (`frame_loads`), their features g_jf (`FEATURES`: 1, the moment, a unit
payload's moments, steps of the joint's torque), the displacement of the measured point per
small motion of each frame (`point_motions`), and the columns they make (`structured_design`),
computed BLOCK_POSES poses at a time (`pose_blocks`).
"""

from __future__ import annotations

import numpy as np

from robot_calib.effects.compliance import GRAVITY
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses

#: the steps' widths tau_k: shares of the largest rms gravity torque of a joint over the
#: fitted poses, the same for every joint (a UR10: about 1, 3 and 10 N m)
STEP_SHARES = (0.01, 0.03, 0.1)
#: a frame whose torque rms is below this [N m] gets steps of this width (a vertical axis:
#: M_z = 0 everywhere, the steps are zero columns)
MIN_TAU_NM = 1e-6
FEATURES = (
    "1",
    "M_x",
    "M_y",
    "M_z",
    "P_x",
    "P_y",
    "P_z",
    *(f"C{a}_{b}" for a in "xyz" for b in "xyz"),
    *(f"step{k + 1}" for k in range(len(STEP_SHARES))),
)
MOTIONS = ("x", "y", "z", "rx", "ry", "rz")
BLOCK_POSES = 2000  # poses per block of the design matrix (a block: 3 x 2000 x ~300 x 8 B)


def frame_loads(robot: RobotDescription, q: Array) -> Array:
    """(n, J, 6): of every frame j = 0..J-1 (the housing of joint j + 1), in frame j, M
    [N m] the gravity moment about its origin of the links beyond it (links j + 1..J, the
    robot's mass model), then P [N m / kg] that of a unit mass at the flange's origin: a
    payload or tool the mass model does not know (its mass unknown) loads every frame as a
    multiple of P. Nominal kinematics of readings q (n, J) [rad]."""
    frames = robot.nominal_frames(q)
    com = np.einsum("njab,jb->nja", frames[:, 1:, :3, :3], robot.link_com) + frames[:, 1:, :3, 3]
    force = robot.link_mass[:, None] * GRAVITY  # (J, 3) base frame
    n, n_joints = q.shape
    flange, flange_axes = frames[:, -1, :3, 3], frames[:, -1, :3, :3]
    weight = np.broadcast_to(GRAVITY, flange.shape)
    # a unit first moment along each flange axis: x R6 e_a g (the payload's centre off the
    # flange, times its mass), the same about every frame's origin
    first = [np.cross(flange_axes[:, :, a], weight) for a in range(3)]
    out = np.zeros((n, n_joints, 15))
    for j in range(n_joints):
        origin, axes = frames[:, j, None, :3, 3], frames[:, j, :3, :3]
        moment = np.cross(com[:, j:] - origin, force[j:]).sum(axis=1)
        unit = np.cross(flange - origin[:, 0], weight)
        for k, vector in enumerate([moment, unit, *first]):
            out[:, j, 3 * k : 3 * k + 3] = np.einsum("nab,na->nb", axes, vector)
    return out


def load_features(loads: Array, step_tau: Array) -> Array:
    """(n, J, F) load features (`FEATURES`) of loads (n, J, 6) (`frame_loads`), steps tau
    (J, K) [N m]."""
    n, n_joints, _ = loads.shape
    steps = np.tanh(loads[:, :, 2:3] / step_tau[None])  # (n, J, K)
    return np.concatenate([np.ones((n, n_joints, 1)), loads, steps], axis=2)


def point_motions(model: KinematicModel, params: ParameterVector, poses: Poses) -> Array:
    """(n, 3, J, 6): the tracker-frame displacement of each measured point per unit motion
    (MOTIONS: [m] translations, [rad] rotations) of each frame j = 0..J-1, in frame j."""
    frames = model.link_frames(params, poses)
    b2t = model.base2tracker(params)
    rot = b2t[:3, :3]
    point = (model.target_points(params, poses) - b2t[:3, 3]) @ rot  # base frame
    n, n_joints = poses.q.shape
    out = np.empty((n, 3, n_joints, 6))
    for j in range(n_joints):
        axes = frames[:, j, :3, :3]
        lever = point - frames[:, j, :3, 3]
        for a in range(3):
            out[:, :, j, a] = axes[:, :, a] @ rot.T
            out[:, :, j, 3 + a] = np.cross(axes[:, :, a], lever) @ rot.T
    return out


def structured_design(
    model: KinematicModel,
    params: ParameterVector,
    columns: tuple[str, ...],
    step_tau: Array,
    poses: Poses,
) -> Array:
    """(n, 3, P) the structured columns at `poses`: J x 6 x F load-driven motions, then the
    model's Jacobian columns `columns`."""
    n = len(poses)
    features = load_features(frame_loads(model.robot, poses.q), step_tau)  # (n, J, F)
    motions = point_motions(model, params, poses)  # (n, 3, J, 6)
    loaded = np.einsum("najm,njf->najmf", motions, features).reshape(n, 3, -1)
    if not columns:
        return loaded
    _, jac = model.jacobian(params, poses)
    return np.concatenate([loaded, jac[:, :, [params.index(c) for c in columns]]], axis=2)


def pose_blocks(n: int) -> list[slice]:
    return [slice(s, min(s + BLOCK_POSES, n)) for s in range(0, n, BLOCK_POSES)]
