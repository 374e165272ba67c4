"""A learned correction of what a physical model leaves: a Gaussian process of its residuals.

Why one module: one Gaussian process. Its features and kernel (`_phi`, `_kernel`) serve the
hyperparameter search, both fits (exact, subset of regressors) and
`GaussianProcessCorrection.predict`, and its file format is that fitted state; the hybrid model
builds on it from outside (`identify.correction_structured`).

The residual r = predicted - measured [m] of a calibration is modelled as a function of
the joint readings (and of which target is measured, with several targets): a Gaussian
process with a squared-exponential kernel on (sin q_j, cos q_j) of every joint, one length
scale per joint (ARD: a joint the residuals do not depend on gets an infinite length
scale), a signal variance and white noise; the three components of r share the kernel.

    k(a, b) = s^2 exp(-1/2 sum_j (2 - 2 cos(q_aj - q_bj)) / l_j^2 - u_T^2 [t_a != t_b])

2 - 2 cos(dq) is the squared distance of the points (cos q, sin q): periodic, so a joint's
+-180 deg meet, and ~dq^2 for small dq (l_j is about a length scale in rad). The target
term (several targets only) lets the targets' corrections differ (u_T = 0: one function).

Hyperparameters maximise the marginal likelihood (scipy L-BFGS-B, analytic gradient) on
at most MAX_LEARN poses (a random subset: each step is O(n^3)); the model is then fitted
on every pose up to MAX_POINTS exactly, above that as a subset of regressors (Nystrom) on
m = INDUCING inducing poses drawn at random: O(n m^2) time, O(m^2) memory (the poses
streamed in blocks), so 100k poses fit. Parametrised by inverse length scales u_j = 1 / l_j >= 0:
u_j = 0 (the joint does not matter) is a natural end, not a bound (in u the search takes
a third of the steps it takes in 1 / l^2, and fewer than in log l). The one artificial
edge of each joint is its shortest length scale (MIN_LENGTH_SCALE_RAD); ending there, or
at an edge of the signal or noise variance, gives a warning kept on the result (the data
want structure the model may not resolve).

Why our own few lines and not scikit-learn's GaussianProcessRegressor: one length scale
per joint ties the sin and cos features of a joint (sklearn's RBF has one per feature),
the multi-output likelihood shares one Cholesky factor, and the fitted state must be plain
arrays for PARAMS.json; `predict` is pure numpy (reading a parameter file needs no scipy).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError, check_keys
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.poses import Poses
from robot_calib.records import Record

FORMAT = "robot_calib.correction/1"
CORRECTION_KEYS = (
    "format",
    "method",
    "n_targets",
    "fitted_poses",
    "rms_m",
    "length_scales_deg",
    "noise_mm",
    "inverse_length_scales",
    "signal_variance",
    "noise_variance",
    "mean_m",
    "scale_m",
    "inducing_q_rad",
    "inducing_target",
    "dual",
    "warnings",
)
#: a learned correction larger than this is no correction of a calibrated robot [m]: a file
#: that says so (or predicts so at its own poses) is refused
MAX_CORRECTION_M = 0.010
MAX_LEARN = 400  # poses the hyperparameters are learned on (a random subset above)
MAX_POINTS = 3000  # poses fitted exactly (one Cholesky, 0.4 s at 3000); above, a subset of
INDUCING = 2000  # regressors on this many inducing poses: O(n INDUCING^2), 100k poses ~15 s
#: poses a learned correction is fitted on at most (`fitting_rows`: a fixed random subset
#: above): its cost grows with n (the load-driven part's normal equations, the process's
#: subset of regressors), what it learns of structure in six joint readings does not
#: (diagnose of 100k poses spent minutes on corrections of 80k poses each)
MAX_FIT_POSES = MAX_POINTS  # the process exact, no subset of regressors
MIN_LENGTH_SCALE_RAD = math.radians(1.0)  # a joint's shortest length scale (an edge)
# the target code's largest inverse length scale: targets uncorrelated to e^-25 there (a
# saturation, not an edge that changes predictions)
MAX_TARGET_INVERSE = 5.0
# signal and noise variance of the residuals scaled to unit rms: outside these the model
# explains nothing or everything; ending at one is said
SIGNAL_BOUNDS = (1e-4, 1e3)
NOISE_BOUNDS = (1e-6, 10.0)
# The marginal likelihood has local optima (from long length scales a sharp structure of
# one joint is invisible: the search ends with everything noise). The starts: every joint
# at l = 57 deg (u = 1/rad), every joint at 10 deg, and each joint alone at 19 or 5 deg
# with the others at 57; the likelihood at each is evaluated on COARSE poses (cheap), the
# best STARTS_SEARCHED are searched there, the best of those refined on all MAX_LEARN.
STARTS_INVERSE = (1.0, 5.7)
STARTS_ONE_JOINT = (3.0, 12.0)
STARTS_SEARCHED = 2
START_SIGNAL, START_NOISE = 1.0, 0.1
COARSE = 200
# u_j = 0 is stationary (dK/du_j = 0 there): a joint dropped on the coarse poses (or in a
# warm start) re-enters the refinement at this inverse length scale (l = 190 deg), so the
# refinement can bring it back (measured: 4 simulated UR10 cases reach the best optimum
# found by any start this way, 1 of 4 without)
REVIVE_INVERSE = 0.3
MAX_ITERATIONS = 100  # L-BFGS-B steps of the hyperparameter search
WARM_ITERATIONS = 30  # from a warm start (the first fold's hyperparameters)
# stop when a step lowers -log p by less than this share: scipy's default (2e-9) spends a
# fifth more steps on digits that change no prediction (4 simulated UR10 cases: held-out
# rms equal to 0.1 um)
FTOL = 1e-6
CHUNK_ELEMENTS = 1 << 22  # kernel entries per block (32 MB): predict and fit stream rows
JITTER = 1e-10  # relative diagonal added where a Cholesky factor needs it
EDGE = 1e-3  # relative distance to an edge that counts as "at" it


def stored_readings(q: Array) -> Array:
    """Joint readings (m, J) [rad] as PARAMS.json stores a correction's inducing poses:
    rounded to 1e-12 rad (far below any encoder). What a correction is checked against
    when it is loaded is computed at these, at fit time as at load time."""
    return np.round(q, 12)


def features(poses: Poses, n_targets: int) -> Array:
    """The inputs of residual models of `poses`: shape (n, 2J [+ T]), sin q_j of every
    joint reading, then cos q_j, then the target's one-hot code when there are several
    targets (n_targets > 1)."""
    return _features(poses.q, poses.target_index, n_targets)


def _features(q: Array, target: IntArray, n_targets: int) -> Array:
    columns = [np.sin(q), np.cos(q)]
    if n_targets > 1:
        columns.append(np.eye(n_targets)[target])
    return np.hstack(columns)


@dataclass(frozen=True)
class Hyperparameters:
    """The kernel's hyperparameters, for residuals scaled to unit rms.

    inverse : shape (J [+ 1],), u_j = 1 / l_j [1/rad] of every joint (0: the joint does
        not matter), then u_T of the target code with several targets [1]
    signal_variance : s^2 [1]
    noise_variance : sigma^2 of the white noise [1]
    """

    inverse: Array
    signal_variance: float
    noise_variance: float

    def vector(self) -> Array:
        """(J [+ 1] + 2,) the optimiser's vector: u, log s^2, log sigma^2."""
        return np.concatenate(
            [self.inverse, [np.log(self.signal_variance), np.log(self.noise_variance)]]
        )

    @classmethod
    def of_vector(cls, theta: Array) -> Hyperparameters:
        return cls(
            np.array(theta[:-2], dtype=float), float(np.exp(theta[-2])), float(np.exp(theta[-1]))
        )


