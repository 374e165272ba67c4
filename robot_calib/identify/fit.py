"""Levenberg-Marquardt fit of any `KinematicModel` to measured points (absolute residuals,
tracker frame, O(N) in the number of poses), with analytic Jacobians.

Why one module: one Levenberg-Marquardt fit. The weighted residuals and their Jacobian
(`_Problem`, half the module), the solver loop (`_solve`) and `fit_model` (which fixes what
the data cannot identify before solving and reads the covariance after) all work on the same
weighted rows (`weighted_rows`, `PRIOR_ROW`, which the ladder reuses).

residual_i = predicted target (params, pose_i) - measured point_i   [m], 3 per pose,
plus, for a 6-DoF probe's measurement, the rotation vector of predicted * measured
orientation [rad], 3 more; all weighted by the stated accuracies (`identify.weights`).
Before solving, parameters the data cannot identify are fixed (`identifiability`); after,
the standard deviation of every free parameter comes from the Jacobian and the residual.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError
from robot_calib.identify.identifiability import (
    Identifiability,
    covariance,
    describe,
    fix_poorly_determined,
    fix_unidentifiable,
)
from robot_calib.identify.objectives import AbsoluteObjective, Objective
from robot_calib.identify.prior import prior_sigmas
from robot_calib.identify.reports import SolverReport
from robot_calib.identify.weights import orientation_errors, row_weights
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.log import Log
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses


@dataclass(frozen=True)
class FitResult:
    """parameters: fitted vector (fixed flags and reasons included); std : (P,) 1-sigma of
    each parameter in its unit (0 for fixed), from the objective's residuals;
    residuals : (n, 3) predicted - measured points [m] (whatever the objective);
    identifiability of the free set; solver : scipy's whole result and our timing;
    orientation_residuals : (n, 3) rotation vectors of predicted * measured orientation
    [rad], tracker frame, NaN where no orientation was fitted (None: none at all)."""

    parameters: ParameterVector
    std: Array
    residuals: Array
    identifiability: Identifiability
    solver: SolverReport
    orientation_residuals: Array | None = None


@dataclass(frozen=True)
class _Solved:
    """What one solver run left: free values x and scipy's status, message, counts."""

    x: Array
    status: int
    message: str
    nfev: int
    njev: int
    optimality: float


def _solve(
    problem: _Problem,
    x0: Array,
    progress: Log | None,
    robust_scale: float | None,
    rough: bool = False,
) -> _Solved:
    """Minimise the problem's residuals from x0: Levenberg-Marquardt for least squares
    (MINPACK: fast and exact for small dense problems), or trust-region reflective with a
    soft-L1 loss of `robust_scale` [m] (LM supports no robust loss). x_scale='jac': the
    parameters mix metres and radians, the Jacobian's columns give their natural scales.
    scipy.optimize is imported here, at the first fit: importing it costs 0.5 s, which a
    process that only reads calibrations (the report helpers, predict, export) saves."""
    from scipy.optimize import least_squares

    if not len(x0):
        return _Solved(x0, 0, "no free parameters", 0, 0, 0.0)
    last_report = [time.monotonic()]

    def fun(x: Array) -> Array:
        residual = problem.evaluate(x)[0]
        if progress and time.monotonic() - last_report[0] > 1.0:
            last_report[0] = time.monotonic()
            rms = problem.data_rms(x) * 1e3
            progress(f"  LM: {problem.evaluations} evaluations, rms {rms:.4f} mm")
        return residual

    def jac(x: Array) -> Array:
        return problem.evaluate(x)[1]

    if robust_scale is None:
        tol = ROUGH_TOLERANCE if rough else 1e-12
        solution = least_squares(
            fun,
            x0,
            jac=jac,
            method="lm",
            x_scale="jac",
            xtol=tol,
            ftol=tol,
            gtol=tol,
            max_nfev=min(100 * (len(x0) + 1), MAX_EVALUATIONS),
        )
    else:
        solution = least_squares(
            fun,
            x0,
            jac=jac,
            method="trf",
            loss="soft_l1",
            f_scale=robust_scale,
            x_scale="jac",
            xtol=1e-10,
            ftol=1e-10,
            gtol=1e-10,
            max_nfev=50 * (len(x0) + 1),
        )
    return _Solved(
        solution.x,
        int(solution.status),
        str(solution.message),
        int(solution.nfev),
        int(solution.njev or 0),
        float(solution.optimality),
    )


