"""Capture on a robot with ROS 2 (msgs_doc/capture.md): the pure rules (limits,
step limit, approach side, settling) and the graph capture -> sim_robot (controller mode)
-> sim_tracker, in-process on this test process's private ROS_DOMAIN_ID. Known answer: the
campaign bag of a 60-pose D-optimal plan calibrates to the noise floor of the default
world, whose true geometry is known."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy

from robot_calib.bag.read import read_recording
from robot_calib.capture.moves import MoveRules, describe, parse_approach, plan_moves
from robot_calib.capture.settle import Settler
from robot_calib.errors import InputError
from robot_calib.identify.calibrate import calibrate
from robot_calib.nodes.capture import CaptureNode
from robot_calib.nodes.ros_outputs import capture_status
from robot_calib.nodes.sim_robot import SimRobotNode
from robot_calib.nodes.sim_tracker import SimTrackerNode
from robot_calib.poses import Poses
from robot_calib.sim.plans import random_plan
from robot_calib.sim.world import load_world

WORLD = load_world(None)
ROBOT = WORLD.model.robot
NAMES = ROBOT.joint_names
# abs rms of the default world's noise per point: tracker 3.75 um and target 3 um per axis
NOISE_FLOOR_MM = float(np.sqrt(3 * (3.75**2 + 3.0**2))) * 1e-3
FAST = [  # a robot 3 x faster than the KR5's data sheet, settling checked at 100 Hz
    Parameter("mode", value="controller"),
    Parameter("speed_fraction", value=3.0),
    Parameter("state_rate", value=100.0),
]
TIMEOUT_S = 60.0


def rules(step_deg: float = 90.0, approach: str = "0", overshoot_deg: float = 1.0) -> MoveRules:
    return MoveRules(
        np.radians(step_deg), parse_approach(approach, ROBOT.n_joints), np.radians(overshoot_deg)
    )


def test_moves_refuse_poses_outside_the_limits_and_split_long_steps() -> None:
    q = np.radians([[0, -90, 90, 0, 45, 0], [160, -90, 90, 0, 45, 0], [0, -90, 90, 0, 200, 0]])
    moves, refused = plan_moves(q, q[0], ROBOT.limits, NAMES, rules(step_deg=50.0))
    assert [m.pose for m in moves] == [0, 1] and [r.pose for r in refused] == [2]
    assert "joint_a5 = 3.49066 rad (200.00 deg) outside its limits" in refused[0].reason
    path = np.vstack([q[:1], moves[1].waypoints])
    assert len(moves[1].waypoints) == 4  # 160 deg in steps of <= 50 deg
    assert np.degrees(np.abs(np.diff(path, axis=0))).max() <= 50.0 + 1e-9
    assert np.allclose(moves[1].waypoints[-1], q[1])
    assert "largest step 40.00 deg" in describe(moves, NAMES)[1]


def test_each_pose_is_approached_from_the_configured_side() -> None:
    q = random_plan(ROBOT, 20, np.random.default_rng(0)).q
    moves, refused = plan_moves(q, q[0], ROBOT.limits, NAMES, rules(approach="+,-,+,-,+,0"))
    assert not refused
    side = np.array([1, -1, 1, -1, 1, 0])
    for move in moves:
        last = move.waypoints[-1] - move.waypoints[-2]
        assert np.allclose(last, side * np.radians(1.0))  # the final move: 1 deg, that side
    with pytest.raises(InputError, match="one per joint"):
        parse_approach("+,-", ROBOT.n_joints)
    edge = q[:1].copy()
    edge[0, 0] = ROBOT.limits[0, 0]  # at joint 1's lower limit: no room to approach from below
    _, refused = plan_moves(edge, q[0], ROBOT.limits, NAMES, rules(approach="+"))
    assert "its approach point has joint_a1" in refused[0].reason


def test_settled_only_after_the_whole_settle_time_within_tolerance() -> None:
    settler = Settler(np.zeros(2), tolerance_rad=1e-4, settle_s=0.5)
    for t, q in ((0.0, 1e-3), (0.1, 5e-5), (0.4, 5e-5), (0.5, 2e-4), (0.6, 0.0), (1.0, 0.0)):
        settler.add(t, np.full(2, q))
        assert not settler.settled
    settler.add(0.9, np.zeros(2))  # an older stamp changes nothing
    settler.add(1.1, np.zeros(2))
    assert settler.settled and settler.settled_since == 0.6  # a stamp it was given (a copy)


def run_graph(
    context: Context,
    capture_parameters: list[Parameter],
    tracker_parameters: list[Parameter] | None = None,
    stop: Callable[[CaptureNode], bool] = lambda capture: False,
    listeners: Sequence[Node] = (),
    settled: Callable[[], bool] = lambda: True,
) -> CaptureNode:
    """capture + sim_robot (controller mode) + sim_tracker in one executor until capture
    has finished and `settled()` (or `stop(capture)`: then it is stopped as by Ctrl-C);
    `listeners` spin with them (and are left to the caller)."""
    robot = SimRobotNode(context=context, parameter_overrides=FAST)
    tracker = SimTrackerNode(context=context, parameter_overrides=tracker_parameters or [])
    capture = CaptureNode(
        context=context,
        parameter_overrides=[
            Parameter("settle_time", value=0.03),
            Parameter("speed", value=600.0),  # deg/s: the moves' times (the robot is fast)
            *capture_parameters,
        ],
    )
    executor = SingleThreadedExecutor(context=context)
    for node in (robot, tracker, capture, *listeners):
        executor.add_node(node)
    deadline = time.monotonic() + TIMEOUT_S
    try:
        while not (capture.finished and settled()) and not stop(capture):
            assert time.monotonic() < deadline, "capture timed out"
            executor.spin_once(timeout_sec=0.01)
    finally:
        for node in (capture, robot, tracker):
            executor.remove_node(node)
            node.destroy_node()
        for node in listeners:
            executor.remove_node(node)
        executor.shutdown()
    return capture


@pytest.mark.slow
def test_a_planned_campaign_captured_in_the_graph_calibrates_to_the_noise_floor(
    context: Context, tmp_path: Path
) -> None:
    from robot_calib.cli import main

    # 60 poses: the model error of a 30-pose plan exceeds the floor in ~5 % of noise draws
    # (offline, 20 draws: median 5.7 um, max 11.1 um); 60 poses: max 6.2 um of 40
    plan = tmp_path / "plan.yaml"
    assert (
        main(
            [
                "plan",
                "--model",
                "geometric",
                "--poses",
                "60",
                "--candidates",
                "300",
                "--trials",
                "1",
                "-o",
                str(plan),
            ]
        )
        == 0
    )
    bag = tmp_path / "campaign.mcap"
    capture = run_graph(
        context, [Parameter("plan", value=str(plan)), Parameter("output", value=str(bag))]
    )
    assert capture.measured == 60 and not capture.skipped
    recording = read_recording([bag], ROBOT)
    assert len(recording) == 60 and recording.n_unpaired == 0
    from robot_calib.plan.plan_file import load_plan

    assert np.abs(recording.poses.q - load_plan(plan, ROBOT).q).max() < 1e-4  # in order
    cal = calibrate(recording, ROBOT, "geometric")
    assert cal.accuracy.absolute_rms_mm < 1.5 * NOISE_FLOOR_MM
    poses = Poses.from_readings(random_plan(ROBOT, 300, np.random.default_rng(9)).q)
    truth = WORLD.model.target_points(WORLD.truth, poses)
    model_error = np.sqrt(np.mean(np.sum((cal.predict(poses) - truth) ** 2, axis=1))) * 1e3
    assert model_error < NOISE_FLOOR_MM  # the model's own error, held-out, vs the truth


def test_an_interrupted_campaign_resumes_into_a_second_part(
    context: Context, tmp_path: Path
) -> None:
    bag = tmp_path / "c.mcap"
    common = [Parameter("plan", value="paper-test1"), Parameter("output", value=str(bag))]
    first = run_graph(context, common, stop=lambda c: c.measured == 5)
    assert first.measured == 5 and bag.exists()
    second = run_graph(
        context, [*common, Parameter("max_step", value=400.0)], stop=lambda c: c.measured == 4
    )
    assert second.n_already == 5 and second.bag_path == tmp_path / "c.part2.mcap"
    recording = read_recording([bag, tmp_path / "c.part2.mcap"], ROBOT)
    from robot_calib.sim.plans import paper_test_plan

    plan = paper_test_plan(1).q
    assert len(recording) == 9
    assert np.abs(recording.poses.q - plan[:9]).max() < 1e-4  # each pose once, in order


def test_trigger_service_approach_side_and_skipped_poses(context: Context, tmp_path: Path) -> None:
    bag = tmp_path / "t.mcap"
    capture = run_graph(
        context,
        [
            Parameter("plan", value="paper-test1"),
            Parameter("output", value=str(bag)),
            Parameter("trigger_service", value="/sim_tracker/measure"),
            Parameter("approach", value="+"),
            Parameter("approach_overshoot", value=2.0),
        ],
        [Parameter("triggered", value=True)],
        stop=lambda c: c.measured == 6,
    )
    assert capture.measured == 6
    recording = read_recording([bag], ROBOT)
    assert len(recording) == 6  # one point per trigger, none from the streaming states
    # the recorded directions are the approach side (+1), not the pose-to-pose change
    assert np.all(recording.poses.direction == 1)
    assert np.any(np.diff(recording.poses.q, axis=0) < -1e-3)  # the plan goes both ways

    # a controller with other joint names: refused at the first joint state, nothing written
    with pytest.raises(InputError, match="lack the robot's joints|are not the robot's joints"):
        run_graph(
            context,
            [
                Parameter("plan", value="paper-test1"),
                Parameter("output", value=str(tmp_path / "s.mcap")),
                Parameter("joint_names", value=[f"j{k}" for k in range(1, 7)]),
            ],
        )
    assert not (tmp_path / "s.mcap").exists()


def test_no_controller_or_no_tracker_stops_with_one_line_and_no_bag(
    context: Context, tmp_path: Path
) -> None:
    """Nothing listening on the command topic: an error after connect_timeout; a tracker
    that never measures: the first poses fail and the campaign stops, no empty bag."""
    capture = CaptureNode(
        context=context,
        parameter_overrides=[
            Parameter("plan", value="paper-test1"),
            Parameter("output", value=str(tmp_path / "n.mcap")),
            Parameter("connect_timeout", value=0.3),
        ],
    )
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(capture)
    try:
        with pytest.raises(InputError, match="no controller subscribes .*joint_trajectory"):
            deadline = time.monotonic() + TIMEOUT_S
            while time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.01)
    finally:
        executor.remove_node(capture)
        capture.destroy_node()
        executor.shutdown()
    with pytest.raises(InputError, match="the first 3 poses all failed"):
        run_graph(
            context,
            [
                Parameter("plan", value="paper-test1"),
                Parameter("output", value=str(tmp_path / "t.mcap")),
                Parameter("measure_timeout", value=0.2),
            ],
            [Parameter("triggered", value=True)],  # measures only when asked: never
        )
    assert not (tmp_path / "n.mcap").exists() and not (tmp_path / "t.mcap").exists()


def test_dry_run_moves_nothing_and_bad_parameters_are_refused(
    context: Context, tmp_path: Path
) -> None:
    dry = CaptureNode(
        context=context,
        parameter_overrides=[
            Parameter("plan", value="paper-test1"),
            Parameter("output", value=str(tmp_path / "d.mcap")),
            Parameter("dry_run", value=True),
        ],
    )
    assert dry.finished and len(dry.moves) == 120 and not (tmp_path / "d.mcap").exists()
    dry.destroy_node()
    status = capture_status("robot_calib: capture", ROBOT.name, dry.progress())
    assert status.level == DiagnosticStatus.OK and values(status)["step"] == "dry run"
    for overrides, message in (
        ([], "parameter 'output' must name a .mcap bag"),
        (
            [Parameter("output", value="x.mcap"), Parameter("settle_time", value=0.0)],
            "'settle_time' must be > 0",
        ),
        (
            [Parameter("output", value="x.mcap"), Parameter("plan", value="nope")],
            "unknown plan 'nope'",
        ),
    ):
        with pytest.raises(InputError, match=message):
            CaptureNode(context=context, parameter_overrides=overrides)


def test_moves_are_timed_for_a_real_controller_and_directions_follow_the_stream() -> None:
    """A joint_trajectory_controller rejects times that do not increase and has no speed
    limit: the times are strictly increasing and set by the speed; the approach direction
    is the last motion beyond the tolerance, a slow one included, jitter not."""
    from robot_calib.capture.moves import PEAK_OVER_MEAN, waypoint_times
    from robot_calib.poses import DirectionTracker

    start = np.zeros(6)
    waypoints = np.radians([[30, 0, 0, 0, 0, 0], [30, -10, 0, 0, 0, 0], [30, -10, 0, 0, 0, 0.01]])
    times = waypoint_times(start, waypoints, np.radians(20.0))
    assert np.all(np.diff(np.concatenate([[0.0], times])) > 0)
    assert times[0] == pytest.approx(PEAK_OVER_MEAN * 30 / 20)  # 30 deg at 20 deg/s mean x 1.5
    assert times[2] - times[1] == pytest.approx(0.1)  # a tiny step still takes 0.1 s
    stretched = waypoint_times(start, waypoints, np.radians(20.0), least_s=10.0)
    assert stretched[-1] == pytest.approx(10.0, abs=1e-9)  # scaled: computed
    tracker = DirectionTracker(1e-4)
    for q in np.linspace(0.0, -1e-3, 50):  # slow: 2e-5 rad per sample, below the tolerance
        tracker.add(np.full(6, q))
    tracker.add(np.full(6, -1e-3 + 5e-5))  # jitter back, below the tolerance
    assert np.all(tracker.direction == -1)


class DiagnosticsListener(Node):
    """capture's statuses on /diagnostics (RELIABLE, VOLATILE, as diagnostic_aggregator
    reads them), in order."""

    def __init__(self, context: Context) -> None:
        super().__init__("diagnostics_listener", context=context)
        self.statuses: list[DiagnosticStatus] = []
        self.create_subscription(
            DiagnosticArray,
            "/diagnostics",
            lambda msg: self.statuses.extend(
                s for s in msg.status if s.name == "robot_calib: capture"
            ),
            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE),
        )

    def spin_until_finished(self, context: Context) -> DiagnosticStatus:
        """Spin alone until the campaign's last status ('finished') arrived; returns it."""
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(self)
        deadline = time.monotonic() + TIMEOUT_S
        try:
            while not self.statuses or values(self.statuses[-1])["step"] != "finished":
                assert time.monotonic() < deadline, "no final status"
                executor.spin_once(timeout_sec=0.01)
        finally:
            executor.remove_node(self)
            executor.shutdown()
        return self.statuses[-1]