def _phi(q: Array, target: IntArray, hyper: Hyperparameters, n_targets: int) -> Array:
    """(n, 2J [+ T]) features (`features`) scaled by the inverse length scales:
    k(a, b) = s^2 exp(phi_a . phi_b - c), c = sum_j u_j^2 + u_T^2 (`_offset`)."""
    inputs = _features(q, target, n_targets)
    return inputs * _feature_scale(hyper.inverse, q.shape[1], inputs.shape[1])


def _offset(hyper: Hyperparameters) -> float:
    return float(np.sum(hyper.inverse**2))


def _kernel(phi_a: Array, phi_b: Array, hyper: Hyperparameters) -> Array:
    """(n_a, n_b) signal kernel of scaled features (`_phi`)."""
    out = phi_a @ phi_b.T  # in place from here: no n_a x n_b temporaries
    out -= _offset(hyper)
    np.exp(out, out=out)
    out *= hyper.signal_variance
    return out


def _feature_scale(u: Array, n_joints: int, n_columns: int) -> Array:
    """(n_columns,) the scale of every column of `_features` ([sin q, cos q, target code])
    by the inverse length scales u (J [+ 1],): u_j on both columns of joint j, u_T on the
    target code's."""
    return np.concatenate([u[:n_joints], u[:n_joints], np.full(n_columns - 2 * n_joints, u[-1])])