#: model evaluations a Levenberg-Marquardt solve may make: a well-posed fit converges in a
#: few tens; one that needs hundreds is crawling along a flat valley (then the prior and the
#: never-worse-than-the-start guard decide, not more evaluations)
MAX_EVALUATIONS = 200
ROUGH_TOLERANCE = 1e-6  # relative cost/step change: enough to judge identifiability at
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


def fitted_orientations(model: KinematicModel, poses: Poses) -> NDArray[np.bool_]:
    """(n,) the measurements whose orientation `model` predicts: measured by a 6-DoF probe
    at a target of the model's `oriented`."""
    which = [model.targets.index(t) for t in model.oriented]
    return poses.oriented & np.isin(poses.target_index, which)


def orientation_residuals(
    model: KinematicModel, params: ParameterVector, poses: Poses
) -> Array | None:
    """(n, 3) rotation vectors of predicted * measured orientation [rad] of the 6-DoF
    measurements of `model`'s oriented targets, NaN elsewhere; None when there are none."""
    rows = fitted_orientations(model, poses)
    if not rows.any() or poses.rotation is None:
        return None
    out = np.full((len(poses), 3), np.nan)
    sub = poses.subset(rows)
    assert sub.rotation is not None
    out[rows] = orientation_errors(model.probe_orientations(params, sub), sub.rotation)
    return out


