"""sim_tracker: a simulated laser tracker watching a target on the simulated robot.

Subscribes /joint_states; for every reading computes the physical target of the world's
true model (effects see the approach-direction history and the time since the first
reading), adds tracker/target noise, and publishes geometry_msgs/PointStamped on
/laser_tracker/point (frame `laser_tracker`, metres). Its stamp precedes the joint-state
stamp by a random latency; points may drop out (line of sight), as the world says.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState

from robot_calib.errors import InputError
from robot_calib.messages import (
    JOINT_STATES_TOPIC,
    TRACKER_FRAME,
    joint_positions,
    ns_to_sec_nanosec,
    stamp_to_ns,
    target_topic,
)
from robot_calib.nodes._common import declare, run_node
from robot_calib.nodes.sim_robot import QOS
from robot_calib.sim.measure import StreamingTracker
from robot_calib.sim.world import load_world


class SimTrackerNode(Node):
    """One point per received JointState (unless dropped); counts in `received`/`published`."""

    def __init__(self, **kwargs: Any) -> None:  # rclpy.node.Node's keyword arguments
        super().__init__("sim_tracker", **kwargs)
        world_file = declare(self, "world", "", "world YAML file ('' = built-in default)")
        seed = declare(self, "seed", -1, "random seed (-1 = the world's seed + 1)")
        self.world = load_world(world_file or None)
        rng = np.random.default_rng(self.world.seed + 1 if seed < 0 else seed)
        self.tracker = StreamingTracker(self.world, rng)
        self.wait_for = declare(
            self,
            "wait_for_subscribers",
            0,
            "subscribe to /joint_states only once this many readers of the points are matched"
            " (so a robot that waits for its own readers starts only when no point is lost)",
        )
        # one topic per target of the world (msgs_doc/targets.md); the first is POINT_TOPIC
        self.topics = [target_topic(t) for t in self.world.model.targets]
        self.publishers_by_target = [
            self.create_publisher(PointStamped, topic, QOS) for topic in self.topics
        ]
        self.publisher = self.publishers_by_target[0]
        self.subscription: Subscription | None = None
        self.received = 0
        self.published = 0
        self.dropped = 0
        self._wait_timer = self.create_timer(0.01, self._subscribe_when_ready)
        self._subscribe_when_ready()

    def _subscribe_when_ready(self) -> None:
        if self.subscription is not None:
            return
        if self.publisher.get_subscription_count() < self.wait_for:
            return
        self.destroy_timer(self._wait_timer)
        self.subscription = self.create_subscription(
            JointState, JOINT_STATES_TOPIC, self.on_joint_state, QOS
        )

    def on_joint_state(self, msg: JointState) -> None:
        self.received += 1
        try:
            q = joint_positions(msg, self.world.model.robot.joint_names)
        except InputError as exc:
            self.get_logger().error(str(exc))
            return
        stamp = stamp_to_ns(msg.header.stamp)
        result = self.tracker.measure_targets(q, stamp * 1e-9)
        if result is None:
            self.dropped += 1
            return
        points, latency_s = result
        for publisher, point in zip(self.publishers_by_target, points):
            out = PointStamped()
            out.header.frame_id = TRACKER_FRAME
            out.header.stamp.sec, out.header.stamp.nanosec = ns_to_sec_nanosec(
                stamp - int(round(latency_s * 1e9))
            )
            out.point.x, out.point.y, out.point.z = (float(v) for v in point)
            publisher.publish(out)
        self.published += 1


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(SimTrackerNode, args))


if __name__ == "__main__":
    main()