def values(status: DiagnosticStatus) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


def test_progress_is_published_on_diagnostics(context: Context, tmp_path: Path) -> None:
    """Pose by pose, OK with poses done / total and the plan pose at hand; stopped with
    poses to go: WARN, saying how to resume."""
    listener = DiagnosticsListener(context)
    try:
        run_graph(
            context,
            [
                Parameter("plan", value="paper-test1"),
                Parameter("output", value=str(tmp_path / "p.mcap")),
            ],
            stop=lambda c: c.measured == 3,
            listeners=[listener],
        )
        final = listener.spin_until_finished(context)
    finally:
        listener.destroy_node()
    running = listener.statuses[:-1]
    assert running and all(s.level == DiagnosticStatus.OK for s in running)
    assert {s.hardware_id for s in listener.statuses} == {ROBOT.name}
    done = [int(values(s)["poses_done"]) for s in running]
    assert done == sorted(done) and {0, 1, 2} <= set(done)
    assert {values(s)["poses_total"] for s in listener.statuses} == {"120"}
    moving = [s for s in running if values(s)["step"] == "settle"]
    assert [values(s)["current_pose"] for s in moving][:3] == ["0", "1", "2"]
    assert moving[0].message == "0 of 120 poses measured; at plan pose 0 (settle)"
    assert final.level == DiagnosticStatus.WARN
    assert final.message.startswith("stopped at plan pose 3: 3 of 120 poses measured")
    assert values(final)["failures"] == "0" and values(final)["poses_done"] == "3"


