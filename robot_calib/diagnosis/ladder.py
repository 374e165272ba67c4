"""The diagnosis ladder: from `geometric`, add the effect that most reduces the error on data
not used to fit it, until nothing beats the noise level (msgs_doc/specification.md section 4).

Why one module: the climb (screen, refit, k-fold score, accept or stop) and its linearised
screen (`LinearScreen`) share the folds over whole poses (`pose_folds`), the selection score
(`combined_rms`) and the normal-equation sums (`_Sums`, which `kfold_parameters` uses too);
apart, each half would import the other's private pieces.

Screening is linearised and cheap: the current model is extended by every candidate at
zero (which changes no prediction), one Jacobian gives all candidate columns, and each
candidate is scored by k-fold cross-validation over whole poses (and on the hold-out bags
when given) with one Gauss-Newton step from the current solution. The winner is then
fitted in full (Levenberg-Marquardt) and its rung scored with real refits per fold.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from robot_calib.accuracy import Accuracy, accuracy
from robot_calib.diagnosis.frequency import (
    ASIDE_POSES,
    JointSpectrum,
    harmonic_candidates,
    joint_spectra,
)
from robot_calib.diagnosis.learnable import (
    LearnableBound,
    bound_of,
    corrected_heldout,
    final_correction,
)
from robot_calib.diagnosis.noise import NoiseLevel, estimate_noise
from robot_calib.effects import Effect, ladder_candidates
from robot_calib.identify.calibrate import calibrate, model_name
from robot_calib.identify.calibration import LEARNED_SUFFIX, Calibration
from robot_calib.identify.fit import BLOCK_POSES, PRIOR_ROW, weighted_rows
from robot_calib.identify.outliers import (
    Outlier,
    describe_outliers,
    outlier_mask,
    robust_sigma,
)
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.log import Log
from robot_calib.measurements import Recording
from robot_calib.measurements.split import N_FOLDS, pose_folds
from robot_calib.model import KinematicModel
from robot_calib.parallel import aside
from robot_calib.records import Record

MAX_RUNGS = 6
MIN_GAIN = 0.05  # a candidate must cut the held-out rms by 5 % ...
AT_FLOOR = 1.2  # ... and the ladder stops once held-out rms <= 1.2 x the noise floor
HOLDOUT_K = 12.0  # hold-out blunders: scored only, never refitted, so a higher bar
TRY_TOP = 3  # candidates refitted per round when the best one's refit disappoints
CONFIRMED = 0.05  # a refit within this share of its linearised score confirms the screening
SCREEN_DAMPING = 1e-6  # of the screening step, relative to unit-norm Jacobian columns


@dataclass(frozen=True)
class Rung:
    """One model of the ladder and its scores on held-out data (CV folds or hold-out bags)."""

    model: str
    effects: tuple[Effect, ...]
    calibration: Calibration
    heldout: Accuracy
    heldout_residuals: Array  # (m, 3) predicted - measured [m] of the scored points
    score_m: float  # selection score: combined k-fold + hold-out rms [m] after refits
    # the hybrid rung: `calibration` carries a learned correction; `insample` its in-sample
    # accuracy with it (the calibration's own `accuracy` is the physical model's)
    learned: bool = False
    insample: Accuracy | None = None
    # the measurements (indices into the recording) of `heldout_residuals` in the k-fold
    # case when only a subset was scored (SCORED_POSES); None: all of them
    scored_rows: IntArray | None = None

    def scored(self, points: Array) -> Array:
        """`points` (n, 3) of the recording (k-fold) at the rung's scored measurements."""
        return points if self.scored_rows is None else points[self.scored_rows]


@dataclass(frozen=True)
class RefitOutcome(Record):
    """One candidate the ladder refitted (DIAGNOSIS.json `refits`): its linearised
    held-out estimate, in-sample rms after the refit, held-out score (None: rejected
    before k-fold) [mm], whether it became a rung, and why not."""

    model: str
    linearised_mm: float
    insample_rms_mm: float
    heldout_mm: float | None
    accepted: bool
    reason: str


