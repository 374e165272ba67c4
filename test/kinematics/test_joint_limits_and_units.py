"""Safe in the field: one check of joint limits and units
(`RobotDescription.check_joints`) shared by `compensate`, the compensator node, `capture`,
`sim_robot` and `plan`; the compensator node forwards nothing the CLI would refuse or flag
(a trajectory in degrees, a point beyond the joint limits), tested through real rclpy on
this process's private ROS_DOMAIN_ID (conftest.py)."""

from __future__ import annotations

import csv
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from cli_runner import cli
from compensation_world import ROBOT, calibrated
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from robot_calib.capture.moves import limit_violations
from robot_calib.identify.params_file import write_json_atomic
from robot_calib.kinematics.description import JointLimitError
from robot_calib.nodes.compensator import CompensatorNode
from robot_calib.sim.plans import random_plan

IN, OUT = "/field_safety/in", "/field_safety/out"
TIMEOUT_S = 20.0
INSIDE = np.radians([0.0, -90.0, 90.0, 0.0, 45.0, 0.0])  # KR5: well inside every limit


def test_one_check_one_message_in_rad_and_deg() -> None:
    ROBOT.check_joints(np.vstack([INSIDE, INSIDE]), "x")  # nothing to say
    beyond = INSIDE.copy()
    beyond[4] = np.radians(100.0)  # joint_a5 limits +-90 deg
    with pytest.raises(JointLimitError) as found:
        ROBOT.check_joints(np.vstack([INSIDE, beyond]), "plan.yaml")
    assert str(found.value) == (
        "plan.yaml: pose 1: joint_a5 = 1.74533 rad (100.00 deg) outside its limits "
        "[-90.0, 90.0] deg (1 of 2 poses)"
    )
    # the same pose given in degrees: the same answer with unit='deg', and 'degrees?' as rad
    with pytest.raises(JointLimitError, match=r"pose 0: joint_a5 = 1.74533 rad \(100.00 deg\)"):
        ROBOT.check_joints(np.degrees(beyond), "t", unit="deg")
    ROBOT.check_joints(np.degrees(INSIDE), "t", unit="deg")
    with pytest.raises(
        JointLimitError,
        match="joint_a2 = -90 rad is beyond any reading of "
        "this joint in rad .* degrees\\? joint readings take rad",
    ):
        ROBOT.check_joints(np.degrees(INSIDE), "t")
    nan = INSIDE.copy()
    nan[2] = np.nan
    with pytest.raises(JointLimitError, match="joint_a3 = nan \\(not a finite number\\)"):
        ROBOT.check_joints(nan, "t")
    # one tolerance: a reading written at its limit (rounded) passes, 1 urad beyond does not
    at_limit = INSIDE.copy()
    at_limit[4] = ROBOT.limits[4, 1] + 1e-12
    ROBOT.check_joints(at_limit, "t")
    at_limit[4] = ROBOT.limits[4, 1] + 1e-6
    with pytest.raises(JointLimitError):
        ROBOT.check_joints(at_limit, "t")
    # capture's moves say the same as the others
    assert limit_violations(np.vstack([INSIDE, beyond]), ROBOT.limits, ROBOT.joint_names) == [
        None,
        "joint_a5 = 1.74533 rad (100.00 deg) outside its limits [-90.0, 90.0] deg",
    ]


def spin_until(executor: SingleThreadedExecutor, condition: Callable[[], bool]) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        executor.spin_once(timeout_sec=0.01)


def trajectory(q: np.ndarray) -> JointTrajectory:
    msg = JointTrajectory(joint_names=list(ROBOT.joint_names))
    for k, row in enumerate(q):
        msg.points.append(
            JointTrajectoryPoint(
                positions=[float(v) for v in row], time_from_start=Duration(sec=k + 1)
            )
        )
    return msg


@pytest.fixture(scope="module")
def params_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    cal, recording = calibrated()
    path = tmp_path_factory.mktemp("params") / "params.json"
    write_json_atomic(cal.to_dict(recording), path)
    return path


def test_the_compensator_forwards_no_degrees_and_nothing_beyond_the_limits(
    context: Context, params_file: Path
) -> None:
    compensator = CompensatorNode(
        context=context,
        parameter_overrides=[
            Parameter("params", value=str(params_file)),
            Parameter("input_topic", value=IN),
            Parameter("output_topic", value=OUT),
            Parameter("joint_states_topic", value=""),
        ],
    )
    client = Node("field_safety_client", context=context)
    publisher = client.create_publisher(JointTrajectory, IN, 10)
    received: list[JointTrajectory] = []
    client.create_subscription(JointTrajectory, OUT, received.append, 10)
    executor = SingleThreadedExecutor(context=context)
    for node in (compensator, client):
        executor.add_node(node)
    q = random_plan(ROBOT, 6, np.random.default_rng(3)).q  # inside the limits
    beyond = q.copy()
    beyond[4, 1] = np.radians(10.0)  # joint_a2's limits: [-162, -5] deg
    errors = []
    try:
        spin_until(
            executor,
            lambda: (
                publisher.get_subscription_count() > 0
                and compensator.publisher.get_subscription_count() > 0
            ),
        )
        for k, sent in enumerate((np.degrees(q), beyond, q), start=1):
            publisher.publish(trajectory(sent))
            spin_until(executor, lambda k=k: compensator.received == k)
            errors.append(compensator.last_error)
        spin_until(executor, lambda: len(received) == 1)
        executor.spin_once(timeout_sec=0.2)
    finally:
        executor.shutdown()
        for node in (compensator, client):
            node.destroy_node()
    # the trajectory in degrees and the one beyond the limits: dropped, one line each;
    # the good one (sent last) is the only one out, so the topic works
    assert (compensator.published, compensator.dropped, len(received)) == (1, 2, 1)
    assert errors[0] is not None and errors[0].startswith(
        f"dropped a trajectory, not sent: {IN}: point 0: "
    )
    assert "degrees? joint readings take rad" in errors[0]
    assert errors[1] == (
        f"dropped a trajectory, not sent: {IN}: point 4: joint_a2 = 0.174533 rad (10.00 deg) "
        "outside its limits [-162.0, -5.0] deg (1 of 6 points)"
    )
    out = np.array([p.positions for p in received[0].points])
    assert 0 < np.abs(out - q).max() < 0.05  # the good one, compensated (by mrad)


def test_compensate_flags_commands_beyond_the_limits(tmp_path: Path, params_file: Path) -> None:
    """`compensate --joints`: a command beyond the joint limits comes out `beyond_limits`
    (was `ok`), as msgs_doc/compensate.md says."""
    q = random_plan(ROBOT, 4, np.random.default_rng(6)).q
    q[2, 1] = np.radians(10.0)
    joints = tmp_path / "j.csv"
    np.savetxt(joints, q, delimiter=",", comments="", header="q1,q2,q3,q4,q5,q6")
    proc = cli(
        "compensate", str(params_file), "--joints", str(joints), "-o", "out.csv", cwd=tmp_path
    )
    assert proc.returncode == 0, proc.stderr
    with (tmp_path / "out.csv").open() as handle:
        status = [row["status"] for row in csv.DictReader(handle)]
    assert status[2] == "beyond_limits" and status.count("beyond_limits") == 1, status
    assert "1 row(s) reached only beyond the joint limits" in proc.stderr
