"""The learned residual correction (a learnable bound that learns, the hybrid
model). Known answers: smooth structure of known joints is recovered and the joints it
does not depend on are found irrelevant; a simulated UR10 whose compliance the geometric
model lacks is mostly learnable; an edge of a hyperparameter's range is said; a correction
survives PARAMS.json exactly."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from robot_calib.cli import main
from robot_calib.compensation import compensate_commands
from robot_calib.compensation.solve import nominal_counterpart
from robot_calib.diagnosis.ladder import kfold_parameters
from robot_calib.diagnosis.learnable import corrected_heldout, learnable_bound
from robot_calib.errors import InputError
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import Calibration
from robot_calib.identify.correction import GaussianProcessCorrection, fit_correction
from robot_calib.identify.correction_structured import StructuredCorrection
from robot_calib.identify.score import score
from robot_calib.ik import first_tool2flange, tool2base
from robot_calib.kinematics.frames import Array
from robot_calib.poses import Poses
from robot_calib.sim.scenarios import Scenario, ur10_random

# compliance of joints 2 and 3 (gravity bends them): smooth in the readings, not in the
# geometric model: about 0.9 mm rms of geometric's held-out error
COMPLIANCE = (
    {"name": "compliance", "joints": [2, 3], "values": {"compliance2": 2e-5, "compliance3": 2e-5}},
)


def rms_mm(residuals: Array) -> float:
    return float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))) * 1e3)


@pytest.fixture(scope="module")
def compliant() -> tuple[Scenario, Calibration]:
    """A UR10 random-pose campaign (700 calibration, 300 hold-out poses) with compliance
    the geometric calibration does not model."""
    scenario = ur10_random(seed=1, n=1000, effects=COMPLIANCE)
    geo = calibrate(scenario.calibration, scenario.world.model.robot, "geometric")
    return scenario, geo


def smooth(q: Array) -> Array:
    """(n, 3) [m]: a residual of joints 2 and 3 only."""
    return np.column_stack(
        [1e-4 * np.sin(q[:, 1]), 5e-5 * np.cos(q[:, 1] + q[:, 2]), 2e-5 * np.sin(2 * q[:, 2])]
    )


def test_smooth_structure_is_recovered_and_the_other_joints_found_irrelevant() -> None:
    rng = np.random.default_rng(3)
    q = rng.uniform(-np.pi, np.pi, (300, 6))
    noise = 1e-6  # m per axis
    residual = smooth(q) + rng.normal(0.0, noise, q.shape[:1] + (3,))
    correction = fit_correction(Poses.from_readings(q), residual, 1)
    new = rng.uniform(-np.pi, np.pi, (300, 6))
    error = correction.predict(Poses.from_readings(new)) - smooth(new)
    assert rms_mm(error) < 3e-3  # 3 um of a 0.1 mm structure
    scales = correction.length_scales_deg
    assert scales[1] is not None and scales[2] is not None  # the joints it depends on
    assert all(s is None or s > 300 for k, s in enumerate(scales) if k not in (1, 2)), scales
    assert correction.noise_mm == pytest.approx(noise * 1e3, rel=0.3)
    assert not [w for w in correction.warnings if "length scale" in w]
    assert "exact on all 300 poses" in correction.method


@pytest.mark.parametrize("n_targets", [1, 3])
def test_the_likelihood_and_its_gradient_are_those_of_the_distance_form(n_targets: int) -> None:
    """The marginal likelihood from the features (no (G, n, n) distances) equals the one
    written with the squared distances 2 - 2 cos(q_a - q_b) (and 2 [t_a != t_b]) it stands
    for, and its analytic gradient matches forward finite differences."""
    from scipy.optimize import approx_fprime

    from robot_calib.identify.correction import _features, _negative_log_likelihood

    rng = np.random.default_rng(3)
    n, n_joints = 120, 6
    q = rng.uniform(-3.0, 3.0, (n, n_joints))
    target = rng.integers(0, n_targets, n)
    y = rng.normal(size=(n, 3))
    inputs = _features(q, target, n_targets)
    groups = n_joints + (n_targets > 1)
    theta = np.r_[rng.uniform(0.2, 3.0, groups), 0.1, np.log(0.05)]
    value, grad = _negative_log_likelihood(theta, inputs, y, n_joints)
    dist = [2.0 - 2.0 * np.cos(q[:, None, j] - q[None, :, j]) for j in range(n_joints)]
    if n_targets > 1:
        dist.append(2.0 * (target[:, None] != target[None, :]))
    k = np.exp(theta[-2]) * np.exp(-0.5 * np.tensordot(theta[:-2] ** 2, np.stack(dist), 1))
    k += np.exp(theta[-1]) * np.eye(n)
    expected = 0.5 * float(np.sum(y * np.linalg.solve(k, y))) + 3 * float(
        np.sum(np.log(np.diag(np.linalg.cholesky(k))))
    )
    assert value == pytest.approx(expected, rel=1e-12)
    numeric = approx_fprime(
        theta, lambda t: _negative_log_likelihood(t, inputs, y, n_joints)[0], 1e-6
    )
    assert np.max(np.abs(grad - numeric)) < 1e-4 * np.max(np.abs(numeric))


def test_subset_of_regressors_above_max_points_predicts_like_the_exact_fit() -> None:
    """Above `max_points` the model is built on that many inducing poses; every pose still
    counts, and the prediction is close to the exact fit's."""
    rng = np.random.default_rng(4)
    q = rng.uniform(-np.pi, np.pi, (500, 6))
    poses = Poses.from_readings(q)
    residual = smooth(q) + rng.normal(0.0, 1e-6, (500, 3))
    exact = fit_correction(poses, residual, 1)
    sparse = fit_correction(poses, residual, 1, hyper=exact.hyper, max_points=200)
    assert sparse.inducing_q.shape == (200, 6) and sparse.n_fitted == 500
    assert "subset of regressors on 200 of 500 poses" in sparse.method
    new = Poses.from_readings(rng.uniform(-np.pi, np.pi, (500, 6)))
    assert rms_mm(sparse.predict(new) - exact.predict(new)) < 0.02 * rms_mm(smooth(new.q))