def _negative_log_likelihood(
    theta: Array, inputs: Array, y: Array, n_joints: int
) -> tuple[float, Array]:
    """-log p(y | theta) (constant dropped) of the (n, C) outputs `y` sharing the kernel,
    and its gradient in theta = (u (G,), log s^2, log sigma^2); `inputs` (n, 2J [+ T]) the
    unscaled features (`_features`) of the n poses, J = `n_joints`.

    The kernel is s^2 exp(phi_a . phi_b - sum u^2) of the scaled features (`_kernel`'s
    form: one (n, 2J + T) x (2J + T, n) product), and the gradient's sums over the squared
    distances D_g of each joint (2 - 2 cos(q_a - q_b) = 2 - 2 (sin sin + cos cos)) and of
    the target code (2 [t_a != t_b]) are formed from the features too:
    sum(D_g * M) = 2 sum(M) - 2 sum over g's columns f of f^T M f. No (G, n, n) array of
    distances: 8 MB per evaluation at 400 poses that streamed through the cache twice.
    Equal to the distance form to rounding (1e-13 relative typically; 3e-11 for joints
    read over a few degrees only, and a gradient component exactly zero there comes out
    as a difference of large sums, ~1e-7)."""
    from scipy.linalg import lapack

    n, n_outputs = y.shape
    u, signal, noise = theta[:-2], np.exp(theta[-2]), np.exp(theta[-1])
    phi = inputs * _feature_scale(u, n_joints, inputs.shape[1])
    k_signal = _kernel(phi, phi, Hyperparameters(u, signal, noise))  # in place from here
    k = k_signal.copy()
    k.flat[:: n + 1] += noise
    factor, info = lapack.dpotrf(k, lower=1)  # clean: the upper triangle zero
    if info:  # not positive definite at these values: a wall the search backs off from
        return 1e25, np.zeros_like(theta)
    alpha, _ = lapack.dpotrs(factor, y, lower=1)
    inverse, _ = lapack.dpotri(factor, lower=1)  # lower triangle of K^-1, upper zero
    trace_inverse = float(np.trace(inverse))
    value = 0.5 * float(np.sum(y * alpha)) + n_outputs * float(np.sum(np.log(np.diag(factor))))
    # dNLL/dtheta = -1/2 sum(W * dK/dtheta), W = alpha alpha^T - C K^-1, both symmetric:
    # against a symmetric matrix, K^-1 counts as its lower triangle doubled off the diagonal
    inverse *= -2.0 * n_outputs
    inverse.flat[:: n + 1] *= 0.5
    weight = alpha @ alpha.T
    weight += inverse
    weight *= k_signal  # M = W * K_signal
    total = float(np.sum(weight))
    quadratic = np.einsum("ac,ac->c", inputs, weight @ inputs)  # f^T M f of every column
    per_group = quadratic[:n_joints] + quadratic[n_joints : 2 * n_joints]
    if len(u) > n_joints:  # the target code's columns
        per_group = np.append(per_group, quadratic[2 * n_joints :].sum())
    grad = np.empty_like(theta)
    # dK/du_g = -u_g D_g K_s: -1/2 sum(W * dK/du_g) = 1/2 u_g sum(D_g * M)
    grad[:-2] = u * (total - per_group)
    grad[-2] = -0.5 * total
    grad[-1] = -0.5 * noise * (float(np.sum(alpha * alpha)) - n_outputs * trace_inverse)
    return value, grad


def _bounds(
    n_joints: int, n_targets: int, min_length_scale_rad: float
) -> list[tuple[float, float]]:
    joints = [(0.0, 1.0 / min_length_scale_rad)] * n_joints
    target = [(0.0, MAX_TARGET_INVERSE)] if n_targets > 1 else []
    return joints + target + [tuple(np.log(SIGNAL_BOUNDS)), tuple(np.log(NOISE_BOUNDS))]  # type: ignore[list-item]