@dataclass(frozen=True)
class Ladder:
    """The rungs in the order added, the noise level, the candidates of every round, the
    recordings it was climbed and scored on (without the outliers) and the outliers."""

    rungs: list[Rung]
    noise: NoiseLevel
    scored_on: str
    candidates: list[list[tuple[str, float]]] = field(default_factory=list)
    recording: Recording | None = None
    holdout: Recording | None = None
    outliers: tuple[Outlier, ...] = ()
    learnable: LearnableBound | None = None  # what a residual model reaches (learnable.py)
    refits: list[RefitOutcome] = field(default_factory=list)  # every candidate refitted
    # the frequency scan of each rung the ladder scanned, by its model name
    spectra: dict[str, list[JointSpectrum]] = field(default_factory=dict)


def candidates(
    robot: RobotDescription,
    recording: Recording,
    present: tuple[Effect, ...],
    spectra: list[JointSpectrum] | None = None,
) -> list[Effect]:
    """Every effect x joint (x option, e.g. eccentricity order) of the vocabulary able to
    move a measured point (`Effect.ladder_candidates`), and the joint_harmonics the
    frequency scan `spectra` picked (`frequency.harmonic_candidates`), that add parameters
    to the model (not already present, nor covered by a present effect, e.g. a lower
    order)."""
    pool = ladder_candidates(robot, recording.poses)
    pool += harmonic_candidates(spectra or [], present)
    return [e for e in pool if not any(p.supersedes(e, robot) for p in present)]


def _replace(
    present: tuple[Effect, ...], new: Effect, robot: RobotDescription
) -> tuple[Effect, ...]:
    """`present` plus `new`, which replaces what it supersedes (e.g. a lower order)."""
    return tuple(e for e in present if not new.supersedes(e, robot)) + (new,)


#: poses the hybrid rung's learned correction is scored on at most in the k-fold case (and
#: its in-sample figures computed on): a fixed random subset of whole poses above
SCORED_POSES = 20000
#: poses the screening ranks candidates on at most (a fixed random subset of whole poses
#: above): its linearised figures only order the candidates, the refits and their k-fold
#: scores use every pose (a screening round of 100k poses and ~150 columns took 20 s)
SCREEN_POSES = 20000


Screened = tuple[Effect, float, float]  # candidate, linearised held-out, in-sample rms [m]


def _screen(
    cal: Calibration, pool: list[Effect], recording: Recording, holdout: Recording | None
) -> tuple[float, list[Screened]]:
    """Linearised held-out rms [m] of the current model, and of each candidate added with
    its linearised in-sample rms [m] (one step on all calibration points)."""
    robot = cal.model.robot
    recording = recording.at_most(SCREEN_POSES)  # a ranking: a random subset above
    holdout = None if holdout is None else holdout.at_most(SCREEN_POSES)
    every = cal.model.effects + tuple(pool)
    widest: list[Effect] = []  # every effect merged with those it shares parameters with
    for e in every:
        for k, w in enumerate(widest):
            merged = w.union(e, robot) if type(w) is type(e) else None
            if merged is not None:
                widest[k] = merged  # in place: the parameter order stays about that of `every`
                break
        else:
            widest.append(e)
    superset = KinematicModel(robot, tuple(widest), cal.model.targets, cal.model.oriented)
    params = superset.parameters().with_values(
        dict(zip(cal.parameters.names, cal.parameters.values))
    )
    base_cols = [params.index(name) for name in cal.parameters.free_names]
    screen = LinearScreen.of_model(superset, params, recording, holdout)
    base = screen.score(base_cols)
    scores = []
    for effect in pool:
        cols = base_cols + [
            params.index(name)
            for name in effect.parameter_names(robot)
            if params.index(name) not in base_cols
        ]
        scores.append((effect, screen.score(cols), screen.insample(cols)))
    return base, scores


def combined_rms(cv_residuals: Array, holdout_residuals: Array | None) -> float:
    """The selection score [m]: rms point error of the k-fold predictions and (when given)
    of the hold-out bags, each source weighted equally whatever its size."""
    parts = [cv_residuals] if holdout_residuals is None else [cv_residuals, holdout_residuals]
    return float(np.sqrt(np.mean([np.mean(np.sum(r**2, axis=1)) for r in parts])))


