"""Compensation: joint commands of a program taught on the nominal model,
corrected so that the calibrated robot (effects included) puts the tool where the nominal
model promised. Known answer: the simulated true robot commanded with them."""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli
from compensation_world import NOISE_FLOOR_M, ROBOT, WORLD, calibrated

from robot_calib.compensation import compensate_commands, compensate_targets
from robot_calib.compensation.solve import BRANCH_JUMP_RAD, _follow_the_rows, nominal_counterpart
from robot_calib.compensation.targets import Targets, goals_in_base
from robot_calib.identify.params_file import write_json_atomic
from robot_calib.ik import IKSolution, first_tool2flange, tool2base
from robot_calib.poses import Poses, approach_directions
from robot_calib.sim.plans import random_plan


def test_the_true_robot_reaches_what_the_nominal_model_promised() -> None:
    cal, _ = calibrated()
    commands = Poses.from_readings(random_plan(ROBOT, 200, np.random.default_rng(5)).q)
    result = compensate_commands(cal, commands)
    assert result.converged.all() and result.error_m.max() < 1e-8
    nominal, nominal_params = nominal_counterpart(cal.model, cal.parameters)
    promised = nominal.target_points(nominal_params, commands)  # tracker frame
    as_commanded = WORLD.model.target_points(WORLD.truth, commands)
    compensated = WORLD.model.target_points(WORLD.truth, replace(commands, q=result.q))
    miss = np.linalg.norm(as_commanded - promised, axis=1)
    reach = np.linalg.norm(compensated - promised, axis=1)
    assert miss.mean() > 0.3e-3  # the nominal program misses by tenths of a millimetre
    assert reach.mean() < 0.0135e-3  # within 1.5 x the simulated noise floor (~9 um)


def test_at_the_wrist_singularity_only_the_position_is_compensated() -> None:
    """Joint 5 at 0: the exact pose would swing joints 4 and 6 by tens of degrees for a few
    urad of orientation (the new user's 67.9 deg); the row is solved for the position alone
    with a small joint change and flagged, its orientation error reported."""
    from robot_calib.compensation.write import row_status

    cal, _ = calibrated()
    q = np.radians([[0, -90, 90, 0, 0, 0], [0, -90, 90, 0, 45, 0], [30, -60, 100, 20, 0.001, 5]])
    commands = Poses.from_readings(q)
    result = compensate_commands(cal, commands)
    assert result.position_only is not None
    assert result.position_only.tolist() == [True, False, True]
    assert np.degrees(np.abs(result.q - q)).max() < 0.5 and result.error_m.max() < 1e-8
    assert 0 < result.error_rad[0] < 1e-2 and result.error_rad[1] < 1e-8
    assert row_status(result, q) == ["position_only", "ok", "position_only"]


