"""Identification against known answers: simulated worlds whose true parameters are known.

CPA on exact points must give the true geometry exactly; with noise, the LM fit must land
within 3 standard deviations of the truth and predict held-out poses as well as the truth
does (noise floor); eccentricity needs general poses to be identified, and says so.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli

from robot_calib.accuracy import accuracy, pairwise_errors
from robot_calib.csv_tables import read_joints_csv
from robot_calib.effects import make_effect
from robot_calib.identify.calibrate import calibrate, parse_model
from robot_calib.identify.calibration import Calibration
from robot_calib.identify.cpa import circle_point_analysis
from robot_calib.identify.identifiability import fix_unidentifiable
from robot_calib.kinematics.frames import rpy_to_matrix
from robot_calib.measurements import recording_from_arrays
from robot_calib.model import KinematicModel, absorb_base_offsets
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import paper_test_plan, random_plan
from robot_calib.sim.world import load_world, with_effect

ROOT = Path(__file__).resolve().parents[2]
WORLD = load_world()
ROBOT = WORLD.model.robot
GEOMETRIC_NAMES = [n for n in WORLD.truth.names if not n.startswith(("base2", "target"))]


def measure(world, q: np.ndarray, seed: int, noisy: bool = True):  # noqa: ANN001, ANN201
    poses = Poses.from_readings(q)
    return poses, physical_points(world, poses, np.random.default_rng(seed), noisy=noisy)


def holdout(world, seed: int = 99, n: int = 200):  # noqa: ANN001, ANN201
    return measure(world, random_plan(ROBOT, n, np.random.default_rng(seed)).q, seed + 1)


def test_cpa_on_exact_points_gives_the_true_geometry() -> None:
    plan = paper_test_plan(2)
    poses, points = measure(WORLD, plan.q, 0, noisy=False)
    cpa = circle_point_analysis(recording_from_arrays(plan.q, points), ROBOT)
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    for name in truth.names:
        assert cpa.parameters[name] == pytest.approx(truth[name], abs=1e-9), name
    assert all(s.circle.rms < 1e-9 for s in cpa.sweeps)
    # The axis lines are the world's joint axes at the reference pose.
    frames = KinematicModel(ROBOT)._chain(WORLD.truth, Poses.from_readings(cpa.q_ref[None])).frames
    b2t = KinematicModel.base2tracker(WORLD.truth)
    for j, axis in enumerate(cpa.axes):
        z = b2t[:3, :3] @ frames[0, j, :3, 2]
        origin = b2t[:3, :3] @ frames[0, j, :3, 3] + b2t[:3, 3]
        assert axis.direction @ z == pytest.approx(1.0, abs=1e-12)
        assert np.linalg.norm(np.cross(axis.point - origin, z)) < 1e-9


@pytest.mark.parametrize("test_number", [2, 3, 5])
def test_cpa_with_noise_is_close_to_the_truth(test_number: int) -> None:
    plan = paper_test_plan(test_number)
    poses, points = measure(WORLD, plan.q, test_number)
    cpa = circle_point_analysis(recording_from_arrays(plan.q, points), ROBOT)
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    for name in GEOMETRIC_NAMES:
        angle = name.startswith(("theta", "alpha", "beta"))
        tol = np.radians(5e-3) if angle else 20e-6  # 0.005 deg, 20 um
        assert abs(cpa.parameters[name] - truth[name]) < tol, name
    assert all(s.circle.rms < 15e-6 for s in cpa.sweeps)


def test_geometric_fit_is_within_three_sigma_and_at_the_noise_floor_on_holdout() -> None:
    plan = paper_test_plan(2)
    poses, points = measure(WORLD, plan.q, 0)
    cal = calibrate(recording_from_arrays(plan.q, points), ROBOT, "geometric")
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    free = cal.parameters.free
    z = (cal.parameters.values - truth.values)[free] / cal.std[free]
    assert np.all(np.abs(z) < 3.0), dict(zip(cal.parameters.free_names, np.round(z, 2)))
    assert free.sum() == 27  # 4 x 6 DH/Hayati - 6 structurally fixed + 6 base + 3 target
    h_poses, h_points = holdout(WORLD)
    fitted = accuracy(h_points, cal.predict(h_poses))
    floor = accuracy(h_points, WORLD.model.target_points(WORLD.truth, h_poses))
    assert fitted.absolute_mean_mm < 1.2 * floor.absolute_mean_mm
    assert fitted.pairwise_mean_mm < 1.2 * floor.pairwise_mean_mm
    nominal = calibrate(recording_from_arrays(plan.q, points), ROBOT, "nominal")
    assert (
        accuracy(h_points, nominal.predict(h_poses)).pairwise_mean_mm > 10 * floor.pairwise_mean_mm
    )


def test_geometric_from_general_poses_only_starts_from_the_nominal_model() -> None:
    q = random_plan(ROBOT, 300, np.random.default_rng(3)).q
    poses, points = measure(WORLD, q, 3)
    cal = calibrate(recording_from_arrays(q, points), ROBOT, "geometric")
    assert cal.cpa is None
    assert cal.accuracy.absolute_rms_mm < 0.015  # noise level: ~8 um per point


def test_redundant_parameters_are_found_and_fixed_with_their_partner() -> None:
    plan = paper_test_plan(3)
    poses, points = measure(WORLD, plan.q, 0)
    model = KinematicModel(ROBOT)
    params = model.parameters(
        tuple(WORLD.truth[n] for n in WORLD.truth.names if n.startswith("base2")),
        (0.06, 0.0, 0.05),
    ).freed(["theta1"])  # theta1 turns the robot like the tracker yaw does
    _, jac = model.jacobian(params, poses)
    fixed_params, ident = fix_unidentifiable(params, jac.reshape(-1, len(params)))
    assert len(ident.fixed) == 1
    name, reason = ident.fixed[0]
    assert name == "base2tracker_yaw" and "theta1" in reason
    assert not fixed_params.free[fixed_params.index("base2tracker_yaw")]


def test_eccentricity_needs_general_poses_and_then_reaches_the_noise_floor() -> None:
    world = with_effect(WORLD, make_effect("eccentricity", range(1, 7), order=1))
    plan = paper_test_plan(2)
    general = random_plan(ROBOT, 100, np.random.default_rng(7)).q
    h_poses, h_points = holdout(world)
    floor = accuracy(h_points, world.model.target_points(world.truth, h_poses))

    q = np.concatenate([plan.q, general])
    poses, points = measure(world, q, 5)
    rec = recording_from_arrays(q, points)
    geo = calibrate(rec, ROBOT, "geometric")
    ecc = calibrate(rec, ROBOT, "geometric+eccentricity")
    geo_h = accuracy(h_points, geo.predict(h_poses))
    ecc_h = accuracy(h_points, ecc.predict(h_poses))
    assert geo_h.pairwise_mean_mm > 5 * floor.pairwise_mean_mm  # runout is not geometry
    assert ecc_h.pairwise_mean_mm < 1.5 * floor.pairwise_mean_mm
    assert ecc_h.absolute_mean_mm < 1.5 * floor.absolute_mean_mm
    # Constant terms duplicate the DH parameters: fixed, with the reason.
    reasons = dict(ecc.identifiability.fixed)
    assert "ecc2_dx_D" in reasons and "a1" in reasons["ecc2_dx_D"]

    # Sweeps alone: the fit is perfect in-sample but leaves more terms unidentified and
    # generalises worse; the output says which terms it fixed.
    sweeps_only = calibrate(
        recording_from_arrays(plan.q, points[: len(plan.q)]), ROBOT, "geometric+eccentricity"
    )
    assert len(sweeps_only.identifiability.fixed) > len(ecc.identifiability.fixed)
    assert accuracy(h_points, sweeps_only.predict(h_poses)).pairwise_mean_mm > 3 * (
        ecc_h.pairwise_mean_mm
    )


def test_effect_models_fit_their_effect() -> None:
    world = with_effect(WORLD, make_effect("backlash", [4]))
    q = np.concatenate([paper_test_plan(3).q, random_plan(ROBOT, 60, np.random.default_rng(1)).q])
    poses, points = measure(world, q, 2)
    cal = calibrate(recording_from_arrays(q, points), ROBOT, "geometric+backlash:4")
    play = cal.parameters["backlash4"]
    assert play == pytest.approx(
        world.truth["backlash4"], abs=4 * cal.std[cal.parameters.index("backlash4")]
    )
    assert parse_model("geometric+compliance:2,3+thermal_drift", ROBOT)[1][1].joints == ()


def test_pairwise_criterion_is_frame_free_and_matches_brute_force() -> None:
    rng = np.random.default_rng(0)
    measured = rng.normal(size=(50, 3))
    predicted = measured + rng.normal(scale=1e-3, size=(50, 3))
    i, j = np.triu_indices(50, 1)
    brute = np.abs(
        np.linalg.norm(measured[i] - measured[j], axis=1)
        - np.linalg.norm(predicted[i] - predicted[j], axis=1)
    )
    mean, worst = pairwise_errors(measured, predicted)
    assert mean == pytest.approx(brute.mean()) and worst == pytest.approx(brute.max())
    moved = predicted @ rpy_to_matrix(0.3, -0.2, 2.0).T + [1.0, -4.0, 2.0]
    assert pairwise_errors(measured, moved) == pytest.approx((mean, worst))


def test_calibrate_and_predict_commands(tmp_path: Path) -> None:
    bag = ROOT / "bags" / "paper_test3.mcap"
    params = tmp_path / "params.json"
    proc = cli("calibrate", str(bag), "--model", "geometric", "-o", str(params))
    assert proc.returncode == 0, proc.stderr
    assert "beta2 [deg]" in proc.stdout and "seed criterion" in proc.stdout
    doc = json.loads(params.read_text())
    assert doc["model"] == "geometric" and doc["measurements"]["paired"] == 290
    assert {f["name"] for f in doc["fixed"]} >= {"theta1", "d1", "d2", "theta6"}
    a2 = next(p for p in doc["parameters"] if p["name"] == "a2")
    assert a2["unit"] == "m" and 0 < a2["std"] < 1e-5

    h_poses, h_points = holdout(load_world(ROOT / "bags" / "paper_test3.world.yaml"))
    joints = tmp_path / "joints.csv"
    header = "t," + ",".join(f"q{j}" for j in range(1, 7))
    rows = [f"{t},{','.join(repr(float(v)) for v in q)}" for t, q in zip(h_poses.time, h_poses.q)]
    joints.write_text(header + "\n" + "\n".join(rows) + "\n")
    points = tmp_path / "points.csv"
    predict = ["predict", str(params), "--joints"]
    proc = cli(*predict, str(joints), "-o", str(points))
    assert proc.returncode == 0, proc.stderr
    predicted = np.loadtxt(points, delimiter=",", skiprows=1)
    assert points.read_text().startswith("x,y,z\n") and predicted.shape == (200, 3)
    model, values = (loaded := Calibration.load(params)).model, loaded.parameters
    same = model.target_points(values, read_joints_csv(joints, 6))
    assert np.allclose(predicted, same, atol=1e-12)
    assert np.linalg.norm(predicted - h_points, axis=1).mean() < 2e-5  # held-out, ~noise

    bad = tmp_path / "bad.csv"
    bad.write_text("q1,q2,q3\n1,2,3\n")
    proc = cli(*predict, str(bad), "-o", str(points))
    assert proc.returncode == 2 and "bad.csv: header lacks ['q4', 'q5', 'q6']" in proc.stderr
    proc = cli("calibrate", str(bag), "--model", "geometric+wobble", "-o", "x")
    assert proc.returncode == 2 and "unknown effect 'wobble'" in proc.stderr


def test_seed_objective_finds_the_same_geometry() -> None:
    """The seed's pairwise-distance objective (anchored on circle centres 1, 3, 5) and the
    absolute one identify the same robot on effect-free data."""
    plan = paper_test_plan(3)
    poses, points = measure(WORLD, plan.q, 11)
    rec = recording_from_arrays(plan.q, points)
    absolute = calibrate(rec, ROBOT, "geometric")
    seed = calibrate(rec, ROBOT, "geometric", objective="seed")
    assert seed.solver.objective == "seed pairwise distances"
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    for name in GEOMETRIC_NAMES:
        if absolute.parameters.free[absolute.parameters.index(name)]:
            sigma = absolute.std[absolute.parameters.index(name)]
            assert abs(seed.parameters[name] - truth[name]) < 5 * sigma, name
    assert seed.accuracy.pairwise_mean_mm < 1.1 * absolute.accuracy.pairwise_mean_mm


def test_pairwise_criterion_samples_pairs_for_large_sets() -> None:
    """Above MAX_EXACT_POINTS the criterion comes from a random sample of pairs: a uniform
    1e-3 scale error gives a pair error of 1e-3 x the pair distance, whose mean is known."""
    from robot_calib.accuracy import MAX_EXACT_POINTS

    rng = np.random.default_rng(1)
    measured = rng.uniform(-1.0, 1.0, size=(MAX_EXACT_POINTS + 1000, 3))
    mean, worst = pairwise_errors(measured, measured * 1.001)
    i, j = rng.integers(0, len(measured), (2, 200_000))
    expected = 1e-3 * np.linalg.norm(measured[i] - measured[j], axis=1).mean()
    assert mean == pytest.approx(expected, rel=0.01)
    assert worst <= 1e-3 * 2 * np.sqrt(3) * 1.0001