class LinearScreen:
    """`combined_rms` of |r + J dx| [m] for any subset of a model's columns: k-fold (dx the
    least-squares step on the other folds) and on the hold-out points (dx from all
    calibration points). Every fold's sums over its own rows are formed once over all
    columns (each scaled to unit norm): J^T J, J^T r and r^T r. A subset's fold then costs
    a (p, p) solve and its sum of squares |r + J dx|^2 = r^T r + 2 dx^T J^T r +
    dx^T J^T J dx, never a pass over the rows: the ladder screens ~100 candidates per
    round, and memory beyond the Jacobian is O(P^2) per fold.

    own : each fold's sums over its own rows (unscaled); holdout : the hold-out rows' sums
    or None; n_points, n_holdout : their numbers of points (3 rows each).
    """

    def __init__(
        self, own: dict[int, _Sums], holdout: _Sums | None, n_points: int, n_holdout: int = 0
    ) -> None:
        n_cols = len(next(iter(own.values())).rhs) if own else 0
        total = _Sums.total(list(own.values()), n_cols)
        norms = np.sqrt(np.maximum(np.diag(total.gram), 0.0))  # the columns' norms
        self.keep = norms > 0
        scale = np.where(self.keep, 1.0 / np.where(self.keep, norms, 1.0), 0.0)
        self.n_points, self.n_holdout = n_points, n_holdout
        # each fold's own sums (its test set's) and the training set's: the total minus its own
        self.own = {f: s.scaled(scale) for f, s in own.items()}
        self.all = total.scaled(scale)
        self.training = {f: self.all.minus(s) for f, s in self.own.items()}
        self.holdout = None if holdout is None else holdout.scaled(scale)

    @classmethod
    def of_rows(
        cls,
        residual: Array,
        jac: Array,
        fold: IntArray,
        h_res: Array | None = None,
        h_jac: Array | None = None,
    ) -> LinearScreen:
        """The screen of residuals (n, 3) [m] and their Jacobian (n, 3, P) with the fold
        (n,) of each, and hold-out rows h_res (m, 3), h_jac (m, 3, P) or None."""
        n_cols = jac.shape[-1]
        own = {
            int(f): _Sums.of(jac[fold == f].reshape(-1, n_cols), residual[fold == f].reshape(-1))
            for f in np.unique(fold)
        }
        held = None
        if h_res is not None and h_jac is not None:
            held = _Sums.of(h_jac.reshape(-1, n_cols), h_res.reshape(-1))
        return cls(own, held, len(residual), 0 if h_res is None else len(h_res))

    @classmethod
    def of_model(
        cls,
        model: KinematicModel,
        params: ParameterVector,
        recording: Recording,
        holdout: Recording | None,
    ) -> LinearScreen:
        """The screen of `model` at `params` on `recording` (k-fold by `pose_folds`) and
        `holdout`, its Jacobian evaluated BLOCK_POSES poses at a time and folded into the
        sums: memory O(block x P + P^2 x folds), never (n, 3, P)."""
        n_cols = len(params)
        fold = pose_folds(recording)

        def sums(
            rec: Recording, which: IntArray | None, first: int = 0, end: int | None = None
        ) -> dict[int, _Sums]:
            out: dict[int, _Sums] = {}
            end = len(rec) if end is None else end
            for start in range(first, end, BLOCK_POSES):
                rows = slice(start, min(start + BLOCK_POSES, end))
                predicted, jac = model.jacobian(params, rec.poses.subset(rows))
                residual = predicted - rec.points[rows]
                labels = np.zeros(len(residual), dtype=int) if which is None else which[rows]
                for f in np.unique(labels):
                    part = labels == f
                    block = _Sums.of(jac[part].reshape(-1, n_cols), residual[part].reshape(-1))
                    out[int(f)] = block if int(f) not in out else out[int(f)].plus(block)
            return out

        # the calibration poses' second half summed by a forked child meanwhile
        # (`parallel.aside`: a forked child from the command line) when enough to pay
        n = len(recording)
        half = n // 2 if n >= ASIDE_POSES else n
        with aside([("rest", partial(sums, recording, fold, half))] if half < n else []) as rest:
            own = sums(recording, fold, 0, half)
            held = None if holdout is None else sums(holdout, None).get(0)
            if half < n:
                for f, part in rest.result("rest").items():
                    own[f] = own[f].plus(part) if f in own else part
        return cls(own, held, n, 0 if holdout is None else len(holdout))

    @staticmethod
    def _step(normal: _Sums, cols: list[int]) -> Array:
        """The damped Gauss-Newton step (J^T J + SCREEN_DAMPING I) dx = -J^T r over `cols`
        (unit-norm columns): as one Levenberg-Marquardt step, directions the fold cannot
        determine do not take the prediction of the other fold anywhere (an undamped step
        sent a 10-term eccentricity candidate to 4x the error its refit reaches)."""
        damped = normal.gram[np.ix_(cols, cols)] + SCREEN_DAMPING * np.eye(len(cols))
        return np.asarray(np.linalg.solve(damped, -normal.rhs[cols]), dtype=float)  # SPD: damped

    def insample(self, cols: list[int]) -> float:
        """rms |r + J dx| [m] over every calibration point, dx the step from all of them:
        the linearised in-sample figure a refit of these columns should reach."""
        cols = [c for c in cols if self.keep[c]]
        total = self.all.after(self._step(self.all, cols), cols)
        return float(np.sqrt(total / max(self.n_points, 1)))

    def score(self, cols: list[int]) -> float:
        cols = [c for c in cols if self.keep[c]]
        total = sum(
            self.own[f].after(self._step(normal, cols), cols)
            for f, normal in self.training.items()
        )
        cv = total / max(self.n_points, 1)
        if self.holdout is None:
            return float(np.sqrt(cv))
        held = self.holdout.after(self._step(self.all, cols), cols) / max(self.n_holdout, 1)
        return float(np.sqrt(np.mean([cv, held])))  # as combined_rms: each source equally


