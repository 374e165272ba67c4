"""calibrator node through real rclpy: from the sample bag, results reach a subscriber that
joins later (latched); from live topics of a simulated world, the identified geometry is the
world's truth; a bad bag gives one error line and exit status 2. Also the pure pairing of live
messages, which must give the bag's recording."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli
from diagnostic_msgs.srv import SelfTest
from geometry_msgs.msg import PointStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty, Float64MultiArray, String
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from robot_calib.bag import BagReader
from robot_calib.bag.read import read_recording
from robot_calib.errors import InputError
from robot_calib.identify.calibration import Calibration
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import recording_from_stream
from robot_calib.messages import (
    JOINT_STATES_TOPIC,
    POINT_TOPIC,
    joint_positions,
    ns_to_sec_nanosec,
    stamp_to_ns,
    velocity_signs,
)
from robot_calib.model import KinematicModel, absorb_base_offsets
from robot_calib.nodes.calibrator import LATCHED, CalibratorNode
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import paper_test_plan
from robot_calib.sim.world import load_world

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "bags" / "paper_test3.mcap"
BIN = Path(sys.executable).parent
TIMEOUT_S = 20.0
T0_NS = 1_700_000_000_000_000_000
RESULTS = {
    "parameters": String,
    "summary": String,
    "residuals": Float64MultiArray,
    "markers": MarkerArray,
}


def spin_until(executor: SingleThreadedExecutor, condition: Callable[[], bool]) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        executor.spin_once(timeout_sec=0.01)


class Listener(Node):
    """Subscribes to the calibrator's four result topics with the latched QoS."""

    def __init__(self, context: Context) -> None:
        super().__init__("listener", context=context)
        self.last: dict[str, object] = {}
        for name, msg_type in RESULTS.items():
            self.create_subscription(
                msg_type,
                f"/calibrator/{name}",
                lambda msg, name=name: self.last.__setitem__(name, msg),
                LATCHED,
            )

    def has_all(self) -> bool:
        return set(self.last) == set(RESULTS)


def by_namespace(markers: MarkerArray) -> dict[str, list[Marker]]:
    out: dict[str, list[Marker]] = {}
    for m in markers.markers:
        if m.action == Marker.ADD:
            out.setdefault(m.ns, []).append(m)
    return out


def xyz(points: list) -> np.ndarray:  # noqa: ANN001 - geometry_msgs/Point list
    return np.array([[p.x, p.y, p.z] for p in points])


