"""sim_robot: a simulated robot controller publishing its joint readings per plan.

Publishes sensor_msgs/JointState on /joint_states (names joint_a1..a6, position [rad]),
one message per measurement pose, header.stamp = the pose's measurement time. Waits until
`wait_for_subscribers` readers are matched, so no first pose is lost. With `publish_clock`
it also drives /clock (rosgraph_msgs/Clock), so nodes with use_sim_time run on plan time.
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

from robot_calib.messages import JOINT_STATES_TOPIC, ns_to_sec_nanosec
from robot_calib.nodes._common import declare, run_node
from robot_calib.sim.plans import PLAN_NAMES, Plan, make_plan, plan_times
from robot_calib.sim.world import load_world

SYSTEM_CLOCK = RosClock(clock_type=ClockType.SYSTEM_TIME)
QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=1000
)


class SimRobotNode(Node):
    """Publishes the plan's readings; `publish_pose(k)` lets a driver step it in lockstep."""

    def __init__(self, **kwargs: Any) -> None:  # rclpy.node.Node's keyword arguments
        super().__init__("sim_robot", **kwargs)
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
            1,
            "start once this many /joint_states readers are matched",
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
        rng = np.random.default_rng(self.world.seed if seed < 0 else seed)
        nominal = self.world.model.parameters()
        self.plan: Plan = make_plan(self.plan_name, self.world.model, nominal, rng, n_random)
        self.times_s = plan_times(self.plan, self.world.timing)
        self.publisher = self.create_publisher(JointState, JOINT_STATES_TOPIC, QOS)
        self.clock_publisher = (
            self.create_publisher(Clock, "/clock", 10) if publish_clock else None
        )
        self.next_pose = 0
        self.start_ns: int | None = None
        self._start_wall_ns = 0
        self._done_wall_ns: int | None = None
        if autostart:
            self._timer = self.create_timer(0.005, self._tick)
        self.get_logger().info(
            f"plan {self.plan_name}: {len(self.plan)} poses over {self.times_s[-1] / 60:.1f} min "
            f"of robot time; waiting for {self.wait_for} subscriber(s) on {JOINT_STATES_TOPIC}"
        )

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
        if self.clock_publisher is not None:
            self.clock_publisher.publish(Clock(clock=Time(nanoseconds=self.stamp_ns(k)).to_msg()))

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
    sys.exit(run_node(SimRobotNode, args, done=lambda node: node.finished))


if __name__ == "__main__":
    main()
