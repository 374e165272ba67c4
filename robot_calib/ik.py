"""Inverse kinematics of the forward model, batched: goal poses in, readings out.

One solver for every place that needs readings for a pose: compensation of joint commands
and of targets (`compensate`), and the simulator's plans (`sim.plans.inverse_kinematics`).
It solves, for every pose n at once,

    flange2base(q_n) * tool2flange  =  goal2base_n

with the model's effects evaluated at the poses' approach directions, times and
temperatures: the tool point's position (3 equations) and, where `oriented[n]`, the tool
frame's orientation too (3 more), by Levenberg-Marquardt steps (damped Gauss-Newton with a
per-pose damping, raised x10 when a step does not reduce the error, lowered /10 when it
does) from the seed readings `poses.q`. The Jacobian (n, 6, J) comes from J + 1 batched
evaluations of the model per iteration (finite differences: every effect's dependence on
the readings is included without each effect supplying a derivative). Poses that have
converged are no longer evaluated. A position-only goal (3 equations, J > 3 unknowns) takes
the smallest steps that reach it: the orientation stays where the seed had it, up to the
minimum-norm correction.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel, target_parameters
from robot_calib.poses import Poses

MAX_ITERATIONS = 20
TOLERANCE_M = 1e-9  # stop when a pose's error is below this (position [m] and
# orientation [rad] times ORIENTATION_LEVER_M)
CONVERGED_M = 1e-8  # a pose whose final error is below this (or the tolerance) converged
ORIENTATION_LEVER_M = 0.1  # an orientation error of 1 rad counts as 0.1 m of position
DAMPING = 1e-9  # least damping of the normal equations: raised x10 per rejected step
STEP_RAD = 1e-7  # finite-difference step of the readings


@dataclass(frozen=True)
class IKSolution:
    """Readings that reach the goals, and how well.

    q : shape (n, J), the readings found [rad]
    error_m : shape (n,), the model's remaining position error of the tool point there [m]
    error_rad : shape (n,), its remaining orientation error [rad] (0 for position-only goals)
    iterations : shape (n,), the Levenberg-Marquardt steps each pose took (accepted or not)
    converged : shape (n,) bool, error (position + lever x orientation) below
        max(tolerance, CONVERGED_M)
    position_only : shape (n,) bool, rows solved for the tool position alone although an
        orientation was asked (compensate: near a singularity; error_rad is then the
        orientation left), None: none
    """

    q: Array
    error_m: Array
    error_rad: Array
    iterations: IntArray
    converged: NDArray[np.bool_]
    position_only: NDArray[np.bool_] | None = None


def first_tool2flange(model: KinematicModel, params: ParameterVector) -> Array:
    """The tool frame of a calibration in the flange frame (DH frame J), shape (4, 4): the
    first target's offset [m] as its origin, its probe frame's orientation where the
    calibration has one (msgs_doc/six_dof.md), the flange's otherwise."""
    name = model.targets[0]
    out = np.eye(4)
    out[:3, 3] = [params[k] for k in target_parameters(name)]
    out[:3, :3] = model.tool_rotations(params)[0]  # identity without a probe frame
    return out


def tool2base(
    model: KinematicModel, params: ParameterVector, poses: Poses, tool2flange: Array
) -> Array:
    """The tool frame at `poses` in the robot base frame, effects included, shape (n, 4, 4);
    tool2flange : shape (4, 4), the tool frame in the flange frame [m]."""
    return model.flange2base(params, poses) @ tool2flange


def pose_error(actual2base: Array, goal2base: Array) -> Array:
    """(n, 6): position error [m] and orientation error (the rotation vector of
    goal^T actual: its angle [rad] about its axis, up to pi) times ORIENTATION_LEVER_M, of
    tool frames actual2base and goal2base (n, 4, 4) in the robot base frame. The rotation
    vector, not the small-angle vector of the antisymmetric part: that one is zero at a
    half turn, where the solver stopped and called a tool pointing the opposite way
    reached (0 urad). Formed from that small-angle vector (its length is sin(angle)):
    scipy's Rotation.as_rotvec agrees to 1e-11 but takes 2.5-4 x as long in the solver's
    loop (3000 poses: 4.3 vs 1.1 ms); it is used only within 1e-6 of a half turn, where
    the axis must come from the symmetric part."""
    turn = np.einsum("nba,nbc->nac", goal2base[:, :3, :3], actual2base[:, :3, :3])
    vee = 0.5 * np.stack(
        [
            turn[:, 2, 1] - turn[:, 1, 2],
            turn[:, 0, 2] - turn[:, 2, 0],
            turn[:, 1, 0] - turn[:, 0, 1],
        ],
        axis=1,
    )  # sin(angle) x axis
    sine = np.linalg.norm(vee, axis=1)
    cosine = 0.5 * (np.trace(turn, axis1=1, axis2=2) - 1.0)
    angle = np.arctan2(sine, cosine)
    vector = vee * np.where(sine > 1e-12, angle / np.maximum(sine, 1e-12), 1.0)[:, None]
    near_half_turn = (cosine < 0.0) & (sine < 1e-6)  # the axis from the symmetric part
    if near_half_turn.any():
        from scipy.spatial.transform import Rotation

        vector[near_half_turn] = Rotation.from_matrix(turn[near_half_turn]).as_rotvec()
    return np.hstack([actual2base[:, :3, 3] - goal2base[:, :3, 3], ORIENTATION_LEVER_M * vector])