def solve_in_bag_mode(calibrator: CalibratorNode, context: Context) -> Listener:
    """Spin a bag-mode calibrator with a listener of its outputs until it has published
    them all (or failed); both nodes destroyed after. Returns the listener."""
    listener = Listener(context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(calibrator)
    executor.add_node(listener)
    try:
        spin_until(executor, lambda: listener.has_all() or calibrator.error is not None)
    finally:
        executor.shutdown()
        calibrator.destroy_node()
        listener.destroy_node()
    return listener


def test_bag_mode_results_are_latched_for_late_subscribers(context: Context) -> None:
    calibrator = CalibratorNode(bags=[SAMPLE], context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(calibrator)
    listener = None
    try:
        spin_until(executor, lambda: calibrator.calibration is not None)
        listener = Listener(context)  # joins after the results went out
        executor.add_node(listener)
        spin_until(executor, listener.has_all)
    finally:
        executor.shutdown()
        calibrator.destroy_node()
        if listener is not None:
            listener.destroy_node()
    assert calibrator.error is None and not calibrator.failed
    doc = json.loads(listener.last["parameters"].data)
    assert doc["model"] == "geometric" and doc["recordings"] == [str(SAMPLE)]
    assert doc["measurements"] == {"paired": 290, "unpaired": 0, "sweeps": 6, "general_poses": 0}
    assert doc["residuals"]["absolute_mean_mm"] < 0.05
    assert "model: geometric" in listener.last["summary"].data

    # The identified model predicts the world's exact points within the noise (a few um).
    world = load_world(SAMPLE.with_suffix(".world.yaml"))
    poses = calibrator.recording.poses
    predicted = KinematicModel(world.model.robot).target_points(
        ParameterVector.from_dict(doc["parameters"]), poses
    )
    exact = physical_points(world, poses, None, noisy=False)
    assert np.linalg.norm(predicted - exact, axis=1).max() < 20e-6

    # ~/residuals: dims [n, 4], rows x, y, z (measured) and |predicted - measured| [m].
    residuals = listener.last["residuals"]
    assert [(d.label, d.size, d.stride) for d in residuals.layout.dim] == [
        ("measurement", 290, 1160),
        ("x,y,z,residual", 4, 4),
    ]
    table = np.array(residuals.data).reshape(290, 4)
    measured = calibrator.recording.points
    np.testing.assert_allclose(table[:, :3], measured)
    assert table[:, 3].mean() * 1e3 == pytest.approx(doc["residuals"]["absolute_mean_mm"])

    # ~/markers: a DELETEALL first, 6 axes, 6 circles, one residual line per point (x100).
    markers = listener.last["markers"]
    assert markers.markers[0].action == Marker.DELETEALL
    shown = by_namespace(markers)
    assert {m.frame_id for m in (x.header for x in markers.markers)} == {"laser_tracker"}
    assert [m.id for m in shown["axes"]] == [1, 2, 3, 4, 5, 6]
    assert all(m.type == Marker.ARROW and len(m.points) == 2 for m in shown["axes"])
    assert len(shown["circles"]) == 6
    for strip, sweep in zip(shown["circles"], calibrator.calibration.cpa.sweeps):
        ring = xyz(strip.points)
        radius = np.linalg.norm(ring - sweep.circle.centre, axis=1)
        np.testing.assert_allclose(radius, sweep.circle.radius, rtol=1e-9)
    (lines,) = shown["residuals"]
    assert lines.type == Marker.LINE_LIST and len(lines.points) == 2 * 290
    ends = xyz(lines.points).reshape(290, 2, 3)
    np.testing.assert_allclose(ends[:, 0], measured)
    np.testing.assert_allclose(ends[:, 1], measured + 100.0 * calibrator.calibration.residuals)
    assert len(shown["measured"][0].points) == 290


def test_bag_mode_with_a_learned_correction_publishes_the_hybrid_model(
    context: Context,
) -> None:
    """Parameter learned_correction: ~/parameters holds the correction (PARAMS.json
    `correction`), which reads back into the hybrid model; ~/summary gives its size."""
    learned = [Parameter("learned_correction", value=True)]
    calibrator = CalibratorNode(bags=[SAMPLE], context=context, parameter_overrides=learned)
    listener = solve_in_bag_mode(calibrator, context)
    assert calibrator.error is None
    doc = json.loads(listener.last["parameters"].data)
    assert doc["correction"]["format"] == "robot_calib.correction/2"
    assert doc["correction"]["fitted_poses"] == 290
    assert "learned correction:" in listener.last["summary"].data
    cal = calibrator.calibration
    assert cal is not None and cal.correction is not None
    back = Calibration.from_dict(doc)
    poses = calibrator.recording.poses
    np.testing.assert_allclose(back.predict(poses), cal.predict(poses), rtol=0, atol=1e-12)


@pytest.mark.parametrize("trigger", ["solve_topic", "service", "idle"])
def test_live_mode_identifies_the_world_truth(context: Context, trigger: str) -> None:
    """The seed's Test 3 from a simulated world (exact points) through real publishers;
    one extra point far from any joint state is dropped and counted."""
    world = load_world()
    robot = world.model.robot
    plan = paper_test_plan(3)
    points = physical_points(world, Poses.from_readings(plan.q), None, noisy=False)
    idle_s = 0.3 if trigger == "idle" else 0.0
    calibrator = CalibratorNode(solve_after_idle_s=idle_s, context=context)
    listener = Listener(context)
    source = Node("source", context=context)
    deep = QoSProfile(
        reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=1000
    )
    js_pub = source.create_publisher(JointState, JOINT_STATES_TOPIC, deep)
    pt_pub = source.create_publisher(PointStamped, POINT_TOPIC, deep)
    solve_pub = source.create_publisher(Empty, "/calibrator/solve", 10)
    client = source.create_client(Trigger, "/calibrator/solve")
    executor = SingleThreadedExecutor(context=context)
    for node in (calibrator, listener, source):
        executor.add_node(node)
    try:
        spin_until(
            executor,
            lambda: min(p.get_subscription_count() for p in (js_pub, pt_pub, solve_pub)) > 0,
        )
        stamps = [T0_NS + k * 1_000_000_000 for k in range(len(plan))]
        for stamp, q, p in zip(stamps, plan.q, points):
            js = JointState(name=list(robot.joint_names), position=q.tolist())
            js.header.stamp.sec, js.header.stamp.nanosec = ns_to_sec_nanosec(stamp)
            js_pub.publish(js)
            pt = PointStamped()
            pt.header.frame_id = "laser_tracker"
            pt.header.stamp.sec, pt.header.stamp.nanosec = ns_to_sec_nanosec(stamp - 1_000_000)
            pt.point.x, pt.point.y, pt.point.z = p.tolist()
            pt_pub.publish(pt)
        stray = PointStamped()
        stray.header.frame_id = "laser_tracker"
        stray.header.stamp.sec, stray.header.stamp.nanosec = ns_to_sec_nanosec(stamps[-1] + 10**10)
        stray.point.x = 1.0
        pt_pub.publish(stray)
        expected = {JOINT_STATES_TOPIC: len(plan), POINT_TOPIC: len(plan) + 1}
        spin_until(executor, lambda: calibrator.received == expected)
        if trigger != "idle":
            assert calibrator.calibration is None  # nothing before the trigger
        if trigger == "solve_topic":
            solve_pub.publish(Empty())
        if trigger == "service":
            spin_until(executor, client.service_is_ready)
            future = client.call_async(Trigger.Request())
            spin_until(executor, future.done)
            answer = future.result()
            # the outcome in one line: model, in-sample accuracy (exact points: ~0 mm), points
            assert answer.success, answer.message
            assert answer.message.startswith("geometric: in-sample seed criterion mean 0.0000")
            assert answer.message.endswith("(290 points)")
        spin_until(executor, lambda: "parameters" in listener.last)
        if trigger == "idle":  # no new point since: no second solve
            deadline = time.monotonic() + 2 * idle_s
            while time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.01)
        assert calibrator.solves == 1
    finally:
        executor.shutdown()
        for node in (calibrator, listener, source):
            node.destroy_node()
    doc = json.loads(listener.last["parameters"].data)
    assert doc["measurements"] == {"paired": 290, "unpaired": 1, "sweeps": 6, "general_poses": 0}
    assert any("1 of 291 points" in w for w in doc["warnings"])
    identified = ParameterVector.from_dict(doc["parameters"])
    truth = absorb_base_offsets(robot, world.truth)
    assert identified.names == truth.names
    for name, unit, value, true in zip(
        truth.names, (p.unit for p in truth.parameters), identified.values, truth.values
    ):
        tolerance = 1e-5 if unit == "m" else np.radians(1e-3)  # 0.01 mm, 0.001 deg
        assert abs(value - true) < tolerance, name


def test_live_solve_without_data_logs_an_error_and_keeps_running(context: Context) -> None:
    calibrator = CalibratorNode(context=context)
    caller = Node("caller", context=context)
    client = caller.create_client(Trigger, "/calibrator/solve")
    executor = SingleThreadedExecutor(context=context)
    for node in (calibrator, caller):
        executor.add_node(node)
    try:
        spin_until(executor, client.service_is_ready)
        future = client.call_async(Trigger.Request())
        spin_until(executor, future.done)
        assert isinstance(calibrator.error, InputError)
        assert "none of 0 tracker points" in str(calibrator.error)
        assert not calibrator.failed  # live mode: the node stays up
        assert calibrator.solve() is None
    finally:
        executor.shutdown()
        for node in (calibrator, caller):
            node.destroy_node()
    answer = future.result()
    assert not answer.success and answer.message == str(calibrator.error)


def test_deprecated_selftest_service_still_answers_and_warns_once(
    context: Context, capfd: pytest.CaptureFixture[str]
) -> None:
    """~/calibrate (diagnostic_msgs/srv/SelfTest) works for a release more beside ~/solve
    (std_srvs/srv/Trigger); its first call logs one warning naming the replacement. Both
    services also answer in bag mode, with the bags' calibration (no second solve)."""
    calibrator = CalibratorNode(bags=[SAMPLE], context=context)
    caller = Node("caller", context=context)
    old = caller.create_client(SelfTest, "/calibrator/calibrate")
    new = caller.create_client(Trigger, "/calibrator/solve")
    executor = SingleThreadedExecutor(context=context)
    for node in (calibrator, caller):
        executor.add_node(node)
    answers = []
    try:
        spin_until(executor, lambda: calibrator.calibration is not None)
        spin_until(executor, lambda: old.service_is_ready() and new.service_is_ready())
        for client, request in (
            (old, SelfTest.Request()),
            (old, SelfTest.Request()),
            (new, Trigger.Request()),
        ):
            future = client.call_async(request)
            spin_until(executor, future.done)
            answers.append(future.result())
    finally:
        executor.shutdown()
        for node in (calibrator, caller):
            node.destroy_node()
    assert calibrator.solves == 1
    line = calibrator.calibration.accuracy.line()
    for answer in answers[:2]:
        assert answer.passed == b"\x01" and answer.id == "geometric"
        assert answer.status[0].message == line
        values = {kv.key: kv.value for kv in answer.status[0].values}
        assert values["points"] == "290" and float(values["absolute_mean_mm"]) < 0.05
    assert answers[2].success and answers[2].message == f"geometric: in-sample {line}"
    warnings = [x for x in capfd.readouterr().err.splitlines() if "deprecated" in x]
    assert len(warnings) == 1, warnings
    assert "/calibrator/calibrate" in warnings[0] and "/calibrator/solve" in warnings[0]
    assert "std_srvs/srv/Trigger" in warnings[0]


def test_bad_bag_exits_with_status_2_and_one_error_line() -> None:
    result = subprocess.run(
        [str(BIN / "calibrator"), "--ros-args", "-p", "bags:=['/nonexistent.mcap']"],
        env=dict(os.environ),
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 2, result.stderr
    errors = [line for line in result.stderr.splitlines() if "error" in line.lower()]
    assert len(errors) == 1, result.stderr
    assert "/nonexistent.mcap: no such bag file" in errors[0]


def test_live_pairing_gives_the_bags_recording() -> None:
    """recording_from_stream on the sample bag's messages, shuffled, equals read_recording."""
    robot = load_world().model.robot
    js_ns, js_q, js_v, pt_ns, pts = [], [], [], [], []
    with BagReader(SAMPLE) as reader:
        for m in reader.messages([JOINT_STATES_TOPIC, POINT_TOPIC]):
            msg = m.decode()
            if m.topic == JOINT_STATES_TOPIC:
                js_ns.append(stamp_to_ns(msg.header.stamp))
                js_q.append(joint_positions(msg, robot.joint_names))
                js_v.append(velocity_signs(msg, robot.joint_names))
            else:
                pt_ns.append(stamp_to_ns(msg.header.stamp))
                pts.append([msg.point.x, msg.point.y, msg.point.z])
    rng = np.random.default_rng(0)
    a, b = rng.permutation(len(js_ns)), rng.permutation(len(pt_ns))
    live = recording_from_stream(
        np.array(js_ns)[a],
        np.array(js_q)[a],
        np.array(js_v)[a],
        np.array(pt_ns)[b],
        np.array(pts)[b],
    )
    bag = read_recording([SAMPLE], robot)
    for field in ("q", "direction", "time"):
        np.testing.assert_array_equal(getattr(live.poses, field), getattr(bag.poses, field))
    np.testing.assert_array_equal(live.points, bag.points)
    assert [(s.joint, s.index.tolist()) for s in live.sweeps] == [
        (s.joint, s.index.tolist()) for s in bag.sweeps
    ]
    assert live.n_unpaired == 0 and live.sources == ("live",)

    # A velocity sign wins over the reading's history; a point in mm is refused.
    q = np.zeros((2, 6))
    q[1, 0] = 0.1
    v = np.zeros((2, 6))
    v[1, 1] = -1.0
    rec = recording_from_stream([0, 10**9], q, v, [0, 10**9], np.ones((2, 3)))
    assert rec.poses.direction[1, :2].tolist() == [1.0, -1.0]
    with pytest.raises(InputError, match="millimetres"):
        recording_from_stream([0], q[:1], v[:1], [0], [[1500.0, 200.0, 300.0]])


def test_bag_mode_runs_the_diagnosis_and_latches_its_summary(
    context: Context, tmp_path: Path
) -> None:
    """A world with joint-4 backlash: the node's diagnosis names it, on the hold-out bag."""
    bag, holdout = tmp_path / "cal.mcap", tmp_path / "hold.mcap"
    for cmd in (
        ["--plan", "paper-test3", "--effects", "backlash:4", "--seed", "2", "-o", str(bag)],
        [
            "--plan",
            "random",
            "--n-random",
            "100",
            "--world",
            str(bag.with_suffix(".world.yaml")),
            "--seed",
            "3",
            "-o",
            str(holdout),
        ],
    ):
        made = cli("simulate", *cmd)
        assert made.returncode == 0, made.stderr
    calibrator = CalibratorNode(
        bags=[bag],
        context=context,
        parameter_overrides=[
            Parameter("diagnose", value=True),
            Parameter("holdout_bags", value=[str(holdout)]),
        ],
    )
    listener = Node("diag_listener", context=context)
    got: dict[str, str] = {}
    for name in ("diagnosis", "diagnosis_summary"):
        listener.create_subscription(
            String, f"/calibrator/{name}", lambda m, n=name: got.__setitem__(n, m.data), LATCHED
        )
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(calibrator)
    executor.add_node(listener)
    try:
        spin_until(executor, lambda: len(got) == 2 or calibrator.error is not None)
    finally:
        executor.shutdown()
        calibrator.destroy_node()
        listener.destroy_node()
    assert calibrator.error is None
    doc = json.loads(got["diagnosis"])
    assert doc["dominant_effect"] == {"effect": "backlash", "joints": [4]}
    assert doc["scored_on"] == "hold-out bags"
    assert "dominant effect: backlash on joints [4]" in got["diagnosis_summary"]


def test_node_answers_while_it_solves(context: Context, tmp_path: Path) -> None:
    """The solve runs in its own callback group: under a MultiThreadedExecutor the node's
    parameter service answers while a calibration + diagnosis is still running."""
    from rcl_interfaces.srv import GetParameters
    from rclpy.executors import MultiThreadedExecutor

    calibrator = CalibratorNode(
        bags=[SAMPLE], context=context, parameter_overrides=[Parameter("diagnose", value=True)]
    )
    client_node = Node("asker", context=context)
    client = client_node.create_client(GetParameters, "/calibrator/get_parameters")
    executor = MultiThreadedExecutor(num_threads=4, context=context)
    executor.add_node(calibrator)
    executor.add_node(client_node)
    answered_while_busy: list[bool] = []
    try:
        assert client.wait_for_service(timeout_sec=TIMEOUT_S)
        spin_until(executor, lambda: calibrator.busy or calibrator.solves > 0)
        assert calibrator.busy, "the solve ended before the node could be asked"
        future = client.call_async(GetParameters.Request(names=["model", "robot"]))
        future.add_done_callback(lambda _f: answered_while_busy.append(calibrator.busy))
        spin_until(executor, future.done)
        spin_until(executor, lambda: calibrator.solves > 0 or calibrator.error is not None)
    finally:
        executor.shutdown()
        calibrator.destroy_node()
        client_node.destroy_node()
    assert [v.string_value for v in future.result().values] == ["geometric", "kr5_sixx_r650"]
    assert answered_while_busy == [True]
    assert calibrator.error is None and calibrator.diagnosis is not None


def test_node_destroyed_mid_solve_publishes_nothing(
    context: Context, capfd: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C during a solve destroys the node while the solving thread runs on: that
    thread then ends without publishing on destroyed publishers (no exception, which rclpy
    would report as 'never retrieved' when the task is collected)."""
    import gc

    from rclpy.executors import MultiThreadedExecutor

    calibrator = CalibratorNode(
        bags=[SAMPLE], context=context, parameter_overrides=[Parameter("diagnose", value=True)]
    )
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(calibrator)
    spin_until(executor, lambda: calibrator.busy or calibrator.solves > 0)
    assert calibrator.busy, "the solve ended before the node could be destroyed"
    executor.shutdown(timeout_sec=0)
    calibrator.destroy_node()
    deadline = time.monotonic() + TIMEOUT_S
    while calibrator.busy:
        assert time.monotonic() < deadline, "the solving thread did not end"
        time.sleep(0.01)
    time.sleep(0.1)  # the task records its outcome after the callback returns
    del executor
    gc.collect()
    assert calibrator.solves == 0 and calibrator.calibration is None
    err = capfd.readouterr().err
    assert "never retrieved" not in err and "Destroyable" not in err, err


def test_bag_with_a_blunder_is_calibrated_and_published_without_it(
    context: Context, tmp_path: Path
) -> None:
    """A point 5 mm off: the node publishes every result; the summary and PARAMS.json list
    the outlier; the residuals and markers hold the fitted points only."""
    from bag_files import write_measurements

    rec = read_recording([SAMPLE], load_world().model.robot)
    points = rec.points.copy()
    points[150] += [0.0, 0.0, 5e-3]
    bag = tmp_path / "blunder.mcap"
    write_measurements(bag, rec.poses.q, points)
    calibrator = CalibratorNode(bags=[bag], context=context)
    listener = solve_in_bag_mode(calibrator, context)
    assert calibrator.error is None and calibrator.solves == 1
    doc = json.loads(listener.last["parameters"].data)
    assert [o["index"] for o in doc["outliers"]] == [150]
    assert f"{bag} point 150" in listener.last["summary"].data
    assert listener.last["residuals"].layout.dim[0].size == len(points) - 1
