"""capture: drive a robot through a measurement plan, settle, measure, record.

For each pose of the plan (a built-in name or a PLAN.yaml of `robot-calib plan`):

1. sends the move (capture/moves.py: limits, step limit, approach side) as one
   trajectory_msgs/JointTrajectory on /<controller>/joint_trajectory (ros2_control's
   joint_trajectory_controller topic interface);
2. waits until /joint_states stay within `position_tolerance` of the pose for
   `settle_time` (capture/settle.py); after `move_timeout` the pose is skipped and named;
3. measures: the first /laser_tracker/point (and each further target's point) stamped
   after the robot had settled, or, with `trigger_service`, calls that std_srvs/Trigger
   service first and takes the points that follow it; after `measure_timeout`: skipped;
4. records the pair (the joint state nearest the point's stamp and the points) into the
   campaign bag with the recorder's writer (the MCAP contract: /joint_states,
   /laser_tracker/point, /laser_tracker/NAME/point), one pair per pose. The joint state's
   `velocity` holds each joint's approach direction as its sign (+-1e-9 rad/s: the robot
   stands still), the direction of that joint's last move into the pose, which the
   contract reads from a non-empty velocity: with an approach side, the pose-to-pose
   change would give the wrong one.

Progress ("pose k of N, ~m:ss left") is logged per pose and published on /diagnostics
(poses done / total, the current pose, failures; WARN once a pose is skipped, ERROR on
abort: nodes/ros_outputs.py), again every second. An existing bag resumes the
campaign: its poses (and those of its .partK bags) are skipped, the rest go into the next
part (capture/resume.py). `dry_run` logs every move and exits without moving or writing.
Parameters and topics: msgs_doc/capture.md.
"""

from __future__ import annotations

import copy
import json
import sys
import time
from collections import deque
from dataclasses import asdict, dataclass
from functools import partial
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from robot_calib.bag import BagWriter
from robot_calib.capture.moves import (
    Move,
    describe,
    plan_moves,
    waypoint_times,
)
from robot_calib.capture.resume import existing_parts, measured, part_path
from robot_calib.capture.settle import Settler
from robot_calib.errors import InputError, RobotCalibError
from robot_calib.kinematics.description import home_pose
from robot_calib.kinematics.frames import Array
from robot_calib.messages import (
    JOINT_STATE_TYPE,
    JOINT_STATES_TOPIC,
    POINT_TYPE,
    joint_positions,
    stamp_to_ns,
    target_topic,
)
from robot_calib.model import KinematicModel
from robot_calib.nodes._common import run_node
from robot_calib.nodes.capture_parameters import declare_parameters
from robot_calib.nodes.ros_outputs import (
    DIAGNOSTIC_PERIOD_S,
    DIAGNOSTICS_QOS,
    DIAGNOSTICS_TOPIC,
    ROBOT_DESCRIPTION_QOS,
    CaptureProgress,
    capture_status,
    diagnostic_array,
    status_name,
)
from robot_calib.nodes.sim_robot import QOS, trajectory_topic
from robot_calib.poses import DirectionTracker
from robot_calib.sim.plans import make_plan

DIRECTION_SPEED_RAD_S = 1e-9  # |velocity| recorded with a settled pose: only its sign counts
STATE_BUFFER = 400  # joint states kept to pair a point with (a few seconds at 100 Hz)
FAIL_FAST = 3  # the first this many poses all failing: stop, the setup is wrong
RESUME_MATCH_RAD = 1e-3  # a recorded pose within this of a plan pose counts as measured


@dataclass(frozen=True)
class Skipped:
    """A pose not measured: its plan index and why."""

    pose: int
    reason: str