def test_the_compensate_command(tmp_path: Path) -> None:
    cal, recording = calibrated()
    params = tmp_path / "p.json"
    write_json_atomic(cal.to_dict(recording), params)
    q = random_plan(ROBOT, 20, np.random.default_rng(6)).q
    joints = tmp_path / "j.csv"
    np.savetxt(joints, q, delimiter=",", comments="", header="q1,q2,q3,q4,q5,q6")
    proc = cli("compensate", str(params), "--joints", str(joints), "-o", "out.csv", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "20 compensated commands" in proc.stdout
    with (tmp_path / "out.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 20 and float(rows[0]["error_mm"]) < 1e-5
    assert [r["dir1"] for r in rows[:2]] == ["1", "1" if q[1, 0] > q[0, 0] else "-1"]
    corrected = np.array([[float(r[f"q{j}"]) for j in range(1, 7)] for r in rows])
    change = np.abs(corrected - q).max(axis=1)  # per command [rad]
    assert change.min() > 0 and np.median(change) < 0.01  # mrad, more only near the wrist
    # singularity (joint 5 near 0: joints 4 and 6 trade a small orientation error)
    again = cli("compensate", str(params), "--joints", str(joints), "-o", "out.csv", cwd=tmp_path)
    assert again.returncode == 2 and "exists" in again.stderr
    np.savetxt(joints, np.degrees(q), delimiter=",", comments="", header="q1,q2,q3,q4,q5,q6")
    degrees = cli("compensate", str(params), "--joints", str(joints), "-o", "d.csv", cwd=tmp_path)
    assert degrees.returncode == 2 and "degrees?" in degrees.stderr
    assert not (tmp_path / "d.csv").exists()


def target_poses(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Readings (n, J) [rad] of random poses within the limits and the tool frames
    (n, 4, 4) the nominal model (with the calibration's frames) puts there, base frame."""
    cal, _ = calibrated()
    q = random_plan(ROBOT, n, np.random.default_rng(seed)).q
    tool = first_tool2flange(cal.model, cal.parameters)
    nominal, nominal_params = nominal_counterpart(cal.model, cal.parameters)
    return q, tool2base(nominal, nominal_params, Poses.from_readings(q), tool)


def in_tracker(goal2base: np.ndarray) -> np.ndarray:
    """The tool points (n, 3) [m] of goals in the calibration's tracker frame."""
    cal, _ = calibrated()
    b2t = cal.model.base2tracker(cal.parameters)
    return goal2base[:, :3, 3] @ b2t[:3, :3].T + b2t[:3, 3]


def targets_of(goal2base: np.ndarray, oriented: bool, seed: np.ndarray | None) -> Targets:
    n = len(goal2base)
    rotation = goal2base[:, :3, :3] if oriented else None
    return Targets(goal2base[:, :3, 3], rotation, seed, None, np.zeros(n), None, tuple(range(n)))


@pytest.mark.parametrize("oriented", [True, False])
def test_the_true_robot_reaches_the_targets(oriented: bool) -> None:
    """Targets (poses, or positions only) with taught seed readings 0.05 rad off: commanded
    with the nominal model's inverse kinematics the simulated true robot misses them by
    tenths of a millimetre; with the compensated commands it reaches them within 1.5 x the
    noise floor (the calibration's own error)."""
    cal, _ = calibrated()
    q, goal = target_poses(150, 7)
    seed = q + np.random.default_rng(8).uniform(-0.05, 0.05, q.shape)
    found = compensate_targets(cal, targets_of(goal, oriented, seed), goal)
    assert found.reached.all() and found.compensated.error_m.max() < 1e-8
    assert found.nominal.converged.all()
    if oriented:  # the solution near the seed: the pose the targets came from (but near a
        # singularity, where the same pose is reached by readings mrad apart)
        assert np.mean(np.abs(found.nominal.q - q).max(axis=1) < 1e-6) > 0.95
        assert found.compensated.error_rad.max() < 1e-7
    else:  # three equations: the orientation stays near the seed's
        assert np.abs(found.nominal.q - q).max() > 1e-3
    # the directions assumed are those of the commands in row order (the robot's)
    np.testing.assert_array_equal(found.direction, approach_directions(found.compensated.q))
    wanted = in_tracker(goal)
    as_nominal = WORLD.model.target_points(WORLD.truth, Poses.from_readings(found.nominal.q))
    compensated = WORLD.model.target_points(
        WORLD.truth, Poses.from_readings(found.compensated.q, found.direction)
    )
    miss = np.linalg.norm(as_nominal - wanted, axis=1)
    reach = np.linalg.norm(compensated - wanted, axis=1)
    assert miss.mean() > 0.3e-3
    assert reach.mean() < 1.5 * NOISE_FLOOR_M and reach.max() < 0.03e-3


def test_targets_from_the_home_pose_in_either_frame() -> None:
    """Without seeds the nominal inverse kinematics starts at the home pose (joint 1 facing
    the target): position targets are reached (within the joint limits) nearly all; the
    same targets given in the tracker frame give the same commands."""
    cal, _ = calibrated()
    _, goal = target_poses(100, 9)
    targets = targets_of(goal, False, None)
    found = compensate_targets(cal, targets, goal)
    assert found.reached.mean() >= 0.9
    # every target moved from the nominal solution took steps to get there (all rounds)
    moved = np.abs(found.compensated.q - found.nominal.q).max(axis=1) > 1e-9
    assert moved.any() and np.all(found.compensated.iterations[moved] >= 1)
    compensated = WORLD.model.target_points(
        WORLD.truth, Poses.from_readings(found.compensated.q, found.direction)
    )
    reach = np.linalg.norm(compensated - in_tracker(goal), axis=1)[found.reached]
    assert reach.mean() < 1.5 * NOISE_FLOOR_M
    tracker = replace(targets, position=in_tracker(goal))
    again = goals_in_base(tracker, "tracker", cal.model, cal.parameters)
    np.testing.assert_allclose(again[:, :3, 3], goal[:, :3, 3], atol=1e-12)


def test_targets_of_poses_within_the_limits_are_reached_within_them() -> None:
    """Position targets the robot reaches within its joint limits (made from 300 random
    poses within them), no seeds: the nominal IK from the home pose ended on the branch
    behind the robot for some (4 of 300 'beyond_limits' in the field, joint 1 past its
    limit); seeds over the arm's branches find one within the limits for every target."""
    cal, _ = calibrated()
    _, goal = target_poses(300, 11)
    targets = targets_of(goal, False, None)
    found = compensate_targets(cal, targets, goal)
    limits = ROBOT.limits
    inside = np.all(
        (found.compensated.q >= limits[:, 0]) & (found.compensated.q <= limits[:, 1]), axis=1
    )
    assert found.reached.all() and inside.all(), (found.reached.sum(), inside.sum())


def test_a_path_behind_the_robot_stays_on_one_branch() -> None:
    """Position targets along a path the arm reaches over backwards (joint 1 near 0, the
    tool behind the base; from the home pose facing them the IK takes another branch for
    some): every target reached within the limits, and the commands move smoothly from
    one row to the next (no switch of branch: at most 0.2 rad per step; 3.1 rad before)."""
    cal, _ = calibrated()
    tool = first_tool2flange(cal.model, cal.parameters)
    a = np.array([-0.015, -1.827, -1.646, -1.615, 0.513, -1.581])
    b = np.array([0.10, -1.75, -1.55, -1.50, 0.60, -1.40])
    q = a + np.linspace(0.0, 1.0, 20)[:, None] * (b - a)  # steps of < 0.01 rad
    nominal, nominal_params = nominal_counterpart(cal.model, cal.parameters)
    goal = tool2base(nominal, nominal_params, Poses.from_readings(q), tool)
    found = compensate_targets(cal, targets_of(goal, False, None), goal)
    limits = ROBOT.limits
    commands = found.compensated.q
    assert found.reached.all()
    assert np.all((commands >= limits[:, 0]) & (commands <= limits[:, 1]))
    assert np.abs(np.diff(commands, axis=0)).max() < 0.2


def test_a_target_at_no_finite_distance_is_not_reached() -> None:
    """The nominal inverse kinematics retries a target it missed from its nearest reached
    neighbour; a target at 1e300 m (a caller past the CSV reader's check) has none: it is
    not reached, the others are, nothing raises."""
    cal, _ = calibrated()
    _, goal = target_poses(6, 9)
    goal[2, 0, 3] = 1e300
    targets = targets_of(goal, False, None)
    found = compensate_targets(cal, targets, goal)
    assert not found.reached[2] and found.reached[[0, 1, 3, 4, 5]].sum() >= 4


def test_the_compensate_command_with_targets(tmp_path: Path) -> None:
    from scipy.spatial.transform import Rotation

    cal, recording = calibrated()
    params = tmp_path / "p.json"
    write_json_atomic(cal.to_dict(recording), params)
    q, goal = target_poses(12, 10)
    b2t = cal.model.base2tracker(cal.parameters)
    in_t = b2t @ goal
    quat = Rotation.from_matrix(in_t[:, :3, :3]).as_quat()
    table = np.hstack([in_t[:, :3, 3] * 1e3, quat])
    table[-1, :3] = [5000.0, 0.0, 0.0]  # 5 m away: out of reach
    targets = tmp_path / "t.csv"
    np.savetxt(targets, table, delimiter=",", comments="", header="x,y,z,qx,qy,qz,qw")
    seeds = tmp_path / "s.csv"
    np.savetxt(seeds, q + 0.02, delimiter=",", comments="", header="q1,q2,q3,q4,q5,q6")
    proc = cli(
        "compensate",
        str(params),
        "--targets",
        str(targets),
        "--frame",
        "tracker",
        "--unit",
        "mm",
        "--seed-joints",
        str(seeds),
        "-o",
        "out.csv",
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    assert "12 commands (rad) for target poses (tracker frame" in proc.stdout
    assert "11/12 reached" in proc.stdout
    assert "1 row(s) not reached" in proc.stderr and "data rows 12" in proc.stderr
    with (tmp_path / "out.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 12 and int(rows[0]["iterations"]) >= 1
    assert max(float(r["error_mm"]) for r in rows[:-1]) < 1e-5
    assert float(rows[-1]["error_mm"]) > 1000.0  # 5 m out, ~4 m beyond the arm's reach
    assert rows[-1]["status"] == "not_reached" and rows[-1]["q1"] == "nan"  # never sendable
    status = [r["status"] for r in rows[:-1]]
    assert status.count("ok") >= 10 and set(status) <= {"ok", "large_change"}
    if "large_change" in status:  # near the elbow singularity a pose needs degrees: flagged
        assert "moved by more than 2 deg" in proc.stderr
    corrected = np.array([[float(r[f"q{j}"]) for j in range(1, 7)] for r in rows[:-1]])
    assert np.abs(corrected - q[:-1]).max(axis=1).min() > 1e-5  # corrected, by mrad:
    assert np.median(np.abs(corrected - q[:-1])) < 0.01  # the seeds' IK is the source pose

    def refused(*extra: str) -> str:
        out = cli("compensate", str(params), *extra, "-o", "bad.csv", cwd=tmp_path)
        assert out.returncode == 2 and not (tmp_path / "bad.csv").exists()
        return out.stderr

    table[0, 3:] *= 2.0
    np.savetxt(targets, table, delimiter=",", comments="", header="x,y,z,qx,qy,qz,qw")
    assert "t.csv:2: quaternion" in refused("--targets", str(targets))
    assert "--frame goes with --targets" in refused("--joints", str(seeds), "--frame", "base")
    np.savetxt(targets, table[:, :2], delimiter=",", comments="", header="x,y")
    assert "header lacks ['z']" in refused("--targets", str(targets))
    np.savetxt(targets, table[:, :3], delimiter=",", comments="", header="x,y,z")  # mm as m
    assert "every target is out of robot" in refused("--targets", str(targets))
    assert "(--unit mm)" in refused("--targets", str(targets))
    table[1, 0] = 1e300  # a corrupt coordinate (it made the nominal IK's retry crash)
    np.savetxt(targets, table[:, :3], delimiter=",", comments="", header="x,y,z")
    message = refused("--targets", str(targets), "--unit", "mm")
    assert "t.csv:3: target x,y,z" in message and "beyond +-10000 m" in message, message
    assert len(message.strip().splitlines()) == 1, message


def row_by_row(
    found: IKSolution,
    start: Poses,
    goal2base: np.ndarray,
    oriented: np.ndarray,
    solve: Callable[..., IKSolution],
    limits: np.ndarray,
) -> np.ndarray:
    """The rule of `_follow_the_rows` as it reads, one row after another (the known
    answer): each row that jumps more than BRANCH_JUMP_RAD from the row before as it
    finally stands is solved from it, and kept where it converges within the limits and
    moves less."""
    q = found.q.copy()
    ok = found.converged & np.all((q >= limits[:, 0]) & (q <= limits[:, 1]), axis=1)
    for i in range(1, len(q)):
        jump = np.abs(q[i] - q[i - 1]).max()
        if not (ok[i] and ok[i - 1]) or jump <= BRANCH_JUMP_RAD:
            continue
        again = solve(
            replace(start.subset(np.array([i])), q=q[i - 1 : i]), goal2base[[i]], oriented[[i]]
        )
        inside = np.all((again.q >= limits[:, 0]) & (again.q <= limits[:, 1]))
        if again.converged[0] and inside and np.abs(again.q[0] - q[i - 1]).max() < jump:
            q[i] = again.q[0]
    return q


@pytest.mark.parametrize("seed", range(6))
def test_the_rows_of_a_program_follow_the_row_by_row_rule(seed: int) -> None:
    """`_follow_the_rows` decides its rows in batched rounds (was one solve per row: 11
    target poses/s); its result is the row-by-row rule's exactly, on an arm of two joints
    whose every target has three branches (the solver lands on the one nearest its seed,
    some beyond the limits) along 200 rows: scattered, and a path with branch switches
    (a first batched version kept rows decided against a row before that then changed)."""
    rng = np.random.default_rng(seed)
    n, limits = 200, np.array([[-3.0, 3.0], [-3.0, 3.0]])
    path = np.cumsum(rng.normal(0.0, 0.05, (n, 2)), axis=0)
    centre = path if seed % 2 else rng.uniform(-2.0, 2.0, (n, 2))
    branches = centre[:, None, :] + np.array([[0.0, 0.0], [1.2, -1.4], [-2.5, 2.2]])  # (n, 3, 2)
    goal2base = np.tile(np.eye(4), (n, 1, 1))
    goal2base[:, 0, 3] = np.arange(n)  # the row's index: which target

    def solve(poses: Poses, goal: np.ndarray, which: np.ndarray) -> IKSolution:
        rows = goal[:, 0, 3].astype(int)
        nearest = np.argmin(np.abs(branches[rows] - poses.q[:, None, :]).max(axis=2), axis=1)
        q = branches[rows, nearest]
        zero = np.zeros(len(rows))
        return IKSolution(
            q, zero, zero, np.ones(len(rows), dtype=np.int64), np.ones(len(rows), dtype=bool)
        )

    seeds = branches[np.arange(n), rng.integers(0, 3, n)]  # each row alone: any branch
    start = Poses(seeds, np.ones_like(seeds), np.zeros(n))
    oriented = np.zeros(n, dtype=bool)
    found = solve(start, goal2base, oriented)
    batched = _follow_the_rows(found, start, goal2base, oriented, solve, limits)
    expected = row_by_row(found, start, goal2base, oriented, solve, limits)
    assert not np.array_equal(expected, found.q)  # the rule changed rows
    np.testing.assert_array_equal(batched.q, expected)


def test_oriented_targets_without_seeds_are_reached_in_orientation_or_said_not() -> None:
    """Pose targets (position and orientation) of 40 random poses within the limits, half
    of them turned 60 deg about the tool's x axis, no seeds: every row called reached has
    the calibrated tool frame within 1e-6 rad of its goal by the rotation angle (was: a
    tool pointing the opposite way, 180 deg off, reported reached with 0 urad: the
    small-angle orientation error is zero at a half turn)."""
    cal, _ = calibrated()
    _, goal = target_poses(40, 21)
    turned = np.eye(4)
    turned[1:3, 1:3] = [[0.5, -np.sqrt(0.75)], [np.sqrt(0.75), 0.5]]
    goal[::2] = goal[::2] @ turned
    found = compensate_targets(cal, targets_of(goal, True, None), goal)
    tool = first_tool2flange(cal.model, cal.parameters)
    at = replace(Poses.from_readings(found.compensated.q), direction=found.direction)
    actual = tool2base(cal.model, cal.parameters, at, tool)
    turn = np.einsum("nba,nbc->nac", goal[:, :3, :3], actual[:, :3, :3])
    angle = np.arccos(np.clip((np.trace(turn, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0))
    reached = found.reached
    assert reached.sum() >= 30, reached.sum()
    assert angle[reached].max() < 1e-6, np.degrees(angle[reached]).max()
