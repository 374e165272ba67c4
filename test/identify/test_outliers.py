"""Tracker blunders, bad starts and too little data, against known answers in
the simulated world: the corrupted points are the ones flagged, the held-out error stays
that of the clean fit, clean data flag nothing, and the diagnosis never calls a blunder an
effect of the robot."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from bag_files import write_measurements
from cli_runner import cli

from robot_calib.accuracy import accuracy
from robot_calib.diagnosis.diagnosis import diagnose
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import summary
from robot_calib.identify.fit import fit_model
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses
from robot_calib.sim.blind import make_case
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import paper_test_plan, plan_times, random_plan
from robot_calib.sim.world import World, build_world, load_world

WORLD = load_world()
ROBOT = WORLD.model.robot


def simulate_test2(world: World, seed: int) -> tuple[Recording, Poses, np.ndarray]:
    """The seed's Test 2 recording (580 points) and 200 random hold-out poses + points."""
    rng = np.random.default_rng(seed)
    plan = paper_test_plan(2)
    time = plan_times(plan, world.timing)
    points = physical_points(world, Poses.from_readings(plan.q, time=time), rng)
    held = Poses.from_readings(random_plan(world.model.robot, 200, rng).q)
    return recording_from_arrays(plan.q, points, time), held, physical_points(world, held, rng)


def corrupt(points: np.ndarray, sizes: np.ndarray, rng: np.random.Generator) -> tuple:
    """Points with len(sizes) of them displaced by `sizes` [m] in random directions."""
    index = np.sort(rng.choice(len(points), len(sizes), replace=False))
    direction = rng.normal(size=(len(sizes), 3))
    out = points.copy()
    out[index] += direction / np.linalg.norm(direction, axis=1)[:, None] * sizes[:, None]
    return out, index


@pytest.mark.parametrize(
    "blunders",
    ["3 x 5 mm", "1 x 1 m", "1.5 % at 1-8 mm"],
)
def test_blunders_are_flagged_and_do_not_move_the_fit(blunders: str) -> None:
    rng = np.random.default_rng(7)
    recording, held, held_points = simulate_test2(WORLD, 3)
    sizes = {
        "3 x 5 mm": np.full(3, 5e-3),
        "1 x 1 m": np.array([1.0]),
        "1.5 % at 1-8 mm": rng.uniform(1e-3, 8e-3, round(0.015 * len(recording))),
    }[blunders]
    points, index = corrupt(recording.points, sizes, rng)
    dirty = recording_from_arrays(recording.poses.q, points, recording.poses.time)
    clean_cal = calibrate(recording, ROBOT)
    cal = calibrate(dirty, ROBOT)
    assert [o.index for o in cal.outliers] == index.tolist()
    assert clean_cal.outliers == ()
    for outlier, size in zip(cal.outliers, sizes):
        assert outlier.size_m == pytest.approx(size, rel=0.01, abs=5e-5)
        assert outlier.bag == "arrays" and outlier.sigmas > 8
    clean = accuracy(held_points, clean_cal.predict(held)).absolute_rms_mm
    dirty_rms = accuracy(held_points, cal.predict(held)).absolute_rms_mm
    assert dirty_rms <= 1.2 * clean
    assert "outliers: " + str(len(sizes)) in summary(cal, dirty)
    doc = json.loads(json.dumps(cal.to_dict(dirty)))
    assert [o["index"] for o in doc["outliers"]] == index.tolist()


def test_clean_data_flag_nothing_over_20_seeds() -> None:
    flagged = 0
    for seed in range(20):
        recording, _, _ = simulate_test2(WORLD, 100 + seed)
        flagged += len(calibrate(recording, ROBOT).outliers)
    assert flagged == 0