def test_a_length_scale_at_its_bound_is_said() -> None:
    """A 6th harmonic of joint 1 (period 60 deg) wants a length scale of about 30 deg:
    with 40 deg the shortest allowed, joint 1 ends at that bound, and says so."""
    rng = np.random.default_rng(0)
    q = np.column_stack([rng.uniform(-np.pi, np.pi, 400), rng.uniform(-0.3, 0.3, (400, 5))])
    residual = np.zeros((400, 3))
    residual[:, 0] = 1e-4 * np.sin(6 * q[:, 0])
    residual += rng.normal(0.0, 1e-6, residual.shape)
    poses = Poses.from_readings(q)
    free = fit_correction(poses, residual, 1)  # the default bound, 1 deg: not reached
    assert free.length_scales_deg[0] == pytest.approx(30.0, abs=6.0)
    assert not [w for w in free.warnings if "length scale" in w]
    capped = fit_correction(poses, residual, 1, min_length_scale_rad=math.radians(40.0))
    assert capped.length_scales_deg[0] == pytest.approx(40.0, rel=1e-3)
    said = [w for w in capped.warnings if "length scale" in w]
    assert len(said) == 1 and "joint 1" in said[0] and "lower bound 40 deg" in said[0], said


def test_compliance_the_geometry_lacks_is_learnable(
    compliant: tuple[Scenario, Calibration],
) -> None:
    scenario, geo = compliant
    no_folds = np.zeros(len(scenario.calibration), int)
    bound = learnable_bound(
        geo, scenario.calibration, scenario.holdout, no_folds, {}, "hold-out bags"
    )
    assert bound.learnable_share > 0.65, bound.line()
    assert bound.holdout_abs_rms_mm < 0.35 * bound.geometric_abs_rms_mm
    # compliance is linear in the gravity torque: the load-driven geometry learns it (joints
    # 2 and 3 turning about their axes), the process of the rest learns nothing held out
    correction = geo.with_learned_correction(scenario.calibration).correction
    assert isinstance(correction, StructuredCorrection)
    joints = {(s.joint, s.motion) for s in correction.strongest(scenario.calibration.poses)}
    assert {(2, "rz"), (3, "rz")} <= joints, joints
    assert not np.any(correction.gp.dual), correction.line()
    assert "Gaussian process" in bound.line() and bound.fitted_poses == 700


