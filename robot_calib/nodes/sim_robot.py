"""sim_robot: a simulated robot controller publishing its joint readings.

Two modes (parameter `mode`):

- `plan` (default): publishes sensor_msgs/JointState on /joint_states (the robot's joint
  names, position [rad]), one message per measurement pose of a plan, header.stamp = the
  pose's measurement time. Waits until `wait_for_subscribers` readers are matched, so no
  first pose is lost. With `publish_clock` it also drives /clock (rosgraph_msgs/Clock), so
  nodes with use_sim_time run on plan time.
- `controller`: behaves like a ros2_control joint_trajectory_controller: takes
  trajectory_msgs/JointTrajectory commands on /<controller>/joint_trajectory (joints by
  name, in any order; waypoints at time_from_start, never faster than `speed_fraction` of
  the world's joint speeds), moves there smoothly (sim/controller.py) and publishes
  /joint_states at `state_rate` while moving and while holding. A command naming unknown
  joints, missing one, or leaving the joint limits is rejected whole (logged), as the
  controller does; an empty command stops the robot where it is.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
from rclpy.clock import Clock as RosClock
from rclpy.clock import ClockType
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from robot_calib.errors import InputError
from robot_calib.kinematics.description import JointLimitError, home_pose
from robot_calib.messages import JOINT_STATES_TOPIC, ns_to_sec_nanosec
from robot_calib.nodes._cdr import ClockEncoder, JointStateEncoder
from robot_calib.nodes._common import declare, in_ros_terms, run_node
from robot_calib.sim.controller import Motion, follow, hold, state_at
from robot_calib.sim.plans import PLAN_NAMES, Plan, make_plan, plan_times
from robot_calib.sim.world import load_world

SYSTEM_CLOCK = RosClock(clock_type=ClockType.SYSTEM_TIME)
QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=1000
)
MODES = ("plan", "controller")
# /joint_states readers plan mode waits for: the README's recipe runs a recorder and
# sim_tracker; starting on the first one would lose the poses the other one missed
DEFAULT_WAIT_FOR = 2


def trajectory_topic(controller: str) -> str:
    """The command topic of a joint_trajectory_controller named `controller`."""
    return f"/{controller.strip('/')}/joint_trajectory"


class SimRobotNode(Node):
    """Publishes the plan's readings; `publish_pose(k)` lets a driver step it in lockstep."""

    def __init__(self, **kwargs: Any) -> None:  # rclpy.node.Node's keyword arguments
        super().__init__("sim_robot", **kwargs)
        self.mode = declare(self, "mode", "plan", f"what drives the robot: {' or '.join(MODES)}")
        if self.mode not in MODES:
            raise InputError(
                f"sim_robot: parameter 'mode' must be one of {MODES}, not {self.mode!r}"
            )
        self.plan_name = declare(
            self,
            "plan",
            "paper-test3",
            f"measurement plan: {', '.join(PLAN_NAMES)}, or a PLAN.yaml file",
        )
        world_file = declare(self, "world", "", "world YAML file ('' = built-in default)")
        self.rate = declare(
            self,
            "rate",
            1.0,
            "time factor vs the plan's realistic timing (1 = real time, "
            "10 = ten times faster, <= 0 = as fast as possible)",
        )
        seed = declare(self, "seed", -1, "random seed (-1 = the world's seed)")
        n_random = declare(self, "n_random", 200, "number of poses of the 'random' plan")
        self.wait_for = declare(
            self,
            "wait_for_subscribers",
            DEFAULT_WAIT_FOR,
            "start once this many /joint_states readers are matched (2: a recorder and "
            "sim_tracker, as in the README's recipe)",
        )
        if self.wait_for < 0:
            raise InputError(
                f"{self.get_name()}: parameter 'wait_for_subscribers' must be "
                f">= 0, not {self.wait_for}"
            )
        publish_clock = declare(
            self, "publish_clock", False, "also publish /clock = measurement time (simulated time)"
        )
        autostart = declare(
            self,
            "autostart",
            True,
            "publish on a wall-clock timer (false: a driver calls "
            "publish_pose(), as robot-calib simulate does)",
        )
        self.world = load_world(world_file or None)
        if self.mode == "controller":
            self._start_controller()
            return
        rng = np.random.default_rng(self.world.seed if seed < 0 else seed)
        nominal = self.world.model.parameters()
        self.plan: Plan = make_plan(self.plan_name, self.world.model, nominal, rng, n_random)
        self.times_s = plan_times(self.plan, self.world.timing)
        self.publisher = self.create_publisher(JointState, JOINT_STATES_TOPIC, QOS)
        self.clock_publisher = (
            self.create_publisher(Clock, "/clock", 10) if publish_clock else None
        )
        self.next_pose = 0
        # publish_poses' CDR template (nodes/_cdr.py); None: messages (rclpy read it otherwise)
        self._encoder: JointStateEncoder | None = None
        self._encoder_checked = False
        self._clock_encoder: ClockEncoder | None = None  # the same for /clock
        self._clock_encoder_checked = False
        self.start_ns: int | None = None
        self._start_wall_ns = 0
        self._done_wall_ns: int | None = None
        if autostart:
            self._timer = self.create_timer(0.005, self._tick)
        self.get_logger().info(
            f"plan {self.plan_name}: {len(self.plan)} poses over {self.times_s[-1] / 60:.1f} min "
            f"of robot time; waiting for {self.wait_for} subscriber(s) on {JOINT_STATES_TOPIC}"
        )

    def _start_controller(self) -> None:
        """Controller mode (module docstring): hold the home pose, publish at state_rate."""
        from trajectory_msgs.msg import JointTrajectory

        controller = declare(
            self,
            "controller",
            "joint_trajectory_controller",
            "controller name: commands on /<controller>/joint_trajectory",
        )
        state_rate = declare(self, "state_rate", 50.0, "joint states per second [Hz]")
        self.speed_fraction = declare(
            self,
            "speed_fraction",
            0.25,
            "top speed as a fraction of the world's max joint speeds (> 1: faster than real)",
        )
        if not state_rate > 0 or not self.speed_fraction > 0:
            raise InputError("sim_robot: parameters 'state_rate' and 'speed_fraction' must be > 0")
        robot = self.world.model.robot
        self.motion: Motion = hold(np.clip(home_pose(robot), *robot.limits.T), self._now_s())
        self.commands = 0
        self.publisher = self.create_publisher(JointState, JOINT_STATES_TOPIC, QOS)
        self.topic = trajectory_topic(controller)
        self.create_subscription(JointTrajectory, self.topic, self._on_command, 10)
        self._timer = self.create_timer(1.0 / state_rate, self._publish_state)
        self.get_logger().info(
            f"controller mode: commands on {self.topic}, joint states at {state_rate:g} Hz"
        )

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _publish_state(self) -> None:
        now = self.get_clock().now().nanoseconds
        q, velocity = state_at(self.motion, now * 1e-9)
        msg = JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = ns_to_sec_nanosec(now)
        msg.name = list(self.world.model.robot.joint_names)
        msg.position = q.tolist()
        msg.velocity = velocity.tolist()
        self.publisher.publish(msg)

    def _on_command(self, msg: Any) -> None:  # noqa: ANN401 - trajectory_msgs JointTrajectory
        """A JointTrajectory: the new motion from where the robot is now, or rejected."""
        robot = self.world.model.robot
        now = self._now_s()
        q_now, _ = state_at(self.motion, now)
        if not msg.points:
            self.motion = hold(q_now, now)
            return
        names = list(msg.joint_names)
        unknown = [n for n in names if n not in robot.joint_names]
        missing = [n for n in robot.joint_names if n not in names]
        if unknown or missing or len(set(names)) != len(names):
            self.get_logger().error(
                f"{self.topic}: rejected: joints {names} are not {list(robot.joint_names)} "
                f"(unknown {unknown}, missing {missing})"
            )
            return
        order = [names.index(n) for n in robot.joint_names]
        try:
            waypoints = np.array([[p.positions[k] for k in order] for p in msg.points], float)
        except IndexError:
            self.get_logger().error(f"{self.topic}: rejected: a point has too few positions")
            return
        times = np.array(
            [p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points]
        )
        if len(times) > 1 and np.any(np.diff(times) <= 0):
            self.get_logger().error(
                f"{self.topic}: rejected: time_from_start not strictly increasing "
                f"({times.round(3).tolist()} s), as a joint_trajectory_controller rejects it"
            )
            return
        if times[0] <= 0:
            self.get_logger().warning(
                f"{self.topic}: a first point at time 0: a real controller jumps there; this "
                "simulation moves at its speed limit",
                throttle_duration_sec=10.0,
            )
        try:  # the one check of limits and units (compensate, compensator, capture, plan)
            robot.check_joints(waypoints, f"{self.topic}: rejected", what="point")
        except JointLimitError as exc:
            self.get_logger().error(in_ros_terms(exc))
            return
        speed = self.world.timing.speeds(robot.n_joints)
        self.motion = follow(now, q_now, waypoints, times, self.speed_fraction * speed)
        self.commands += 1

    @property
    def done(self) -> bool:
        return self.next_pose >= len(self.plan)

    def ready(self) -> bool:
        return self.publisher.get_subscription_count() >= self.wait_for

    def stamp_ns(self, k: int) -> int:
        """Measurement time of pose k [ns]; the plan starts at the first publication."""
        assert self.start_ns is not None
        return self.start_ns + int(round(self.times_s[k] * 1e9))

    def publish_clock(self, k: int) -> None:
        """Advance /clock to the measurement time of pose k (simulated-time mode). Simulated
        time starts at the wall-clock time of the first pose, so bags carry real dates."""
        if self.start_ns is None:
            self.start_ns = SYSTEM_CLOCK.now().nanoseconds
        if self.clock_publisher is None:
            return
        stamp = self.stamp_ns(k)
        sec, nanosec = ns_to_sec_nanosec(stamp)
        if not self._clock_encoder_checked:  # rclpy must read the template's bytes
            self._clock_encoder_checked = True
            encoder = ClockEncoder()
            self._clock_encoder = encoder if encoder.check(sec, nanosec) else None
        if self._clock_encoder is not None:
            self.clock_publisher.publish(self._clock_encoder.encode(sec, nanosec))
        else:
            self.clock_publisher.publish(Clock(clock=Time(nanoseconds=stamp).to_msg()))

    def publish_pose(self) -> int:
        """Publish the next pose's readings; returns its stamp [ns]."""
        k = self.next_pose
        if self.start_ns is None:
            self.start_ns = self.get_clock().now().nanoseconds
        stamp = self.stamp_ns(k)
        msg = JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = ns_to_sec_nanosec(stamp)
        msg.name = list(self.world.model.robot.joint_names)
        msg.position = self.plan.q[k].tolist()
        self.publisher.publish(msg)
        self.next_pose += 1
        return stamp

    def publish_poses(self, count: int) -> list[int]:
        """Publish the next `count` poses' readings at once (a burst: the readers' queues
        must hold `count` messages; `robot-calib simulate` sizes it so); returns their
        stamps [ns]. The messages are those of `publish_pose`, their CDR bytes built from a
        template (nodes/_cdr.py) unless rclpy reads the first ones otherwise."""
        if self.start_ns is None:
            self.start_ns = self.get_clock().now().nanoseconds
        stop = min(self.next_pose + count, len(self.plan))
        stamps = [self.stamp_ns(k) for k in range(self.next_pose, stop)]
        positions = self.plan.q[self.next_pose : stop].tolist()
        encoder = self._encoder
        if not self._encoder_checked and stamps:  # rclpy must read the template's bytes
            self._encoder_checked = True
            sec, nanosec = ns_to_sec_nanosec(stamps[0])
            encoder = JointStateEncoder(self.world.model.robot.joint_names)
            self._encoder = encoder = (
                encoder if encoder.check(sec, nanosec, positions[0]) else None
            )
        publish = self.publisher.publish
        for stamp, q in zip(stamps, positions):
            sec, nanosec = divmod(stamp, 1_000_000_000)
            if encoder is not None:
                publish(encoder.encode(sec, nanosec, q))
            else:
                msg = JointState()
                msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
                msg.name = list(self.world.model.robot.joint_names)
                msg.position = q
                publish(msg)
        self.next_pose = stop
        return stamps

    @property
    def finished(self) -> bool:
        """Done, and 0.5 s have passed for reliable readers to take the last poses."""
        return (
            self._done_wall_ns is not None
            and SYSTEM_CLOCK.now().nanoseconds - self._done_wall_ns > 500_000_000
        )

    def _tick(self) -> None:
        """Standalone mode: publish on a wall-clock timer at the plan's timing / rate."""
        if self.done:
            return
        if self.start_ns is None:
            if not self.ready():
                return
            self._start_wall_ns = self.get_clock().now().nanoseconds
            self.start_ns = self._start_wall_ns
        elapsed_s = (self.get_clock().now().nanoseconds - self._start_wall_ns) * 1e-9
        while not self.done and (
            self.rate <= 0 or self.times_s[self.next_pose] / self.rate <= elapsed_s
        ):
            self.publish_clock(self.next_pose)
            self.publish_pose()
            if self.rate <= 0:
                break  # one pose per tick: readers keep up with a depth-1000 queue
        if self.done:
            self._done_wall_ns = SYSTEM_CLOCK.now().nanoseconds
            self.get_logger().info(f"plan {self.plan_name} done: {len(self.plan)} poses")


def main(args: list[str] | None = None) -> None:
    sys.exit(
        run_node(
            SimRobotNode,
            args,
            name="sim_robot",
            done=lambda node: node.mode == "plan" and node.finished,
        )
    )


if __name__ == "__main__":
    main()
