"""recorder node through real rclpy: in-process with an executor, and as a process stopped by
SIGINT, SIGTERM, SIGHUP and SIGKILL. Bags land in tmp_path and are read back by our reader, by
mcap_ros2 (via BagMessage.decode) and by rosbags. The ROS domain is the test process's own
(conftest.py); the recorder process inherits it."""

from __future__ import annotations

import signal
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from geometry_msgs.msg import PointStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from recorder_process import (
    JS,
    PS,
    TIMEOUT_S,
    joint_state,
    point,
    publish_to_process,
    readable,
    start_recorder,
    stop,
    wait_until,
)
from rosbags.rosbag2.storage_mcap import McapReader as RosbagsMcapReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from robot_calib.bag import BagReader
from robot_calib.errors import BagError, InputError
from robot_calib.nodes.recorder import RecorderNode


def spin_until(executor: SingleThreadedExecutor, condition: Callable[[], bool]) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        executor.spin_once(timeout_sec=0.01)


def rosbags_messages(path: Path) -> list[tuple[str, object]]:
    """(topic, message) of a bare .mcap file, decoded by rosbags with the bag's own schemas."""
    storage = RosbagsMcapReader(path)
    storage.open()
    try:
        typestore = get_typestore(Stores.EMPTY)
        for connection in storage.connections:
            typestore.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        return [
            (c.topic, typestore.deserialize_cdr(bytes(data), c.msgtype))
            for c, _, data in storage.messages(storage.connections)
        ]
    finally:
        storage.close()