def _edge_warnings(
    hyper: Hyperparameters, n_joints: int, min_length_scale_rad: float, scale_m: float
) -> tuple[str, ...]:
    """'warning: learned correction: ...' for every hyperparameter at an edge of its range."""
    out = []
    top = 1.0 / min_length_scale_rad
    for j, u in enumerate(hyper.inverse[:n_joints]):
        if u >= top * (1 - EDGE):
            out.append(
                f"warning: learned correction: joint {j + 1}'s length scale ends at its "
                f"lower bound {math.degrees(min_length_scale_rad):.3g} deg: the residuals "
                "vary faster with this joint than the model resolves (high-order joint "
                "harmonics?); the correction smooths them"
            )
    for name, value, (low, high), meaning in (
        (
            "signal variance",
            hyper.signal_variance,
            SIGNAL_BOUNDS,
            "the structure's size is not determined by the data",
        ),
        (
            "noise variance",
            hyper.noise_variance,
            NOISE_BOUNDS,
            "the residuals are nearly noise-free or all noise at this scale",
        ),
    ):
        if value <= low * (1 + EDGE) or value >= high * (1 - EDGE):
            size = math.sqrt(value) * scale_m * 1e3
            out.append(
                f"warning: learned correction: {name} ends at an edge of its range "
                f"({value:.3g} of the residuals' variance, {size:.3g} mm): {meaning}"
            )
    return tuple(out)


def _subset(n: int, size: int, rng: np.random.Generator) -> IntArray:
    """Sorted indices of at most `size` of n rows (all when n <= size)."""
    if n <= size:
        return np.arange(n)
    return np.sort(rng.choice(n, size, replace=False))


def fitting_rows(n: int) -> IntArray:
    """Sorted indices of the at most MAX_FIT_POSES of n poses a learned correction is
    fitted on: all up to MAX_FIT_POSES, else a random subset (its own seed: the same rows
    for the same n, whatever else draws random numbers)."""
    return _subset(n, MAX_FIT_POSES, np.random.default_rng(20260))


def _shuffled_subset(n: int, size: int, rng: np.random.Generator) -> IntArray:
    """At most `size` of n rows in random order (all when n <= size)."""
    return rng.permutation(n)[:size]


def _starts(n_joints: int, n_targets: int) -> list[Array]:
    """The optimiser's candidate starts (STARTS_INVERSE, STARTS_ONE_JOINT)."""
    noise = np.log([START_SIGNAL, START_NOISE])
    target = [1.0] if n_targets > 1 else []
    out = [np.r_[np.full(n_joints, u), target, noise] for u in STARTS_INVERSE]
    for j in range(n_joints):
        for u in STARTS_ONE_JOINT:
            inverse = np.full(n_joints, STARTS_INVERSE[0])
            inverse[j] = u
            out.append(np.r_[inverse, target, noise])
    return out


def learn_hyperparameters(
    poses: Poses,
    residuals: Array,
    n_targets: int,
    rng: np.random.Generator | None = None,
    start: Hyperparameters | None = None,
    min_length_scale_rad: float = MIN_LENGTH_SCALE_RAD,
    max_learn: int = MAX_LEARN,
) -> tuple[Hyperparameters, tuple[str, ...]]:
    """The kernel's hyperparameters by maximum marginal likelihood of `residuals` (n, 3)
    [m, tracker frame, predicted - measured] at `poses` (n poses, readings [rad]), on at
    most MAX_LEARN poses (a random subset drawn with `rng`, default seed 0).

    start : hyperparameters to start from (a warm start: WARM_ITERATIONS steps at most),
        else the best of STARTS_INVERSE (s^2 = 1, sigma^2 = 0.1) on COARSE of the poses
    min_length_scale_rad : every joint's shortest length scale [rad]
    max_learn : poses learned on (default MAX_LEARN; fewer for a warm start's refinement)

    Returns
    -------
    hyper : Hyperparameters, for the residuals scaled to unit rms (`_scaling`)
    warnings : 'warning: learned correction: ...' for every edge reached (`_edge_warnings`)
        and a search that failed
    """
    from scipy.optimize import minimize

    rng = np.random.default_rng(0) if rng is None else rng
    rows = _shuffled_subset(len(poses), max_learn, rng)
    mean, scale = _scaling(residuals)
    y = (residuals[rows] - mean) / scale
    n_joints = poses.q.shape[1]
    inputs = _features(poses.q[rows], poses.target_index[rows], n_targets)
    bounds = _bounds(n_joints, n_targets, min_length_scale_rad)
    low, high = np.array(bounds).T

    def search(theta: Array, block: slice, iterations: int) -> Any:
        # L-BFGS-B: a smooth objective with an analytic gradient and box bounds (u >= 0)
        return minimize(
            _negative_log_likelihood,
            np.clip(theta, low, high),
            args=(inputs[block], y[block], n_joints),
            jac=True,
            method="L-BFGS-B",
            bounds=bounds,
            options={"maxiter": iterations, "ftol": FTOL},
        )

    def revived(theta: Array) -> Array:
        theta = theta.copy()
        theta[:-2] = np.maximum(theta[:-2], REVIVE_INVERSE)
        return theta

    if start is not None:
        found = search(revived(start.vector()), slice(None), WARM_ITERATIONS)
    else:  # the rows are in random order: the first COARSE are a random subset too
        coarse = slice(0, min(COARSE, len(rows)))
        starts = _starts(n_joints, n_targets)
        at_start = [
            _negative_log_likelihood(t, inputs[coarse], y[coarse], n_joints)[0] for t in starts
        ]
        best = np.argsort(at_start)[:STARTS_SEARCHED]
        found = min(
            (search(starts[k], coarse, MAX_ITERATIONS) for k in best), key=lambda f: float(f.fun)
        )
        if len(rows) > COARSE:
            found = search(revived(found.x), slice(None), MAX_ITERATIONS)
    hyper = Hyperparameters.of_vector(found.x)
    warnings = _edge_warnings(hyper, n_joints, min_length_scale_rad, scale)
    if not found.success and "ITERATIONS" not in str(found.message).upper():
        warnings += (
            f"warning: learned correction: the hyperparameter search stopped: {found.message}",
        )
    return hyper, warnings