class _Problem:
    """Residuals and Jacobian of the free parameters, evaluated once per x (LM asks for
    both at the same point).

    With the absolute objective (3 rows per pose, then 3 per 6-DoF orientation, weighted
    by `identify.weights`) the Jacobian is written block by block (BLOCK_POSES poses) into
    one C-ordered (3n + 3m, n_free) array, reused at every x: no (n, 3, P) array and no
    copy of the free columns. scipy copies what it is given (its VectorFunction returns
    J.astype(...), MINPACK copies into its own fjac), so the buffer may be overwritten at
    the next x. C order: MINPACK would first copy a Fortran array into C order. Other
    objectives (rows from pairs of poses) get the full (n, 3, P), unweighted and without
    orientations.
    """

    def __init__(
        self,
        model: KinematicModel,
        start: ParameterVector,
        poses: Poses,
        points: Array,
        objective: Objective,
        fallback: tuple[float, float] | None = None,
        prior_reference: float | None = None,
        compressed: bool = False,
    ) -> None:
        self.model, self.start, self.poses, self.points = model, start, poses, points
        self.objective, self.fallback = objective, fallback
        self._x: Array | None = None
        self._cache: tuple[Array, Array] = (np.empty(0), np.empty((0, 0)))
        self.predicted = np.empty((0, 3))
        self.evaluations = 0
        self._jac: Array | None = None  # (3n + 3m, n_free) buffer of the blocked path
        self.weights = row_weights(poses, fitted_orientations(model, poses), fallback)
        self.rows6 = np.zeros(0, dtype=np.int64)  # measurements with an orientation row
        self.orientation_error = np.zeros((0, 3))  # (m, 3) [rad] at the last x
        # the weak prior (`identify.prior`): one row per free parameter that has one
        sigma = prior_sigmas(start)[start.free]
        self.prior_cols = np.flatnonzero(np.isfinite(sigma))
        stated = float(np.median(self.weights.sigma[:, 0])) if len(poses) else 1e-5
        self.prior_reference = max(stated, prior_reference or 0.0)
        self.prior_weight = self.prior_reference / sigma[self.prior_cols]
        self.prior_nominal = start.nominal[start.free][self.prior_cols]
        self._costs: dict[bytes, float] = {}  # sum of squares at every x evaluated
        self.n_data = objective.n_rows(len(points))
        # compressed: the rows reduced block by block to R of [J | r] (`_compress`)
        self.compressed = compressed and type(objective) is AbsoluteObjective
        self._data_r = np.zeros((0, 0))  # R of the data's [J | r] at the last x (compressed)
        self._data_ss = 0.0  # the data's sum of squares at the last x [m^2]
        if type(objective) is AbsoluteObjective:  # not a subclass with other residuals
            self.rows6 = np.flatnonzero(self.weights.oriented)
            self.n_data = 3 * (len(poses) + len(self.rows6))
            if not self.compressed:
                self._jac = np.zeros((self.n_data + len(self.prior_cols), int(start.free.sum())))

    def evaluate(self, x: Array) -> tuple[Array, Array]:
        """Objective residuals (m,) [m] and their Jacobian (m, n_free) at free values x,
        the prior's rows last (the data's are the first `n_data`). The Jacobian array is
        reused: valid until evaluate is called at another x."""
        if self._x is None or not np.array_equal(x, self._x):
            params = self.start.unpack(x)
            prior = self.prior_weight * (x[self.prior_cols] - self.prior_nominal)
            if self.compressed:
                self._cache = self._compress(params, prior)
            elif self._jac is None:
                predicted, jac = blocked_jacobian(self.model, params, self.poses)
                residual, data_jac = self.objective.residuals(
                    predicted, jac[:, :, params.free], self.points
                )
                prior_jac = np.zeros((len(prior), len(x)))
                prior_jac[np.arange(len(prior)), self.prior_cols] = self.prior_weight
                self._cache = (np.concatenate([residual, prior]), np.vstack([data_jac, prior_jac]))
            else:
                predicted, residual = self._weighted(params, self._jac[: self.n_data])
                rows = self.n_data + np.arange(len(prior))
                self._jac[rows, self.prior_cols] = self.prior_weight  # the rest stays 0
                self._cache = (np.concatenate([residual, prior]), self._jac)
            if not self.compressed:
                self.predicted = predicted
                self._data_ss = float(
                    self._cache[0][: self.n_data] @ self._cache[0][: self.n_data]
                )
            self._x = x.copy()
            self.evaluations += 1
            self._costs[x.tobytes()] = float(self._cache[0] @ self._cache[0])
        return self._cache

    def cost(self, x: Array) -> float:
        """Sum of squared residuals (the prior's rows included) at free values x [m^2]: from
        the evaluations already made at x when there is one (no new Jacobian)."""
        if x.tobytes() not in self._costs:
            self.evaluate(x)
        return self._costs[x.tobytes()]

    def set_prior_reference(self, reference: float) -> None:
        """Take `reference` [m] as the prior's unit (`identify.prior`); the residuals and
        Jacobian of the last evaluation are updated in place, not evaluated again (only
        the prior's rows change)."""
        self.prior_reference = reference
        self.prior_weight = reference / prior_sigmas(self.start)[self.start.free][self.prior_cols]
        self._costs.clear()
        if self._x is None:
            return
        if self.compressed:
            prior = self.prior_weight * (self._x[self.prior_cols] - self.prior_nominal)
            self._cache = self._with_prior(prior)
            self._costs[self._x.tobytes()] = float(self._cache[0] @ self._cache[0])
            return
        residual, jac = self._cache
        rows = self.n_data + np.arange(len(self.prior_cols))
        residual[rows] = self.prior_weight * (self._x[self.prior_cols] - self.prior_nominal)
        jac[rows, self.prior_cols] = self.prior_weight
        self._costs[self._x.tobytes()] = float(residual @ residual)

    def data_rms(self, x: Array) -> float:
        """rms of the data's (weighted) residuals at free values x [m], the prior's rows left
        out."""
        self.evaluate(x)
        return float(np.sqrt(self._data_ss / max(self.n_data, 1)))

    def data_rows(self, x: Array) -> tuple[Array, Array, int]:
        """The data's rows at free values x, the prior's left out: residuals (k,) [m] and
        their Jacobian (k, n_free), and the number of data rows m. Uncompressed k = m, the
        rows themselves (the Jacobian valid until the next evaluation); compressed k = n_free
        + 1, the R of [J | r] (the same J^T J, J^T r and r^T r: what the identifiability
        analysis and the covariance use, with `rows` m)."""
        residual, jac = self.evaluate(x)
        if not self.compressed:
            return residual[: self.n_data], jac[: self.n_data], self.n_data
        r = self._data_r
        return r[:, -1].copy(), r[:, :-1].copy(), self.n_data

    def _compress(self, params: ParameterVector, prior: Array) -> tuple[Array, Array]:
        """The compressed rows at `params` (`compressed`): the data's rows (weighted, 6-DoF
        orientation rows included) computed BLOCK_POSES poses at a time and each block
        folded into R of [J | r] by a QR of [R so far; block] (a tall-skinny QR), then the
        prior's rows `prior` (k,). Returns f (n_free + 1,) and its Jacobian (n_free + 1,
        n_free): Q^T r and R of the whole [J | r] = Q [R_J  f] (R_J's last row zero), so
        that |f| = |r|, f's Jacobian^T f = J^T r and its Gram matrix J^T J at every x:
        Levenberg-Marquardt (MINPACK) on them takes the steps it takes on the rows, while
        memory stays O(block x n_free) whatever the number of poses."""
        n, w = len(self.poses), self.weights
        free = params.free
        n_free = int(free.sum())
        r = np.zeros((0, n_free + 1))
        predicted = np.empty((n, 3))
        ss = 0.0

        def fold(r: Array, jac: Array, residual: Array) -> Array:
            block = np.empty((len(r) + len(residual), n_free + 1), order="F")
            block[: len(r)] = r
            block[len(r) :, :-1] = jac
            block[len(r) :, -1] = residual
            return cast(Array, np.linalg.qr(block, mode="r"))

        columns = np.flatnonzero(free)
        for start in range(0, n, BLOCK_POSES):
            rows = slice(start, min(start + BLOCK_POSES, n))
            block = self.poses if n <= BLOCK_POSES else self.poses.subset(rows)
            points, jac_t = self.model.jacobian_columns(params, block, columns)  # (F, m, 3)
            predicted[rows] = points
            weight = w.position[rows]
            residual = ((points - self.points[rows]) * weight[:, None]).reshape(-1)
            if not w.uniform:
                jac_t *= weight[None, :, None]
            ss += float(residual @ residual)
            # (F, 3m) rows are the F-ordered block's columns: contiguous copies
            r = fold(r, jac_t.reshape(n_free, len(residual)).T, residual)
        for start in range(0, len(self.rows6), BLOCK_POSES):
            which = self.rows6[start : start + BLOCK_POSES]
            sub = self.poses.subset(which)
            assert sub.rotation is not None
            frames, omega = self.model.orientation_jacobian(params, sub)
            error = orientation_errors(frames, sub.rotation)
            self.orientation_error = (
                error if start == 0 else np.concatenate([self.orientation_error, error])
            )
            factor = w.orientation[which]
            residual = (error * factor[:, None]).reshape(-1)
            jac = (omega[:, :, free] * factor[:, None, None]).reshape(len(residual), n_free)
            ss += float(residual @ residual)
            r = fold(r, jac, residual)
        self.predicted, self._data_ss, self._data_r = predicted, ss, r
        return self._with_prior(prior)

    def _with_prior(self, prior: Array) -> tuple[Array, Array]:
        """f and its Jacobian (`_compress`) of the data's R at the last x and the prior's
        rows `prior` (k,) [m]."""
        n_free = self._data_r.shape[1] - 1
        rows = np.zeros((len(prior), n_free + 1))
        rows[np.arange(len(prior)), self.prior_cols] = self.prior_weight
        rows[:, -1] = prior
        stacked = np.vstack([self._data_r, rows])
        r = stacked if len(stacked) <= n_free + 1 else np.linalg.qr(stacked, mode="r")
        out = np.zeros((n_free + 1, n_free + 1))  # MINPACK needs rows >= columns
        out[: len(r)] = r
        return out[:, -1].copy(), out[:, :-1].copy()

    def _weighted(self, params: ParameterVector, out: Array) -> tuple[Array, Array]:
        """Points (n, 3) [m] and the weighted residuals (3n + 3m,); their Jacobian written
        into `out` (3n + 3m, n_free)."""
        n, w = len(self.poses), self.weights
        predicted = self._free_jacobian(params, out[: 3 * n])
        residual = ((predicted - self.points) * w.position[:, None]).reshape(-1)
        if not w.uniform:
            out[: 3 * n] *= np.repeat(w.position, 3)[:, None]
        if not len(self.rows6):
            return predicted, residual
        sub = self.poses.subset(self.rows6)
        assert sub.rotation is not None
        frames, omega = self.model.orientation_jacobian(params, sub)
        self.orientation_error = orientation_errors(frames, sub.rotation)
        factor = w.orientation[self.rows6]
        rows = (omega[:, :, params.free] * factor[:, None, None]).reshape(3 * len(self.rows6), -1)
        out[3 * n :] = rows  # (no free parameter: an empty (3m, 0) block)
        rotation_rows = (self.orientation_error * factor[:, None]).reshape(-1)
        return predicted, np.concatenate([residual, rotation_rows])

    def residual_sigmas(self, x: Array) -> tuple[float, float] | None:
        """Standard deviations (position per coordinate [m], orientation per axis [rad]) of
        the unweighted residuals at x, when orientations are fitted and some accuracy was
        not stated (the weights then rest on the data: one variance component per kind);
        None otherwise, or when already reweighted."""
        stated = self.weights.stated
        if not len(self.rows6) or self.fallback is not None or stated.all():
            return None
        self.evaluate(x)
        position = float(np.sqrt(np.mean((self.predicted - self.points) ** 2)))
        orientation = float(np.sqrt(np.mean(self.orientation_error**2)))
        if not (position > 0 and orientation > 0):
            return None
        return position, orientation

    def reweighted(
        self, fallback: tuple[float, float] | None, start: ParameterVector | None = None
    ) -> _Problem:
        """The same problem (from `start`, default the same) with accuracies not stated
        taken as `fallback` (position [m], orientation [rad]); evaluations carried on."""
        out = _Problem(
            self.model,
            start or self.start,
            self.poses,
            self.points,
            self.objective,
            fallback,
            self.prior_reference,
            self.compressed,
        )
        out.evaluations = self.evaluations
        return out

    def orientation_residuals(self) -> Array | None:
        """(n, 3) [rad] at the last x, NaN where no orientation is fitted (None: none)."""
        if not len(self.rows6):
            return None
        out = np.full((len(self.poses), 3), np.nan)
        out[self.rows6] = self.orientation_error
        return out

    def _free_jacobian(self, params: ParameterVector, out: Array) -> Array:
        """Points (n, 3) [m]; d points / d free parameters written into `out` (3n, n_free),
        rows 3i..3i+2 for pose i, BLOCK_POSES poses at a time."""
        n = len(self.poses)
        free = np.flatnonzero(params.free)
        jac = out.reshape(n, 3, len(free))  # a view: out is C-contiguous
        points = np.empty((n, 3))
        for start in range(0, n, BLOCK_POSES):
            rows = slice(start, min(start + BLOCK_POSES, n))
            block = self.poses if n <= BLOCK_POSES else self.poses.subset(rows)
            points[rows], block_jac = self.model.jacobian(params, block)
            jac[rows] = block_jac[:, :, free]
        return points


