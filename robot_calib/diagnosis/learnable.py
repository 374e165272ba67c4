"""The learnable bound: how far any model could bring the held-out error from these data.

A nonparametric model of the geometric calibration's residuals, fitted on the calibration
poses only and scored where the rungs are scored (the hold-out bags, else the same k-fold
over whole poses, the geometry refitted per fold): "any model could reach about X mm from
these data". Residual structure that is systematic in the joint readings is learnable;
noise, and structure the data do not sample, are not. The ladder then reports what share
of that learnable gap (geometric's held-out error minus the bound) each physical effect
explains.

The model (`identify.correction_structured`):
load-driven geometry first, every link frame's small motion times the gravity moment it
carries and steps of its joint's gravity torque (plus the model's own Jacobian columns),
a ridge fit whose ridge is chosen by generalised cross-validation on the calibration
residuals only; then, on what that leaves, the Gaussian process of `identify.correction`
(squared-exponential kernel on
(sin q_j, cos q_j) of every joint's reading, periodic so a joint's +-180 deg meet, one
length scale per joint, white noise, the target's code with several targets), its
hyperparameters by marginal likelihood on the calibration poses only: on hold-out bags
from all calibration residuals, in the k-fold case per fold from that fold's training
poses (nested: the fold scored never chooses them; the first fold's hyperparameters start
the others' search). Every calibration pose is fitted (exact up to MAX_POINTS, a subset of
regressors on INDUCING inducing poses above). A length scale per joint learns smooth
pose-dependent structure (gravity, compliance, a joint's low harmonics) and ignores the
joints it does not depend on; structure faster than its shortest length scale (a high
harmonic of a gear) it learns poorly, and says so when a length scale ends there: the
bound is what this model learns, a lower bound of what is learnable. The same correction,
fitted on every calibration residual, is the learned part of the hybrid model
(`corrected_heldout`).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np

from robot_calib.identify.calibration import Calibration
from robot_calib.identify.correction import (
    INDUCING,
    MAX_LEARN,
    MAX_POINTS,
    Hyperparameters,
    fitting_rows,
)
from robot_calib.identify.correction_structured import LearnedCorrection, StructuredCorrection
from robot_calib.identify.correction_structured_fit import (
    StructuredPart,
    fit_structured,
    fit_structured_part,
)
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import Recording
from robot_calib.model import corrected
from robot_calib.parallel import Box, aside, mailbox
from robot_calib.records import Record

METHOD = (
    "load-driven geometry of the geometric residuals (link frames' motions times the "
    "gravity loads they carry, ridge by generalised cross-validation on the calibration "
    "poses, per fold on its training poses in k-fold), then a Gaussian process of what it "
    "leaves (squared-exponential kernel on sin/cos of "
    "the joint readings, one length scale per joint, white noise; hyperparameters by "
    f"marginal likelihood on at most {MAX_LEARN} calibration poses, per fold from its "
    f"training poses in k-fold; exact on up to {MAX_POINTS} poses, else a subset of "
    f"regressors on {INDUCING})"
)

#: poses a fold after the first learns its hyperparameters on, warm-started from the first
#: fold's (the search only refines them: 300 poses cost a quarter of MAX_LEARN's)
WARM_LEARN = 300
#: the bound must beat geometric by this share of its held-out rms to count as structure
MIN_LEARNABLE_SHARE = 0.05


@dataclass(frozen=True)
class LearnableBound(Record):
    """DIAGNOSIS.json `learnable` (msgs_doc/diagnosis.md): geometric's held-out error and
    that of geometric corrected by the residual model, on the same held-out data [mm];
    learnable_share = 1 - corrected / geometric (rms): the part of geometric's held-out
    error that is systematic and learnable from these data.

    The correction fitted on every calibration pose: length_scales_deg (J,) each joint's
    length scale [deg] (null: the residuals do not depend on the joint), noise_mm the
    white noise it attributes to the residuals (1-sigma per axis) [mm], fitted_poses;
    warnings: hyperparameters at an edge of their range (all folds'), one line each."""

    method: str
    scored_on: str
    geometric_abs_rms_mm: float
    geometric_abs_mean_mm: float
    holdout_abs_rms_mm: float
    holdout_abs_mean_mm: float
    learnable_share: float
    length_scales_deg: list[float | None] = field(default_factory=list)
    noise_mm: float | None = None
    fitted_poses: int = 0
    warnings: list[str] = field(default_factory=list)
    # the model whose residuals the process learned: geometric, or the ladder's best
    # physical rung (the hybrid model's physical part)
    learned_on: str = "geometric"

    @property
    def structure_left(self) -> bool:
        """True when the residual model beats geometric by MIN_LEARNABLE_SHARE or more."""
        return self.learnable_share >= MIN_LEARNABLE_SHARE

    @property
    def bounds(self) -> bool:
        """False when the residual model did worse held out than geometric alone: it did
        not fit (it learned the calibration poses, not the robot), so its figure bounds
        nothing (a '10.0150 mm bound' beside a 0.155 mm geometric error)."""
        return self.holdout_abs_rms_mm <= self.geometric_abs_rms_mm

    def line(self) -> str:
        if not self.bounds:
            edge = f"; {len(self.warnings)} warning(s) in the reports" if self.warnings else ""
            return (
                f"learnable bound: none: the residual model did not fit (geometric "
                f"{self.geometric_abs_rms_mm:.4f} mm rms held-out, "
                f"{self.holdout_abs_rms_mm:.4f} mm with it: it learned the calibration "
                f"poses, not the robot; {self.scored_on}{edge})"
            )
        share = (
            f"{100 * self.learnable_share:.0f} % of geometric's error is learnable"
            if self.learnable_share > 0
            else "it learns nothing"
        )
        edge = f"; {len(self.warnings)} warning(s) in the reports" if self.warnings else ""
        whose = "its" if self.learned_on == "geometric" else f"{self.learned_on}'s"
        return (
            f"learnable bound: geometric {self.geometric_abs_rms_mm:.4f} mm -> "
            f"{self.holdout_abs_rms_mm:.4f} mm rms held-out with load-driven geometry and a "
            f"Gaussian process of {whose} residuals ({share}; {self.scored_on}{edge})"
        )


def _figures(residuals: Array) -> tuple[float, float]:
    if not len(residuals):
        return 0.0, 0.0
    norm = np.linalg.norm(residuals, axis=1) * 1e3
    return float(np.sqrt(np.mean(norm**2))), float(np.mean(norm))


def corrected_heldout(
    cal: Calibration,
    recording: Recording,
    holdout: Recording | None,
    fold: IntArray,
    fold_parameters: dict[int, ParameterVector],
    rng: np.random.Generator | None = None,
    final: bool = True,
) -> tuple[Array, Array, LearnedCorrection]:
    """The residuals of `cal`'s physical model (its own correction, if any, left out) on
    held-out data before and after a learned correction (`identify.correction_structured`:
    load-driven geometry, then a Gaussian process of the rest), and the
    correction fitted on every calibration residual of `cal` (the hybrid model's).

    cal : a calibration of `recording` (its measurements, tracker blunders left out)
    holdout : hold-out measurements: scored there, the correction fitted on every
        calibration residual; None: over the folds
    fold : shape (n,), the fold of each measurement of `recording` (whole poses)
    fold_parameters : per fold, `cal`'s parameters refitted without it; fold f is scored
        with them and a correction fitted on their residuals at the other folds' poses
        (its hyperparameters from those poses only, the first fold's starting the search)
    rng : draws the learning subsets and inducing poses (default: seed 0)
    final : False to skip the correction of all calibration residuals in the k-fold case:
        the first fold's is returned instead (its hyperparameters, length scales and noise
        are those the final one would reuse); a caller that may not apply it fits the
        final one later (`final_correction`)

    Returns
    -------
    before : shape (m, 3), predicted - measured on the held-out data [m, tracker frame]:
        every hold-out measurement, else those of the folds in `fold_parameters` in
        recording order
    after : shape (m, 3), the same minus the correction's predicted residual [m]
    correction : the correction of all calibration residuals of `cal` (with `final`
        False in the k-fold case: the first fold's), its `warnings` those of every fold
    """
    rng = np.random.default_rng(0) if rng is None else rng
    poses, points = recording.poses, recording.points
    residuals = cal.model.target_points(cal.parameters, poses) - points
    if holdout is not None:
        rows = fitting_rows(len(poses))
        correction = fit_structured(
            cal.model, cal.parameters, poses.subset(rows), residuals[rows], rng
        )
        before = cal.model.target_points(cal.parameters, holdout.poses) - holdout.points
        with np.errstate(over="ignore", invalid="ignore"):  # a model beyond physics (1e9 m
            # of backlash): its inf / nan figures are flagged implausible, not a warning line
            return before, corrected(before, holdout.poses, correction), correction
    before, after = np.zeros_like(points), np.zeros_like(points)
    folds = list(fold_parameters)
    seeds = rng.integers(0, 2**63, size=len(folds))  # each fold its own stream: any order
    train_rows: list[IntArray] = []
    for f in folds:
        train = np.flatnonzero(fold != f)
        train_rows.append(train[fitting_rows(len(train))])

    def structure(k: int) -> tuple[StructuredPart, Array]:
        """Fold folds[k]'s load-driven geometry (no hyperparameter needed), and its
        parameters' residuals (n, 3) [m] at every pose, which it is fitted on."""
        train = train_rows[k]
        fitted = cal.model.target_points(fold_parameters[folds[k]], poses) - points
        return fit_structured_part(
            cal.model, fold_parameters[folds[k]], poses.subset(train), fitted[train]
        ), fitted

    def one(
        k: int,
        structured: tuple[StructuredPart, Array],
        start: Hyperparameters | None,
        on_learned: Callable[[Hyperparameters], object] | None = None,
    ) -> tuple[StructuredCorrection, Array]:
        """Fold folds[k]'s correction learned on its training poses (its hyperparameters
        searched from `start`, else cold; `on_learned` called with them at once), and its
        prediction at the fold's poses (m, 3) [m] (recording order)."""
        train, test = train_rows[k], fold == folds[k]
        part, fitted = structured
        local = fit_structured(
            cal.model,
            fold_parameters[folds[k]],
            poses.subset(train),
            fitted[train],
            np.random.default_rng(seeds[k]),
            start=start,
            max_learn=MAX_LEARN if start is None else WARM_LEARN,
            part=part,
            on_learned=on_learned,
        )
        return local, local.predict(poses.subset(test))

    computed: dict[int, tuple[StructuredPart, Array]] = {}  # each process's own

    def part(k: int) -> tuple[StructuredPart, Array]:
        if k not in computed:
            computed[k] = structure(k)
        return computed[k]

    def rest(k: int, box: Box[Hyperparameters]) -> tuple[tuple[str, ...], Array]:
        """Fold folds[k] from the first fold's hyperparameters (`box`): `one`'s warnings
        and prediction, what the caller needs (light to send)."""
        local, predicted = one(k, part(k), box.get())
        return local.warnings, predicted

    warned: list[tuple[str, ...]] = []  # each fold's warnings, in the order of `folds`
    learned: StructuredCorrection | None = None  # the first fold's correction
    if folds:
        # the folds are independent but for the process's hyperparameters, the first
        # fold's starting the others' search. Two processes (`parallel.aside`, a forked
        # child from the command line: threads ran
        # at 1.1 cores): a child fits the other folds' load-driven geometry while this one
        # learns the first fold's hyperparameters, then (they come through `box` as soon as
        # they are learned) half of the other folds while this one fits the first fold and
        # the rest. Results are the same either way.
        others = list(range(1, len(folds)))
        theirs = others[: (len(others) + 1) // 2]
        mine = [k for k in others if k not in theirs]
        # the child: first the geometry of every other fold (this process's folds' first:
        # wanted soonest), all while this one learns (the hyperparameters come at about
        # the time the child is done with them), then its own folds' processes (its
        # results sent as they are done): 0.1 s sooner than each fold's geometry just
        # before its process (the child waited for the hyperparameters in between)
        tasks: list[tuple[Hashable, Callable[[], Any]]]
        tasks = [(("part", k), partial(part, k)) for k in mine]
        with mailbox() as box:
            tasks += [(("part", k), partial(part, k)) for k in theirs]
            tasks += [(("fold", k), partial(rest, k, box)) for k in theirs]
            with aside(tasks, mailbox=box) as child:
                learned, predicted = one(0, part(0), None, on_learned=box.put)
                outcomes = {0: (learned.warnings, predicted)}
                for k in mine:
                    computed[k] = child.result(("part", k))
                    outcomes[k] = rest(k, box)
                for k in theirs:
                    computed[k] = child.result(("part", k))
                    outcomes[k] = child.result(("fold", k))
        for k, f in enumerate(folds):
            test = fold == f
            before[test] = computed[k][1][test]
            after[test] = computed[k][1][test] - outcomes[k][1]
            warned.append(outcomes[k][0])
    warnings = [f"{w} (fold {f})" for f, ws in zip(folds, warned) for w in ws]
    scored = np.isin(fold, folds)
    if not final and learned is not None:
        return before[scored], after[scored], replace(learned, warnings=tuple(warnings))
    # all calibration residuals, with the first fold's hyperparameters (learned on most of
    # the same calibration poses: a search again would change them by its noise)
    hyper = None if learned is None else learned.hyper
    return before[scored], after[scored], _fitted_on_all(cal, recording, hyper, warnings)


def final_correction(
    cal: Calibration, recording: Recording, first: LearnedCorrection
) -> StructuredCorrection:
    """The correction of every calibration residual of `cal` (of `recording`), its
    process's hyperparameters those of `first` (the first fold's, from `corrected_heldout`
    with `final` False) and its warnings `first`'s (every fold's)."""
    return _fitted_on_all(cal, recording, first.hyper, first.warnings)


def _fitted_on_all(
    cal: Calibration,
    recording: Recording,
    hyper: Hyperparameters | None,
    folds_warnings: Sequence[str],
) -> StructuredCorrection:
    """The correction of the residuals of `cal` at (at most MAX_FIT_POSES of) the poses of
    `recording`, its process's hyperparameters `hyper` (None: learned), its warnings its
    own and then the folds'. With `hyper` given on at most MAX_POINTS poses no random draw
    is made (the seed only serves a search)."""
    rows = fitting_rows(len(recording))
    poses = recording.poses.subset(rows)
    residuals = cal.model.target_points(cal.parameters, poses) - recording.points[rows]
    out = fit_structured(
        cal.model, cal.parameters, poses, residuals, np.random.default_rng(0), hyper=hyper
    )
    return replace(out, warnings=out.warnings + tuple(folds_warnings))


def learnable_bound(
    geo: Calibration,
    recording: Recording,
    holdout: Recording | None,
    fold: IntArray,
    fold_parameters: dict[int, ParameterVector],
    scored_on: str,
) -> LearnableBound:
    """The bound of `geo` (the geometric calibration of `recording`) from
    `corrected_heldout`: on `holdout`, else over the folds `fold` (n,) with
    `fold_parameters` the geometry refitted without each fold; `scored_on` says which."""
    before, after, correction = corrected_heldout(geo, recording, holdout, fold, fold_parameters)
    assert correction is not None
    return bound_of(before, after, correction, scored_on)


def bound_of(
    geometric_residuals: Array,
    after: Array,
    correction: LearnedCorrection,
    scored_on: str,
    learned_on: str = "geometric",
) -> LearnableBound:
    """The bound from geometric's held-out residuals (m, 3) [m] and those (m, 3) [m] of
    the model `learned_on` corrected by a learned correction, on the same held-out data
    (`corrected_heldout`), and the `correction` fitted on all calibration residuals."""
    geo_rms, geo_mean = _figures(geometric_residuals)
    rms, mean = _figures(after)
    share = 1.0 - rms / geo_rms if geo_rms > 0 else 0.0
    method = (
        METHOD
        if learned_on == "geometric"
        else METHOD.replace("of the geometric residuals", f"of the residuals of {learned_on}")
    )
    return LearnableBound(
        method,
        scored_on,
        geo_rms,
        geo_mean,
        rms,
        mean,
        share,
        correction.length_scales_deg,
        correction.noise_mm,
        correction.n_fitted,
        list(correction.warnings),
        learned_on,
    )