def _scaling(residuals: Array) -> tuple[Array, float]:
    """The residuals' mean (3,) [m] and rms about it over all components [m] (> 0): the
    model works on (residuals - mean) / scale, one scale for the three components so that
    isotropic tracker noise stays isotropic."""
    mean = residuals.mean(axis=0) if len(residuals) else np.zeros(3)
    scale = float(np.sqrt(np.mean((residuals - mean) ** 2))) if len(residuals) else 0.0
    return mean, max(scale, 1e-12)


def _blocks(n: int, width: int) -> list[slice]:
    """Row blocks of an (n, width) kernel of at most CHUNK_ELEMENTS entries each."""
    step = max(1, CHUNK_ELEMENTS // max(width, 1))
    return [slice(s, min(s + step, n)) for s in range(0, n, step)]


@dataclass(frozen=True)
class GaussianProcessCorrection(Record):
    """A fitted residual correction: what it predicts needs only these arrays.

    inducing_q : shape (m, J), the joint readings of the poses the prediction is built on
        [rad] (every fitted pose up to MAX_POINTS, else a random INDUCING of them), held
        as PARAMS.json stores them (`stored_readings`): what it predicts in memory is what
        its file predicts
    inducing_target : shape (m,), their targets (indices into the calibration's targets)
    dual : shape (m, 3), the dual coefficients of the scaled residuals [1]
    hyper : the kernel's hyperparameters (for residuals scaled to unit rms)
    mean_m : shape (3,), the fitted residuals' mean [m, tracker frame]
    scale_m : their rms about it [m]: the model's unit
    n_targets : the calibration's number of targets (the target code's length)
    n_fitted : poses the correction was fitted on
    rms_m : rms norm of the correction at the fitted poses [m]: its size
    method : how it was learned, for people
    warnings : 'warning: learned correction: ...' lines (hyperparameters at an edge)
    """

    inducing_q: Array
    inducing_target: IntArray
    dual: Array
    hyper: Hyperparameters
    mean_m: Array
    scale_m: float
    n_targets: int
    n_fitted: int
    rms_m: float
    method: str
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "inducing_q", stored_readings(self.inducing_q))

    @property
    def n_joints(self) -> int:
        return int(self.inducing_q.shape[1])

    @property
    def length_scales_deg(self) -> list[float | None]:
        """Every joint's length scale l_j [deg] (about the change of its reading over
        which the residuals change); None where the residuals do not depend on it."""
        u = self.hyper.inverse[: self.n_joints]
        return [math.degrees(1.0 / v) if v > 0 else None for v in u]

    @property
    def noise_mm(self) -> float:
        """The white noise the model attributes to the residuals, 1-sigma per axis [mm]."""
        return math.sqrt(self.hyper.noise_variance) * self.scale_m * 1e3

    def predict(self, poses: Poses) -> Array:
        """The predicted residual (predicted - measured) of the calibration at `poses`:
        shape (n, 3) [m, tracker frame]; subtract it from the model's points. Computed in
        blocks of CHUNK_ELEMENTS kernel entries (bounded memory for any n). InputError when
        the poses have another number of joints or a target beyond the calibration's."""
        n = len(poses)
        if poses.q.shape[1] != self.n_joints:
            raise InputError(
                f"learned correction: poses of {poses.q.shape[1]} joints, the "
                f"correction was fitted on {self.n_joints}"
            )
        target = poses.target_index
        if n and int(target.max()) >= self.n_targets:
            raise InputError(
                f"learned correction: target index {int(target.max())} beyond "
                f"the calibration's {self.n_targets} target(s)"
            )
        phi_z = _phi(self.inducing_q, self.inducing_target, self.hyper, self.n_targets)
        out = np.empty((n, 3))
        for rows in _blocks(n, len(phi_z)):
            phi = _phi(poses.q[rows], target[rows], self.hyper, self.n_targets)
            out[rows] = _kernel(phi, phi_z, self.hyper) @ self.dual
        return out * self.scale_m + self.mean_m

    def line(self) -> str:
        """One human line: size, length scales, noise, poses."""
        scales = ", ".join("-" if v is None else f"{v:.0f}" for v in self.length_scales_deg)
        return (
            f"learned correction: {self.rms_m * 1e3:.4f} mm rms at its {self.n_fitted} "
            f"calibration poses; length scales per joint [deg] {scales} (-: no influence); "
            f"noise {self.noise_mm:.4f} mm per axis"
        )

    def to_dict(self) -> dict[str, Any]:
        """PARAMS.json `correction` (msgs_doc/parameters.md): plain numbers, SI units; the
        readings rounded to 1e-12 rad (far below any encoder; predictions change by less
        than 1e-12 m), the other numbers kept exact."""
        return {
            "format": FORMAT,
            "method": self.method,
            "n_targets": self.n_targets,
            "fitted_poses": self.n_fitted,
            "rms_m": self.rms_m,
            "length_scales_deg": self.length_scales_deg,  # for people; not read back
            "noise_mm": self.noise_mm,  # for people; not read back
            "inverse_length_scales": [float(v) for v in self.hyper.inverse],
            "signal_variance": self.hyper.signal_variance,
            "noise_variance": self.hyper.noise_variance,
            "mean_m": [float(v) for v in self.mean_m],
            "scale_m": self.scale_m,
            "inducing_q_rad": stored_readings(self.inducing_q).tolist(),
            "inducing_target": [int(t) for t in self.inducing_target],
            "dual": self.dual.tolist(),
            "warnings": list(self.warnings),
        }

    @classmethod
    def from_dict(
        cls, data: Mapping[str, Any], where: str = "correction"
    ) -> GaussianProcessCorrection:
        """The correction of a `to_dict` mapping; InputError naming `where` when it is of
        another format, lacks a field, or has arrays of inconsistent shapes or values that
        are not finite."""
        if not isinstance(data, Mapping) or data.get("format") != FORMAT:
            found = data.get("format") if isinstance(data, Mapping) else type(data).__name__
            raise InputError(
                f"{where}: not a learned correction of a known format "
                "(robot_calib.correction/2, the hybrid model's, or "
                f"{FORMAT}, the process alone; format {found!r})"
            )
        check_keys(data, CORRECTION_KEYS, where)
        if not isinstance(data.get("warnings", []), list):
            raise InputError(f"{where}: malformed learned correction: warnings must be a list")
        try:
            q = np.array(data["inducing_q_rad"], dtype=float)
            target = np.array(data["inducing_target"], dtype=np.int64)
            dual = np.array(data["dual"], dtype=float)
            w = np.array(data["inverse_length_scales"], dtype=float)
            mean = np.array(data["mean_m"], dtype=float)
            scalars = {
                k: float(data[k])
                for k in ("signal_variance", "noise_variance", "scale_m", "rms_m")
            }
            n_targets, n_fitted = int(data["n_targets"]), int(data["fitted_poses"])
            warnings = tuple(str(v) for v in data.get("warnings", []))
            method = str(data["method"])
        except KeyError as exc:
            raise InputError(f"{where}: malformed learned correction (no field {exc})") from None
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: malformed learned correction ({exc})") from None
        m = len(q)
        problems = [
            (q.ndim != 2 or m == 0, "inducing_q_rad must be an (m, J) table, m >= 1"),
            (
                target.shape != (m,) or (m and (target.min() < 0 or target.max() >= n_targets)),
                "inducing_target must hold m target indices below n_targets",
            ),
            (dual.shape != (m, 3), "dual must be an (m, 3) table"),
            (
                q.ndim == 2 and w.shape != (q.shape[1] + (n_targets > 1),),
                f"inducing_q_rad has {q.shape[-1]} columns (joints) and inverse_length_scales "
                f"{w.size} values: one per joint (+ 1 with several targets) in both",
            ),
            (mean.shape != (3,), "mean_m must have 3 values"),
            (n_targets < 1, "n_targets must be >= 1"),
            (not all(np.isfinite(a).all() for a in (q, dual, w, mean)), "values not finite"),
            (bool((w < 0).any()), "inverse_length_scales must be >= 0"),
            (not all(math.isfinite(v) for v in scalars.values()), "values not finite"),
            (
                min(scalars["signal_variance"], scalars["noise_variance"], scalars["scale_m"])
                <= 0,
                "signal_variance, noise_variance and scale_m must be > 0",
            ),
        ]
        for bad, what in problems:
            if bad:
                raise InputError(f"{where}: malformed learned correction: {what}")
        physical = [
            (not 0 <= scalars["rms_m"] <= MAX_CORRECTION_M, "rms_m beyond 0..10 mm"),
            (float(np.max(np.abs(mean))) > MAX_CORRECTION_M, "mean_m beyond 10 mm"),
            (scalars["scale_m"] > MAX_CORRECTION_M, "scale_m beyond 10 mm"),
            (n_fitted < m, "fitted_poses below the inducing poses"),
            (float(np.max(np.abs(q))) > 4 * np.pi, "inducing_q_rad beyond 4 pi (degrees?)"),
        ]
        for bad, what in physical:
            if bad:
                raise InputError(f"{where}: implausible learned correction: {what}")
        hyper = Hyperparameters(w, scalars["signal_variance"], scalars["noise_variance"])
        out = cls(
            q,
            target,
            dual,
            hyper,
            mean,
            scalars["scale_m"],
            n_targets,
            n_fitted,
            scalars["rms_m"],
            method,
            warnings,
        )
        # what it predicts where it was fitted: finite, and of a correction's size
        with np.errstate(all="ignore"):
            at_fit = out.predict(replace(Poses.from_readings(q), target=target))
        size = float(np.max(np.linalg.norm(at_fit, axis=1))) if len(at_fit) else 0.0
        if not np.isfinite(at_fit).all():
            raise InputError(
                f"{where}: implausible learned correction: it predicts "
                "non-finite values at its own poses"
            )
        if size > MAX_CORRECTION_M:
            raise InputError(
                f"{where}: implausible learned correction: it predicts "
                f"{size * 1e3:.3g} mm at its own poses (at most "
                f"{MAX_CORRECTION_M * 1e3:.0f} mm)"
            )
        return out


