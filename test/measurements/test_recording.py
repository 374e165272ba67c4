"""Reading a recording: pairing points with joint states, directions, sweeps, and the one-line
errors for bad input (real MCAP files written with our writer and rclpy serialisation)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from bag_files import JS, PS_TYPE, write_measurements
from cli_runner import cli

from robot_calib.bag.read import read_recording
from robot_calib.errors import RobotCalibError
from robot_calib.kinematics.description import with_joint_names
from robot_calib.kinematics.loader import load_robot
from robot_calib.measurements import find_sweeps, recording_from_arrays
from robot_calib.sim.plans import paper_test_plan, random_plan

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "bags" / "paper_test3.mcap"
ROBOT = load_robot("kr5_sixx_r650")


def test_sweeps_of_the_paper_plan() -> None:
    plan = paper_test_plan(2)
    sweeps = find_sweeps(plan.q)
    assert [s.joint for s in sweeps] == [1, 2, 3, 4, 5, 6]
    assert [s.n_poses for s in sweeps] == [120, 60, 100, 120, 60, 120]
    for s in sweeps:  # each sweep is exactly the plan's poses labelled with that joint
        assert np.array_equal(s.index, np.flatnonzero(plan.sweep == s.joint))


def test_general_poses_make_no_sweeps_and_a_shared_pose_starts_the_next_sweep() -> None:
    assert find_sweeps(random_plan(ROBOT, 50, np.random.default_rng(0)).q) == []
    q = np.zeros((7, 6))
    q[1:4, 0] = [0.1, 0.2, 0.3]  # joint 1 turns over poses 0-3
    q[4:, 0] = 0.3
    q[4:, 1] = [0.1, 0.2, 0.3]  # then joint 2 from pose 3 on
    sweeps = find_sweeps(q)
    assert [(s.joint, s.index.tolist()) for s in sweeps] == [(1, [0, 1, 2, 3]), (2, [3, 4, 5, 6])]


def test_sample_bag_pairs_every_point() -> None:
    rec = read_recording([SAMPLE], ROBOT)
    assert len(rec) == 290 and rec.n_unpaired == 0
    assert [s.joint for s in rec.sweeps] == [1, 2, 3, 4, 5, 6]
    assert rec.general.sum() == 0
    # the first stamp minus itself (integer ns): exactly 0
    assert rec.poses.time[0] == 0.0 and np.all(np.diff(rec.poses.time) > 0)
    # Forth then back: joint 1 approaches its first half from +, the second half from -.
    d = rec.poses.direction[rec.sweeps[0].index, 0]
    assert np.all(d[1:30] == -1.0) and np.all(d[31:] == 1.0)  # signs (+-1), exact


def test_unpaired_points_are_counted_and_reported(tmp_path: Path) -> None:
    plan = paper_test_plan(3)
    offsets = np.zeros(len(plan.q))
    offsets[[5, 50, 100]] = 0.3  # 0.3 s from any joint state: beyond the 0.05 s tolerance
    path = tmp_path / "late.mcap"
    # distinct points, as a tracker measures (identical ones would be copies: counted once)
    points = 1.0 + np.random.default_rng(0).normal(0.0, 1e-3, (len(plan.q), 3))
    write_measurements(path, plan.q, points, point_offsets_s=offsets)
    log: list[str] = []
    rec = read_recording([path], ROBOT, log=log.append)
    assert rec.n_unpaired == 3 and len(rec) == len(plan.q) - 3
    assert any("3 of 290 points have no joint state" in w for w in log)
    # With a wider tolerance they pair again.
    assert read_recording([path], ROBOT, pair_tolerance=0.5).n_unpaired == 0


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("text", "not an MCAP file"),
        ("missing_topic", "no topic /laser_tracker/point"),
        ("wrong_type", "has type geometry_msgs/msg/PointStamped, not sensor_msgs/msg/JointState"),
        ("nan", "is not finite"),
        ("millimetres", "look like millimetres"),
        ("names", "are not the robot's joints ['joint_a1', 'joint_a2', 'joint_a3', 'joint_a4', "),
        ("truncated", "truncated MCAP file"),
    ],
)
def test_bad_bags_give_one_line_errors(tmp_path: Path, case: str, message: str) -> None:
    path = tmp_path / f"{case}.mcap"
    q = paper_test_plan(3).q[:20]
    points = np.tile([2.0, 1.0, 0.1], (20, 1))
    if case == "text":
        path.write_text("x,y,z\n1,2,3\n")
    elif case == "missing_topic":
        write_measurements(path, q, points, topics=(JS,))
    elif case == "wrong_type":
        write_measurements(path, q, points, js_type=PS_TYPE)
    elif case == "nan":
        points[7, 1] = np.nan
        write_measurements(path, q, points)
    elif case == "millimetres":
        write_measurements(path, q, points * 1e3)
    elif case == "names":
        write_measurements(path, q, points, names=[f"j{j}" for j in range(6)])
    elif case == "truncated":
        write_measurements(path, q, points)
        path.write_bytes(path.read_bytes()[:-200])
    with pytest.raises(RobotCalibError) as err:
        read_recording([path], ROBOT)
    assert message in str(err.value) and str(path) in str(err.value)
    assert "\n" not in str(err.value)
    # The command line says the same in one line with exit status 2 and writes nothing.
    out = tmp_path / f"{case}.json"
    proc = cli("calibrate", str(path), "-o", str(out))
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_small_sweeps_are_used_as_general_poses_with_a_warning() -> None:
    q = np.zeros((5, 6))
    q[:, 3] = np.radians([0, 1, 2, 3, 4])  # 4 deg: too small to fit a circle
    rec = recording_from_arrays(q, np.random.default_rng(0).normal(size=(5, 3)))
    assert rec.sweeps == () and rec.general.all()
    assert "too small to fit a circle" in rec.warnings[0]


def test_joint_names_map_another_naming(tmp_path: Path) -> None:
    """A bag whose JointState names are not the robot's reads as the robot with renamed
    joints (`--joint-names`), with the same readings and sweeps as the robot's own names."""
    plan = paper_test_plan(3)
    points = np.random.default_rng(1).normal(2.0, 0.1, (len(plan.q), 3))
    own, other = tmp_path / "own.mcap", tmp_path / "other.mcap"
    names = [f"j{j}" for j in range(1, 7)]
    write_measurements(own, plan.q, points)
    write_measurements(other, plan.q[:, ::-1], points, names=names[::-1])  # any order
    expected = read_recording([own], ROBOT)
    renamed = read_recording([other], with_joint_names(ROBOT, ",".join(names)))
    np.testing.assert_array_equal(renamed.poses.q, expected.poses.q)
    assert [(s.joint, s.index.tolist()) for s in renamed.sweeps] == [
        (s.joint, s.index.tolist()) for s in expected.sweeps
    ]
    out = tmp_path / "p.json"
    proc = cli(
        "calibrate",
        str(other),
        "--model",
        "nominal",
        "--joint-names",
        ",".join(names),
        "-o",
        str(out),
    )
    assert proc.returncode == 0 and out.exists(), proc.stderr
    # The calibration is of the same robot: score and predict read it (names aside).
    joints = tmp_path / "joints.csv"
    joints.write_text("q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0\n")
    for args in (
        ["score", str(out), str(other), "--joint-names", ",".join(names)],
        ["predict", str(out), "--joints", str(joints), "-o", str(tmp_path / "x.csv")],
    ):
        proc = cli(*args)
        assert proc.returncode == 0, (args[0], proc.stderr)


def test_coupled_readings_sweep_one_joint() -> None:
    """With a J3 += J2 coupling, the plan's joint-2 sweep moves readings 2 and 3 together:
    on the readings it is no sweep, on the robot's joint variables it is joint 2's."""
    coupled = replace(ROBOT, reading_matrix=np.eye(6) + np.eye(6, k=-1) * (np.arange(6) == 1))
    assert coupled.reading_matrix is not None and coupled.reading_matrix[2, 1] == 1.0
    plan = paper_test_plan(2)
    q = coupled.readings(plan.q)
    points = np.random.default_rng(2).normal(2.0, 0.1, (len(q), 3))
    assert 2 not in {s.joint for s in find_sweeps(q)}
    rec = recording_from_arrays(q, points, robot=coupled)
    assert [s.joint for s in rec.sweeps] == [1, 2, 3, 4, 5, 6]
    plain = recording_from_arrays(plan.q, points)
    assert [s.index.tolist() for s in rec.sweeps] == [s.index.tolist() for s in plain.sweeps]