@dataclass(frozen=True)
class _Sums:
    """The sums of a set of rows (scaled Jacobian A (rows, P), residual r (rows,) [m]) that
    every linear figure of them needs: gram = A^T A, rhs = A^T r, rr = r^T r [m^2]."""

    gram: Array
    rhs: Array
    rr: float

    @classmethod
    def of(cls, a: Array, r: Array) -> _Sums:
        return cls(a.T @ a, a.T @ r, float(r @ r))

    @classmethod
    def total(cls, parts: list[_Sums], n_cols: int) -> _Sums:
        gram, rhs = np.zeros((n_cols, n_cols)), np.zeros(n_cols)
        for p in parts:
            gram += p.gram
            rhs += p.rhs
        return cls(gram, rhs, sum(p.rr for p in parts))

    def minus(self, other: _Sums) -> _Sums:
        return _Sums(self.gram - other.gram, self.rhs - other.rhs, self.rr - other.rr)

    def plus(self, other: _Sums) -> _Sums:
        return _Sums(self.gram + other.gram, self.rhs + other.rhs, self.rr + other.rr)

    def scaled(self, scale: Array) -> _Sums:
        """The sums of the rows with column c multiplied by scale[c] (P,)."""
        return _Sums(self.gram * np.outer(scale, scale), self.rhs * scale, self.rr)

    def after(self, step: Array, cols: list[int]) -> float:
        """|r + A[:, cols] step|^2 [m^2] of these rows (never below 0: rounding)."""
        value = self.rr + 2.0 * float(step @ self.rhs[cols])
        value += float(step @ self.gram[np.ix_(cols, cols)] @ step)
        return max(value, 0.0)


def score_rung(
    cal: Calibration, recording: Recording, holdout: Recording | None
) -> tuple[Accuracy, Array, float]:
    """Held-out accuracy of a calibrated model (on the hold-out bags when given, else k-fold
    over whole poses, each fold refitted from the full solution), its residuals (m, 3) [m],
    and the selection score `combined_rms` [m]."""
    cv_acc, cv_res = _kfold(cal, recording)
    if holdout is None:
        return cv_acc, cv_res, combined_rms(cv_res, None)
    predicted = cal.predict(holdout.poses)
    h_res = predicted - holdout.points
    return accuracy(holdout.points, predicted), h_res, combined_rms(cv_res, h_res)


