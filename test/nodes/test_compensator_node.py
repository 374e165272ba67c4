"""The compensator node (msgs_doc/compensator.md) through real rclpy on this
process's private ROS_DOMAIN_ID (conftest.py): a JointTrajectory in the controller's joint
order (shuffled against the model's) comes back corrected, equal to the pure function's
answer, and the simulated true robot commanded with it reaches what the nominal model
promised (known answer: test_compensate's KR5 with 2 mrad of joint-4 backlash)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from compensation_world import NOISE_FLOOR_M, ROBOT, WORLD, calibrated
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from robot_calib.compensation import compensate_commands
from robot_calib.compensation.solve import nominal_counterpart
from robot_calib.errors import InputError
from robot_calib.identify.params_file import write_json_atomic
from robot_calib.nodes.compensator import CompensatorNode
from robot_calib.poses import Poses, approach_directions
from robot_calib.sim.plans import random_plan

IN, OUT = "/test_compensator/in", "/test_compensator/out"
ORDER = [3, 0, 5, 1, 4, 2]  # the controller's joint order: model joints 4, 1, 6, 2, 5, 3
TIMEOUT_S = 20.0


def spin_until(executor: SingleThreadedExecutor, condition: Callable[[], bool]) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        executor.spin_once(timeout_sec=0.01)


def trajectory(q: np.ndarray, names: list[str]) -> JointTrajectory:
    """Points q (n, J) [rad] (model order) in the order of `names` (ORDER), 0.5 s apart,
    with velocities that must pass unchanged."""
    msg = JointTrajectory(joint_names=names)
    msg.header.frame_id = "base_link"
    msg.header.stamp.sec = 42
    for k, row in enumerate(q):
        msg.points.append(
            JointTrajectoryPoint(
                positions=[float(row[j]) for j in ORDER],
                velocities=[0.1 * k + j for j in range(len(names))],
                time_from_start=Duration(sec=k // 2, nanosec=500_000_000 * (k % 2)),
            )
        )
    return msg


@pytest.fixture
def params_file(tmp_path: Path) -> Path:
    cal, recording = calibrated()
    path = tmp_path / "params.json"
    write_json_atomic(cal.to_dict(recording), path)
    return path


def nodes(
    context: Context, params_file: Path, *extra: Parameter
) -> tuple[CompensatorNode, Node, Any, list[JointTrajectory]]:
    """The compensator (IN -> OUT) and a client publishing on IN and collecting OUT."""
    compensator = CompensatorNode(
        context=context,
        parameter_overrides=[
            Parameter("params", value=str(params_file)),
            Parameter("input_topic", value=IN),
            Parameter("output_topic", value=OUT),
            *extra,
        ],
    )
    client = Node("trajectory_client", context=context)
    publisher = client.create_publisher(JointTrajectory, IN, 10)
    received: list[JointTrajectory] = []
    client.create_subscription(JointTrajectory, OUT, received.append, 10)
    return compensator, client, publisher, received


def test_a_trajectory_comes_back_compensated(context: Context, params_file: Path) -> None:
    compensator, client, publisher, received = nodes(context, params_file)
    states = client.create_publisher(JointState, "/joint_states", 10)
    executor = SingleThreadedExecutor(context=context)
    for node in (compensator, client):
        executor.add_node(node)
    names = [ROBOT.joint_names[j] for j in ORDER]
    q = random_plan(ROBOT, 40, np.random.default_rng(11)).q
    # the robot stands at the first point, joint 4 having come down to it (backlash side -1):
    # a joint that keeps still keeps that side, which the node must take from /joint_states
    start = (q[0], np.array([1.0, 1.0, 1.0, -1.0, 1.0, 1.0]))
    standing = JointState(
        name=list(ROBOT.joint_names),
        position=start[0].tolist(),
        velocity=(start[1] * 1e-9).tolist(),
    )
    try:
        spin_until(
            executor,
            lambda: (
                publisher.get_subscription_count() > 0
                and compensator.publisher.get_subscription_count() > 0
                and states.get_subscription_count() > 0
            ),
        )
        states.publish(standing)
        spin_until(executor, lambda: compensator.robot_state is not None)
        publisher.publish(trajectory(q, names))
        spin_until(executor, lambda: len(received) == 1)
        bad = trajectory(q[:3], [*names[:-1], "joint_x"])  # an unknown joint: dropped
        publisher.publish(bad)
        spin_until(executor, lambda: compensator.received == 2)
        executor.spin_once(timeout_sec=0.2)
    finally:
        executor.shutdown()
        for node in (compensator, client):
            node.destroy_node()
    assert (compensator.published, compensator.dropped, len(received)) == (1, 1, 1)
    out = received[0]
    assert list(out.joint_names) == names and out.header.stamp.sec == 42
    assert out.header.frame_id == "base_link" and len(out.points) == len(q)
    corrected = np.array([p.positions for p in out.points])[:, np.argsort(ORDER)]  # model order
    seconds = np.array(
        [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in out.points]
    )
    np.testing.assert_allclose(seconds, 0.5 * np.arange(len(q)), rtol=0, atol=1e-9)  # sec + ns
    assert [list(p.velocities) for p in out.points] == [
        list(p.velocities) for p in trajectory(q, names).points
    ]

    cal, _ = calibrated()
    commands = Poses.from_readings(q, approach_directions(q, start=start), seconds)
    assert commands.direction[0, 3] == -1.0  # a sign (+-1), not a computed value
    expected = compensate_commands(cal, commands)
    np.testing.assert_allclose(corrected, expected.q, rtol=0, atol=1e-12)
    assert np.abs(corrected - q).max() > 1e-4  # corrected (backlash 2 mrad), not passed on

    nominal, nominal_params = nominal_counterpart(cal.model, cal.parameters)
    promised = nominal.target_points(nominal_params, commands)  # tracker frame
    moved = Poses.from_readings(  # as the robot moves, from where it stood
        corrected, approach_directions(corrected, start=start)
    )
    as_planned = WORLD.model.target_points(WORLD.truth, commands)
    compensated = WORLD.model.target_points(WORLD.truth, moved)
    assert np.linalg.norm(as_planned - promised, axis=1).mean() > 0.3e-3
    assert np.linalg.norm(compensated - promised, axis=1).mean() < 1.5 * NOISE_FLOOR_M


def test_a_compensator_without_params_is_refused(context: Context) -> None:
    with pytest.raises(InputError, match="parameter 'params'"):
        CompensatorNode(context=context)


def test_a_trajectory_corrected_beyond_max_correction_is_not_sent(
    context: Context, params_file: Path
) -> None:
    """A correction larger than `max_correction` (a wrist flip near the singularity; here a
    bound below the 2 mrad backlash's) drops the trajectory: nothing reaches the robot."""
    compensator, client, publisher, received = nodes(
        context,
        params_file,
        Parameter("max_correction", value=0.01),  # deg
    )
    executor = SingleThreadedExecutor(context=context)
    for node in (compensator, client):
        executor.add_node(node)
    try:
        spin_until(
            executor,
            lambda: (
                publisher.get_subscription_count() > 0
                and compensator.publisher.get_subscription_count() > 0
            ),
        )
        q = random_plan(ROBOT, 5, np.random.default_rng(2)).q
        publisher.publish(trajectory(q, [ROBOT.joint_names[j] for j in ORDER]))
        spin_until(executor, lambda: compensator.received == 1)
        executor.spin_once(timeout_sec=0.2)
    finally:
        executor.shutdown()
        for node in (compensator, client):
            node.destroy_node()
    assert (compensator.published, compensator.dropped, received) == (0, 1, [])


def test_each_trajectory_outcome_is_reported_on_status(
    context: Context, params_file: Path
) -> None:
    """The sender learns what became of each trajectory on ~/status (DiagnosticStatus):
    the first corrected (OK, its largest correction), the second dropped for a point in
    degrees (ERROR, the reason), each with its stamp and number of points."""
    from diagnostic_msgs.msg import DiagnosticStatus

    compensator, client, publisher, received = nodes(context, params_file)
    statuses: list[DiagnosticStatus] = []
    client.create_subscription(DiagnosticStatus, "/compensator/status", statuses.append, 10)
    executor = SingleThreadedExecutor(context=context)
    for node in (compensator, client):
        executor.add_node(node)
    names = [ROBOT.joint_names[j] for j in ORDER]
    try:
        spin_until(
            executor,
            lambda: (
                publisher.get_subscription_count() > 0
                and compensator.status.get_subscription_count() > 0
            ),
        )
        q = random_plan(ROBOT, 4, np.random.default_rng(5)).q
        publisher.publish(trajectory(q, names))
        spin_until(executor, lambda: len(statuses) == 1)
        degrees = trajectory(np.degrees(q[:3]), names)
        degrees.header.stamp.sec = 43
        publisher.publish(degrees)
        spin_until(executor, lambda: len(statuses) == 2)
    finally:
        executor.shutdown()
        for node in (compensator, client):
            node.destroy_node()
    ok, dropped = statuses
    assert ok.level == DiagnosticStatus.OK and ok.message.startswith("corrected: 4 points")
    values = {v.key: v.value for v in ok.values}
    assert values["stamp"] == "42.000000000" and values["points"] == "4"
    assert float(values["largest_correction_mrad"]) > 0.1  # the 2 mrad backlash's share
    assert dropped.level == DiagnosticStatus.ERROR
    assert dropped.message.startswith("dropped, not sent:") and "degrees" in dropped.message
    assert {v.key: v.value for v in dropped.values}["stamp"] == "43.000000000"
    assert len(received) == 1


def test_the_follow_joint_trajectory_adapter_needs_control_msgs(
    context: Context, params_file: Path
) -> None:
    """control_msgs is not installable here: asking for the adapter is one error naming
    the parameter and the package (on a Jazzy install the adapter serves the action)."""
    try:
        import control_msgs  # noqa: F401

        pytest.skip("control_msgs installed: the adapter would start")
    except ImportError:
        pass
    with pytest.raises(InputError, match="parameter 'action_controller': control_msgs is not"):
        nodes(
            context,
            params_file,
            Parameter("action_controller", value="/jtc/follow_joint_trajectory"),
        )
