"""The learnable bound: how far any model could bring the held-out error from these data.

A nonparametric model of the geometric calibration's residuals, fitted on the calibration
poses only and scored where the rungs are scored (the hold-out bags, else the same k-fold
over whole poses, the geometry refitted per fold): "any model could reach about X mm from
these data". Residual structure that is systematic in the joint readings is learnable;
noise, and structure the data do not sample, are not. The ladder then reports what share
of that learnable gap (geometric's held-out error minus the bound) each physical effect
explains.

The model: kernel ridge regression (scikit-learn's `KernelRidge`, RBF kernel) of the three
residual components [mm] on (sin q_j, cos q_j) of every joint's reading (periodic, so a
joint's +-180 deg meet), plus the target's one-hot code with several targets. Its two
hyperparameters (ridge alpha, RBF gamma) are chosen by 5-fold cross-validation over whole
calibration poses (`GridSearchCV`), on at most MAX_SEARCH poses (a random subset above:
the search is O(n^3) per fit). scikit-learn earns its place: a maintained, tested kernel
ridge and cross-validated search instead of hand-written linear algebra. An isotropic
kernel on all readings learns smooth pose-dependent structure (gravity, a joint's low
harmonics) better than sharp structure in one joint (a high harmonic of a wrist joint):
the bound is what this model learns, a lower bound of what is learnable.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from robot_calib.identify.calibrate import Calibration
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import Recording
from robot_calib.poses import Poses
from robot_calib.records import Record

METHOD = (
    "kernel ridge regression (scikit-learn KernelRidge, RBF kernel on sin/cos of the joint "
    "readings) of the geometric residuals; alpha, gamma by 5-fold CV over calibration poses"
)
ALPHAS = (1e-2, 1e-1, 1.0)
GAMMAS = (0.05, 0.2, 1.0)
MAX_SEARCH = 800  # poses in the hyperparameter search (a random subset above)
MAX_FIT = 2000  # measurements the model is fitted on (a random subset above: the kernel
# matrix is O(n^2) in memory, 32 MB here, 80 GB at 100k poses)

#: the bound must beat geometric by this share of its held-out rms to count as structure
MIN_LEARNABLE_SHARE = 0.05


def features(poses: Poses, n_targets: int) -> Array:
    """(n, 2J [+ T]) inputs: sin and cos of every reading, and the target's one-hot code
    when there are several targets."""
    columns = [np.sin(poses.q), np.cos(poses.q)]
    if n_targets > 1:
        columns.append(np.eye(n_targets)[poses.target_index])
    return np.hstack(columns)


@dataclass(frozen=True)
class ResidualModel:
    """A fitted kernel ridge model of residuals: `predict` gives (n, 3) [m]."""

    regressor: Any  # sklearn.kernel_ridge.KernelRidge, fitted on residuals in mm
    n_targets: int
    alpha: float
    gamma: float

    def predict(self, poses: Poses) -> Array:
        """Predicted residuals (predicted - measured) at `poses`, shape (n, 3) [m]."""
        if not len(poses):
            return np.zeros((0, 3))
        return np.asarray(self.regressor.predict(features(poses, self.n_targets))) * 1e-3


def _subset(n: int, size: int, seed: int) -> IntArray:
    """Sorted indices of at most `size` of n rows (all when n <= size), reproducibly."""
    if n <= size:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size, replace=False))


def search_hyperparameters(
    poses: Poses, residuals: Array, fold: IntArray, n_targets: int, seed: int = 0
) -> tuple[float, float]:
    """(alpha, gamma) of the kernel ridge of `residuals` (n, 3) [m] at `poses` by
    cross-validation over the folds `fold` (n,) (whole poses), on at most MAX_SEARCH
    measurements (a random subset above)."""
    from sklearn.kernel_ridge import KernelRidge
    from sklearn.model_selection import GridSearchCV

    rows = _subset(len(poses), MAX_SEARCH, seed)
    x, y = features(poses, n_targets)[rows], residuals[rows] * 1e3
    folds = fold[rows]
    splits = [(np.flatnonzero(folds != f), np.flatnonzero(folds == f)) for f in np.unique(folds)]
    search = GridSearchCV(KernelRidge(kernel="rbf"),
                          {"alpha": list(ALPHAS), "gamma": list(GAMMAS)},
                          cv=splits, scoring="neg_mean_squared_error")  # fmt: skip
    search.fit(x, y)
    return float(search.best_params_["alpha"]), float(search.best_params_["gamma"])


def fit_residual_model(
    poses: Poses,
    residuals: Array,
    n_targets: int,
    hyper: tuple[float, float],
    seed: int = 0,
) -> ResidualModel:
    """Kernel ridge (alpha, gamma = `hyper`) of `residuals` (n, 3) [m] at `poses`, on at
    most MAX_FIT measurements (a random subset above)."""
    from sklearn.kernel_ridge import KernelRidge

    rows = _subset(len(poses), MAX_FIT, seed)
    x, y = features(poses, n_targets)[rows], residuals[rows] * 1e3
    regressor = KernelRidge(kernel="rbf", alpha=hyper[0], gamma=hyper[1]).fit(x, y)
    return ResidualModel(regressor, n_targets, hyper[0], hyper[1])


@dataclass(frozen=True)
class LearnableBound(Record):
    """DIAGNOSIS.json `learnable` (msgs_doc/diagnosis.md): geometric's held-out error and
    that of geometric corrected by the residual model, on the same held-out data [mm];
    learnable_share = 1 - corrected / geometric (rms): the part of geometric's held-out
    error that is systematic and learnable from these data; alpha, gamma the chosen
    hyperparameters (residuals in mm, inputs sin/cos)."""

    method: str
    scored_on: str
    geometric_abs_rms_mm: float
    geometric_abs_mean_mm: float
    holdout_abs_rms_mm: float
    holdout_abs_mean_mm: float
    learnable_share: float
    alpha: float
    gamma: float

    @property
    def structure_left(self) -> bool:
        """True when the residual model beats geometric by MIN_LEARNABLE_SHARE or more."""
        return self.learnable_share >= MIN_LEARNABLE_SHARE

    def line(self) -> str:
        share = (f"{100 * self.learnable_share:.0f} % of geometric's error is learnable"
                 if self.learnable_share > 0 else "it learns nothing")  # fmt: skip
        return (
            f"learnable bound: geometric {self.geometric_abs_rms_mm:.4f} mm -> "
            f"{self.holdout_abs_rms_mm:.4f} mm rms held-out with a kernel ridge of its "
            f"residuals ({share}; {self.scored_on})"
        )


def _figures(residuals: Array) -> tuple[float, float]:
    norm = np.linalg.norm(residuals, axis=1) * 1e3
    return float(np.sqrt(np.mean(norm**2))), float(np.mean(norm))


def learnable_bound(
    geo: Calibration,
    recording: Recording,
    holdout: Recording | None,
    fold: IntArray,
    fold_parameters: dict[int, ParameterVector],
    scored_on: str,
) -> LearnableBound:
    """The bound of `geo` (the geometric calibration of `recording`): on `holdout` (the
    residual model fitted on all calibration residuals), else over the folds `fold` (n,)
    with `fold_parameters` the geometry refitted without each fold (the residual model
    fitted on that fold's training residuals). The hyperparameters come from the
    calibration residuals (in the k-fold case including the fold scored: two numbers,
    a mild optimism of the bound)."""
    n_targets = len(recording.target_names)
    poses, points, model = recording.poses, recording.points, geo.model
    residuals = geo.predict(poses) - points
    hyper = search_hyperparameters(poses, residuals, fold, n_targets)
    if holdout is not None:
        learned = fit_residual_model(poses, residuals, n_targets, hyper)
        before = geo.predict(holdout.poses) - holdout.points
        after = before - learned.predict(holdout.poses)
    else:
        before, after = np.empty_like(points), np.empty_like(points)
        for f, params in fold_parameters.items():
            train, test = fold != f, fold == f
            fitted = model.target_points(params, poses) - points
            local = fit_residual_model(poses.subset(train), fitted[train], n_targets, hyper)
            before[test] = fitted[test]
            after[test] = fitted[test] - local.predict(poses.subset(test))
    geo_rms, geo_mean = _figures(before)
    rms, mean = _figures(after)
    share = 1.0 - rms / geo_rms if geo_rms > 0 else 0.0
    return LearnableBound(METHOD, scored_on, geo_rms, geo_mean, rms, mean, share, *hyper)