def kfold_parameters(
    cal: Calibration, recording: Recording
) -> tuple[IntArray, dict[int, ParameterVector]]:
    """The folds (n,) of `recording` (`pose_folds`) and, per fold, the parameters of `cal`'s
    model refitted without that fold's measurements: one Gauss-Newton step from the full
    solution on the other folds' rows (weighted as the fit weighs them, the weak prior
    included, columns scaled to unit norm, damped by SCREEN_DAMPING), less the step all
    the rows would take (none at a converged fit). That is the refit to first order (exact
    for a model linear in its parameters fitted to convergence); it costs one Jacobian
    instead of five Levenberg-Marquardt solves (105 s of a 138 s diagnosis were k-fold
    refits)."""
    fold = pose_folds(recording)
    params = cal.parameters
    residual, jac, owner = weighted_rows(cal.model, params, recording.poses, recording.points)
    prior = owner == PRIOR_ROW
    row_fold = np.full(len(owner), -1)  # the prior's rows are in no fold: every fold keeps them
    row_fold[~prior] = fold[owner[~prior]]
    x = params.pack()
    # each fold's sums over its own rows, and the prior's (in every fold's training set):
    # a fold's training sums are the total minus its own (no copy of the rows per fold)
    own = {int(f): _Sums.of(jac[row_fold == f], residual[row_fold == f]) for f in np.unique(fold)}
    data = _Sums.total(list(own.values()), len(x))
    norms = np.sqrt(np.maximum(np.diag(data.gram), 0.0))  # the data's columns set the scale
    scale = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 0.0)
    total = data.plus(_Sums.of(jac[prior], residual[prior])).scaled(scale)
    damping = SCREEN_DAMPING * np.eye(len(x))
    # the step the whole data would take from `cal`'s solution: 0 at a converged fit; where
    # a nonlinear parameter (a warm-up's time constant) stopped short of it, every fold
    # would take it too, and a fold's refit differs from the whole fit by the rest only
    whole = -np.linalg.solve(total.gram + damping, total.rhs) * scale
    fitted = {}
    for f, sums in own.items():
        train = total.minus(sums.scaled(scale))
        step = -np.linalg.solve(train.gram + damping, train.rhs) * scale
        fitted[f] = params.unpack(x + step - whole)
    return fold, fitted


def _kfold(cal: Calibration, recording: Recording) -> tuple[Accuracy, Array]:
    fold, fitted = kfold_parameters(cal, recording)
    predicted = np.empty_like(recording.points)
    for f, params in fitted.items():
        test = fold == f
        predicted[test] = cal.model.target_points(params, recording.poses.subset(test))
    return accuracy(recording.points, predicted), predicted - recording.points


def run_ladder(
    recording: Recording,
    robot: RobotDescription,
    holdout: Recording | None = None,
    log: Log | None = None,
    tracker_sigma_m: float | None = None,
) -> Ladder:
    """Climb the ladder on `recording`, scoring on `holdout` (or k-fold CV); the noise
    floor from the data, else `tracker_sigma_m` (a stated 1-sigma per axis [m]), else
    unknown (`estimate_noise`). Ends with the learnable bound (`learnable_bound`).

    Tracker blunders never become robot effects: the measurements the geometric
    calibration flags (`calibrate`'s outlier screening; those the best rung then explains
    are re-admitted and the ladder climbed again) and the hold-out points beyond
    HOLDOUT_K robust sigmas of the best rung's hold-out residuals (then the ladder is
    climbed again without them) are left out of every rung, its scores and the noise floor,
    and listed in `Ladder.outliers`."""
    say = log or (lambda _m: None)
    full = recording
    geo = calibrate(recording, robot, "geometric", log=log, tracker_sigma_m=tracker_sigma_m)
    outliers = geo.outliers
    if geo.inliers is not None:
        recording = recording.subset(geo.inliers)
    climb = partial(_climb, robot=robot, say=say, tracker_sigma_m=tracker_sigma_m)
    found = climb(recording, geo=geo, holdout=holdout)
    if geo.inliers is not None and len(found.rungs) > 1:
        # Judged again against the best rung: what an effect explains (the coldest points
        # of a strong thermal effect, the far ends of a compliance) is no blunder.
        best = found.rungs[-1].calibration
        residual = best.predict(full.poses) - full.points
        sigma = robust_sigma(residual[geo.inliers])
        still = ~geo.inliers & outlier_mask(residual, sigma)
        readmitted, n_flagged = int((~geo.inliers & ~still).sum()), int((~geo.inliers).sum())
        if readmitted:
            say(
                f"outliers: {readmitted} of the {n_flagged} flagged measurements are explained "
                f"by {best.name}: re-admitted, climbing again"
            )
            recording = full.subset(~still)
            geo = calibrate(
                recording,
                robot,
                "geometric",
                log=None,
                screen_outliers=False,
                tracker_sigma_m=tracker_sigma_m,
            )
            outliers = describe_outliers(full, still, residual, sigma)
            found = climb(recording, geo=geo, holdout=holdout)
    if holdout is not None:  # judged against the best model: an effect's structure is not
        best = found.rungs[-1].calibration  # a blunder; no refit possible, so a higher bar
        h_res = best.predict(holdout.poses) - holdout.points
        sigma = robust_sigma(h_res)
        flagged = outlier_mask(h_res, sigma, HOLDOUT_K)
        if flagged.any():
            outliers += describe_outliers(holdout, flagged, h_res, sigma)
            holdout = holdout.subset(~flagged)
            say(
                f"outliers: {int(flagged.sum())} hold-out points beyond {HOLDOUT_K:g} robust "
                f"sigmas ({sigma * 1e3:.4f} mm) of {best.name}: not scored; climbing again"
            )
            found = climb(recording, geo=geo, holdout=holdout)
    rungs, noise, scored_on = found.rungs, found.noise, found.scored_on
    bound, hybrid = _learn_the_rest(rungs, recording, holdout, scored_on)
    say(bound.line())
    if hybrid is not None:
        say(
            f"  hybrid {hybrid.model}: held-out rms {hybrid.heldout.absolute_rms_mm:.4f} mm "
            f"(physical {rungs[-1].heldout.absolute_rms_mm:.4f} mm)"
        )
        rungs = [*rungs, hybrid]
    return Ladder(
        rungs,
        noise,
        scored_on,
        found.rounds,
        recording,
        holdout,
        outliers,
        bound,
        found.refits,
        found.spectra,
    )