def test_gear_harmonics_of_joint_2_are_partly_learnable_on_the_ur10_gear_world() -> None:
    """The simulated UR10 (2773 random poses, 70/30; joint 2's 11th and 27th harmonics, joint
    1's 17th): the kernel ridge bound learned nothing there (0.191 -> 0.192 mm); one length
    scale per joint finds joint 2's short one and learns about half."""
    scenario = ur10_random(seed=0)
    geo = calibrate(scenario.calibration, scenario.world.model.robot, "geometric")
    no_folds = np.zeros(len(scenario.calibration), int)
    bound = learnable_bound(
        geo, scenario.calibration, scenario.holdout, no_folds, {}, "hold-out bags"
    )
    assert bound.learnable_share > 0.4, bound.line()
    joint2 = bound.length_scales_deg[1]
    assert joint2 is not None and joint2 < 10, bound.length_scales_deg  # period 13 deg


def test_k_fold_hyperparameters_come_from_each_folds_training_poses(
    compliant: tuple[Scenario, Calibration],
) -> None:
    """Without hold-out bags: per fold the geometry refitted and a correction learned on
    the other folds only; every calibration pose is scored once."""
    scenario, geo = compliant
    recording = scenario.calibration.subset(np.arange(700) < 400)  # 400 poses: fast
    geo400 = calibrate(recording, scenario.world.model.robot, "geometric")
    fold, fitted = kfold_parameters(geo400, recording)
    before, after, correction = corrected_heldout(geo400, recording, None, fold, fitted)
    assert before.shape == after.shape == (400, 3)
    assert rms_mm(after) < 0.5 * rms_mm(before)
    assert correction.n_fitted == 400


def test_a_correction_survives_json_exactly() -> None:
    """Two targets (the target code is an input); to_dict -> JSON -> from_dict predicts
    the same, and a malformed section names where it is."""
    rng = np.random.default_rng(5)
    q = rng.uniform(-np.pi, np.pi, (250, 6))
    target = rng.integers(0, 2, 250)
    poses = replace(Poses.from_readings(q), target=target)
    residual = smooth(q) + 3e-5 * target[:, None] + rng.normal(0.0, 1e-6, (250, 3))
    correction = fit_correction(poses, residual, 2)
    text = json.dumps(correction.to_dict())
    back = GaussianProcessCorrection.from_dict(json.loads(text), "PARAMS.json: correction")
    new = replace(
        Poses.from_readings(rng.uniform(-np.pi, np.pi, (200, 6))), target=rng.integers(0, 2, 200)
    )
    assert np.allclose(back.predict(new), correction.predict(new), rtol=0, atol=1e-12)
    assert back.length_scales_deg == correction.length_scales_deg
    doc = json.loads(text)
    doc["dual"] = doc["dual"][:-1]
    with pytest.raises(InputError, match=r"^x.json: correction: malformed .*dual"):
        GaussianProcessCorrection.from_dict(doc, "x.json: correction")
    with pytest.raises(InputError, match="x.json: correction: not a learned correction"):
        GaussianProcessCorrection.from_dict(
            {**doc, "format": "robot_calib.correction/99"}, "x.json: correction"
        )
    # finite but absurd: a predicted correction of kilometres, or NaN, is never applied
    good = json.loads(text)
    for change, said in (
        ({"signal_variance": 1e308}, "non-finite"),
        ({"mean_m": [1000.0, 0.0, 0.0]}, "mean_m beyond 10 mm"),
        ({"scale_m": 1e6}, "scale_m beyond 10 mm"),
        ({"dual": [[1e3] * 3] * len(good["dual"])}, "predicts .* mm at its own poses"),
        ({"bogus": 1}, "unknown key 'bogus'"),
    ):
        with pytest.raises(InputError, match=said):
            GaussianProcessCorrection.from_dict({**good, **change}, "x.json: correction")


def test_the_hybrid_model_round_trips_through_params_json(
    compliant: tuple[Scenario, Calibration],
) -> None:
    scenario, geo = compliant
    recording, held = scenario.calibration, scenario.holdout
    before, after, correction = corrected_heldout(geo, recording, held, np.zeros(0, int), {})
    hybrid = replace(geo, correction=correction)  # geometric + the learned correction
    assert np.allclose(hybrid.predict(held.poses) - held.points, after, rtol=0, atol=1e-12)
    assert np.allclose(geo.predict(held.poses) - held.points, before, rtol=0, atol=1e-12)
    doc = json.loads(json.dumps(hybrid.to_dict(recording)))
    assert doc["correction"]["format"] == "robot_calib.correction/2"
    assert len(json.dumps(doc, indent=2)) < 1_000_000
    back = Calibration.from_dict(doc, "hybrid.json")
    assert back.correction is not None
    assert np.allclose(back.predict(held.poses), hybrid.predict(held.poses), rtol=0, atol=1e-12)
    assert rms_mm(back.predict(held.poses) - held.points) < 0.5 * rms_mm(
        geo.predict(held.poses) - held.points
    )
    # a file without the section is the physical model alone, as before
    plain = Calibration.from_dict(json.loads(json.dumps(geo.to_dict(recording))))
    assert plain.correction is None and "correction" not in geo.to_dict(recording)
    assert np.allclose(plain.predict(held.poses), geo.predict(held.poses), rtol=0, atol=1e-12)
    # a correction of another robot's joints or targets is refused, naming the file
    doc["correction"]["n_targets"] = 2
    with pytest.raises(InputError, match="hybrid.json: correction"):
        Calibration.from_dict(doc, "hybrid.json")


