"""The calibrator node says when its result is wrong and acts on its own diagnosis, through
real rclpy: a solve of joints sent in degrees answers success=False with the reasons; a
backlash world diagnosed in the node warns on /diagnostics that the published geometric
model leaves the backlash, and with publish:=best publishes the backlash model itself."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_spin import spin_until as wait_until
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from robot_calib.errors import InputError
from robot_calib.flows.simulate import simulate as simulate_world
from robot_calib.messages import JOINT_STATES_TOPIC, POINT_TOPIC, ns_to_sec_nanosec
from robot_calib.nodes.calibrator import LATCHED, CalibratorNode
from robot_calib.nodes.simulate import simulate_bag
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import random_plan
from robot_calib.sim.world import build_world, load_world

TIMEOUT_S = 60.0
T0_NS = 1_700_000_000_000_000_000


def spin_until(executor: SingleThreadedExecutor, condition: Callable[[], bool]) -> None:
    wait_until(executor, condition, TIMEOUT_S)  # a diagnosis in the node takes seconds


def test_a_solve_of_joints_in_degrees_answers_failure(context: Context) -> None:
    """Live mode, the robot's readings sent in degrees (a driver's unit slip): the result is
    nonsense, so ~/solve answers success=False with the implausibility, not an accuracy."""
    world = load_world()
    robot = world.model.robot
    plan = random_plan(robot, 60, np.random.default_rng(3))
    points = physical_points(world, Poses.from_readings(plan.q), None, noisy=False)
    calibrator = CalibratorNode(context=context)
    source = Node("source", context=context)
    deep = QoSProfile(
        reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=1000
    )
    js_pub = source.create_publisher(JointState, JOINT_STATES_TOPIC, deep)
    pt_pub = source.create_publisher(PointStamped, POINT_TOPIC, deep)
    client = source.create_client(Trigger, "/calibrator/solve")
    executor = SingleThreadedExecutor(context=context)
    for node in (calibrator, source):
        executor.add_node(node)
    try:
        spin_until(executor, lambda: min(p.get_subscription_count() for p in (js_pub, pt_pub)))
        for k, (q, p) in enumerate(zip(plan.q, points)):
            stamp = T0_NS + k * 1_000_000_000
            js = JointState(name=list(robot.joint_names), position=np.degrees(q).tolist())
            js.header.stamp.sec, js.header.stamp.nanosec = ns_to_sec_nanosec(stamp)
            js_pub.publish(js)
            pt = PointStamped()
            pt.header.frame_id = "laser_tracker"
            pt.header.stamp.sec, pt.header.stamp.nanosec = ns_to_sec_nanosec(stamp)
            pt.point.x, pt.point.y, pt.point.z = p.tolist()
            pt_pub.publish(pt)
        spin_until(executor, lambda: calibrator.received.get(POINT_TOPIC, 0) == len(plan))
        spin_until(executor, client.service_is_ready)
        future = client.call_async(Trigger.Request())
        spin_until(executor, future.done)
        answer = future.result()
        status = calibrator._status
    finally:
        executor.shutdown()
        for node in (calibrator, source):
            node.destroy_node()
    assert answer is not None and not answer.success, answer
    assert "implausible" in answer.message and "degrees" in answer.message, answer.message
    assert status.level == DiagnosticStatus.ERROR


@pytest.fixture(scope="module")
def backlash_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    world = build_world({"seed": 4, "effects": [{"name": "backlash", "joints": [4]}]}, "backlash")
    bag = tmp_path_factory.mktemp("backlash") / "backlash.mcap"
    simulate_world(bag, "paper-test2", world, record=simulate_bag)
    return bag


def _solved(context: Context, bag: Path, **settings: object) -> tuple[CalibratorNode, dict]:
    """A bag-mode calibrator with parameters `settings`, run to its result; the node
    (destroyed) and the PARAMS.json document it latched."""
    overrides = [_param(k, v) for k, v in settings.items()]
    calibrator = CalibratorNode(bags=[bag], context=context, parameter_overrides=overrides)
    listener = Node("listener", context=context)
    got: dict[str, String] = {}
    listener.create_subscription(
        String, "/calibrator/parameters", lambda m: got.__setitem__("doc", m), LATCHED
    )
    executor = SingleThreadedExecutor(context=context)
    for node in (calibrator, listener):
        executor.add_node(node)
    try:
        spin_until(executor, lambda: "doc" in got or calibrator.error is not None)
    finally:
        executor.shutdown()
        for node in (calibrator, listener):
            node.destroy_node()
    assert calibrator.error is None, calibrator.error
    return calibrator, json.loads(got["doc"].data)


def test_the_node_warns_when_it_publishes_less_than_its_diagnosis_found(
    context: Context, backlash_bag: Path
) -> None:
    calibrator, doc = _solved(context, backlash_bag, diagnose=True)
    assert doc["model"] == "geometric"  # what parameter model asks for
    status = calibrator._status
    assert status.level == DiagnosticStatus.WARN, status.message
    assert "the diagnosis chose geometric+backlash:4" in status.message, status.message
    assert "publish: best" in status.message
    assert calibrator.diagnosis is not None
    scores = {r.model: r.holdout_abs_rms_mm for r in calibrator.diagnosis.ladder}
    assert f"{scores['geometric+backlash:4']:.4f} mm" in status.message
    assert f"over the published geometric ({scores['geometric']:.4f} mm)" in status.message


def test_publish_best_publishes_the_diagnosis_model(context: Context, backlash_bag: Path) -> None:
    calibrator, doc = _solved(context, backlash_bag, diagnose=True, publish="best")
    assert doc["model"] == "geometric+backlash:4"
    assert calibrator.calibration is not None and calibrator.calibration.name == doc["model"]
    assert calibrator._status.level == DiagnosticStatus.OK, calibrator._status.message
    with pytest.raises(InputError, match="set diagnose to true"):
        CalibratorNode(
            bags=[backlash_bag], context=context, parameter_overrides=[_param("publish", "best")]
        )


def _param(name: str, value: object):  # noqa: ANN202 - rclpy Parameter
    from rclpy.parameter import Parameter

    return Parameter(name, value=value)


@pytest.mark.slow
def test_the_nodes_diagnosis_is_the_command_lines(
    context: Context, backlash_bag: Path, tmp_path: Path
) -> None:
    """The same bags diagnosed by `robot-calib diagnose --holdout` and by the calibrator
    node (diagnose, holdout_bags): one DIAGNOSIS.json document, its warnings included (a
    richer model that generalises worse was the command line's alone before); only the
    command line writes a report, so only it has the report's header (its date, its
    command)."""
    from cli_runner import cli

    world = build_world({"seed": 9, "effects": [{"name": "backlash", "joints": [4]}]}, "hold")
    holdout = tmp_path / "holdout.mcap"
    simulate_world(holdout, "random", world, seed=19, n_random=60, record=simulate_bag)
    run = cli(
        "diagnose", str(backlash_bag), "--holdout", str(holdout), "-o", str(tmp_path / "d.json")
    )
    assert run.returncode == 0, run.stderr
    by_cli = json.loads((tmp_path / "d.json").read_text())
    calibrator, _ = _solved(context, backlash_bag, diagnose=True, holdout_bags=[str(holdout)])
    assert calibrator.diagnosis is not None
    by_node = json.loads(json.dumps(calibrator.diagnosis.to_dict()))
    header = by_cli.pop("header")
    assert header["command"].startswith("robot-calib diagnose") and by_node.pop("header") is None
    assert by_node["warnings"] == by_cli["warnings"]
    assert any("generalises worse" in w for w in by_cli["warnings"]), by_cli["warnings"]
    assert by_node == by_cli