class CaptureNode(Node):
    """The capture state machine (module docstring), stepped by a timer; `finished` once
    every pose is measured or skipped (then the bag is closed: `close()`)."""

    def __init__(self, **kwargs: Any) -> None:  # rclpy.node.Node's keyword arguments
        super().__init__("capture", **kwargs)
        self._writer: BagWriter | None = None
        try:
            self._setup()
        except RobotCalibError:
            super().destroy_node()
            raise

    def _setup(self) -> None:
        self.settings = settings = declare_parameters(self)
        robot, rules = settings.robot, settings.rules
        model = KinematicModel(robot, ())
        rng = np.random.default_rng(settings.seed)
        plan = make_plan(settings.plan, model, model.parameters(), rng)
        self.plan_q: Array = plan.q
        self.parts = [] if settings.dry_run else existing_parts(settings.output)
        done = measured(plan.q, self.parts, robot, max(RESUME_MATCH_RAD, 2 * settings.tolerance))
        home = home_pose(robot)
        todo = np.flatnonzero(np.logical_not(done))
        # refusals do not depend on where a move starts; the waypoints are planned again from
        # the robot's latest joint state when each move is sent (`_send`)
        moves, refused = plan_moves(plan.q[todo], home, robot.limits, settings.joint_names, rules)
        self.moves = [Move(int(todo[m.pose]), m.waypoints) for m in moves]
        self.skipped = [
            Skipped(
                int(todo[r.pose]), r.reason.replace(f"pose {r.pose}:", f"pose {todo[r.pose]}:", 1)
            )
            for r in refused
        ]
        for skip in self.skipped:
            self.get_logger().warning(f"refused {skip.reason}")
        self.n_already = int(done.sum())
        log = self.get_logger()
        log.info(f"plan {settings.plan}: {len(plan.q)} poses; {self.resume_line()}")
        self.finished = False
        self.measured = 0
        self._index = 0
        self._state = "connect"  # then send -> settle -> measure per pose
        self._settler: Settler | None = None
        self._since = 0.0
        self._settled_wall = 0.0
        self._triggered = False
        self._trigger_future: Any = None
        self._durations: deque[float] = deque(maxlen=20)
        self._pose_started = time.monotonic()
        self._states: deque[tuple[int, Array, Any]] = deque(maxlen=STATE_BUFFER)
        self._point_topics = [target_topic(t) for t in ("", *settings.targets)]
        self._points: dict[str, list[Any]] = {t: [] for t in self._point_topics}
        self._directions = DirectionTracker()
        self.error: str | None = None
        self._attempts = 0
        self._failed = 0  # poses skipped while running (not refused up front)
        self._started = time.monotonic()
        self.bag_path = part_path(settings.output, len(self.parts) + 1)
        self._diagnostics = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS
        )
        # the progress for a program (a cell controller, a GUI), latched; ~/cancel stops
        self._progress = self.create_publisher(String, "~/progress", ROBOT_DESCRIPTION_QOS)
        self.cancelled = False
        self.create_service(Trigger, "~/cancel", self._on_cancel)
        self.create_timer(DIAGNOSTIC_PERIOD_S, self.report)
        if settings.dry_run:
            start = "; ".join(
                f"{n}={v:.1f}" for n, v in zip(settings.joint_names, np.degrees(home))
            )
            log.info(
                f"dry run: from the home pose ({start} deg); a real run plans each move "
                "from where the robot stands"
            )
            for line in describe(self.moves, settings.joint_names):
                log.info(f"dry run: {line}")
            log.info("dry run: nothing moved, nothing written")
            self.finished = True
            self.report()
            return
        if not self.moves:
            log.info("nothing to measure")
            self.finished = True
            self.report()
            return
        from trajectory_msgs.msg import JointTrajectory

        self.command = self.create_publisher(
            JointTrajectory, trajectory_topic(settings.controller), 10
        )
        self.create_subscription(JointState, JOINT_STATES_TOPIC, self._on_state, QOS)
        for topic in self._point_topics:
            self.create_subscription(PointStamped, topic, partial(self._on_point, topic), QOS)
        self.trigger = None
        if settings.trigger_service:
            self.trigger = self.create_client(Trigger, settings.trigger_service)
        self._timer = self.create_timer(0.01, self._step)
        log.info(
            f"commands on {trajectory_topic(settings.controller)}; the bag "
            f"{self.bag_path} is written from the first pose measured"
        )
        self.report()

    # --- callbacks ------------------------------------------------------------------------

    def resume_line(self) -> str:
        """'N already in BAG, ...; M to measure, K refused', or 'no earlier bag; ...'."""
        earlier = (
            f"{self.n_already} already in {', '.join(map(str, self.parts))}"
            if self.parts
            else "no earlier bag"
        )
        return f"{earlier}; {len(self.moves)} to measure, {len(self.skipped)} refused"

    def _on_state(self, msg: JointState) -> None:
        try:
            q = joint_positions(msg, self.settings.joint_names)
        except InputError as exc:
            self.error = f"{JOINT_STATES_TOPIC}: {exc}"
            return
        stamp = stamp_to_ns(msg.header.stamp)
        self._states.append((stamp, q, msg))
        self._directions.add(q)
        if self._settler is not None:
            self._settler.add(stamp * 1e-9, q)

    def _on_point(self, topic: str, msg: PointStamped) -> None:
        self._points[topic].append(msg)

    # --- the state machine ----------------------------------------------------------------

    def _step(self) -> None:
        """One step of the state machine; a fatal problem closes the bag and raises (the
        standalone node then exits 2 with that one line)."""
        if self.finished:
            return
        try:
            if self.error is not None:
                raise InputError(self.error)
            getattr(self, f"_{self._state}")()
        except RobotCalibError as exc:
            self.error = str(exc)
            self.close()
            raise

    def _connect(self) -> None:
        """Wait for the controller's subscription and a first joint state."""
        if self.command.get_subscription_count() >= 1 and self._states:
            self._state = "send"
            return
        if time.monotonic() - self._started > self.settings.connect_timeout:
            missing = (
                f"no controller subscribes {self.command.topic_name} (parameter "
                "controller: is it running?)"
                if self.command.get_subscription_count() < 1
                else f"no joint state on {JOINT_STATES_TOPIC}"
            )
            raise InputError(f"{missing} after {self.settings.connect_timeout:g} s")

    def _send(self) -> None:
        """Plan the next move from where the robot stands and send it, timed."""
        from builtin_interfaces.msg import Duration
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

        pose = self.moves[self._index]
        here = self._states[-1][1]
        planned, _ = plan_moves(
            self.plan_q[[pose.pose]],
            here,
            self.settings.robot.limits,
            self.settings.joint_names,
            self.settings.rules,
        )
        waypoints = planned[0].waypoints
        times = waypoint_times(here, waypoints, self.settings.speed_rad_s, self.settings.move_time)
        msg = JointTrajectory()
        msg.joint_names = list(self.settings.joint_names)
        for q, at in zip(waypoints, times):
            point = JointTrajectoryPoint()
            point.positions = q.tolist()
            point.time_from_start = Duration(sec=int(at), nanosec=int(round((at % 1) * 1e9)))
            msg.points.append(point)
        self._settler = Settler(waypoints[-1], self.settings.tolerance, self.settings.settle_s)
        self._since = time.monotonic()
        self._pose_started = self._since
        self._move_s = float(times[-1])
        self.command.publish(msg)
        self._state = "settle"
        self.report()

    def _settle(self) -> None:
        assert self._settler is not None
        if self._settler.settled:
            for points in self._points.values():
                points.clear()
            self._settled_wall = time.monotonic()
            self._triggered = False
            self._state = "measure"
        elif time.monotonic() - self._since > self.settings.move_timeout + self._move_s:
            self._skip(
                f"not settled within {self.settings.move_timeout:g} s after its "
                f"{self._move_s:.1f} s "
                f"move (largest joint error {np.degrees(self._settler.largest_error_rad):.4f} "
                "deg)"
            )

    def _measure(self) -> None:
        assert self._settler is not None and self._settler.settled_since is not None
        if self.trigger is not None and not self._triggered:
            if not self.trigger.service_is_ready():
                if time.monotonic() - self._settled_wall > self.settings.measure_timeout:
                    self._skip(f"trigger service {self.trigger.srv_name} not available")
                return
            for points in self._points.values():
                points.clear()
            self._trigger_future = self.trigger.call_async(Trigger.Request())
            self._triggered = True
            self._attempts += 1
            return
        future = self._trigger_future
        if future is not None and future.done():
            answer = future.result()
            self._trigger_future = None
            if answer is not None and not answer.success:
                if self._attempts < self.settings.trigger_retries:
                    self._triggered = False  # call again
                    return
                self._skip(f"the tracker said no {self._attempts} times: {answer.message}")
                return
        since_ns = int(self._settler.settled_since * 1e9)
        fresh = {}
        for topic, points in self._points.items():
            after = [p for p in points if stamp_to_ns(p.header.stamp) >= since_ns]
            if after:
                fresh[topic] = after[0]
        if len(fresh) == len(self._points):
            self._record(fresh)
        elif time.monotonic() - self._settled_wall > self.settings.measure_timeout:
            missing = [t for t in self._points if t not in fresh]
            self._skip(
                f"no point on {', '.join(missing)} within {self.settings.measure_timeout:g} s "
                "after settling"
            )

    def _record(self, points: dict[str, Any]) -> None:
        """Write the pose's joint state (nearest the first point's stamp) and its points;
        the bag is created with the first pose measured (a campaign that measures nothing
        leaves no file)."""
        if self._writer is None:
            self._writer = BagWriter(self.bag_path)
            self._writer.add_topic(JOINT_STATES_TOPIC, JOINT_STATE_TYPE)
            for topic in self._point_topics:
                self._writer.add_topic(topic, POINT_TYPE)
        assert self._directions.direction is not None
        stamp = stamp_to_ns(points[self._point_topics[0]].header.stamp)
        state = copy.deepcopy(min(self._states, key=lambda s: abs(s[0] - stamp))[2])
        names = list(state.name)
        velocity = np.zeros(len(names))
        for j, name in enumerate(self.settings.joint_names):
            velocity[names.index(name)] = self._directions.direction[j] * DIRECTION_SPEED_RAD_S
        state.velocity = velocity.tolist()
        now = time.time_ns()
        self._writer.write(JOINT_STATES_TOPIC, serialize_message(state), now)
        for topic, msg in points.items():
            self._writer.write(topic, serialize_message(msg), now)
        self.measured += 1
        self._durations.append(time.monotonic() - self._pose_started)
        left = len(self.moves) - self._index - 1
        eta = left * float(np.mean(self._durations))
        move = self.moves[self._index]
        self.get_logger().info(
            f"pose {self._index + 1} of {len(self.moves)} (plan pose {move.pose}) measured; "
            f"~{int(eta // 60)}:{int(eta % 60):02d} left"
        )
        self._next()

    def _skip(self, reason: str) -> None:
        move = self.moves[self._index]
        self.skipped.append(Skipped(move.pose, f"pose {move.pose}: {reason}"))
        self.get_logger().warning(f"skipped pose {move.pose}: {reason}")
        self._failed += 1
        if self.measured == 0 and self._failed >= FAIL_FAST:
            raise InputError(
                f"the first {FAIL_FAST} poses all failed, stopping (last: {reason}); "
                "check the controller, the tracker and their topics"
            )
        self._next()

    def _next(self) -> None:
        self._settler = None
        self._trigger_future = None
        self._attempts = 0
        self._index += 1
        if self._index >= len(self.moves):
            self.close()
        else:
            self._state = "send"
            self.report()

    def close(self) -> None:
        """Finish: stop the robot if a move may still run (interrupted, or a fatal error),
        close the bag and log the summary. Idempotent."""
        if self.finished:
            return
        self.finished = True
        incomplete = self._index < len(self.moves)
        if incomplete and self._state != "connect" and hasattr(self, "command"):
            from trajectory_msgs.msg import JointTrajectory

            stop = JointTrajectory()  # no points: the controller holds where it is
            stop.joint_names = list(self.settings.joint_names)
            self.command.publish(stop)
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        self.get_logger().info(self.summary())
        self.report()

    def progress(self) -> CaptureProgress:
        """Where the campaign stands (what /diagnostics says); a finished campaign that
        measured nothing is an error, as for the exit status (`_done`)."""
        dry_run = self.settings.dry_run
        left = self._index < len(self.moves) and not dry_run
        error = self.error
        if error is None and self.finished and not (self.measured or left or dry_run):
            error = "no pose measured" if self.moves else None
        eta = None
        if self._durations and left and not self.finished:
            eta = (len(self.moves) - self._index) * float(np.mean(self._durations))
        return CaptureProgress(
            measured=self.measured,
            total=len(self.moves),
            earlier=self.n_already,
            current_pose=self.moves[self._index].pose if left else None,
            step="dry run" if dry_run else "finished" if self.finished else self._state,
            skipped=tuple(s.reason for s in self.skipped),
            bag=str(self.bag_path),
            eta_s=eta,
            error=error,
        )

    def report(self) -> None:
        """Publish the progress on /diagnostics and ~/progress (on each step and every
        second)."""
        if not self.context.ok():
            return  # shutting down (Ctrl-C): close() runs without a graph
        name, robot = status_name(self.get_name()), self.settings.robot.name
        progress = self.progress()
        status = capture_status(name, robot, progress)
        self._diagnostics.publish(diagnostic_array(status, self.get_clock().now().to_msg()))
        doc = {**asdict(progress), "skipped": list(progress.skipped), "cancelled": self.cancelled}
        self._progress.publish(String(data=json.dumps(doc)))

    def _on_cancel(self, _request: Trigger.Request, response: Trigger.Response) -> Any:
        """Service ~/cancel (std_srvs/srv/Trigger): stop the campaign now: the robot told
        to hold, the bag closed with every pose measured so far (resumable: run again with
        the same plan and output). `success` false when it had already finished."""
        if self.finished:
            response.success, response.message = False, f"already finished: {self.summary()}"
            return response
        self.cancelled = True
        self.get_logger().warning("cancelled (service ~/cancel)")
        self.close()
        response.success, response.message = True, f"cancelled: {self.summary()}"
        return response

    def summary(self) -> str:
        """'N poses measured -> BAG; K skipped: pose i: why; ...' (and what is left)."""
        where = self.bag_path if self.measured else "no bag written"
        text = f"{self.measured} poses measured -> {where}"
        if self.n_already:
            text += f" ({self.n_already} earlier, in {', '.join(map(str, self.parts))})"
        if self.skipped:
            text += f"; {len(self.skipped)} skipped: " + "; ".join(s.reason for s in self.skipped)
        left = len(self.moves) - self._index
        if left > 0:
            text += (
                f"; stopped with {left} pose(s) to go (robot told to hold): run again "
                "with the same plan and output to resume"
            )
        return text

    def destroy_node(self) -> None:
        """Close the bag (what was measured stays), then destroy the node."""
        try:
            self.close()
        finally:
            super().destroy_node()


def _done(node: CaptureNode) -> bool:
    """Finished; a campaign that measured nothing is an error (exit 2), not a success."""
    if node.finished and node.measured == 0 and node.moves and not node.settings.dry_run:
        raise InputError(f"no pose measured ({node.summary()})")
    return node.finished


def _left(node: CaptureNode) -> str | None:
    """What a signal left of the campaign (its summary), None when it had finished."""
    if node.finished and node._index >= len(node.moves):
        return None
    node.close()  # the robot told to hold, the bag closed: the summary is final
    return node.summary() if node._index < len(node.moves) else None


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(CaptureNode, args, done=_done, name="capture", left=_left))


if __name__ == "__main__":
    main()
