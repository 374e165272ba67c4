"""The models of the ladder (msgs_doc/specification.md sections 2-3) identified from a recording.

- `nominal`: the nominal DH table; only the tracker pose and the target offset are fitted.
- `cpa`: circle point analysis (seed section 5), parameters straight from the axis lines.
- `geometric`: all geometric parameters by Levenberg-Marquardt on absolute residuals,
  starting from CPA (or from `nominal` when the recording has no full set of sweeps).
- `geometric+EFFECT[:J,J..][:order=K][+...]`: effects of the vocabulary fitted jointly with
  the geometry, starting from `geometric`; e.g. `geometric+eccentricity` (all joints, order
  `ecc_order`), `geometric+eccentricity:6:order=3`, `geometric+backlash:4`,
  `geometric+compliance:2,3+thermal_drift`.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping
from dataclasses import replace
from functools import partial

import numpy as np

from robot_calib.accuracy import accuracy
from robot_calib.effects import Effect, parse_effect, vocabulary
from robot_calib.effects.eccentricity import Eccentricity
from robot_calib.errors import InputError, param
from robot_calib.identify import DEFAULT_ECC_ORDER, DEFAULT_MODEL
from robot_calib.identify.calibration import Calibration
from robot_calib.identify.canonical import canonical_form
from robot_calib.identify.cpa import CPAResult, circle_point_analysis, pooled_circle_noise
from robot_calib.identify.fit import (
    FitResult,
    SolverReport,
    check_enough_data,
    fit_model,
    orientation_residuals,
    weighted_jacobian,
)
from robot_calib.identify.identifiability import (
    fix_poorly_determined,
    fix_unidentifiable,
)
from robot_calib.identify.model_spec import ModelSpec
from robot_calib.identify.objectives import AbsoluteObjective, Objective, SeedObjective
from robot_calib.identify.outliers import (
    OUTLIER_K,
    describe_outliers,
    group_sigmas,
    outlier_mask,
    robust_sigma,
)
from robot_calib.identify.plausibility import (
    calibration_warnings,
    check_points_spread,
    implausible_reasons,
    inconsistent_orientations,
    recording_warnings,
    stated_accuracy_warnings,
)
from robot_calib.identify.registration import fit_frames, initial_tool_rotations
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.log import Log
from robot_calib.measurements import Recording
from robot_calib.messages import target_topic
from robot_calib.model import KinematicModel, target_parameters
from robot_calib.poses import JOINT_CHANGE_TOLERANCE, Poses

BASE_MODELS = ("nominal", "cpa", "geometric")
#: the models a calibration is compared with that need no ladder (`reference_models`)
REFERENCE_MODELS = ("nominal", "cpa")
OBJECTIVES = ("absolute", "seed")
SEED_ANCHORS = (1, 3, 5)  # the seed fixes the cloud on the centres of circles 1, 3 and 5
MAX_OUTLIER_ROUNDS = 4  # refits without the flagged points until the set is stable
START_POSES = 20_000  # poses (a fixed random subset above) of the frames-only start fit


def parse_model(
    spec: str, robot: RobotDescription, ecc_order: int = DEFAULT_ECC_ORDER
) -> tuple[str, list[Effect]]:
    """Split a model name such as 'geometric+eccentricity' or
    'geometric+backlash:4+thermal_drift'; `ecc_order` is the default Fourier `order` of
    effects that have one. Raises InputError on an unknown base or effect.

    Returns
    -------
    base : str
        'nominal', 'cpa' or 'geometric'.
    effects : list of Effect
        The effects after the base, in the order written (empty unless base is 'geometric').
    """
    parsed = ModelSpec.parse(spec)
    base, extras = parsed.base, list(parsed.terms)
    known = ", ".join(vocabulary())
    if base not in BASE_MODELS or (extras and base != "geometric"):
        raise InputError(
            f"{param('model', spec)}: expected nominal, cpa, geometric or "
            f"geometric+EFFECT[:joints] (effects: {known})"
        )
    effects: list[Effect] = []
    owner: dict[str, str] = {}  # parameter -> the term that gives it
    for extra, name in zip(extras, parsed.effect_names):
        if name not in vocabulary():
            raise InputError(f"{param('model', spec)}: unknown effect {name!r} ({known})")
        try:
            # ecc_order is eccentricity's default order, no other effect's
            defaults = {"order": ecc_order} if name == Eccentricity.name else {}
            effects.append(parse_effect(extra, robot.n_joints, **defaults))
        except InputError as exc:
            raise InputError(f"{param('model', spec)}: {exc}") from None
        for parameter in effects[-1].parameter_names(robot):
            if parameter in owner:
                raise InputError(
                    f"{param('model', spec)}: terms {owner[parameter]!r} and {extra!r} both "
                    f"give parameter {parameter}: give each joint (and order) once"
                )
            owner[parameter] = extra
    return base, effects


def model_notes(
    spec: str, robot: RobotDescription, ecc_order: int = DEFAULT_ECC_ORDER
) -> list[str]:
    """A line for each joint_harmonics term of `spec` that leaves its defaults to be guessed
    (no `orders=`: order 2 alone; no joints: every joint; msgs_doc/effects.md)."""
    _, effects = parse_model(spec, robot, ecc_order)
    notes = []
    for text, effect in zip(ModelSpec.parse(spec).terms, effects):
        if effect.name != "joint_harmonics":
            continue
        options = ModelSpec.term_parts(text)[1]
        guessed = [
            what
            for what, given in (
                ("the default order 2 alone", any(o.startswith("orders=") for o in options)),
                ("every joint", any(not o.startswith("orders=") for o in options)),
            )
            if not given
        ]
        if guessed:
            notes.append(
                f"{param('model', spec)}: {text} is {effect.spec} ({' and '.join(guessed)}: "
                "msgs_doc/effects.md)"
            )
    return notes


def _from_fit(
    name: str, model: KinematicModel, fit: FitResult, points: Array, cpa: CPAResult | None = None
) -> Calibration:
    return Calibration(
        name,
        model,
        fit.parameters,
        fit.std,
        accuracy(points, points + fit.residuals),
        fit.residuals,
        fit.identifiability,
        fit.solver,
        cpa,
        orientation_residuals=fit.orientation_residuals,
    )


def calibrate(
    recording: Recording,
    robot: RobotDescription,
    model_spec: str = DEFAULT_MODEL,
    ecc_order: int = DEFAULT_ECC_ORDER,
    log: Log | None = None,
    start: Calibration | None = None,
    objective: str = "absolute",
    screen_outliers: bool = True,
    tracker_sigma_m: float | None = None,
) -> Calibration:
    """Identify `model_spec` from `recording`. `start`: a calibration to start from (its
    parameters seed the geometry), else the ladder below the model is climbed first.
    objective: 'absolute' residuals, or 'seed' (pairwise distances anchored on the CPA
    centres of circles 1, 3, 5, the seed's eq. 18) for the LM models. `tracker_sigma_m`:
    the user's stated tracker accuracy (1-sigma per axis [m]), the noise its warnings
    compare the residual with when there are no circle fits (else an assumed noise).

    Tracker blunders (`screen_outliers`): when a point lies beyond OUTLIER_K robust sigmas
    of the fit, every point is judged against a robust (soft-L1) refit that blunders barely
    pull, the flagged ones are left out and the model identified again from the rest,
    until the flagged set no longer changes (re-admitting any point the cleaner model
    explains). Clean data take the plain path: one fit, nothing flagged.

    Returns
    -------
    calibration : Calibration
        The identified model, with the following fields:

        name : str
            `model_spec`.
        model : KinematicModel
            The forward model: the geometry plus the effects of `model_spec`.
        parameters : ParameterVector
            The P identified values in SI units [m, rad, ...], with their free flags and
            the reason of each parameter fixed (e.g. unidentifiable).
        std : ndarray, shape (P,)
            1-sigma of each parameter in its unit; 0 where fixed (all 0 for 'cpa').
        accuracy : Accuracy
            In-sample accuracy on `recording` (seed pairwise criterion and absolute) [mm].
        residuals : ndarray, shape (n, 3)
            Predicted - measured points of `recording`, tracker frame [m].
        identifiability : Identifiability or None
            Condition number, observability index and the parameters fixed by the
            analysis; None for 'cpa'.
        solver : SolverReport
            How the parameters were found (scipy `least_squares`'s status, message,
            evaluations, optimality; the method only for closed forms).
        cpa : CPAResult or None
            The circle point analysis (axes, circle fits) when it ran, else None.
        outliers : tuple of Outlier
            The measurements flagged as blunders (bag, message index, stamp, size,
            direction, sigmas), excluded from the fit; empty on clean data.
        inliers : ndarray of bool, shape (n,), or None
            Which measurements of `recording` were fitted (None: all). `residuals` and
            `accuracy` are those of the fitted measurements.
        warnings : tuple of str
            Labelled signs of a wrong result (`identify.plausibility`): parameters far
            from nominal, a residual far above the noise, stuck joints, readings outside
            the limits or in degrees; empty when none.
    """
    base, effects = parse_model(model_spec, robot, ecc_order)
    check_points_spread(recording, robot)
    if base != "cpa":  # too few measurements: say so before any work
        targets, oriented = recording.target_names, recording.oriented_targets
        fitted = KinematicModel(robot, tuple(effects), targets, oriented).parameters().parameters
        n_free = sum(p.free and (base != "nominal" or p.group == "frames") for p in fitted)
        # repeats of one pose add noise, not information: count distinct poses (of a target)
        steps = np.round(recording.poses.q / JOINT_CHANGE_TOLERANCE)
        steps = np.column_stack([steps, recording.poses.target_index])
        n_poses = len(np.unique(steps, axis=0)) if len(steps) else 0
        check_enough_data(3 * n_poses, n_poses, n_free, "distinct poses")
    identify = partial(
        _calibrate_once,
        robot=robot,
        model_spec=model_spec,
        ecc_order=ecc_order,
        log=log,
        start=start,
        objective=objective,
    )
    fit = identify(recording)
    cal = _screened(fit, recording, identify, log) if screen_outliers else fit
    geometry_fitted = base not in ("nominal", "cpa")
    blunders: list[str] = []
    if screen_outliers:
        cal, recording, blunders = _orientation_blunders(cal, recording, identify, log)
    mixed_up = inconsistent_orientations(cal, recording, geometry_fitted)
    if mixed_up is not None:  # orientations no rotation explains: the points alone
        recording = replace(recording, poses=replace(recording.poses, rotation=None))
        fit = identify(recording)
        cal = _screened(fit, recording, identify, log) if screen_outliers else fit
    warnings = tuple(
        recording_warnings(recording, robot)
        + blunders
        + ([mixed_up] if mixed_up else [])
        + calibration_warnings(cal, geometry_fitted, tracker_sigma_m)
        + (stated_accuracy_warnings(cal, recording) if geometry_fitted else [])
    )
    say = log or (lambda _msg: None)
    for warning in warnings:
        say(warning)
    extra = _by_extra_targets(cal, recording)
    if len(cal.model.targets) > 1:
        counts = np.bincount(recording.poses.target_index, minlength=len(cal.model.targets))
        say(
            f"targets: {len(counts)} ("
            + ", ".join(f"{target_topic(t)} {c}" for t, c in zip(cal.model.targets, counts))
            + "); identifiable only with the further targets: "
            + (", ".join(extra) if extra else "none")
        )
    implausible = tuple(implausible_reasons(cal, recording, geometry_fitted, cal.simpler))
    for reason in implausible:
        say(f"implausible: {reason}")
    return replace(cal, warnings=warnings, by_extra_targets=extra, implausible=implausible)


def _by_extra_targets(cal: Calibration, recording: Recording) -> tuple[str, ...]:
    """The free parameters of `cal` that the measurements of the first target alone leave
    unidentifiable or poorly determined (the fit's two analyses, at the solution, with the
    solution's residuals as the noise), the further targets' own offsets aside: what
    measuring several targets adds."""
    if len(cal.model.targets) < 2 or cal.identifiability is None:
        return ()
    first = recording.poses.target_index == 0
    if cal.inliers is not None:
        first &= cal.inliers
    if not first.any():
        return tuple(n for n in cal.parameters.free_names if n.startswith("target"))
    own = {p for t in cal.model.targets[1:] for p in target_parameters(t)}
    params = cal.parameters.fixed(sorted(own & set(cal.parameters.free_names)), "other target")
    # rows as the fit sees them: a 6-DoF probe's orientation rows and the weights included
    residuals, jac, rows = weighted_jacobian(
        cal.model, params, recording.poses.subset(first), recording.points[first]
    )
    kept, analysis = fix_unidentifiable(params, jac, rows=rows)
    _, weak = fix_poorly_determined(kept, jac, residuals, rows=rows)
    return tuple(name for name, _ in analysis.fixed + tuple(weak))


def _screened(
    cal: Calibration,
    recording: Recording,
    identify: Callable[[Recording], Calibration],
    log: Log | None,
) -> Calibration:
    """`cal` (a fit of every measurement), or, when some lie beyond OUTLIER_K robust
    sigmas of their group (`group_sigmas`: their sweep, or their bag's general poses), the
    fit without the blunders (`identify` of the rest), with
    `outliers` and `inliers`."""
    sigmas = group_sigmas(recording, cal.residuals)
    if not outlier_mask(cal.residuals, sigmas).any():
        return cal
    say = log or (lambda _msg: None)
    # Judge every point against a fit that the blunders barely pull: soft-L1, scale 3 sigma.
    robust = fit_model(
        cal.model,
        cal.parameters,
        recording.poses,
        recording.points,
        check_identifiability=False,
        robust_scale=3.0 * robust_sigma(cal.residuals),
    )
    sigmas = group_sigmas(recording, robust.residuals)
    flagged = outlier_mask(robust.residuals, sigmas)
    group = "their sweep (or their bag's general poses)" if recording.sweeps else "the campaign"
    for round_ in range(1, MAX_OUTLIER_ROUNDS + 1):
        say(
            f"outliers: {int(flagged.sum())} of {len(flagged)} measurements beyond "
            f"{OUTLIER_K:g} robust sigmas of {group}: fitted without them"
        )
        try:
            cal = identify(recording.subset(~flagged))
        except InputError as exc:
            raise InputError(f"{exc} (after leaving out {int(flagged.sum())} outliers)") from None
        residual_all = cal.predict(recording.poses) - recording.points
        sigmas = group_sigmas(recording, residual_all)
        again = outlier_mask(residual_all, sigmas)
        if np.array_equal(again, flagged) or round_ == MAX_OUTLIER_ROUNDS:
            break  # `cal` is the fit without `flagged`
        flagged = again  # re-admit what the cleaner model explains, flag what it does not
    outliers = describe_outliers(recording, flagged, residual_all, sigmas)
    for outlier in outliers:
        say(f"outlier: {outlier.line()}")
    return replace(cal, outliers=outliers, inliers=~flagged)


def _orientation_blunders(
    cal: Calibration,
    recording: Recording,
    identify: Callable[[Recording], Calibration],
    log: Log | None,
) -> tuple[Calibration, Recording, list[str]]:
    """`cal` and `recording` unchanged, or, when 6-DoF orientations lie beyond OUTLIER_K
    robust sigmas (per axis, of all orientation residuals), the recording without those
    orientations (their points kept: a probe's point and frame are separate readings), the
    calibration of it, and a warning line naming them."""
    errors = cal.orientation_residuals
    if errors is None or recording.poses.rotation is None:
        return cal, recording, []
    rows = np.flatnonzero(np.all(np.isfinite(errors), axis=1))
    sigma = robust_sigma(errors[rows])
    flagged = rows[outlier_mask(errors[rows], sigma)]
    if not len(flagged):
        return cal, recording, []
    rotation = recording.poses.rotation.copy()
    rotation[flagged] = np.nan
    cleaned = replace(recording, poses=replace(recording.poses, rotation=rotation))
    refit = identify(cleaned)
    if cal.outliers:  # keep the point outliers' screening of the first pass
        refit = _screened(refit, cleaned, identify, None)
    index = recording.message_indices()
    named = ", ".join(
        f"{recording.sources[int(recording.bag_index[i])]} point {int(index[i])}: "
        f"{np.degrees(np.linalg.norm(errors[i])):.3g} deg"
        for i in flagged[:5]
    ) + (f" (+{len(flagged) - 5} more)" if len(flagged) > 5 else "")
    line = (
        f"warning: outliers: {len(flagged)} 6-DoF orientation(s) beyond {OUTLIER_K:g} robust "
        f"sigmas ({sigma * 1e6:.1f} urad per axis) of the fit, left out (their points kept): "
        + named
    )
    if log:
        log(line)
    return refit, cleaned, [line]


def _calibrate_once(
    recording: Recording,
    robot: RobotDescription,
    model_spec: str,
    ecc_order: int,
    log: Log | None,
    start: Calibration | None,
    objective: str,
) -> Calibration:
    """`calibrate` of every measurement of `recording` (no outlier screening)."""
    if objective not in OBJECTIVES:
        raise InputError(
            f"{param('objective', objective)}: expected one of {', '.join(OBJECTIVES)}"
        )
    say = log or (lambda _msg: None)
    base, effects = parse_model(model_spec, robot, ecc_order)
    poses, points = recording.poses, recording.points
    geometric = KinematicModel(
        robot, targets=recording.target_names, oriented=recording.oriented_targets
    )
    has_sweeps = all(recording.sweeps_of(j) for j in range(1, robot.n_joints + 1))
    if base == "nominal":
        say("nominal: fitting the tracker pose and target offset only")
        return _from_fit(
            "nominal",
            geometric,
            fit_frames(geometric, geometric.parameters(), poses, points),
            points,
        )
    cpa = None
    if base == "cpa" or (start is None and has_sweeps) or objective == "seed":
        cpa = circle_point_analysis(recording, robot)
        for w in cpa.warnings:
            say(w)
    if base == "cpa":
        assert cpa is not None
        cpa_params = initial_tool_rotations(geometric, _seeded(geometric, cpa.parameters), poses)
        predicted = geometric.target_points(cpa_params, poses)
        return Calibration(
            "cpa",
            geometric,
            cpa_params,
            _cpa_std(recording, robot, geometric, cpa, cpa_params),
            accuracy(points, predicted),
            predicted - points,
            solver=SolverReport("circle point analysis (seed section 5)"),
            cpa=cpa,
            orientation_residuals=orientation_residuals(geometric, cpa_params, poses),
        )
    if start is not None:
        initial = start.parameters
    elif cpa is not None:
        initial = cpa.parameters
    else:
        say("geometric: no sweep of every joint, starting from the nominal model")
        # a start: the frames of at most START_POSES poses place the tracker as well as
        # 100k do (the fit from there uses every pose)
        sample = recording.at_most(START_POSES)
        initial = fit_frames(
            geometric, geometric.parameters(), sample.poses, sample.points
        ).parameters
    initial = initial_tool_rotations(geometric, _seeded(geometric, initial), poses)
    # a start pi and a sign away (CPA's axis lines, a given start) starts where it ends
    initial = canonical_form(geometric, initial, poses).parameters
    simpler = None
    if effects and start is None:  # the geometry first; the effects start from it
        say(f"geometric: Levenberg-Marquardt on {len(points)} points, before the effects")
        geo = _canonical(
            geometric, fit_model(geometric, initial, poses, points, progress=say), poses, say
        )
        initial = geo.parameters
        if objective == "absolute":  # what the full model must not end worse than
            simpler = ("geometric", float(np.sqrt(np.mean(geo.residuals**2))))
    model = KinematicModel(robot, tuple(effects), recording.target_names, geometric.oriented)
    fits = []
    new = [e for e in model.effects if not set(e.parameter_names(robot)) <= set(initial.names)]
    for starts in itertools.product(*(e.fit_starts(robot) for e in new)):  # one fit per start
        params = _seeded(model, initial, {k: v for start in starts for k, v in start.items()})
        n_free = int(params.free.sum())
        say(
            f"{model_spec}: Levenberg-Marquardt on {len(points)} points, {n_free} free "
            "parameters before the identifiability check"
        )
        fits.append(
            fit_model(
                model, params, poses, points, progress=say, objective=_objective(objective, cpa)
            )
        )
    fit = min(fits, key=lambda f: f.solver.cost_m2 or 0.0)  # several starts: the best
    fit = _canonical(model, fit, poses, say)
    return replace(_from_fit(model_spec, model, fit, points, cpa), simpler=simpler)


def _canonical(model: KinematicModel, fit: FitResult, poses: Poses, say: Log) -> FitResult:
    """`fit` with its parameters in the canonical form nearest nominal
    (`identify.canonical`: the predictions unchanged, so residuals and 1-sigma too)."""
    found = canonical_form(model, fit.parameters, poses)
    for line in found.applied:
        say(f"canonical form: {line}")
    return replace(fit, parameters=found.parameters) if found.applied else fit


#: draws of the parametric bootstrap that gives CPA's parameters their 1-sigma
CPA_DRAWS = 40


def _cpa_std(
    recording: Recording,
    robot: RobotDescription,
    geometric: KinematicModel,
    cpa: CPAResult,
    params: ParameterVector,
) -> Array:
    """1-sigma of CPA's parameters (not 0, which PARAMS.json reserves for fixed
    ones): a parametric bootstrap of the circle fits. CPA_DRAWS times, the measured points
    plus Gaussian noise of the circle fits' own level (`pooled_circle_noise`, per axis)
    go through the same analysis; each free parameter's spread over the draws is its
    1-sigma (angles wrapped about the estimate), 0 where fixed. A fixed seed: the same
    file every run. All 0 when the circles leave no noise to draw (exact points)."""
    noise = pooled_circle_noise(list(cpa.sweeps))
    std = np.zeros(len(params))
    if not noise > 0:
        return std
    rng = np.random.default_rng(0)
    draws = []
    for _ in range(CPA_DRAWS):
        shaken = replace(
            recording, points=recording.points + rng.normal(0.0, noise, recording.points.shape)
        )
        try:
            again = circle_point_analysis(shaken, robot)
        except InputError:  # a draw no circle survives: left out
            continue
        values = initial_tool_rotations(
            geometric, _seeded(geometric, again.parameters), shaken.poses
        ).values
        draws.append(values)
    if len(draws) < 2:
        return std
    diff = np.asarray(draws) - params.values
    angles = np.array([p.unit == "rad" for p in params.parameters], dtype=bool)
    diff[:, angles] = (diff[:, angles] + np.pi) % (2 * np.pi) - np.pi
    std[params.free] = np.sqrt(np.mean(diff**2, axis=0))[params.free]
    return std


def _seeded(
    model: KinematicModel, values: ParameterVector, starts: Mapping[str, float] | None = None
) -> ParameterVector:
    """`model`'s parameters (fresh free flags) with the values that `values` also has, and
    `starts` (an effect's fit start, `Effect.fit_starts`) for the parameters it has not."""
    fresh = model.parameters()
    known = {k: v for k, v in zip(values.names, values.values) if k in fresh}
    return fresh.with_values({**(starts or {}), **known})


def _objective(name: str, cpa: CPAResult | None) -> Objective:
    if name == "absolute":
        return AbsoluteObjective()
    assert cpa is not None
    anchors = [next(s.circle.centre for s in cpa.sweeps if s.joint == j) for j in SEED_ANCHORS]
    return SeedObjective(np.array(anchors))


def model_name(effects: tuple[Effect, ...] | list[Effect]) -> str:
    """The `--model` name of the geometric model plus `effects`."""
    return "+".join(["geometric", *(e.spec for e in effects)])


def reference_models(
    recording: Recording,
    robot: RobotDescription,
    given: Mapping[str, Calibration] | None = None,
) -> dict[str, Calibration]:
    """The REFERENCE_MODELS of `recording` (tracker blunders left out) a report compares
    its calibration with: `given` ones, the others identified here, without outlier
    screening (`cpa` left out without the circle sweeps of every joint it needs). They
    need the recording only: a process that has it can identify them while another climbs
    the ladder (`flows.diagnose.ReadAside`)."""
    out = dict(given or {})
    for name in REFERENCE_MODELS:
        if name not in out:
            try:
                out[name] = calibrate(recording, robot, name, screen_outliers=False)
            except InputError:
                continue
    return out
