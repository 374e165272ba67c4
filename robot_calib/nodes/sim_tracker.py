"""sim_tracker: a simulated laser tracker watching a target on the simulated robot.

Subscribes /joint_states; for every reading computes the physical target of the world's
true model (effects see the approach-direction history and the time since the first
reading), adds tracker/target noise, and publishes geometry_msgs/PointStamped on
/laser_tracker/point (frame `laser_tracker`, metres), and on /laser_tracker/NAME/point for
each further target. Its stamp precedes the joint-state stamp by a random latency; points
may drop out (line of sight), as the world says. A target with a 6-DoF probe (world
`six_dof`) also gets its measured frame, with the world's noise stated as covariance, as a
geometry_msgs/PoseWithCovarianceStamped on /laser_tracker/(NAME/)pose (msgs_doc/six_dof.md).
"""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np
from geometry_msgs.msg import Point, PointStamped, PoseWithCovarianceStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array
from robot_calib.messages import (
    JOINT_STATES_TOPIC,
    TRACKER_FRAME,
    joint_positions,
    ns_to_sec_nanosec,
    orientation_quaternion,
    pose_covariance,
    pose_topic,
    reference_topic,
    stamp_to_ns,
    target_topic,
)
from robot_calib.nodes._cdr import JointStateEncoder, PointStampedEncoder
from robot_calib.nodes._common import declare, in_ros_terms, run_node
from robot_calib.nodes.sim_robot import QOS
from robot_calib.sim.measure import StreamingTracker, TrackerReading
from robot_calib.sim.world import load_world

# readers of each published topic to wait for: the recorder (the README's recipe)
DEFAULT_WAIT_FOR = 1
REREAD_STEP_NS = 1_000_000  # the further reads of one pose follow the first 1 ms apart