def _learn_the_rest(
    rungs: list[Rung], recording: Recording, holdout: Recording | None, scored_on: str
) -> tuple[LearnableBound, Rung | None]:
    """The learnable bound and the hybrid rung: a learned correction (load-driven geometry,
    then a Gaussian process: `identify.correction_structured`) of what the best
    physical rung leaves (`learnable.corrected_heldout`), scored on the held-out data of
    the rungs (hold-out bags, else the same k-fold, nested); the hybrid rung (the best
    rung plus the correction fitted on all its calibration residuals) when it beats the
    best rung by MIN_GAIN on those data, else None. The bound: geometric's held-out error
    and the hybrid's, on the same data."""
    physical = rungs[-1]
    geometric = rungs[0].heldout_residuals
    # above SCORED_POSES poses the correction is scored on a fixed random subset of them
    # (its predictions at 80k held-out poses cost more than the rest of a diagnosis)
    keep = recording.sample_mask(SCORED_POSES)
    scored = recording if keep is None else recording.subset(keep)
    if holdout is None:  # the folds' parameters refitted, for the correction's own k-fold
        fold, fitted = kfold_parameters(physical.calibration, recording)
        if keep is not None:
            fold, geometric = fold[keep], geometric[keep]
    else:
        fold, fitted = pose_folds(scored), {}
    before, after, correction = corrected_heldout(
        physical.calibration, scored, holdout, fold, fitted, final=False
    )
    score = combined_rms(after, None)
    gain = score <= (1.0 - MIN_GAIN) * combined_rms(before, None)
    if gain and holdout is None:  # k-fold: the first fold's correction stood in so far
        correction = final_correction(physical.calibration, recording, correction)
    bound = bound_of(geometric, after, correction, scored_on, physical.model)
    if not gain:
        return bound, None
    measured = holdout.points if holdout is not None else scored.points  # as `after`
    cal = replace(physical.calibration, correction=correction)
    acc = accuracy(measured, measured + after)
    insample = accuracy(scored.points, cal.predict(scored.poses))
    cal = replace(cal, hybrid_accuracy=insample)  # what its scores are judged against
    rows = None if keep is None or holdout is not None else np.flatnonzero(keep)
    return bound, Rung(
        physical.model + LEARNED_SUFFIX,
        physical.effects,
        cal,
        acc,
        after,
        score,
        learned=True,
        insample=insample,
        scored_rows=rows,
    )


@dataclass(frozen=True)
class _Climb:
    """What one climb of the ladder found (`_climb`)."""

    rungs: list[Rung]
    noise: NoiseLevel
    scored_on: str
    rounds: list[list[tuple[str, float]]]
    refits: list[RefitOutcome]
    spectra: dict[str, list[JointSpectrum]]


#: a refit whose in-sample rms exceeds the screening's linearised in-sample figure by this
#: factor disappointed the screening: rejected before its k-fold refits
SCREEN_SLACK = 1.1