@dataclass(frozen=True)
class FittedCorrection:
    """`fit_correction_at`'s result: the correction and what its fit computed anyway.

    correction : the fitted GaussianProcessCorrection
    fitted : shape (n, 3), its predicted residual at the fitted poses [m, tracker frame]
    phi : shape (n, F), the fitted poses' scaled features (`_phi`; exact fits; None for a
        subset of regressors): what `exact_holdout` builds the halves' kernels from
    """

    correction: GaussianProcessCorrection
    fitted: Array
    phi: Array | None


def fit_correction(
    poses: Poses,
    residuals: Array,
    n_targets: int,
    rng: np.random.Generator | None = None,
    hyper: Hyperparameters | None = None,
    start: Hyperparameters | None = None,
    min_length_scale_rad: float = MIN_LENGTH_SCALE_RAD,
    max_points: int = MAX_POINTS,
    max_learn: int = MAX_LEARN,
) -> GaussianProcessCorrection:
    """The correction of `residuals` (n, 3) [m, tracker frame, predicted - measured] at
    `poses` (readings (n, J) [rad], targets below `n_targets`).

    hyper : the kernel's hyperparameters, else learned (`learn_hyperparameters`, from
        `start` if given, with `min_length_scale_rad`)
    rng : draws the learning subset and the inducing poses (default: seed 0)

    Every pose is fitted exactly up to `max_points` (the kernel matrix's Cholesky factor);
    above, by a subset of regressors on INDUCING (at most `max_points`) inducing poses
    drawn with `rng`: the
    dual coefficients (sigma^2 K_zz + K_zn K_nz)^-1 K_zn y, accumulated over blocks of
    poses (memory O(max_points^2 + block), time O(n max_points^2)).

    Returns
    -------
    correction : GaussianProcessCorrection; `predict` gives the predicted residual (n, 3) [m]
    """
    return fit_correction_at(
        poses, residuals, n_targets, rng, hyper, start, min_length_scale_rad, max_points, max_learn
    ).correction


