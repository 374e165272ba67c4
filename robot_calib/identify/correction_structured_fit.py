"""The fit of the hybrid correction (`identify.correction_structured`, whose docstring gives
the model): its structured part by ridge least squares on the load-driven design
(`fit_structured_part`), then the Gaussian process of what it leaves (`fit_structured`),
kept only when it generalises in a 2-fold check on the fitted poses.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from robot_calib.errors import InputError
from robot_calib.identify.correction import (
    MAX_LEARN,
    FittedCorrection,
    GaussianProcessCorrection,
    Hyperparameters,
    exact_holdout,
    fit_correction,
    fit_correction_at,
)
from robot_calib.identify.correction_structured import StructuredCorrection, rms_norm
from robot_calib.identify.load_features import (
    FEATURES,
    MIN_TAU_NM,
    STEP_SHARES,
    frame_loads,
    pose_blocks,
    structured_design,
)
from robot_calib.identify.ridge import Ridge, gcv_ridge
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses, reading_groups

#: rows (3 per pose) per column below which the structured part is not fitted
MIN_ROWS_PER_COLUMN = 1.0
#: the process of what the structure leaves is kept when, fitted on half the poses, it
#: brings the other half's rms down by this share (`_process_generalises`)
MIN_PROCESS_GAIN = 0.02
CHECK_MIN_POSES = 50  # per half; with fewer poses the process is kept unchecked
#: up to this many fitted poses the design's blocks are kept for the fitted values (a
#: block: 3 x 2000 x ~700 x 8 B = 34 MB; above, the design is computed again)
KEEP_DESIGN_POSES = 3000


@dataclass(frozen=True)
class StructuredPart:
    """The load-driven geometry of a hybrid correction, before its process
    (`fit_structured_part`): what `fit_structured` needs to go on.

    columns, step_tau, fit : as StructuredCorrection's (`fit` the ridge solution)
    structured : shape (n, 3), its predicted residual at the fitted poses [m, tracker frame]
    how : how it was fitted, for the method line
    warnings : its own warnings (a ridge at its grid's edge)
    """

    columns: tuple[str, ...]
    step_tau: Array
    fit: Ridge
    structured: Array
    how: str
    warnings: tuple[str, ...]


def fit_structured_part(
    model: KinematicModel, parameters: ParameterVector, poses: Poses, residuals: Array
) -> StructuredPart:
    """The load-driven geometry of `residuals` (n, 3) [m, tracker frame, predicted -
    measured] of `model` at `parameters` at `poses` by ridge least squares (ridge by
    generalised cross-validation on these residuals). Needs no hyperparameter of the
    process: folds can fit it while another fold's process searches them."""
    n = len(poses)
    if residuals.shape != (n, 3) or n == 0:
        raise InputError(
            f"learned correction: residuals of shape {residuals.shape} for "
            f"{n} poses (expected ({n}, 3), n >= 1)"
        )
    columns = tuple(name for name, free in zip(parameters.names, parameters.free) if free)
    n_joints = model.robot.n_joints
    torque = np.sqrt(np.mean(frame_loads(model.robot, poses.q)[:, :, 2] ** 2, axis=0))
    # one set of widths for every joint, sized by the most loaded joint: a lightly loaded
    # wrist joint gets no step sharper than the shoulder's (a sharp step fits noise and
    # makes the correction steep, which a compensation's fixed point does not survive)
    step_tau = np.maximum(np.outer(np.full(n_joints, torque.max()), STEP_SHARES), MIN_TAU_NM)
    size = n_joints * 6 * len(FEATURES) + len(columns)
    rows = 3 * n
    warnings: tuple[str, ...] = ()
    designs: list[Array] = []  # the design's blocks, kept for the fitted values
    if rows < MIN_ROWS_PER_COLUMN * size:
        fit = Ridge(np.zeros(size), math.inf, 0.0, False)
        how = (
            f"left out: {n} poses give {rows} rows for {size} columns (at least "
            f"{MIN_ROWS_PER_COLUMN:g} per column)"
        )
    else:
        gram, rhs, total = np.zeros((size, size)), np.zeros(size), 0.0
        for block in pose_blocks(n):
            design = structured_design(model, parameters, columns, step_tau, poses.subset(block))
            flat, y = design.reshape(-1, size), residuals[block].reshape(-1)
            if n <= KEEP_DESIGN_POSES:
                designs.append(design)
            gram += flat.T @ flat
            rhs += flat.T @ y
            total += float(y @ y)
        fit = gcv_ridge(gram, rhs, total, rows)
        how = (
            f"{size - fit.left_out} columns ({fit.left_out} of zero loads left out), "
            f"ridge {fit.ridge:.2g} of the largest eigenvalue by generalised "
            f"cross-validation, {fit.dof:.0f} degrees of freedom"
        )
        if fit.at_edge:
            warnings += (
                "warning: learned correction: the structured part's ridge ends at the "
                "smallest of its grid (the residuals are nearly all structure)",
            )
    if designs:  # the fitted values from the blocks the fit was made of (no second pass)
        structured = np.concatenate([d @ fit.coefficients for d in designs])
    else:
        structured = replace(
            _empty(model, parameters, columns, step_tau, n), coefficients=fit.coefficients
        ).structured(poses)
    return StructuredPart(columns, step_tau, fit, structured, how, warnings)


def fit_structured(
    model: KinematicModel,
    parameters: ParameterVector,
    poses: Poses,
    residuals: Array,
    rng: np.random.Generator | None = None,
    hyper: Hyperparameters | None = None,
    start: Hyperparameters | None = None,
    max_learn: int = MAX_LEARN,
    part: StructuredPart | None = None,
    on_learned: Callable[[Hyperparameters], object] | None = None,
) -> StructuredCorrection:
    """The hybrid correction of `residuals` (n, 3) [m, tracker frame, predicted -
    measured] of `model` at `parameters` at `poses`: the load-driven geometry
    (`fit_structured_part`, or `part` already fitted on these same arguments), then the
    Gaussian process of the rest (`fit_correction` with `rng`, `hyper`, `start`,
    `max_learn`, `on_learned`)."""
    rng = np.random.default_rng(0) if rng is None else rng
    if part is None:
        part = fit_structured_part(model, parameters, poses, residuals)
    structured, fit = part.structured, part.fit
    left = residuals - structured
    fitted = fit_correction_at(
        poses,
        left,
        len(model.targets),
        rng,
        hyper=hyper,
        start=start,
        max_learn=max_learn,
        on_learned=on_learned,
    )
    process, process_fitted = fitted.correction, fitted.fitted
    if not _process_generalises(fitted, poses, left):
        process_fitted = np.zeros_like(left)
        process = replace(
            process,
            dual=np.zeros_like(process.dual),
            mean_m=np.zeros(3),
            rms_m=0.0,
            method=process.method + "; left out: it learned nothing held out in a 2-fold "
            "check on the fitted poses",
        )
    method = (
        "load-driven geometry (every link frame's small motion times 1, the gravity moment "
        "it carries and steps of its joint's gravity torque, plus the model's own Jacobian "
        f"columns; ridge least squares: {part.how}), then a {process.method[0].lower()}"
        f"{process.method[1:]}"
    )
    out = StructuredCorrection(
        model,
        parameters,
        part.columns,
        part.step_tau,
        fit.coefficients,
        fit.ridge,
        fit.dof,
        rms_norm(structured),
        process,
        0.0,
        method,
        part.warnings + process.warnings,
    )
    return replace(out, rms_m=rms_norm(structured + process_fitted)).with_own_rms()


def _process_generalises(fitted: FittedCorrection, poses: Poses, left: Array) -> bool:
    """True when the process (its hyperparameters) fitted on either half of the poses (the
    measurements at one pose's readings on one side)
    brings the other half's `left` residuals (n, 3) [m] below (1 - MIN_PROCESS_GAIN) of
    their rms, over both halves: else what the structure leaves is noise to it (a process
    that interpolates noise roughens the correction for nothing). An exact fit's kernel
    is sliced, not computed again."""
    n = len(poses)
    if n < 2 * CHECK_MIN_POSES:
        return True
    process = fitted.correction
    group = reading_groups(poses.q)  # the reads of one pose on one side
    n_groups = int(group.max()) + 1
    if n_groups < 2 * CHECK_MIN_POSES:
        return True
    half = np.random.default_rng(1).permutation(n_groups)[group] < n_groups // 2
    before, after = 0.0, 0.0
    for train in (half, ~half):
        if fitted.phi is not None:
            predicted = exact_holdout(fitted.phi, process.hyper, left, train)
        else:
            local = fit_correction(
                poses.subset(train), left[train], process.n_targets, hyper=process.hyper
            )
            predicted = local.predict(poses.subset(~train))
        before += float(np.sum(left[~train] ** 2))
        after += float(np.sum((left[~train] - predicted) ** 2))
    return after < (1.0 - MIN_PROCESS_GAIN) ** 2 * before


def _empty(
    model: KinematicModel,
    parameters: ParameterVector,
    columns: tuple[str, ...],
    step_tau: Array,
    n: int,
) -> StructuredCorrection:
    """A structured correction with zero coefficients and a placeholder process (to
    evaluate the structured part of given coefficients)."""
    size = model.robot.n_joints * 6 * len(FEATURES) + len(columns)
    placeholder = GaussianProcessCorrection(
        np.zeros((1, model.robot.n_joints)),
        np.zeros(1, dtype=np.int64),
        np.zeros((1, 3)),
        Hyperparameters(np.zeros(model.robot.n_joints), 1.0, 1.0),
        np.zeros(3),
        1.0,
        len(model.targets),
        n,
        0.0,
        "",
    )
    return StructuredCorrection(
        model,
        parameters,
        columns,
        step_tau,
        np.zeros(size),
        math.inf,
        0.0,
        0.0,
        placeholder,
        0.0,
        "",
    )