def _try_rung(
    current: Rung,
    effect: Effect,
    lin_score: float,
    lin_insample: float,
    recording: Recording,
    holdout: Recording | None,
    say: Log,
) -> tuple[Rung | None, RefitOutcome]:
    """`current` plus `effect` refitted and scored: the new rung when it cuts the score by
    MIN_GAIN (else None), and the refit's outcome (`RefitOutcome`)."""
    robot = current.calibration.model.robot
    effects = _replace(current.effects, effect, robot)
    name = model_name(effects)
    cal = calibrate(
        recording, robot, name, log=None, start=current.calibration, screen_outliers=False
    )
    insample = cal.accuracy.absolute_rms_mm
    reason = _rejected_before_kfold(cal, current, lin_insample)
    if reason:
        say(f"  try {name}: linearised {lin_score * 1e3:.4f} mm, rejected: {reason}")
        return None, RefitOutcome(name, lin_score * 1e3, insample, None, False, reason)
    acc, res, score = score_rung(cal, recording, holdout)
    say(
        f"  try {name}: linearised {lin_score * 1e3:.4f} mm, refitted "
        f"{score * 1e3:.4f} mm ({current.model}: {current.score_m * 1e3:.4f})"
    )
    good = score <= (1.0 - MIN_GAIN) * current.score_m
    outcome = RefitOutcome(
        name,
        lin_score * 1e3,
        insample,
        score * 1e3,
        good,
        ""
        if good
        else f"held-out {score * 1e3:.4f} mm is not {MIN_GAIN:.0%} below "
        f"{current.model}'s {current.score_m * 1e3:.4f} mm",
    )
    return (Rung(name, effects, cal, acc, res, score) if good else None), outcome


def _climb(
    recording: Recording,
    robot: RobotDescription,
    holdout: Recording | None,
    geo: Calibration,
    say: Log,
    tracker_sigma_m: float | None = None,
) -> _Climb:
    """The rungs from `geo` (the geometric calibration of `recording`) up, the noise level,
    what they are scored on, the candidates of every round, every refit's outcome and the
    frequency scan of every rung it scanned."""
    noise = estimate_noise(
        recording, geo.residuals, int(geo.parameters.free.sum()), tracker_sigma_m
    )
    scored_on = "hold-out bags" if holdout is not None else f"{N_FOLDS}-fold CV over poses"
    floor = (
        f"{noise.sigma_m * 1e3:.4f} mm per axis ({noise.basis})"
        if noise.independent
        else "unknown (the stated accuracy is refuted: see below)"
        if noise.warning
        else "unknown (no repeat poses, circle sweeps or stated accuracy)"
    )
    say(f"noise floor: {floor}; scoring on {scored_on}")
    if noise.warning:
        say(noise.warning)
    acc, res, score = score_rung(geo, recording, holdout)
    rungs = [Rung("geometric", (), geo, acc, res, score)]
    rounds: list[list[tuple[str, float]]] = []
    refits: list[RefitOutcome] = []
    spectra: dict[str, list[JointSpectrum]] = {}
    try_rung = partial(_try_rung, recording=recording, holdout=holdout, say=say)
    say(
        f"  geometric: held-out rms {acc.absolute_rms_mm:.4f} mm"
        + (f" (floor {noise.floor_rms_m * 1e3:.4f})" if noise.independent else "")
        + (
            f"; selection score {score * 1e3:.4f} mm (the k-fold's and the hold-out's rms "
            "together, each counting equally: the rungs below are scored by it)"
            if holdout is not None
            else ""
        )
    )
    while len(rungs) <= MAX_RUNGS:
        current = rungs[-1]
        at_floor = current.heldout.absolute_rms_mm <= AT_FLOOR * noise.floor_rms_m * 1e3
        if at_floor and noise.independent:
            break
        fitted = current.calibration
        scan = joint_spectra(fitted.model, fitted.parameters, recording, fitted.residuals)
        spectra[current.model] = scan
        pool = candidates(robot, recording, current.effects, scan)
        distinct = recording.distinct_points()  # re-reads and repeats pin no parameter
        pool, left_out = _affordable(pool, current.calibration, distinct)
        if left_out:
            say(
                f"  {left_out} candidate(s) left out: more free parameters than "
                f"{distinct} distinct points can pin ({RESIDUALS_PER_PARAMETER} residuals "
                "per parameter)"
            )
        if not pool:
            break
        base, scores = _screen(current.calibration, pool, recording, holdout)
        ranked = sorted(scores, key=lambda s: s[1])
        rounds.append(
            [(model_name(_replace(current.effects, e, robot)), s) for e, s, _ in ranked[:8]]
        )
        accepted: Rung | None = None
        at_floor_m = AT_FLOOR * noise.floor_rms_m if noise.independent else 0.0
        for effect, lin_score, lin_insample in ranked[:TRY_TOP]:  # refits confirm the screen
            if lin_score > (1.0 - MIN_GAIN) * base:
                break
            rung, outcome = try_rung(current, effect, lin_score, lin_insample)
            refits.append(outcome)
            if rung is not None and (accepted is None or rung.score_m < accepted.score_m):
                accepted = rung
            if rung is not None and rung.score_m <= at_floor_m:
                break  # at the noise floor already: nothing left to win
            if rung is not None and rung.score_m <= (1.0 + CONFIRMED) * lin_score:
                break  # the refit confirms the screening: the rest screened worse
        if accepted is None:
            break
        rungs.append(accepted)
        # Gear harmonics of other joints screened in the same round barely interact with the
        # ones just added (other columns): tried as the next rungs straight away, without a
        # new scan and screening each (a real arm has them on three joints or more).
        for effect, lin_score, lin_insample in _other_joints_harmonics(ranked, accepted, base):
            if len(rungs) > MAX_RUNGS or rungs[-1].score_m <= at_floor_m:
                break
            rung, outcome = try_rung(rungs[-1], effect, lin_score, lin_insample)
            refits.append(outcome)
            if rung is None:
                break
            rungs.append(rung)
    return _Climb(rungs, noise, scored_on, rounds, refits, spectra)