def fit_correction_at(
    poses: Poses,
    residuals: Array,
    n_targets: int,
    rng: np.random.Generator | None = None,
    hyper: Hyperparameters | None = None,
    start: Hyperparameters | None = None,
    min_length_scale_rad: float = MIN_LENGTH_SCALE_RAD,
    max_points: int = MAX_POINTS,
    max_learn: int = MAX_LEARN,
    on_learned: Callable[[Hyperparameters], object] | None = None,
) -> FittedCorrection:
    """`fit_correction`, with its predictions at the fitted poses and (exact fits) the
    kernel of those poses, which it computes anyway (a caller needing them saves one or
    more n x n kernels); `on_learned` is called with the hyperparameters as soon as they
    are learned (before the fit: another process can start from them meanwhile)."""
    from scipy.linalg import LinAlgError, cho_factor, cho_solve, solve

    rng = np.random.default_rng(0) if rng is None else rng
    n = len(poses)
    if residuals.shape != (n, 3) or n == 0:
        raise InputError(
            f"learned correction: residuals of shape {residuals.shape} for "
            f"{n} poses (expected ({n}, 3), n >= 1)"
        )
    warnings: tuple[str, ...] = ()
    if hyper is None:
        hyper, warnings = learn_hyperparameters(
            poses, residuals, n_targets, rng, start, min_length_scale_rad, max_learn
        )
        if on_learned is not None:
            on_learned(hyper)
    mean, scale = _scaling(residuals)
    y = (residuals - mean) / scale
    q, target = poses.q, poses.target_index
    learned = f"hyperparameters by marginal likelihood on {min(n, max_learn)} poses"
    if n <= max_points:
        inducing: IntArray = np.arange(n)
        phi: Array | None = _phi(q, target, hyper, n_targets)
        assert phi is not None
        with_noise = _kernel(phi, phi, hyper)  # factored in place: one n x n array at most
        with_noise.flat[:: n + 1] += hyper.noise_variance
        dual = cho_solve(cho_factor(with_noise, lower=True, overwrite_a=True), y)
        del with_noise
        # K dual = (K + s^2 I) dual - s^2 dual = y - s^2 dual: the fitted values without K
        fitted = (y - hyper.noise_variance * dual) * scale + mean
        how = f"exact on all {n} poses"
    else:
        inducing = _subset(n, min(max_points, INDUCING), rng)
        phi_z = _phi(q[inducing], target[inducing], hyper, n_targets)
        m = len(inducing)
        gram, rhs = hyper.noise_variance * _kernel(phi_z, phi_z, hyper), np.zeros((m, 3))
        for rows in _blocks(n, m):
            k_zn = _kernel(phi_z, _phi(q[rows], target[rows], hyper, n_targets), hyper)
            gram += k_zn @ k_zn.T
            rhs += k_zn @ y[rows]
        gram.flat[:: m + 1] += JITTER * float(np.trace(gram)) / m
        try:
            dual = solve(gram, rhs, assume_a="pos")
        except LinAlgError:  # numerically singular: the least-squares solution
            dual = np.linalg.lstsq(gram, rhs, rcond=None)[0]
        how = f"subset of regressors on {m} of {n} poses"
        phi = None
    method = (
        "Gaussian process of the residuals (squared-exponential kernel on sin/cos of the "
        "joint readings, one length scale per joint, white noise; "
        f"{learned}; {how})"
    )
    correction = GaussianProcessCorrection(
        q[inducing].copy(),
        target[inducing].copy(),
        dual,
        hyper,
        mean,
        scale,
        n_targets,
        n,
        0.0,
        method,
        warnings,
    )
    if phi is None:
        fitted = correction.predict(poses)
    size = np.linalg.norm(fitted, axis=1)
    correction = replace(correction, rms_m=float(np.sqrt(np.mean(size**2))))
    return FittedCorrection(correction, fitted, phi)


def exact_holdout(
    phi: Array, hyper: Hyperparameters, residuals: Array, train: NDArray[np.bool_]
) -> Array:
    """The exact process of `hyper` on the poses of scaled features `phi` (n, F)
    (`FittedCorrection`) fitted on `residuals[train]` ((n, 3) [m]) and predicting at the
    other poses: shape (n - train.sum(), 3) [m]. The same as `fit_correction` of the
    training poses with these hyperparameters, then its `predict` at the others, from the
    features already scaled (two half-size kernels, one at a time)."""
    from scipy.linalg import cho_factor, cho_solve

    mean, scale = _scaling(residuals[train])
    y = (residuals[train] - mean) / scale
    with_noise = _kernel(phi[train], phi[train], hyper)
    with_noise.flat[:: len(y) + 1] += hyper.noise_variance
    dual = cho_solve(cho_factor(with_noise, lower=True, overwrite_a=True), y)
    del with_noise
    return (_kernel(phi[~train], phi[train], hyper) @ dual) * scale + mean