def test_recorder_in_process_records_every_message(context: Context, tmp_path: Path) -> None:
    output = tmp_path / "in_process.mcap"
    source = Node("source", context=context)
    js_pub = source.create_publisher(JointState, JS, 10)
    ps_pub = source.create_publisher(PointStamped, PS, 10)
    recorder = RecorderNode(output=output, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(source)
    executor.add_node(recorder)
    try:
        spin_until(
            executor, lambda: js_pub.get_subscription_count() and ps_pub.get_subscription_count()
        )
        n = 500
        for i in range(n):  # lockstep: each pair is taken before the next is published
            js_pub.publish(joint_state(i))
            ps_pub.publish(point(i))
            spin_until(executor, lambda i=i: sum(recorder.counts.values()) == 2 * (i + 1))
        assert recorder.counts == {JS: n, PS: n}
        recorder.close()
        recorder.close()  # idempotent
        assert output.exists()
    finally:
        executor.shutdown()
        recorder.destroy_node()
        source.destroy_node()

    with BagReader(output) as reader:
        assert reader.complete and reader.has_summary
        assert reader.counts == {JS: n, PS: n}
        assert reader.topics[JS].type_name == "sensor_msgs/msg/JointState"
        assert reader.topics[PS].type_name == "geometry_msgs/msg/PointStamped"
        offered = reader.topics[JS].offered_qos  # what the source's publisher offered
        assert [(q.reliability, q.durability) for q in offered] == [("reliable", "volatile")]
        assert reader.topics[JS].type_hash.startswith("RIHS01_")
        messages = list(reader.messages())
    joint_states = [m.decode() for m in messages if m.topic == JS]
    assert [m.header.stamp.sec for m in joint_states] == [1000 + i for i in range(n)]
    assert list(joint_states[123].position) == pytest.approx(joint_state(123).position)
    times = [m.log_time_ns for m in messages]
    assert times[0] > 1.6e18 and all(m.publish_time_ns == m.log_time_ns for m in messages)

    by_rosbags = rosbags_messages(output)
    assert len(by_rosbags) == 2 * n
    points = [m for topic, m in by_rosbags if topic == PS]
    assert [p.point.x for p in points] == pytest.approx([0.5 + 1e-3 * i for i in range(n)])


def test_recorder_takes_other_topic_types_from_the_graph(context: Context, tmp_path: Path) -> None:
    output = tmp_path / "chatter.mcap"
    source = Node("talker", context=context)
    publisher = source.create_publisher(String, "/chatter", 10)
    recorder = RecorderNode(output=output, topics=["/chatter", JS], context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(source)
    executor.add_node(recorder)
    try:
        spin_until(executor, lambda: publisher.get_subscription_count() > 0)  # timer found it
        for i in range(5):
            publisher.publish(String(data=f"hello {i}"))
            spin_until(executor, lambda i=i: recorder.counts["/chatter"] == i + 1)
        assert recorder.counts == {"/chatter": 5, JS: 0}
    finally:
        executor.shutdown()
        recorder.destroy_node()  # finalises the bag too
        source.destroy_node()
    with BagReader(output) as reader:
        assert reader.topics["/chatter"].type_name == "std_msgs/msg/String"
        assert [m.decode().data for m in reader.messages()] == [f"hello {i}" for i in range(5)]
        assert JS not in reader.topics  # a channel appears with its first message


def test_recorder_on_sim_time_logs_the_node_clock(context: Context, tmp_path: Path) -> None:
    """With use_sim_time the log time is the node clock's (/clock) time, as in rosbag2."""
    output = tmp_path / "sim_time.mcap"
    source = Node("sim", context=context)
    clock_pub = source.create_publisher(ClockMsg, "/clock", 10)
    ps_pub = source.create_publisher(PointStamped, PS, 10)
    recorder = RecorderNode(
        output=output,
        topics=[PS],
        parameter_overrides=[Parameter("use_sim_time", value=True)],
        context=context,
    )
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(recorder)
    sim_ns = 42_000_000_123
    try:
        spin_until(
            executor,
            lambda: clock_pub.get_subscription_count() and ps_pub.get_subscription_count(),
        )
        clock = ClockMsg()
        clock.clock.sec, clock.clock.nanosec = divmod(sim_ns, 1_000_000_000)
        clock_pub.publish(clock)
        spin_until(executor, lambda: recorder.get_clock().now().nanoseconds == sim_ns)
        ps_pub.publish(point(0))
        spin_until(executor, lambda: recorder.counts[PS] == 1)
    finally:
        executor.shutdown()
        recorder.destroy_node()
        source.destroy_node()
    with BagReader(output) as reader:
        [message] = list(reader.messages())
    assert message.log_time_ns == message.publish_time_ns == sim_ns


def test_recorder_refuses_missing_or_existing_output(context: Context, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="output"):
        RecorderNode(context=context)
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"precious")
    with pytest.raises(BagError, match="already exists") as error:
        RecorderNode(output=existing, context=context)
    assert str(existing) in str(error.value)
    assert existing.read_bytes() == b"precious"


# --- the recorder as a process ----------------------------------------------------------------


@pytest.fixture
def source(context: Context) -> Iterator[Node]:
    node = Node("source", context=context)
    yield node
    node.destroy_node()


def test_recorder_process_refuses_an_existing_file(tmp_path: Path) -> None:
    existing = tmp_path / "taken.mcap"
    existing.write_bytes(b"precious")
    proc = start_recorder(existing)
    stdout, stderr = proc.communicate(timeout=TIMEOUT_S)
    assert proc.returncode == 2
    assert stderr.strip() == f"recorder: error: {existing}: already exists; not overwriting it"
    assert existing.read_bytes() == b"precious"


@pytest.mark.parametrize(
    "signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["SIGINT", "SIGTERM", "SIGHUP"]
)
@pytest.mark.slow
def test_recorder_process_finalises_bag_on_signal(
    source: Node, tmp_path: Path, signum: int
) -> None:
    output = tmp_path / "signalled.mcap"
    proc = start_recorder(output, "max_chunk_age:=0.1")
    n = 400
    try:
        publish_to_process(source, proc, n)
        wait_until(lambda: readable(output) == 2 * n, "the recorder to write all messages")
    finally:
        stdout, stderr = stop(proc, signum)
    assert proc.returncode == 0, stderr
    assert f"recorded {2 * n} messages: {JS}={n}, {PS}={n}" in stdout
    with BagReader(output) as reader:  # strict: footer and summary must be there
        assert reader.complete and reader.has_summary
        assert reader.counts == {JS: n, PS: n}
        stamps = [m.decode().header.stamp.sec for m in reader.messages([JS])]
    assert stamps == [1000 + i for i in range(n)]


def test_killed_recorder_loses_at_most_the_open_chunk(source: Node, tmp_path: Path) -> None:
    """SIGKILL: no summary, but every message of every closed chunk reads back, in order.
    The chunk age limit is off (100 s), so the open chunk (16 KiB, fewer than 100 messages
    of ~200 bytes) is all that may be lost."""
    output = tmp_path / "killed.mcap"
    proc = start_recorder(output, "chunk_size:=16384", "max_chunk_age:=100.0")
    n = 1000
    try:
        publish_to_process(source, proc, n)
        wait_until(lambda: readable(output) >= 2 * n - 100, "the recorder to close chunks")
        before_kill = readable(output)
    finally:
        stdout, _ = stop(proc, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL and "recorded" not in stdout
    with pytest.raises(BagError, match="truncated"):
        BagReader(output)
    with BagReader(output, allow_truncated=True) as reader:
        assert not reader.complete
        stamps = {t: [m.decode().header.stamp.sec for m in reader.messages([t])] for t in (JS, PS)}
    got = len(stamps[JS]) + len(stamps[PS])
    assert got >= before_kill >= 2 * n - 100  # many chunks closed; at most the open one lost
    for topic in (JS, PS):  # what survived is a gap-free prefix of what was sent
        assert stamps[topic] == [1000 + i for i in range(len(stamps[topic]))]


def test_killed_recorder_keeps_chunks_closed_by_age(source: Node, tmp_path: Path) -> None:
    """With max_chunk_age 0.2 s the recorder's timer writes out a quiet open chunk (here the
    only one), so a kill after that loses nothing."""
    output = tmp_path / "aged.mcap"
    proc = start_recorder(output, "max_chunk_age:=0.2")  # 40 messages: far below a chunk
    n = 20
    try:
        publish_to_process(source, proc, n)
        wait_until(lambda: readable(output) == 2 * n, "the open chunk to be written out")
    finally:
        stop(proc, signal.SIGKILL)
    with BagReader(output, allow_truncated=True) as reader:
        assert not reader.complete
        assert reader.counts == {JS: n, PS: n}