def _other_joints_harmonics(ranked: list[Screened], accepted: Rung, base: float) -> list[Screened]:
    """When `accepted` added joint harmonics: the best screened joint_harmonics candidate
    of every other joint that screened MIN_GAIN below `base`, best first; else none."""
    added = accepted.effects[-1]
    if not added.candidates_from_residuals:
        return []
    seen = set(added.joints) | {
        j for e in accepted.effects[:-1] if e.candidates_from_residuals for j in e.joints
    }
    out = []
    for effect, lin_score, lin_insample in ranked:
        if not effect.candidates_from_residuals or lin_score > (1.0 - MIN_GAIN) * base:
            continue
        if set(effect.joints) & seen:
            continue
        seen |= set(effect.joints)
        out.append((effect, lin_score, lin_insample))
    return out


#: residuals a candidate rung needs per free parameter: below, 5-fold CV of a few poses
#: per fold picks effects that are not there (30 poses of a robot with no effect named
#: eccentricity, which then generalised 58 % worse than geometric)
RESIDUALS_PER_PARAMETER = 4


def _affordable(
    pool: list[Effect], current: Calibration, n_points: int
) -> tuple[list[Effect], int]:
    """The candidates of `pool` whose model keeps RESIDUALS_PER_PARAMETER residuals (3 per
    distinct measured point, `Recording.distinct_points`) per free parameter, and how many
    were left out."""
    robot, have = current.model.robot, set(current.parameters.names)
    n_free = int(current.parameters.free.sum())
    budget = 3 * n_points / RESIDUALS_PER_PARAMETER
    kept = [e for e in pool if n_free + len(set(e.parameter_names(robot)) - have) <= budget]
    return kept, len(pool) - len(kept)


def _rejected_before_kfold(cal: Calibration, current: Rung, lin_insample_m: float) -> str:
    """Why a refitted candidate is rejected without its k-fold refits (empty: it is not):
    in-sample worse than the model it extends (the never-worse guard), or in-sample more
    than SCREEN_SLACK above the screening's linearised in-sample figure (the refit did not
    find the gain the screening saw; like with like, whatever the hold-out bags hold)."""
    insample = cal.accuracy.absolute_rms_mm
    before = current.calibration.accuracy.absolute_rms_mm
    if cal.implausible:
        return "implausible: " + "; ".join(cal.implausible)
    if insample > before * (1.0 + 1e-6):
        return (
            f"in-sample {insample:.4f} mm is worse than {current.model}'s {before:.4f} mm "
            "that it extends"
        )
    if insample > SCREEN_SLACK * lin_insample_m * 1e3:
        return (
            f"in-sample {insample:.4f} mm after the refit is above its linearised in-sample "
            f"estimate {lin_insample_m * 1e3:.4f} mm: the refit did not find the screened gain"
        )
    return ""