class SimTrackerNode(Node):
    """Per received JointState (unless dropped) one point per target and one pose per 6-DoF
    probe; counts in `received`/`published` (poses measured). `topics` are the topics it
    publishes: every target's point topic, then the probes' pose topics."""

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
            DEFAULT_WAIT_FOR,
            "subscribe to /joint_states only once this many readers of each topic published "
            "are matched (so a robot that waits for its own readers starts only when no "
            "point or pose is lost; 1: the recorder of the README's recipe; 0: at once)",
        )
        model = self.world.model
        # one topic per target of the world (msgs_doc/targets.md); the first is POINT_TOPIC
        self.point_publishers = [
            self.create_publisher(PointStamped, target_topic(t), QOS) for t in model.targets
        ]
        # and one per 6-DoF probe (msgs_doc/six_dof.md), by target index
        # (and with every point's own stated accuracy, one per target: msgs_doc/sim_tracker.md)
        stated = self.world.noise.point_sigma_range_m[1] > 0
        self.pose_publishers = {
            model.targets.index(t): self.create_publisher(
                PoseWithCovarianceStamped, pose_topic(t), QOS
            )
            for t in model.targets
            if t in model.oriented or stated
        }
        # and one per reference reflector of the world (msgs_doc/references.md)
        self.reference_publishers = [
            self.create_publisher(PointStamped, reference_topic(name), QOS)
            for name in self.world.references
        ]
        self.all_publishers = [
            *self.point_publishers,
            *self.pose_publishers.values(),
            *self.reference_publishers,
        ]
        self.triggered = declare(
            self,
            "triggered",
            False,
            "measure only on a std_srvs/Trigger call of ~/measure (the latest joint state), "
            "as a tracker driver with a trigger service; false: one measurement per reading",
        )
        self._latest: tuple[int, TrackerReading | None] | None = None
        if self.triggered:
            from std_srvs.srv import Trigger

            self.create_service(Trigger, "~/measure", self._on_trigger)
        self.topics = [p.topic_name for p in self.all_publishers]
        self.subscription: Subscription | None = None
        self.received = 0
        self.published = 0
        self.dropped = 0
        # the points' CDR template (nodes/_cdr.py); None: messages (rclpy read it otherwise)
        self._point_encoder: PointStampedEncoder | None = None
        self._point_encoder_checked = False
        self._joint_template: JointStateEncoder | None = None
        # on the steady clock: under use_sim_time /clock stands still until the robot starts
        self._wait_timer = self.create_timer(
            0.01, self._subscribe_when_ready, clock=Clock(clock_type=ClockType.STEADY_TIME)
        )
        self._subscribe_when_ready()
        if self.subscription is None:
            self.get_logger().info(
                f"waiting for {self.wait_for} reader(s) of each of {', '.join(self.topics)} "
                f"before subscribing to {JOINT_STATES_TOPIC}"
            )

    def _subscribe_when_ready(self) -> None:
        if self.subscription is not None:
            return
        if min(p.get_subscription_count() for p in self.all_publishers) < self.wait_for:
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
            self.get_logger().error(in_ros_terms(exc))
            return
        stamp = stamp_to_ns(msg.header.stamp)
        reading = self.tracker.measure_all(q, stamp * 1e-9)  # every reading: the history
        if self.triggered:
            self._latest = (stamp, reading)
            return
        self._publish(stamp, reading)

    def take_joint_states(self) -> list[bool]:
        """Take every joint state waiting on the subscription and measure them in one batch
        (`StreamingTracker.measure_batch`: the readings of `on_joint_state`, bit for bit),
        publishing as `on_joint_state` does: for a driver stepping the graph in bursts
        (`robot-calib simulate`). Returns per joint state taken whether it was measured and
        published (False: dropped, or not a reading of the robot's joints)."""
        subscription = self.subscription
        if subscription is None:
            return []
        names = self.world.model.robot.joint_names
        template = self._joint_template
        if template is None:
            template = self._joint_template = JointStateEncoder(names)
        stamps: list[int] = []
        readings: list[list[float] | tuple[float, ...]] = []
        taken: list[bool] = []
        with subscription.handle:
            take = subscription.handle.take_message
            while (result := take(JointState, True)) is not None:
                self.received += 1
                data = result[0]
                decoded = template.decode(data)
                if decoded is None:  # another layout: by name, as on_joint_state
                    try:
                        msg = deserialize_message(data, JointState)
                        q = joint_positions(msg, names).tolist()
                    except InputError as exc:
                        self.get_logger().error(in_ros_terms(exc))
                        taken.append(False)
                        continue
                    stamp = stamp_to_ns(msg.header.stamp)
                else:
                    sec, nanosec, q = decoded
                    stamp = sec * 1_000_000_000 + nanosec
                    if not all(math.isfinite(v) for v in q):
                        self.get_logger().error(
                            f"{JOINT_STATES_TOPIC}: JointState positions not finite: {list(q)}"
                        )
                        taken.append(False)
                        continue
                stamps.append(stamp)
                readings.append(q)
                taken.append(True)
        if not stamps:
            return taken
        measured = self.tracker.measure_batch(
            np.array(readings, dtype=float), np.array(stamps, dtype=np.int64) * np.float64(1e-9)
        )
        published = iter(zip(stamps, measured))
        out = []
        for ok in taken:
            if not ok:
                out.append(False)
                continue
            stamp, reading = next(published)
            if self.triggered:
                self._latest = (stamp, reading)
                out.append(False)
                continue
            self._publish(stamp, reading)
            out.append(reading is not None)
        return out

    def messages_per_pose(self, topic: str) -> int:
        """How many messages each measured pose publishes on `topic`: every read of it on a
        target's point topic (`reads_per_pose`), one on the others."""
        if any(p.topic_name == topic for p in self.point_publishers):
            return self.world.tracker.reads_per_pose
        return 1

    def _on_trigger(self, request: Any, response: Any) -> Any:  # noqa: ANN401 - std_srvs
        """Trigger: publish the measurement at the latest joint state (success false when
        there is none yet or the line of sight is lost)."""
        del request
        if self._latest is None:
            response.success, response.message = False, "no joint state received yet"
            return response
        stamp, reading = self._latest
        published = self.published
        self._publish(stamp, reading)
        response.success = self.published > published
        response.message = "measured" if response.success else "line of sight lost (dropped)"
        return response

    def _publish(self, stamp: int, reading: TrackerReading | None) -> None:
        """Publish one measurement stamped by its joint state `stamp` [ns] minus latency."""
        if reading is None:
            self.dropped += 1
            return
        sec, nanosec = ns_to_sec_nanosec(stamp - int(round(reading.latency_s * 1e9)))
        header = Header(frame_id=TRACKER_FRAME)
        header.stamp.sec, header.stamp.nanosec = sec, nanosec
        encoder = self._point_encoder
        if not self._point_encoder_checked:  # rclpy must read the template's bytes
            self._point_encoder_checked = True
            x, y, z = (float(v) for v in reading.points[0])
            encoder = PointStampedEncoder(TRACKER_FRAME)
            if not encoder.check(sec, nanosec, x, y, z):
                encoder = None
            self._point_encoder = encoder
        stamp_ns = sec * 1_000_000_000 + nanosec
        first = [*zip(self.point_publishers, reading.points.tolist())]
        if reading.references is not None:
            first += zip(self.reference_publishers, reading.references.tolist())
        points = [(stamp_ns, p, xyz) for p, xyz in first]
        for k, again in enumerate([] if reading.rereads is None else reading.rereads, start=1):
            points += [
                (stamp_ns + k * REREAD_STEP_NS, p, xyz)
                for p, xyz in zip(self.point_publishers, again.tolist())
            ]
        for at, publisher, xyz in points:
            s, ns = ns_to_sec_nanosec(at)
            if encoder is not None:
                publisher.publish(encoder.encode(s, ns, *xyz))
            else:
                head = Header(frame_id=TRACKER_FRAME)
                head.stamp.sec, head.stamp.nanosec = s, ns
                publisher.publish(PointStamped(header=head, point=point_message(xyz)))
        for k, publisher in self.pose_publishers.items():
            frame = None if reading.frames is None else reading.frames[k]
            publisher.publish(pose_message(header, reading.points[k], frame, reading.sigma[k]))
        self.published += 1


def point_message(xyz: Array) -> Point:
    """geometry_msgs/Point of xyz (3,) [m]."""
    return Point(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))


def pose_message(
    header: Header, xyz: Array, rotation: Array | None, sigma: Array
) -> PoseWithCovarianceStamped:
    """The 6-DoF message of a probe (msgs_doc/six_dof.md): its point xyz (3,) [m] and frame
    rotation (3, 3) in the tracker frame (None or NaN: a point without an orientation,
    identity and rotation variances -1), the stated standard deviations sigma (2,) [m, rad]
    as covariance; `header` that of its point."""
    out = PoseWithCovarianceStamped(header=header)
    out.pose.pose.position = point_message(xyz)
    o = out.pose.pose.orientation
    o.x, o.y, o.z, o.w = 0.0, 0.0, 0.0, 1.0
    oriented = rotation is not None and bool(np.all(np.isfinite(rotation)))
    if rotation is not None and oriented:
        o.x, o.y, o.z, o.w = orientation_quaternion(rotation)
    out.pose.covariance = pose_covariance(sigma, oriented=oriented)
    return out


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(SimTrackerNode, args, name="sim_tracker"))


if __name__ == "__main__":
    main()