def test_skipped_poses_warn_and_an_abort_is_an_error(context: Context, tmp_path: Path) -> None:
    listener = DiagnosticsListener(context)
    try:
        with pytest.raises(InputError, match="the first 3 poses all failed"):
            run_graph(
                context,
                [
                    Parameter("plan", value="paper-test1"),
                    Parameter("output", value=str(tmp_path / "t.mcap")),
                    Parameter("measure_timeout", value=0.2),
                ],
                [Parameter("triggered", value=True)],  # measures only when asked: never
                listeners=[listener],
            )
        final = listener.spin_until_finished(context)
    finally:
        listener.destroy_node()
    levels = [s.level for s in listener.statuses]
    assert levels[0] == DiagnosticStatus.OK and DiagnosticStatus.WARN in levels
    first_warning = listener.statuses[levels.index(DiagnosticStatus.WARN)]
    assert values(first_warning)["failures"] == "1"
    assert values(first_warning)["last_failure"].startswith("pose 0: no point on")
    assert first_warning.message.startswith("0 of 120 poses measured, 1 skipped")
    assert final.level == DiagnosticStatus.ERROR
    assert final.message.startswith("aborted: the first 3 poses all failed")
    assert values(final)["failures"] == "3"


def test_capture_cancelled_through_its_service_keeps_the_poses_measured(
    context: Context, tmp_path: Path
) -> None:
    """~/progress (latched JSON) follows the campaign; ~/cancel (std_srvs/Trigger) stops it
    after 4 poses: the robot told to hold, the bag holds those 4 poses, and the answer and
    the progress say how many are left."""
    import json

    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    from robot_calib.nodes.ros_outputs import ROBOT_DESCRIPTION_QOS

    bag = tmp_path / "cancel.mcap"
    operator = Node("operator", context=context)
    progress: list[dict] = []
    operator.create_subscription(
        String,
        "/capture/progress",
        lambda m: progress.append(json.loads(m.data)),
        ROBOT_DESCRIPTION_QOS,
    )
    client = operator.create_client(Trigger, "/capture/cancel")
    answers: list = []  # the future of the one ~/cancel call

    def cancel_at_four(capture: CaptureNode) -> bool:
        if capture.measured >= 4 and not answers and client.service_is_ready():
            answers.append(client.call_async(Trigger.Request()))
        return False  # the campaign ends by itself once cancelled

    capture = run_graph(
        context,
        [Parameter("plan", value="paper-test1"), Parameter("output", value=str(bag))],
        stop=cancel_at_four,
        listeners=[operator],
        settled=lambda: bool(answers) and answers[0].done(),
    )
    operator.destroy_node()
    assert capture.cancelled and capture.finished
    assert answers and answers[0].done() and answers[0].result().success
    assert answers[0].result().message.startswith(f"cancelled: {capture.measured} poses measured")
    assert "to go" in answers[0].result().message
    assert len(read_recording([bag], ROBOT)) == capture.measured >= 4
    assert progress and progress[-1]["cancelled"] and progress[-1]["step"] == "finished"
    assert progress[-1]["measured"] == capture.measured < progress[-1]["total"]
