"""Capture planning (robot_calib/plan/): D-optimal plans against random poses, predicted
1-sigma against the spread of simulated calibrations, PLAN.yaml through simulate and run,
and one-line errors for bad plan files."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import cli

from robot_calib.cli import main
from robot_calib.errors import InputError
from robot_calib.identify.calibrate import calibrate
from robot_calib.kinematics.loader import load_robot
from robot_calib.plan.campaign import planning_problem
from robot_calib.plan.design import d_optimal
from robot_calib.plan.evaluate import predict, world_noise_m
from robot_calib.plan.plan_file import load_plan, plan_text
from robot_calib.sim.measure import record_plan
from robot_calib.sim.world import load_world

WORLD = load_world()


@pytest.fixture(scope="module")
def problem():  # noqa: ANN201 - DesignProblem
    return planning_problem(WORLD, "geometric", 600, np.random.default_rng(0))


def test_d_optimal_worst_sigma_at_least_2x_smaller_than_random(problem) -> None:  # noqa: ANN001
    n = 12  # near the fewest poses that determine the 27 free parameters (10)
    noise = world_noise_m(WORLD, problem)
    planned = predict(problem, problem.plan(d_optimal(problem, n)), noise)
    rng = np.random.default_rng(1)
    random_worst = [
        predict(
            problem, problem.plan(problem.candidates[rng.choice(600, n, replace=False)]), noise
        ).rms_m.max()
        for _ in range(15)
    ]
    assert len(planned.names) == 27  # the geometric parameters of the KR5 with a point target
    assert np.median(random_worst) / planned.rms_m.max() >= 2.0


def test_order_dependent_models_are_planned_in_visiting_order() -> None:
    backlash = planning_problem(WORLD, "geometric+backlash:4", 200, np.random.default_rng(0))
    assert backlash.sequential
    q = d_optimal(backlash, 20)
    # the play of joint 4 is identifiable: both approach directions are among the poses
    assert set(np.sign(np.diff(q[:, 3]))) == {-1.0, 1.0}
    assert np.isfinite(predict(backlash, backlash.plan(q), 5e-6).std).all()


def test_predicted_sigma_matches_the_spread_of_simulated_calibrations(problem) -> None:  # noqa: ANN001
    plan = problem.plan(d_optimal(problem, 30))
    predicted = predict(problem, plan, world_noise_m(WORLD, problem))
    rng = np.random.default_rng(7)
    estimates = []
    for _ in range(12):  # the same true robot, new noise each time
        cal = calibrate(record_plan(WORLD, plan, rng), WORLD.model.robot, "geometric")
        estimates.append([cal.parameters[name] for name in predicted.names])
    spread = np.std(estimates, axis=0, ddof=1)
    ratio = spread / predicted.std
    assert 0.7 < np.median(ratio) < 1.4, ratio
    assert np.all((ratio > 0.3) & (ratio < 2.5)), dict(zip(predicted.names, ratio.round(2)))


@pytest.mark.slow
def test_plan_file_round_trip_through_simulate_and_run(tmp_path: Path) -> None:
    plan = tmp_path / "plan.yaml"
    made = cli("plan", "--poses", "20", "--candidates", "300", "--trials", "0", "-o", str(plan))
    assert made.returncode == 0, made.stderr
    assert "x smaller than random poses at equal N" in made.stdout
    q = load_plan(plan, WORLD.model.robot).q
    assert q.shape == (20, 6)
    # 20 distinct readings of every joint fit orders 1-9 at once (19 unknowns + mean)
    assert "joint-angle harmonics the plan resolves per joint" in made.stdout
    assert made.stdout.count("(9 together") == 6, made.stdout
    sim = cli("simulate", "--plan", str(plan), "-o", str(tmp_path / "p.mcap"))
    assert sim.returncode == 0, sim.stderr
    from robot_calib.flows.bags import read_bags

    recorded = read_bags([tmp_path / "p.mcap"], WORLD.model.robot)
    np.testing.assert_allclose(recorded.poses.q, q, atol=1e-12)  # visited in the order listed
    run = cli("run", "--plan", str(plan), "--holdout", "30", "-o", str(tmp_path / "out"))
    assert run.returncode == 0, run.stderr
    assert "no cpa: the plan has no circle sweep" in run.stdout
    assert list((tmp_path / "out").glob("run-*/params_geometric.json"))


@pytest.mark.slow
def test_sweeps_in_irregular_steps_tell_every_order_apart(tmp_path: Path) -> None:
    """`plan --sweeps paper-test2`: the seed's sweeps, whose regular steps tell joint 4's
    orders apart up to 30 only (60 steps of 6 deg: order k and 60 - k coincide), in
    irregular steps that tell every order up to 64 apart; the file loads, is visited as
    listed, keeps six circle sweeps for cpa; bad requests exit 2 naming the option."""
    from robot_calib.measurements import find_sweeps
    from robot_calib.measurements.aliasing import resolvable_order

    plan = tmp_path / "sweeps.yaml"
    made = cli("plan", "--sweeps", "paper-test2", "-o", str(plan))
    assert made.returncode == 0, made.stderr
    regular, irregular = [line for line in made.stdout.splitlines() if "resolves per" in line]
    assert "joint 4 up to order 30 (" in regular, regular
    assert irregular.count("up to order 64") == 6, irregular
    q = load_plan(plan, WORLD.model.robot).q
    assert q.shape == (580, 6)
    assert [resolvable_order(q[:, j]) for j in range(6)] == [64] * 6
    assert sorted(s.joint for s in find_sweeps(q)) == [1, 2, 3, 4, 5, 6]
    # the seed's sweeps reach below the KR5's mounting plane: said, and kept in the file
    assert "poses put a joint centre, the flange or the target below z = 0 m" in made.stdout
    assert "below z = 0 m" in plan.read_text()
    clear = cli(
        "plan", "--sweeps", "paper-test2", "--floor-z=-inf", "-o", str(tmp_path / "c.yaml")
    )
    assert clear.returncode == 0 and "warning" not in clear.stdout, clear.stdout
    for bad, words in (
        (["--sweeps", "paper-test9"], "--sweeps paper-test9: not one of"),
        (["--sweeps", "test2"], "--sweeps test2"),
        (["--sweeps", "paper-test2", "--max-order", "65"], "--max-order 65"),
        (["--sweeps", "paper-test2", "--poses", "20"], "either --poses"),
        (["--sweeps", "paper-test2", "--candidates", "5"], "--candidates belong"),
        (["--poses", "20", "--max-order", "10"], "--max-order belongs"),
        ([], "either --poses"),
    ):
        out = cli("plan", *bad, "-o", str(tmp_path / "x.yaml"))
        assert out.returncode == 2 and words in out.stderr, (bad, out.stderr)
        assert len(out.stderr.strip().splitlines()) == 1 and not (tmp_path / "x.yaml").exists()


def _plan_doc(**changes: object) -> dict[str, object]:
    robot = WORLD.model.robot
    text = plan_text(robot, "geometric", np.zeros((11, 6)) + [0, -1, 1, 0, 1, 0], 0.1, {}, {})
    doc = yaml.safe_load(text)
    doc.update(changes)
    return {k: v for k, v in doc.items() if v is not None}


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        (_plan_doc(poses=None), "missing key(s) poses"),
        (_plan_doc(poses=[[0.0] * 5]), "pose 0 has 5 readings, the robot 6"),
        (
            _plan_doc(poses=[[0.0, -1.0, 1.0, 0.0, 1.0, 4.0]]),
            "pose 0: joint_a6 = 4 rad (229.18 deg) outside its limits",
        ),
        (_plan_doc(poses=[[0.0, -1.0, float("nan"), 0.0, 1.0, 0.0]]), "non-finite"),
        (_plan_doc(robot="ur10"), "planned for robot ur10, not for kr5_sixx_r650"),
        (_plan_doc(posess=[]), "unknown key 'posess'"),
        (None, "no such plan file"),
    ],
)
def test_bad_plan_files_exit_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], doc: object, message: str
) -> None:
    path = tmp_path / "bad.yaml"
    if doc is not None:
        path.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_plan(path, load_robot("kr5_sixx_r650"))
    status = main(["simulate", "--plan", str(path), "-o", str(tmp_path / "x.mcap")])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and str(path) in err and message in err
    assert not list(tmp_path.glob("x*"))  # nothing written


def test_world_noise_includes_repeatability(problem) -> None:  # noqa: ANN001
    quiet = replace(WORLD, noise=replace(WORLD.noise, joint_sigma_rad=0.0))
    tracker_only = np.hypot(WORLD.noise.tracker_sigma_m, WORLD.noise.target_sigma_m)
    assert world_noise_m(quiet, problem) == pytest.approx(tracker_only)
    assert world_noise_m(WORLD, problem) > 1.05 * tracker_only


def test_candidates_keep_every_joint_centre_above_the_floor() -> None:
    """The review found elbow and wrist centres 41.6 mm under the table with only the flange
    and target checked: every DH frame origin counts now (known geometry: chain's frames)."""
    from robot_calib.kinematics.dh import chain
    from robot_calib.model import KinematicModel
    from robot_calib.plan.design import draw_candidates
    from robot_calib.sim.world import load_world

    model = KinematicModel(load_world(None).model.robot, ())
    params = model.parameters()
    q = draw_candidates(model, params, 400, np.random.default_rng(4), floor_z_m=0.1)
    heights = chain(model.dh_table(params, q))[:, 1:, 2, 3]  # frames 1..J, the flange last
    assert heights.min() >= 0.1 - 1e-9
    from robot_calib.sim.plans import random_plan

    unchecked = chain(
        model.dh_table(params, random_plan(model.robot, 400, np.random.default_rng(4)).q)
    )
    assert (unchecked[:, 1:-1, 2, 3] < 0.1).any()  # the check has something to remove