def weighted_jacobian(
    model: KinematicModel,
    params: ParameterVector,
    poses: Poses,
    points: Array,
    objective: Objective | None = None,
) -> tuple[Array, Array, int]:
    """The objective's rows as the fit sees them (6-DoF orientation rows and the stated
    accuracies' weights included) at `params`, with respect to every parameter (free or
    not, vector order), in the form the identifiability analysis and the covariance take:
    residuals (k,) [m], their Jacobian (k, P) and the number of rows m. For the absolute
    objective the R of [J | r] (k = P + 1: the same J^T J, J^T r, r^T r, memory O(P^2)
    whatever m), else the rows themselves (k = m)."""
    every = params.freed(params.names)
    problem = _Problem(
        model, every, poses, points, objective or AbsoluteObjective(), compressed=True
    )
    residual, jac, rows = problem.data_rows(every.pack())
    return residual.copy(), jac.copy(), rows


#: poses the structural identifiability check looks at (a fixed random subset above): exact
#: redundancy is a property of the model's structure, which 20k random poses show as well
#: as 100k (the check's compressed Jacobian of every parameter costs a fit's evaluation)
STRUCTURE_POSES = 20_000
#: `weighted_rows`' owner of the weak prior's rows (they belong to no measurement)
PRIOR_ROW = -1


