"""replay: publish a bag's messages again, raw CDR bytes, with the recorded timing.

Each topic gets a publisher of its recorded type, with the reliability and durability the
original publishers offered (from the bag's `offered_qos_profiles`; RELIABLE/VOLATILE if the
bag has none or they disagree) and KEEP_LAST `qos_depth`. Messages go out in file order
(the order the recorder received them), spaced by their log-time differences divided by
`rate`; `rate` <= 0 publishes as fast as possible. Topics and parameters: msgs_doc/replay.md.

Note: a burst larger than a subscriber's QoS depth is lost even with RELIABLE. For exact
copies in-process, set autoplay False and call `step()` in lockstep with the consumer.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator, Sequence
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from robot_calib.bag import BagMessage, BagReader, TopicInfo
from robot_calib.errors import InputError, RobotCalibError
from robot_calib.nodes._common import declare, message_class, overrides, run_node

DEFAULT_QOS_DEPTH = 1000
_BURST = 200  # messages per timer tick when rate <= 0
_RELIABILITY = {
    "reliable": ReliabilityPolicy.RELIABLE,
    "best_effort": ReliabilityPolicy.BEST_EFFORT,
}
_DURABILITY = {
    "volatile": DurabilityPolicy.VOLATILE,
    "transient_local": DurabilityPolicy.TRANSIENT_LOCAL,
}


def offered_qos(info: TopicInfo, depth: int) -> QoSProfile:
    """Publisher QoS for a recorded topic: the recorded offers' reliability and durability
    when they all agree (rosbag2's rule), else RELIABLE/VOLATILE; KEEP_LAST `depth`."""
    reliability, durability = ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE
    offers = {(q.reliability, q.durability) for q in info.offered_qos}
    if len(offers) == 1:
        recorded_reliability, recorded_durability = offers.pop()
        reliability = _RELIABILITY.get(recorded_reliability, reliability)
        durability = _DURABILITY.get(recorded_durability, durability)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=reliability,
        durability=durability,
    )


