"""recorder: record topics into one MCAP bag, as `ros2 bag record -s mcap` would.

Subscribes to each topic with raw=True (CDR bytes kept as received, never re-serialised)
and writes them with the middleware's receive time [ns] as log and publish time (with
use_sim_time the node clock's time at the callback, as rosbag2 does). The contract's
topics and further targets' /laser_tracker/NAME/point have known types; other topics (a
6-DoF probe's pose: two types possible) are subscribed once the graph shows their type. A
topic's channel is created at its first message, with the publishers' offered QoS and type
hash as the graph reports them then. Topics and parameters: msgs_doc/recorder.md.

Standalone: `ros2 run robot_calib recorder --ros-args -p output:=run.mcap`; SIGINT, SIGTERM or
SIGHUP closes the bag (summary written) and prints the message counts per topic (SIGKILL
leaves the closed chunks: `robot-calib repair` makes a complete bag of them).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.event_handler import QoSRequestedIncompatibleQoSInfo, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.subscription import Subscription

from robot_calib.bag import BagWriter
from robot_calib.bag.mcap_writer import DEFAULT_CHUNK_SIZE, DEFAULT_MAX_CHUNK_AGE_S
from robot_calib.errors import BagError, InputError, RobotCalibError
from robot_calib.messages import (
    JOINT_STATE_TYPE,
    JOINT_STATES_TOPIC,
    POINT_TOPIC,
    POINT_TYPE,
    reference_topic_name,
    target_topic_name,
)
from robot_calib.nodes._common import (
    declare,
    in_ros_terms,
    message_class,
    overrides,
    qos_to_record,
    run_node,
)

DEFAULT_TOPICS = [JOINT_STATES_TOPIC, POINT_TOPIC]
KNOWN_TYPES = {  # msgs_doc/specification.md section 1
    JOINT_STATES_TOPIC: JOINT_STATE_TYPE,
    POINT_TOPIC: POINT_TYPE,
}
DEFAULT_QOS_DEPTH = 10000


def known_type(topic: str) -> str | None:
    """The type of a topic of the contract or of msgs_doc/targets.md (a further target's
    /laser_tracker/NAME/point), None for others: their type comes from the graph (as a 6-DoF
    probe's pose topic, PoseStamped or PoseWithCovarianceStamped, msgs_doc/six_dof.md)."""
    if topic in KNOWN_TYPES:
        return KNOWN_TYPES[topic]
    known = target_topic_name(topic) is not None or reference_topic_name(topic) is not None
    return POINT_TYPE if known else None


class RecorderNode(Node):
    """Records `topics` into the MCAP file `output` until `close()` (or destroy_node()).

    In-process: `RecorderNode(output=path, topics=[...])`, keyword values become parameter
    overrides (so do any `parameter_overrides=[Parameter(...)]`; keywords win). Standalone
    the parameters come from the command line. `counts` tells the messages written per
    topic. Raises InputError without `output`, BagError if `output` exists.
    """

    def __init__(
        self,
        output: str | os.PathLike[str] | None = None,
        topics: Sequence[str] | None = None,
        *,
        node_name: str = "recorder",
        parameter_overrides: Sequence[Parameter] | None = None,
        **node_kwargs: Any,
    ) -> None:
        values = {
            "output": None if output is None else os.fspath(output),
            "topics": None if topics is None else list(topics),
        }
        super().__init__(
            node_name,
            parameter_overrides=overrides(values, parameter_overrides),
            **node_kwargs,
        )
        try:
            self.output: str = declare(
                self, "output", "", "path of the .mcap file to write (required; must not exist)"
            )
            requested: list[str] = declare(
                self,
                "topics",
                list(DEFAULT_TOPICS),
                "topics to record; the types of others than the contract's come from the graph",
            )
            self.qos_depth: int = declare(
                self,
                "qos_depth",
                DEFAULT_QOS_DEPTH,
                "history depth of each subscription [messages]: bursts up to this are kept",
            )
            chunk_size: int = declare(
                self,
                "chunk_size",
                DEFAULT_CHUNK_SIZE,
                "MCAP chunk size [bytes]; a killed recorder loses at most the open chunk",
            )
            max_chunk_age: float = declare(
                self,
                "max_chunk_age",
                DEFAULT_MAX_CHUNK_AGE_S,
                "a chunk open longer than this is written out [s]",
            )
            compression: str = declare(
                self, "compression", "none", "chunk compression: none (as rosbag2), zstd or lz4"
            )
            if not self.output:
                raise InputError(
                    f"{self.get_name()}: parameter 'output' (the .mcap path) is required"
                )
            if not requested:
                raise InputError(f"{self.get_name()}: parameter 'topics' is empty")
            if self.qos_depth < 1:
                raise InputError(f"{self.get_name()}: parameter 'qos_depth' must be >= 1")
            self._writer = BagWriter(
                self.output,
                chunk_size=chunk_size,
                max_chunk_age_s=max_chunk_age,
                compression=compression,
            )
        except RobotCalibError:
            super().destroy_node()
            raise
        self._topics = list(dict.fromkeys(self.resolve_topic_name(t) for t in requested))
        self._counts = dict.fromkeys(self._topics, 0)
        self._types: dict[str, str] = {}
        self._subscriptions_by_topic: dict[str, Subscription] = {}
        self._pending = [t for t in self._topics if known_type(t) is None]
        self._closed = False
        self.lost: dict[str, int] = {}
        """Messages the middleware reported lost before they reached the recorder, per topic."""
        self._use_sim_time = bool(self.get_parameter("use_sim_time").value)
        for topic in self._topics:
            type_name = known_type(topic)
            if type_name is not None:
                self._subscribe(topic, type_name)
        self._discover()
        self._flush_timer = self.create_timer(  # steady: flushes also while sim time stands
            min(max_chunk_age / 2, 0.5),
            self._on_timer,
            clock=Clock(clock_type=ClockType.STEADY_TIME),
        )
        self.get_logger().info(f"recording {', '.join(self._topics)} to {self.output}")

    # --- public ---------------------------------------------------------------------------

    @property
    def counts(self) -> dict[str, int]:
        """Messages written per recorded topic (0 for a topic that sent none)."""
        return dict(self._counts)

    def summary(self) -> str:
        """'recorded N messages: /topic=n, ... -> FILE' (and messages lost in transport)."""
        if self._closed and not sum(self._counts.values()):
            return f"recorded nothing: {self.output} not written"
        per_topic = ", ".join(f"{t}={n}" for t, n in self._counts.items())
        text = f"recorded {sum(self._counts.values())} messages: {per_topic} -> {self.output}"
        if self.lost:
            text += "; LOST in transport: " + ", ".join(f"{t}={n}" for t, n in self.lost.items())
        return text

    @property
    def subscribed(self) -> list[str]:
        """The topics subscribed so far, in the order of their subscriptions (that in which
        an executor takes their messages when several are waiting)."""
        return list(self._subscriptions_by_topic)

    def take(self, topic: str) -> bool:
        """Record the next message waiting on `topic`'s subscription as the executor would
        deliver it, for a driver that steps the graph itself (`robot-calib simulate`);
        False if none is waiting or the topic is not subscribed."""
        subscription = self._subscriptions_by_topic.get(topic)
        if subscription is None:
            return False
        with subscription.handle:
            taken = subscription.handle.take_message(subscription.msg_type, True)
        if taken is None:
            return False
        self._on_message(topic, *taken)
        return True

    def close(self) -> None:
        """Stop recording and finalise the bag (summary, index). Idempotent; logs counts.
        A bag without a single message is removed (and said): it would only block a rerun
        with the same name."""
        if self._closed:
            return
        self._closed = True
        for subscription in self._subscriptions_by_topic.values():
            self.destroy_subscription(subscription)
        self._subscriptions_by_topic.clear()
        self._writer.close()
        if not sum(self._counts.values()):  # an empty bag says nothing and blocks a rerun
            Path(self.output).unlink(missing_ok=True)
            self.get_logger().warning(
                f"recorded nothing on {', '.join(self._topics)}: {self.output} not written"
            )
            return
        self.get_logger().info(self.summary())

    def destroy_node(self) -> None:
        """Finalise the bag, then destroy the node."""
        try:
            if hasattr(self, "_writer"):
                self.close()
        finally:
            super().destroy_node()

    # --- internals ------------------------------------------------------------------------

    def _subscribe(self, topic: str, type_name: str) -> None:
        try:
            msg_type = message_class(type_name)
        except InputError as exc:
            self.get_logger().error(f"{topic}: not recorded: {exc}")
            return
        self._types[topic] = type_name
        self._subscriptions_by_topic[topic] = self.create_subscription(
            msg_type,
            topic,
            partial(self._on_message, topic),  # two arguments: rclpy passes (data, MessageInfo)
            self._request_qos(topic),
            raw=True,
            event_callbacks=SubscriptionEventCallbacks(
                incompatible_qos=partial(self._on_incompatible_qos, topic),
                message_lost=partial(self._on_lost, topic),
            ),
        )

    def _on_incompatible_qos(self, topic: str, event: QoSRequestedIncompatibleQoSInfo) -> None:
        self.get_logger().warning(
            f"{topic}: a publisher's QoS is incompatible with the recorder's "
            f"request (policy {event.last_policy_kind}); its messages are not recorded"
        )

    def _on_lost(self, topic: str, event: Any) -> None:
        """The middleware reports messages lost on their way to the recorder."""
        self.lost[topic] = self.lost.get(topic, 0) + int(event.total_count_change)
        self.get_logger().warning(
            f"{topic}: {event.total_count_change} messages lost in transport "
            f"({self.lost[topic]} so far)"
        )

    def _request_qos(self, topic: str) -> QoSProfile:
        """RELIABLE/VOLATILE, KEEP_LAST qos_depth; adapted to the publishers already in the
        graph as rosbag2 does (best effort if any offers it, transient local if all do)."""
        offers = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
        reliability = ReliabilityPolicy.RELIABLE
        if offers and any(q.reliability != ReliabilityPolicy.RELIABLE for q in offers):
            reliability = ReliabilityPolicy.BEST_EFFORT
            self.get_logger().warning(f"{topic}: a publisher is best effort; so is the recorder")
        durability = DurabilityPolicy.VOLATILE
        if offers and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offers):
            durability = DurabilityPolicy.TRANSIENT_LOCAL
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=self.qos_depth,
            reliability=reliability,
            durability=durability,
        )

    def _on_message(self, topic: str, data: bytes, info: dict[str, Any]) -> None:
        if self._closed:
            return
        if self._use_sim_time:  # rosbag2 too records the node clock's time then
            received = self.get_clock().now().nanoseconds
        else:
            received = int(info.get("received_timestamp") or 0) or time.time_ns()
        try:
            if not self._writer.has_topic(topic):
                self._add_channel(topic)
            self._writer.write(
                topic,
                data,
                log_time_ns=received,
                publish_time_ns=received,
                sequence=int(info.get("publication_sequence_number") or 0),
            )
        except BagError as exc:
            self.get_logger().error(f"{topic}: message not recorded: {exc}")
            return
        self._counts[topic] += 1

    def _add_channel(self, topic: str) -> None:
        """Create the topic's channel with the publishers' offers as the graph shows them."""
        publishers = self.get_publishers_info_by_topic(topic)
        hashes = {str(info.topic_type_hash) for info in publishers} - {"INVALID"}
        if len(hashes) > 1:
            self.get_logger().warning(f"{topic}: publishers' type hashes differ: {hashes}")
        self._writer.add_topic(
            topic,
            self._types[topic],
            offered_qos=[qos_to_record(info.qos_profile) for info in publishers],
            # as rosbag2: the publishers' common hash, '' if they differ; if none reported
            # one, the installed type's (None: the writer looks it up)
            type_hash=hashes.pop() if len(hashes) == 1 else ("" if hashes else None),
        )

    def _on_timer(self) -> None:
        if self._closed:
            return
        try:
            self._writer.flush_stale()
        except BagError as exc:
            self.get_logger().error(in_ros_terms(exc))
        if self._pending:
            self._discover()

    def _discover(self) -> None:
        """Subscribe to pending topics whose type the graph now shows."""
        if not self._pending:
            return
        graph = dict(self.get_topic_names_and_types())
        for topic in list(self._pending):
            types = graph.get(topic)
            if not types:
                continue
            if len(types) > 1:
                self.get_logger().warning(f"{topic}: several types {types}; recording {types[0]}")
            self._pending.remove(topic)
            self._subscribe(topic, types[0])


def main(args: Sequence[str] | None = None) -> int:
    """`ros2 run robot_calib recorder --ros-args -p output:=FILE.mcap [-p topics:=[...]]`."""

    def stop(node: RecorderNode) -> None:
        node.close()
        print(node.summary(), flush=True)

    return run_node(RecorderNode, args, on_stop=stop, name="recorder")


if __name__ == "__main__":
    raise SystemExit(main())