def weighted_rows(
    model: KinematicModel, params: ParameterVector, poses: Poses, points: Array
) -> tuple[Array, Array, Array]:
    """The rows as the absolute fit sees them at `params` (stated accuracies' weights and
    6-DoF orientation rows included), then the weak prior's rows, its unit the rms of the
    data's rows here (the scatter the solution leaves): residuals (m,) [m], their
    Jacobian (m, n_free) with respect to the free parameters, and the measurement each row
    belongs to (m,) (index into `poses`; PRIOR_ROW for the prior's)."""
    problem = _Problem(model, params, poses, points, AbsoluteObjective())
    x = params.pack()
    data = problem.evaluate(x)[0][: problem.n_data]
    problem.set_prior_reference(float(np.sqrt(np.mean(data**2))) if len(data) else 0.0)
    residual, jac = problem.evaluate(x)
    owner = np.concatenate(
        [
            np.repeat(np.arange(len(poses)), 3),
            np.repeat(problem.rows6, 3),
            np.full(len(problem.prior_cols), PRIOR_ROW),
        ]
    )
    # the problem's own arrays, not copies: it ends here, so nothing evaluates it again (a
    # copy doubled the peak: 2 x 120 MB at 100k poses)
    return residual, jac, owner


def _structurally_identifiable(
    model: KinematicModel,
    start: ParameterVector,
    poses: Poses,
    points: Array,
    objective: Objective,
) -> tuple[ParameterVector, tuple[tuple[str, str], ...]]:
    """`start` with the parameters the data cannot identify at all (exact redundancy, a
    property of the Jacobian's structure that no start changes) fixed, and (name, reason)
    of each. Its own function so that the full Jacobian at the start, (n, 3, P), is freed
    before the solver allocates its own."""
    if len(poses) > STRUCTURE_POSES:  # a structure: a fixed random subset shows it
        keep = np.sort(np.random.default_rng(0).choice(len(poses), STRUCTURE_POSES, False))
        poses, points = poses.subset(keep), points[keep]
    _, jac_full, rows = weighted_jacobian(model, start, poses, points, objective)
    params, ident = fix_unidentifiable(start, jac_full, rows=rows)
    return params, ident.fixed


