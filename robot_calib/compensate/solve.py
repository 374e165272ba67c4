"""Nominal joint commands -> compensated ones, batched damped least squares.

A program taught or planned on the nominal model commands readings q_cmd (n, J) and
expects the tool (the calibration's first target) where the nominal model puts it: at
T_nominal(q_cmd) in the robot base frame. The calibrated model, effects included (backlash
with the commands' approach directions, compliance, transmission error, thermal terms at
the commands' times), says where the robot really goes. The compensated commands q solve

    base2tracker * flange2base_calibrated(q) * tool  =  base2tracker * T_nominal(q_cmd)

for the tool's position and the flange's orientation (6 equations, J unknowns), by
Levenberg-Marquardt-style damped Gauss-Newton steps from q_cmd, every pose at once: the
Jacobian (n, 6, J) comes from J + 1 batched evaluations of the model per iteration.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel, target_parameters
from robot_calib.poses import Poses

MAX_ITERATIONS = 20
TOLERANCE_M = 1e-9  # stop when every pose's error is below this (position [m] and
# orientation [rad] times ORIENTATION_LEVER_M)
ORIENTATION_LEVER_M = 0.1  # an orientation error of 1 rad counts as 0.1 m of position
DAMPING = 1e-9  # least damping of the normal equations: raised x10 per rejected step
STEP_RAD = 1e-7  # finite-difference step of the readings


@dataclass(frozen=True)
class Compensation:
    """q : (n, J) compensated readings [rad]; error_m : (n,) the model's remaining
    position error at them [m]; error_rad : (n,) its orientation error [rad];
    iterations : (n,) the steps each pose took; converged : (n,) error below TOLERANCE_M."""

    q: Array
    error_m: Array
    error_rad: Array
    iterations: IntArray
    converged: np.ndarray


def _tool_poses(model: KinematicModel, params: ParameterVector, poses: Poses) -> Array:
    """(n, 4, 4): the flange's orientation and the first target's position, robot base."""
    frames = model.flange2base(params, poses)
    tool = np.array([params[k] for k in target_parameters(model.targets[0])])
    out = frames.copy()
    out[:, :3, 3] = np.einsum("nab,b->na", frames[:, :3, :3], tool) + frames[:, :3, 3]
    return out


def _error(actual: Array, goal: Array) -> Array:
    """(n, 6): position error [m] and orientation error (small-angle vector of
    goal^T actual) [rad] times ORIENTATION_LEVER_M."""
    turn = np.einsum("nba,nbc->nac", goal[:, :3, :3], actual[:, :3, :3])
    vee = 0.5 * np.stack(
        [
            turn[:, 2, 1] - turn[:, 1, 2],
            turn[:, 0, 2] - turn[:, 2, 0],
            turn[:, 1, 0] - turn[:, 0, 1],
        ],
        axis=1,
    )
    return np.hstack([actual[:, :3, 3] - goal[:, :3, 3], ORIENTATION_LEVER_M * vee])


def compensate_commands(
    calibrated: KinematicModel,
    params: ParameterVector,
    nominal: KinematicModel,
    nominal_params: ParameterVector,
    commands: Poses,
) -> Compensation:
    """The compensated readings of `commands` (readings, approach directions and times of
    the nominal program; see the module docstring). The nominal model's tool is the
    calibrated first target's nominal offset; both models in the robot base frame."""
    goal = _tool_poses(nominal, nominal_params, replace(commands, rotation=None))
    q = commands.q.copy()
    n, n_joints = q.shape
    iterations = np.zeros(n, dtype=np.int64)
    damping = np.full(n, DAMPING)  # per pose, Levenberg-Marquardt style
    error = _error(_tool_poses(calibrated, params, replace(commands, q=q)), goal)
    for _ in range(MAX_ITERATIONS):
        active = np.linalg.norm(error, axis=1) >= TOLERANCE_M
        if not active.any():
            break
        jac = np.empty((n, 6, n_joints))
        for k in range(n_joints):
            moved = q.copy()
            moved[:, k] += STEP_RAD
            shifted = _error(_tool_poses(calibrated, params, replace(commands, q=moved)), goal)
            jac[:, :, k] = (shifted - error) / STEP_RAD
        normal = np.einsum("nak,nal->nkl", jac, jac)
        normal += damping[:, None, None] * (np.eye(n_joints) + np.eye(n_joints) * normal)
        step = np.linalg.solve(normal, np.einsum("nak,na->nk", jac, error)[..., None])[..., 0]
        trial = q - step
        trial_error = _error(_tool_poses(calibrated, params, replace(commands, q=trial)), goal)
        better = active & (np.linalg.norm(trial_error, axis=1) < np.linalg.norm(error, axis=1))
        q[better], error[better] = trial[better], trial_error[better]
        damping = np.where(better, np.maximum(damping / 10.0, DAMPING), damping * 10.0)
        iterations[active] += 1
    final = _error(_tool_poses(calibrated, params, replace(commands, q=q)), goal)
    error_m = np.linalg.norm(final[:, :3], axis=1)
    error_rad = np.linalg.norm(final[:, 3:], axis=1) / ORIENTATION_LEVER_M
    converged = np.linalg.norm(final, axis=1) < max(TOLERANCE_M, 1e-8)
    return Compensation(q, error_m, error_rad, iterations, converged)


def nominal_counterpart(
    model: KinematicModel, params: ParameterVector
) -> tuple[KinematicModel, ParameterVector]:
    """The nominal model of a calibration (the robot's nominal geometry, no effects) with
    the calibration's tracker pose and target offsets: what a program taught on the nominal
    model expects, in the same frames."""
    nominal = KinematicModel(model.robot, (), model.targets, model.oriented)
    fresh = nominal.parameters()
    frames = {p.name: params[p.name] for p in fresh.parameters if p.group == "frames"}
    return nominal, fresh.with_values(frames)