class ReplayNode(Node):
    """Publishes the messages of `bag`; `done` once all are out, `published` counts them.

    In-process: `ReplayNode(bag=path, rate=0.0, autoplay=False)` and `step()` per message,
    or autoplay (the default) paced by a timer once every publisher has
    `wait_for_subscribers` subscribers. Keyword values become parameter overrides (so do any
    `parameter_overrides`; keywords win). Raises InputError without `bag`, BagError for a
    bad bag file.
    """

    def __init__(
        self,
        bag: str | os.PathLike[str] | None = None,
        rate: float | None = None,
        topics: Sequence[str] | None = None,
        wait_for_subscribers: int | None = None,
        autoplay: bool | None = None,
        *,
        node_name: str = "replay",
        parameter_overrides: Sequence[Parameter] | None = None,
        **node_kwargs: Any,
    ) -> None:
        values = {
            "bag": None if bag is None else os.fspath(bag),
            "rate": None if rate is None else float(rate),
            "topics": None if topics is None else list(topics),
            "wait_for_subscribers": wait_for_subscribers,
            "autoplay": autoplay,
        }
        super().__init__(
            node_name,
            parameter_overrides=overrides(values, parameter_overrides),
            **node_kwargs,
        )
        try:
            self.bag: str = declare(self, "bag", "", "path of the .mcap bag to replay (required)")
            self.rate: float = declare(
                self,
                "rate",
                1.0,
                "time factor: 1.0 = recorded timing, 2.0 = twice as fast, <= 0 = at once",
            )
            wanted: list[str] = declare(
                self, "topics", [], "topics to replay (default: all topics of the bag)"
            )
            self.wait_for_subscribers: int = declare(
                self,
                "wait_for_subscribers",
                1,
                "start once every publisher has at least this many subscribers [count] (0: at "
                "once, whoever listens: messages sent before a reader is matched are lost)",
            )
            depth: int = declare(
                self, "qos_depth", DEFAULT_QOS_DEPTH, "history depth of each publisher [messages]"
            )
            self.autoplay: bool = declare(
                self, "autoplay", True, "publish on a timer; False: only `step()` publishes"
            )
            allow_truncated: bool = declare(
                self,
                "allow_truncated",
                False,
                "also replay a bag whose recorder was killed (its complete chunks)",
            )
            if not self.bag:
                raise InputError(
                    f"{self.get_name()}: parameter 'bag' (the .mcap path) is required"
                )
            if depth < 1:
                raise InputError(f"{self.get_name()}: parameter 'qos_depth' must be >= 1")
            self._reader = BagReader(self.bag, allow_truncated=allow_truncated)
        except RobotCalibError:
            super().destroy_node()
            raise
        missing = [t for t in wanted if t not in self._reader.topics]
        if missing:
            self.get_logger().warning(f"{self.bag}: has no topic {', '.join(missing)}")
        self._bag_publishers: dict[str, Publisher] = {}
        for name, info in self._reader.topics.items():
            if wanted and name not in wanted:
                continue
            try:
                msg_type = message_class(info.type_name)
            except InputError as exc:
                self.get_logger().error(f"{name}: not replayed: {exc}")
                continue
            self._bag_publishers[name] = self.create_publisher(
                msg_type, name, offered_qos(info, depth)
            )
        self.published: dict[str, int] = dict.fromkeys(self._bag_publishers, 0)
        self._messages: Iterator[BagMessage] = self._reader.messages(list(self._bag_publishers))
        self._next: BagMessage | None = next(self._messages, None)
        self._start_ns: int | None = None  # monotonic wall time of the first message
        self._first_log_ns = 0
        self.done = False
        if self._next is None:
            self._finish()
        if self.autoplay:
            self._tick_timer = self.create_timer(  # steady: paced on wall time, like `_tick`
                0.001 if self.rate <= 0 else 0.002,
                self._tick,
                clock=Clock(clock_type=ClockType.STEADY_TIME),
            )

    # --- public ---------------------------------------------------------------------------

    def ready(self) -> bool:
        """True if every publisher has at least `wait_for_subscribers` subscribers."""
        return all(
            pub.get_subscription_count() >= self.wait_for_subscribers
            for pub in self._bag_publishers.values()
        )

    def step(self) -> BagMessage | None:
        """Publish the next message now, whatever its time; None when all are out."""
        message = self._next
        if message is None:
            return None
        self._bag_publishers[message.topic].publish(message.data)
        self.published[message.topic] += 1
        self._next = next(self._messages, None)
        if self._next is None:
            self._finish()
        return message

    def summary(self) -> str:
        """'replayed N messages: /topic=n, ... from FILE'."""
        per_topic = "".join(
            f"{', ' if i else ': '}{t}={n}" for i, (t, n) in enumerate(self.published.items())
        )
        return f"replayed {sum(self.published.values())} messages{per_topic} from {self.bag}"

    def wait_for_acks(self, timeout_s: float = 1.0) -> bool:
        """Block until reliable subscribers acknowledged everything published (or timeout)."""
        return all(
            pub.wait_for_all_acked(Duration(nanoseconds=int(timeout_s * 1e9)))
            for pub in self._bag_publishers.values()
        )

    def destroy_node(self) -> None:
        if hasattr(self, "_reader"):
            self._reader.close()
        super().destroy_node()

    # --- internals ------------------------------------------------------------------------

    def _tick(self) -> None:
        if self.done or self._next is None:
            return
        if self._start_ns is None:
            if not self.ready():
                return
            self._start_ns = time.monotonic_ns()
            self._first_log_ns = self._next.log_time_ns
            self.get_logger().info(f"replaying {self.bag} at rate {self.rate}")
        if self.rate <= 0:
            for _ in range(_BURST):
                if self.step() is None:
                    return
            return
        now = time.monotonic_ns()
        while self._next is not None:
            due = self._start_ns + (self._next.log_time_ns - self._first_log_ns) / self.rate
            if due > now:
                return
            self.step()

    def _finish(self) -> None:
        self.done = True
        self.get_logger().info(self.summary())


def main(args: Sequence[str] | None = None) -> int:
    """`ros2 run robot_calib replay --ros-args -p bag:=FILE.mcap [-p rate:=1.0]`; exits when
    all messages are out and acknowledged by reliable subscribers (1 s at most)."""

    def stop(node: ReplayNode) -> None:
        node.wait_for_acks()
        print(node.summary(), flush=True)

    return run_node(ReplayNode, args, done=lambda node: node.done, on_stop=stop, name="replay")


if __name__ == "__main__":
    raise SystemExit(main())