def test_the_diagnosis_never_calls_a_blunder_an_effect() -> None:
    """A robot with no effect, 3 blunders of 5 mm in the calibration bag and 1 in the
    hold-out: the verdict stays null, every blunder is listed, none is fitted."""
    case = make_case("none", 1)
    rng = np.random.default_rng(2)
    points, index = corrupt(case.calibration.points, np.full(3, 5e-3), rng)
    calibration = recording_from_arrays(
        case.calibration.poses.q, points, case.calibration.poses.time, source="cal"
    )
    h_points, h_index = corrupt(case.holdout.points, np.array([5e-3]), rng)
    holdout = recording_from_arrays(case.holdout.poses.q, h_points, source="hold")
    diagnosis, _ = diagnose(calibration, ROBOT, holdout)
    assert diagnosis.dominant_effect is None
    assert [(o.bag, o.index) for o in diagnosis.outliers] == [
        *(("cal", int(i)) for i in index),
        ("hold", int(h_index[0])),
    ]
    assert diagnosis.unexplained.ratio_to_noise_floor < 1.5
    assert diagnosis.to_dict()["outliers"][0]["size_m"] == pytest.approx(5e-3, rel=0.01)


def test_the_calibration_command_lists_outliers(tmp_path: Path) -> None:
    """Through the CLI: stdout names the blunder (bag, message index, size) and PARAMS.json
    lists it with its stamp."""
    recording, _, _ = simulate_test2(WORLD, 5)
    points = recording.points.copy()
    points[100] += [0.0, 0.0, 5e-3]
    bag = tmp_path / "blunder.mcap"
    write_measurements(bag, recording.poses.q, points)
    out = tmp_path / "params.json"
    proc = cli("calibrate", str(bag), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert f"{bag} point 100" in proc.stdout and "5.00" in proc.stdout
    (outlier,) = json.loads(out.read_text())["outliers"]
    assert outlier["bag"] == str(bag) and outlier["index"] == 100
    assert outlier["stamp_ns"] == 1_700_000_000_000_000_000 + 100 * 1_000_000_000 + 0
    assert outlier["direction"] == pytest.approx([0, 0, 1], abs=1e-2)


@pytest.mark.parametrize("model", ["nominal", "geometric"])
def test_a_target_far_from_the_flange_is_found_from_any_start(model: str) -> None:
    """0.34 m off the flange, tracker turned far from the default: the frames come out of a
    global start, nothing is fixed as 'not identifiable', the residual is the model's."""
    world = build_world(
        {
            "target_in_flange_m": [0.34, 0.0, 0.0],
            "base2tracker": {"xyz_m": [3.0, -2.0, 1.0], "rpy_deg": [170, -30, 95]},
        },
        "far target",
    )
    rng = np.random.default_rng(0)
    q = random_plan(ROBOT, 300, rng).q
    recording = recording_from_arrays(q, physical_points(world, Poses.from_readings(q), rng))
    cal = calibrate(recording, ROBOT, model)
    frames = [p for p in cal.parameters.parameters if p.group == "frames"]
    assert all(p.free for p in frames)
    assert cal.parameters["target_x"] == pytest.approx(0.34, abs=2e-3)
    limit = 3.0 if model == "nominal" else 0.02  # nominal: the unmodelled true geometry
    assert cal.accuracy.absolute_rms_mm < limit


def test_a_fit_with_nothing_free_does_not_crash() -> None:
    recording, _, _ = simulate_test2(WORLD, 0)
    model = KinematicModel(ROBOT)
    params = model.parameters()
    everything = params.fixed(params.names, "held for the test")
    fit = fit_model(model, everything, recording.poses, recording.points)
    assert fit.solver.message == "no free parameters" and not fit.std.any()


@pytest.mark.parametrize(
    ("n_points", "model", "needed"), [(2, "nominal", 4), (5, "geometric", 10)]
)
def test_too_few_measurements_is_exit_2_naming_how_many(
    tmp_path: Path, n_points: int, model: str, needed: int
) -> None:
    q = random_plan(ROBOT, n_points, np.random.default_rng(0)).q
    points = physical_points(WORLD, Poses.from_readings(q), np.random.default_rng(1))
    bag = tmp_path / "few.mcap"
    write_measurements(bag, q, points)
    out = tmp_path / "p.json"
    proc = cli("calibrate", str(bag), "--model", model, "-o", str(out))
    assert proc.returncode == 2, proc.stderr
    assert f"at least {needed} distinct poses are needed" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and not out.exists()
