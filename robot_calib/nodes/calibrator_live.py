"""The calibrator's live mode (msgs_doc/calibrator.md, "Pairing (live mode)"): which targets'
topics it takes (parameters `targets`, `six_dof_targets`), the subscriptions that buffer
/joint_states, points and 6-DoF poses, and the pairing of everything buffered into a
`Recording`, exactly as a bag's. The node (`calibrator.py`) decides when to solve."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped, PoseWithCovarianceStamped
from rclpy.callback_groups import CallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import QoSRequestedIncompatibleQoSInfo, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState

from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.measurements import Recording, recording_from_stream
from robot_calib.measurements.six_dof import PoseReading, join_poses
from robot_calib.messages import (
    JOINT_STATES_TOPIC,
    POSE_COV_TYPE,
    POSE_TYPE,
    TRACKER_FRAME,
    joint_positions,
    pose_measurement,
    pose_topic,
    stamp_to_ns,
    target_topic,
    velocity_signs,
)
from robot_calib.poses import PRIMARY_TARGET, TARGET_NAME

FIRST_TARGET = "first"  # the first target's name in `six_dof_targets` (as in a world file)
POSE_CLASSES = {POSE_TYPE: PoseStamped, POSE_COV_TYPE: PoseWithCovarianceStamped}
DISCOVERY_PERIOD_S = 0.1  # how often the graph is asked for the type of a pose topic


@dataclass(frozen=True)
class LiveTargets:
    """The targets of live mode: `names` ('' first, then by name, as a bag's topics are
    read), `points` (whose point topics are taken), `six_dof` (whose pose topics are)."""

    names: tuple[str, ...]
    points: tuple[str, ...]
    six_dof: tuple[str, ...]

    @property
    def topics(self) -> list[str]:
        """The live topics besides /joint_states: point topics, then pose topics."""
        return [
            *(target_topic(t) for t in self.names if t in self.points),
            *(pose_topic(t) for t in self.six_dof),
        ]


def live_targets(node_name: str, further: list[str], six_dof: list[str]) -> LiveTargets:
    """The targets from the parameters `targets` and `six_dof_targets`; InputError naming
    the node for a bad or repeated name."""
    for param, values in (("targets", further), ("six_dof_targets", six_dof)):
        bad = [v for v in values if v != FIRST_TARGET and not TARGET_NAME.fullmatch(v)]
        if param == "targets" and FIRST_TARGET in values:
            bad.append(FIRST_TARGET)  # names the first target in six_dof_targets
        if bad or len(set(values)) != len(values):
            raise InputError(
                f"{node_name}: parameter {param!r}: {values}: want distinct target names "
                f"(letters, digits, underscores, starting with a letter; '{FIRST_TARGET}' "
                "in six_dof_targets only, for the first target)"
            )
    probes = {PRIMARY_TARGET if t == FIRST_TARGET else t for t in six_dof}
    return LiveTargets(
        names=(PRIMARY_TARGET, *sorted((set(further) | probes) - {PRIMARY_TARGET})),
        points=(PRIMARY_TARGET, *further),
        six_dof=tuple(sorted(probes)),
    )


class LiveInputs:
    """Buffers of live mode on `node`: subscriptions (RELIABLE, VOLATILE, `qos_depth`) to
    /joint_states and the topics of `targets`, pose topics subscribed once the graph shows
    their type. Thread-safe: the subscriptions append while a solve takes a snapshot."""

    def __init__(
        self,
        node: Node,
        robot: RobotDescription,
        targets: LiveTargets,
        qos_depth: int,
        group: CallbackGroup | None = None,
    ) -> None:
        self._node = node
        self._group = group  # the solver's: no callback of ours runs while a solve drains
        self._subscriptions: list[tuple[Subscription, Any]] = []
        self.enabled = True  # False: messages taken are dropped (a lifecycle node inactive)
        self._robot = robot
        self.targets = targets
        self._lock = threading.Lock()
        self._js_ns: list[int] = []
        self._js_q: list[Array] = []
        self._js_v: list[Array] = []
        self._pt_ns: list[int] = []
        self._pt_xyz: list[Array] = []
        self._pt_target: list[int] = []  # index into targets.names
        self._poses: list[dict[int, PoseReading]] = [{} for _ in targets.names]
        self._counts = dict.fromkeys([JOINT_STATES_TOPIC, *targets.topics], 0)
        self.rejected = 0  # joint states refused (lacking the robot's joints)
        self._last_point_s: float | None = None
        self._unsolved = False  # points arrived since the last snapshot
        self._qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=qos_depth,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
        )
        self._subscribe(JointState, JOINT_STATES_TOPIC, self._on_joint_state)
        for k, name in enumerate(targets.names):
            if name in targets.points:
                self._subscribe(PointStamped, target_topic(name), partial(self._on_point, k))
        # a pose topic's type (PoseStamped or PoseWithCovarianceStamped) comes from the graph
        self._pending_poses = {
            pose_topic(t): k for k, t in enumerate(targets.names) if t in targets.six_dof
        }
        if self._pending_poses:
            self._discovery_timer = node.create_timer(
                DISCOVERY_PERIOD_S,
                self._discover_poses,
                clock=Clock(clock_type=ClockType.STEADY_TIME),
            )
            self._discover_poses()

    @property
    def counts(self) -> dict[str, int]:
        """Messages buffered per topic (joint states refused are not counted)."""
        with self._lock:
            return dict(self._counts)

    def clear(self) -> dict[str, int]:
        """Forget every message buffered (a new set begins); the counts dropped per topic."""
        with self._lock:
            dropped = {t: n for t, n in self._counts.items() if n}
            for buffer in (
                self._js_ns,
                self._js_q,
                self._js_v,
                self._pt_ns,
                self._pt_xyz,
                self._pt_target,
            ):
                buffer.clear()
            for by_stamp in self._poses:
                by_stamp.clear()
            self._counts = dict.fromkeys(self._counts, 0)
            self._last_point_s, self._unsolved = None, False
        return dropped

    def close(self) -> None:
        """Destroy the subscriptions and the discovery timer (the buffers stay as they are)."""
        for subscription, _ in self._subscriptions:
            self._node.destroy_subscription(subscription)
        self._subscriptions.clear()
        if self._pending_poses:
            self._node.destroy_timer(self._discovery_timer)
            self._pending_poses.clear()

    def drain(self) -> int:
        """Take every message waiting in the subscriptions' queues now (delivered but not
        yet handed to a callback by the executor) and buffer it, so a solve sees all that
        arrived before it: the end of a replayed bag is not lost. Returns how many."""
        taken = 0
        for subscription, callback in self._subscriptions:
            with subscription.handle:
                while (
                    found := subscription.handle.take_message(subscription.msg_type, False)
                ) is not None:
                    callback(found[0])
                    taken += 1
        return taken

    def recording(self, pair_tolerance: float) -> Recording:
        """Everything received so far (`drain` first), paired exactly as a bag is
        (RobotCalibError for bad input, naming the live topics)."""
        self.drain()
        names = self._robot.joint_names
        with self._lock:  # a consistent snapshot while the subscriptions keep appending
            self._unsolved = False
            js_ns = np.array(self._js_ns, dtype=np.int64)
            js_q = np.array(self._js_q).reshape(-1, len(names))
            js_v = np.array(self._js_v).reshape(-1, len(names))
            pt_ns, pt_xyz, pt_target = list(self._pt_ns), list(self._pt_xyz), list(self._pt_target)
            poses = [dict(by_stamp) for by_stamp in self._poses]
        source = "live " + " + ".join([JOINT_STATES_TOPIC, *self.targets.topics])
        targets = self.targets.names
        # a pose joins the point of its target and stamp, as in a bag (msgs_doc/six_dof.md)
        stamped = join_poses(source, targets, pt_ns, pt_xyz, pt_target, poses, set(pt_target))
        return recording_from_stream(
            js_ns,
            js_q,
            js_v,
            stamped.point_ns,
            stamped.points,
            pair_tolerance,
            source=source,
            robot=self._robot,
            point_target=stamped.point_target if len(targets) > 1 else None,
            target_names=targets,
            rotation=stamped.rotation,
            sigma=stamped.sigma,
            received=np.arange(len(js_ns)),  # appended as they arrived: the visiting order
        )

    def idle(self, seconds: float) -> str | None:
        """What awaits a solve ('N points[ and M poses]') once no new point arrived for
        `seconds` after the last one (the plan ended), None before or when nothing new."""
        with self._lock:
            due = (
                self._unsolved
                and self._last_point_s is not None
                and time.monotonic() - self._last_point_s >= seconds
            )
            n_poses = sum(len(by_stamp) for by_stamp in self._poses)
            what = f"{len(self._pt_ns)} points" + (f" and {n_poses} poses" if n_poses else "")
        return what if due else None

    # --- subscriptions ----------------------------------------------------------------------

    def _subscribe(self, msg_type: type, topic: str, callback: Any) -> None:
        """A live subscription warning of incompatible QoS, in the solver's group."""
        subscription = self._node.create_subscription(
            msg_type,
            topic,
            callback,
            self._qos,
            event_callbacks=SubscriptionEventCallbacks(
                incompatible_qos=partial(self._on_incompatible_qos, topic)
            ),
            callback_group=self._group,
        )
        self._subscriptions.append((subscription, callback))

    def _on_incompatible_qos(self, topic: str, event: QoSRequestedIncompatibleQoSInfo) -> None:
        self._node.get_logger().warning(
            f"{topic}: a publisher's QoS is incompatible with RELIABLE "
            f"(policy {event.last_policy_kind}); its messages are not received"
        )

    def _discover_poses(self) -> None:
        """Subscribe to each pose topic once the graph shows its type (a publisher exists)."""
        logger = self._node.get_logger()
        graph = dict(self._node.get_topic_names_and_types())
        for topic, k in list(self._pending_poses.items()):
            types = [t for t in graph.get(topic, []) if t in POSE_CLASSES]
            if not types:
                if graph.get(topic):
                    logger.warning(
                        f"{topic}: type {graph[topic]} is none of {list(POSE_CLASSES)}: "
                        "waiting for a publisher of one of them",
                        throttle_duration_sec=10.0,
                    )
                continue
            del self._pending_poses[topic]
            self._subscribe(POSE_CLASSES[types[0]], topic, partial(self._on_pose, k, topic))
            logger.info(f"{topic}: subscribed as {types[0]}")
        if not self._pending_poses:
            self._discovery_timer.cancel()

    def _check_frame(self, topic: str, frame_id: str) -> None:
        if frame_id != TRACKER_FRAME:
            self._node.get_logger().warning(
                f"{topic}: frame_id {frame_id!r} is not '{TRACKER_FRAME}' "
                "(used as the tracker frame anyway)",
                once=True,
            )

    def _on_joint_state(self, msg: JointState) -> None:
        if not self.enabled:
            return
        names = self._robot.joint_names
        try:
            q = joint_positions(msg, names)
        except InputError as exc:
            self.rejected += 1
            self._node.get_logger().warning(
                f"{exc} ({self.rejected} refused so far)", throttle_duration_sec=10.0
            )
            return
        with self._lock:
            self._js_ns.append(stamp_to_ns(msg.header.stamp))
            self._js_q.append(q)
            self._js_v.append(velocity_signs(msg, names))
            self._counts[JOINT_STATES_TOPIC] += 1

    def _on_point(self, target: int, msg: PointStamped) -> None:
        if not self.enabled:
            return
        topic = target_topic(self.targets.names[target])
        xyz = np.array([msg.point.x, msg.point.y, msg.point.z])
        if not np.all(np.isfinite(xyz)):
            self._node.get_logger().warning(f"{topic}: point not finite {xyz}: ignored")
            return
        self._check_frame(topic, msg.header.frame_id)
        with self._lock:
            self._pt_ns.append(stamp_to_ns(msg.header.stamp))
            self._pt_xyz.append(xyz)
            self._pt_target.append(target)
            self._counts[topic] += 1
            self._last_point_s = time.monotonic()
            self._unsolved = True

    def _on_pose(
        self, target: int, topic: str, msg: PoseStamped | PoseWithCovarianceStamped
    ) -> None:
        if not self.enabled:
            return
        try:
            where = f"{topic} message {self._counts[topic] + 1}"
            reading = pose_measurement(msg, where)
        except InputError as exc:
            self._node.get_logger().warning(f"{exc}: ignored", throttle_duration_sec=10.0)
            return
        self._check_frame(topic, msg.header.frame_id)
        with self._lock:
            self._poses[target][stamp_to_ns(msg.header.stamp)] = reading
            self._counts[topic] += 1
            self._last_point_s = time.monotonic()
            self._unsolved = True