def check_enough_data(
    n_residuals: int, n_points: int, n_free: int, what: str = "measurements"
) -> None:
    """InputError unless the residuals outnumber the free parameters: fewer would leave
    the fit undetermined (and its 1-sigma meaningless). Names how many `what` (3 residuals
    each) are needed."""
    if n_residuals <= n_free:
        needed = n_free // 3 + 1
        raise InputError(
            f"{n_points} {what} ({n_residuals} residuals) cannot determine "
            f"{n_free} free parameters: at least {needed} {what} are needed"
        )


def fit_model(
    model: KinematicModel,
    start: ParameterVector,
    poses: Poses,
    points: Array,
    progress: Log | None = None,
    check_identifiability: bool = True,
    objective: Objective | None = None,
    robust_scale: float | None = None,
    statistics: bool = True,
) -> FitResult:
    """Fit the free parameters of `start` so the model's targets at `poses` match `points`
    (n, 3) [m] in the sense of `objective` (default: absolute residuals). Parameters the
    data cannot identify are fixed: exact redundancies before solving, poorly determined
    ones (1-sigma beyond bounds) judged at the converged point, never at the start, then
    fixed at their start values and the fit repeated. InputError when the residuals do
    not outnumber the free parameters.

    robust_scale : None for least squares (Levenberg-Marquardt); else a soft-L1 loss of
        that scale [m] per residual component (trust-region reflective), which blunders
        barely pull: used to screen outliers (`identify.outliers`), not for the result.
    statistics : False to skip the 1-sigma and the identifiability figures (std all 0,
        condition number and observability NaN): refits whose parameters alone are used
        (k-fold scoring).

    Returns
    -------
    result : FitResult
        The fit, with the following fields:

        parameters : ParameterVector
            `start` with the P fitted values in SI units, and the parameters fixed as
            unidentifiable (free flag off, reason recorded).
        std : ndarray, shape (P,)
            1-sigma of each parameter in its unit, from the objective's residuals and
            Jacobian; 0 for fixed parameters.
        residuals : ndarray, shape (n, 3)
            Predicted - measured points at the solution, tracker frame [m] (whatever the
            objective).
        identifiability : Identifiability
            Condition number and observability index of the free parameters' Jacobian,
            and the (name, reason) of each parameter fixed.
        solver : SolverReport
            scipy `least_squares`'s status, message, success, nfev, njev, optimality,
            cost_m2 (half the sum of squared residuals) [m^2], plus our evaluation count
            and wall time [s]. Without free parameters no solver runs: status 0, message
            'no free parameters'.
    """
    started = time.perf_counter()
    goal: Objective = objective or AbsoluteObjective()
    n_rows = goal.n_rows(len(points))
    check_enough_data(n_rows, len(points), int(start.free.sum()))
    params: ParameterVector = start
    fixed: tuple[tuple[str, str], ...] = ()
    if check_identifiability:
        params, fixed = _structurally_identifiable(model, start, poses, points, goal)
    # least squares: the rows compressed to R of [J | r] (`_Problem._compress`); a robust
    # loss acts on each row, so trust-region reflective gets the rows themselves
    problem = _Problem(model, params, poses, points, goal, compressed=robust_scale is None)
    if len(problem.prior_cols):  # the prior's unit: what the start leaves per residual
        at_start = problem.data_rms(params.pack())
        problem.set_prior_reference(max(problem.prior_reference, at_start))
    # Where a parameter is poorly determined, LM crawls along its flat valley: a coarse
    # solve (ROUGH_TOLERANCE) gets near enough to judge it, then the exact solve runs.
    rough = check_identifiability and robust_scale is None
    solved = _solve(problem, params.pack(), progress, robust_scale, rough=rough)
    # Positions and orientations with accuracies not stated: their weights from the
    # first solution's residuals (one variance component each), then solved again.
    fallback = problem.residual_sigmas(solved.x)
    if fallback is not None:
        problem = problem.reweighted(fallback)
    if check_identifiability and len(solved.x):
        residual, jac_free, n_rows = problem.data_rows(solved.x)
        at_solution = params.unpack(solved.x)
        _, weak = fix_poorly_determined(
            at_solution, jac_free, residual, columns_are_free=True, rows=n_rows
        )
        if weak:  # held at their start values, the rest refitted FROM THE START: at the
            # rough solution the weak ones may have traded radians with the rest
            for name, reason in weak:
                params = params.fixed([name], reason)
            fixed = fixed + tuple(weak)
            problem = problem.reweighted(problem.fallback, params)
        if weak or rough or fallback is not None:
            solved = _solve(problem, params.pack() if weak else solved.x, progress, robust_scale)
    elif fallback is not None:
        solved = _solve(problem, solved.x, progress, robust_scale)
    # Never worse than the start (the simpler model's solution, with the new terms at 0):
    # a solve that ends above the cost it started from is discarded.
    x = solved.x
    status, message, nfev, njev, optimality = (
        solved.status,
        solved.message,
        solved.nfev,
        solved.njev,
        solved.optimality,
    )
    x0 = params.pack()
    if len(x) and robust_scale is None and problem.cost(x) > problem.cost(x0):
        x, status, success_note = x0, 0, "ended above its start: the start kept"
        message = f"{message} ({success_note})"
    data_residual, data_jac, n_rows = problem.data_rows(x)
    fitted = params.unpack(x)
    std = np.zeros(len(fitted))
    if len(x) and statistics:
        std[fitted.free] = np.sqrt(np.diag(covariance(data_jac, data_residual, rows=n_rows)))
    figures = (
        describe(data_jac, fixed, rows=n_rows)
        if statistics
        else Identifiability(np.nan, np.nan, len(x), fixed)
    )
    return FitResult(
        fitted,
        std,
        problem.predicted - points,
        figures,
        SolverReport(
            method=(
                "levenberg-marquardt (scipy least_squares, MINPACK lmder)"
                if robust_scale is None
                else f"trust-region reflective, soft-L1 loss of scale {robust_scale:.3g} m"
            ),
            objective=goal.name,
            status=status,
            message=message,
            success=status > 0,
            nfev=nfev,
            njev=njev,
            optimality=optimality,
            cost_m2=float(0.5 * data_residual @ data_residual),
            evaluations=problem.evaluations,
            time_s=time.perf_counter() - started,
        ),
        problem.orientation_residuals(),
    )