def solve_ik(
    model: KinematicModel,
    params: ParameterVector,
    poses: Poses,
    goal2base: Array,
    tool2flange: Array,
    oriented: NDArray[np.bool_] | None = None,
    *,
    tolerance_m: float = TOLERANCE_M,
    max_iterations: int = MAX_ITERATIONS,
) -> IKSolution:
    """Readings that put the tool frame at the goals (see the module docstring).

    Parameters
    ----------
    model, params : the forward model and its parameters (effects included)
    poses : the seeds: q (n, J) [rad], and the approach directions, times and temperatures
        at which the effects are evaluated (kept as given)
    goal2base : shape (n, 4, 4), the goal tool frames in the robot base frame [m]
    tool2flange : shape (4, 4), the tool frame in the flange frame [m]
    oriented : shape (n,) bool, which goals prescribe the orientation (None: all); the
        others prescribe the tool point's position only
    tolerance_m : a pose stops once its error (position [m] + ORIENTATION_LEVER_M x
        orientation [rad]) is below this
    max_iterations : steps at most per pose
    """
    n, n_joints = poses.q.shape
    weight = np.ones((n, 6))
    if oriented is not None:
        weight[~np.asarray(oriented, dtype=bool), 3:] = 0.0

    def errors(index: IntArray, q: Array) -> Array:
        at = replace(poses.subset(index), q=q)
        return weight[index] * pose_error(
            tool2base(model, params, at, tool2flange), goal2base[index]
        )

    q = poses.q.astype(float, copy=True)
    iterations = np.zeros(n, dtype=np.int64)
    damping = np.full(n, DAMPING)  # per pose, Levenberg-Marquardt style
    everyone = np.arange(n)
    error = errors(everyone, q)
    for _ in range(max_iterations):
        active = np.flatnonzero(np.linalg.norm(error, axis=1) >= tolerance_m)
        if not active.size:
            break
        q_a, error_a = q[active], error[active]
        # every joint's step in one batch (J x m poses: one forward model call, not J)
        moved = np.repeat(q_a[None], n_joints, axis=0)  # (J, m, J): joint k stepped in [k]
        moved[np.arange(n_joints), :, np.arange(n_joints)] += STEP_RAD
        stepped = errors(np.tile(active, n_joints), moved.reshape(-1, n_joints))
        jac = ((stepped.reshape(n_joints, active.size, 6) - error_a) / STEP_RAD).transpose(1, 2, 0)
        normal = np.einsum("nak,nal->nkl", jac, jac)
        eye = np.eye(n_joints)
        normal += damping[active, None, None] * (eye + eye * normal)
        gradient = np.einsum("nak,na->nk", jac, error_a)
        trial = q_a - np.linalg.solve(normal, gradient[..., None])[..., 0]
        trial_error = errors(active, trial)
        better = np.linalg.norm(trial_error, axis=1) < np.linalg.norm(error_a, axis=1)
        q[active[better]], error[active[better]] = trial[better], trial_error[better]
        damping[active] = np.where(
            better, np.maximum(damping[active] / 10.0, DAMPING), damping[active] * 10.0
        )
        iterations[active] += 1
    error_m = np.linalg.norm(error[:, :3], axis=1)
    error_rad = np.linalg.norm(error[:, 3:], axis=1) / ORIENTATION_LEVER_M
    converged = np.linalg.norm(error, axis=1) < max(tolerance_m, CONVERGED_M)
    return IKSolution(q, error_m, error_rad, iterations, converged)
