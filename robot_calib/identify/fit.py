"""Levenberg-Marquardt fit of any `KinematicModel` to measured points (absolute residuals,
tracker frame, O(N) in the number of poses), with analytic Jacobians.

residual_i = predicted target (params, pose_i) - measured point_i   [m], 3 per pose.
Before solving, parameters the data cannot identify are fixed (`identifiability`); after,
the standard deviation of every free parameter comes from the Jacobian and the residual.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from robot_calib.identify.identifiability import (
    Identifiability,
    covariance,
    describe,
    fix_poorly_determined,
    fix_unidentifiable,
)
from robot_calib.identify.objectives import AbsoluteObjective, Objective
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses

Progress = Callable[[str], None]


@dataclass(frozen=True)
class FitResult:
    """parameters: fitted vector (fixed flags and reasons included); std : (P,) 1-sigma of
    each parameter in its unit (0 for fixed), from the objective's residuals;
    residuals : (n, 3) predicted - measured points [m] (whatever the objective);
    identifiability of the free set; solver : status, message, evaluations, cost, time."""

    parameters: ParameterVector
    std: Array
    residuals: Array
    identifiability: Identifiability
    solver: dict[str, object]


BLOCK_POSES = 5000  # Jacobian evaluated in blocks: its temporaries stay in cache (linear time)


def blocked_jacobian(
    model: KinematicModel, params: ParameterVector, poses: Poses
) -> tuple[Array, Array]:
    """`model.jacobian` over `poses` in blocks of BLOCK_POSES: points (n, 3), jac (n, 3, P)."""
    n = len(poses)
    if n <= BLOCK_POSES:
        return model.jacobian(params, poses)
    points, jac = np.empty((n, 3)), np.empty((n, 3, len(params)))
    for start in range(0, n, BLOCK_POSES):
        rows = slice(start, min(start + BLOCK_POSES, n))
        points[rows], jac[rows] = model.jacobian(params, poses.subset(rows))
    return points, jac


class _Problem:
    """Residuals and Jacobian of the free parameters, evaluated once per x (LM asks for
    both at the same point)."""

    def __init__(
        self,
        model: KinematicModel,
        start: ParameterVector,
        poses: Poses,
        points: Array,
        objective: Objective,
    ) -> None:
        self.model, self.start, self.poses, self.points = model, start, poses, points
        self.objective = objective
        self._x: Array | None = None
        self._cache: tuple[Array, Array] = (np.empty(0), np.empty((0, 0)))
        self.predicted = np.empty((0, 3))
        self.evaluations = 0

    def evaluate(self, x: Array) -> tuple[Array, Array]:
        """Objective residuals (m,) and their Jacobian (m, n_free) at free values x."""
        if self._x is None or not np.array_equal(x, self._x):
            params = self.start.unpack(x)
            predicted, jac = blocked_jacobian(self.model, params, self.poses)
            self._cache = self.objective.residuals(predicted, jac[:, :, params.free], self.points)
            self.predicted = predicted
            self._x = x.copy()
            self.evaluations += 1
        return self._cache


def fit_model(
    model: KinematicModel,
    start: ParameterVector,
    poses: Poses,
    points: Array,
    progress: Progress | None = None,
    check_identifiability: bool = True,
    objective: Objective | None = None,
) -> FitResult:
    """Fit the free parameters of `start` so the model's targets at `poses` match `points`
    (n, 3) [m] in the sense of `objective` (default: absolute residuals). Unidentifiable
    parameters are fixed first (at their start values)."""
    started = time.perf_counter()
    objective = objective or AbsoluteObjective()
    params, fixed = start, ()
    if check_identifiability:
        predicted, jac = blocked_jacobian(model, start, poses)
        residual0, jac_full = objective.residuals(predicted, jac, points)
        params, ident = fix_unidentifiable(params, jac_full)
        params, weak = fix_poorly_determined(params, jac_full, residual0)
        fixed = ident.fixed + tuple(weak)
    problem = _Problem(model, params, poses, points, objective)
    last_report = [time.monotonic()]

    def fun(x: Array) -> Array:
        residual = problem.evaluate(x)[0]
        if progress and time.monotonic() - last_report[0] > 1.0:
            last_report[0] = time.monotonic()
            rms = np.sqrt(np.mean(residual**2)) * 1e3
            progress(f"  LM: {problem.evaluations} evaluations, rms {rms:.4f} mm")
        return residual

    x = params.pack()
    status, message = 0, "no free parameters"
    if len(x):
        solution = least_squares(
            fun,
            x,
            jac=lambda x: problem.evaluate(x)[1],
            method="lm",
            x_scale="jac",
            xtol=1e-12,
            ftol=1e-12,
            gtol=1e-12,
            max_nfev=100 * (len(x) + 1),
        )
        x, status, message = solution.x, int(solution.status), str(solution.message)
    residual, jac_free = problem.evaluate(x)
    fitted = params.unpack(x)
    std = np.zeros(len(fitted))
    if len(x):
        std[fitted.free] = np.sqrt(np.diag(covariance(jac_free, residual)))
    return FitResult(
        fitted,
        std,
        problem.predicted - points,
        describe(jac_free, fixed),
        {
            "method": "levenberg-marquardt (scipy least_squares, MINPACK lmder)",
            "objective": objective.name,
            "status": status,
            "message": message,
            "evaluations": problem.evaluations,
            "cost_m2": float(0.5 * residual @ residual),
            "time_s": time.perf_counter() - started,
        },
    )