@pytest.fixture(scope="module")
def hybrid(compliant: tuple[Scenario, Calibration]) -> Calibration:
    """The geometric calibration with a correction learned from its residuals."""
    scenario, geo = compliant
    return geo.with_learned_correction(scenario.calibration)


def test_compensating_with_the_hybrid_model_puts_the_true_tool_nearer(
    compliant: tuple[Scenario, Calibration], hybrid: Calibration
) -> None:
    """Nominal commands compensated with the geometric model alone and with the hybrid
    model: the hybrid's commands put the simulated robot's true tool (compliance and all)
    nearer the nominal promise; its own fixed point (model - correction = goal) holds."""
    scenario, _ = compliant
    model, params = hybrid.model, hybrid.parameters
    nominal, nominal_params = nominal_counterpart(model, params)  # what the program expects
    commands = Poses.from_readings(scenario.holdout.poses.q[:60])
    goal = tool2base(nominal, nominal_params, commands, first_tool2flange(model, params))
    base2tracker = model.base2tracker(params)
    goal_in_tracker = goal[:, :3, 3] @ base2tracker[:3, :3].T + base2tracker[:3, 3]
    world = scenario.world
    errors = {}
    for name, correction in (("physical", None), ("hybrid", hybrid.correction)):
        found = compensate_commands(replace(hybrid, correction=correction), commands)
        at = replace(commands, q=found.q)
        errors[name] = rms_mm(world.model.target_points(world.truth, at) - goal_in_tracker)
    # the fixed point (model - correction = goal) holds where the compensation says it
    # converged, and it says so of every row here (measured: 1e-9 m)
    assert found.converged.all()
    assert np.abs(hybrid.predict(at) - goal_in_tracker).max() < 1e-7
    assert np.allclose(
        found.error_m,
        np.linalg.norm(hybrid.predict(at) - goal_in_tracker, axis=1),
        rtol=0,
        atol=1e-12,
    )
    assert errors["hybrid"] < 0.5 * errors["physical"], errors


def test_predict_score_and_export_use_or_name_the_correction(
    compliant: tuple[Scenario, Calibration],
    hybrid: Calibration,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    scenario, _ = compliant
    held = scenario.holdout
    params_file = tmp_path / "hybrid.json"
    params_file.write_text(json.dumps(hybrid.to_dict(scenario.calibration), indent=2))
    # predict: the hybrid model's points
    q = held.poses.q[:20]
    joints = tmp_path / "joints.csv"
    joints.write_text(
        "q1,q2,q3,q4,q5,q6\n" + "".join(",".join(map(repr, r.tolist())) + "\n" for r in q)
    )
    points = tmp_path / "points.csv"
    assert main(["predict", str(params_file), "--joints", str(joints), "-o", str(points)]) == 0
    assert "the learned correction applied" in capsys.readouterr().out
    written = np.loadtxt(points, delimiter=",", skiprows=1)
    assert np.allclose(written, hybrid.predict(Poses.from_readings(q)), rtol=0, atol=1e-12)
    # score: the hybrid's residuals
    scored = score(hybrid, held)
    assert scored.accuracy.absolute_rms_mm == pytest.approx(
        rms_mm(hybrid.predict(held.poses) - held.points), rel=1e-9
    )
    # export: the URDF's header and stderr say the correction is not in the file
    urdf = tmp_path / "hybrid.urdf"
    assert main(["export", str(params_file), "--format", "urdf", "-o", str(urdf)]) == 0
    said = "The learned correction of this calibration is not in this file"
    assert said in urdf.read_text() and said in capsys.readouterr().err
