"""replay node through real rclpy: a recorded bag replayed into a new recorder gives the
same bag message for message; the time factor spaces messages as recorded; recorded QoS is
offered again; standalone it exits by itself when done."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from geometry_msgs.msg import PointStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from robot_calib.bag import BagReader, BagWriter, QosProfile
from robot_calib.errors import BagError, InputError
from robot_calib.nodes.recorder import RecorderNode
from robot_calib.nodes.replay import ReplayNode

JS, PS = "/joint_states", "/laser_tracker/point"
PS_TYPE = "geometry_msgs/msg/PointStamped"
REPO = Path(__file__).resolve().parents[2]
TIMEOUT_S = 20.0


def spin_until(executor: SingleThreadedExecutor, condition: Callable[[], bool]) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        executor.spin_once(timeout_sec=0.005)


def point(i: int) -> PointStamped:
    msg = PointStamped()
    msg.header.frame_id = "laser_tracker"
    msg.header.stamp.sec = 1000 + i
    msg.point.x = 0.5 + 1e-3 * i
    return msg


def record_live_bag(context: Context, path: Path, n: int) -> None:
    """n JointStates and n PointStamped from a publisher, recorded in lockstep."""
    source = Node("source", context=context)
    js_pub = source.create_publisher(JointState, JS, 10)
    ps_pub = source.create_publisher(PointStamped, PS, 10)
    recorder = RecorderNode(output=path, node_name="first_recorder", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(recorder)
    try:
        spin_until(
            executor, lambda: js_pub.get_subscription_count() and ps_pub.get_subscription_count()
        )
        for i in range(n):
            joint_state = JointState(name=[f"joint_a{j}" for j in range(1, 7)])
            joint_state.position = [1e-3 * i] * 6
            joint_state.header.stamp.sec = 1000 + i
            js_pub.publish(joint_state)
            ps_pub.publish(point(i))
            spin_until(executor, lambda i=i: sum(recorder.counts.values()) == 2 * (i + 1))
    finally:
        executor.shutdown()
        recorder.destroy_node()
        source.destroy_node()


def test_replay_into_a_recorder_copies_the_bag(context: Context, tmp_path: Path) -> None:
    first, second = tmp_path / "first.mcap", tmp_path / "second.mcap"
    n = 300
    record_live_bag(context, first, n)
    replay = ReplayNode(bag=first, rate=0.0, autoplay=False, context=context)
    recorder = RecorderNode(output=second, node_name="second_recorder", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(recorder)  # the replay node is stepped by hand, not spun
    try:
        replay.wait_for_subscribers = 1
        spin_until(executor, replay.ready)
        sent = 0
        while replay.step() is not None:  # lockstep: one message, then let it be recorded
            sent += 1
            spin_until(executor, lambda sent=sent: sum(recorder.counts.values()) == sent)
        assert replay.done and replay.step() is None
        assert replay.published == {JS: n, PS: n}
    finally:
        executor.shutdown()
        recorder.destroy_node()
        replay.destroy_node()

    with BagReader(first) as a, BagReader(second) as b:
        assert a.counts == b.counts == {JS: n, PS: n}
        assert {t: i.type_name for t, i in a.topics.items()} == {
            t: i.type_name for t, i in b.topics.items()
        }
        for topic in (JS, PS):  # same raw CDR bytes, same order per topic
            original = [m.data for m in a.messages([topic])]
            copy = [m.data for m in b.messages([topic])]
            assert copy == original
        assert [m.topic for m in b.messages()] == [m.topic for m in a.messages()]
        assert b.topics[PS].offered_qos[0].reliability == "reliable"  # replay offered it


def test_replay_keeps_the_recorded_timing(context: Context, tmp_path: Path) -> None:
    """20 messages 10 ms apart at rate 1.0 take at least ~0.19 s to go out."""
    bag = tmp_path / "spaced.mcap"
    n, spacing_ns = 20, 10_000_000
    with BagWriter(bag) as writer:
        writer.add_topic(PS, PS_TYPE)
        for i in range(n):
            writer.write(
                PS, serialize_message(point(i)), 1_700_000_000_000_000_000 + i * spacing_ns
            )
    replay = ReplayNode(bag=bag, rate=1.0, wait_for_subscribers=1, context=context)
    recorder = RecorderNode(output=tmp_path / "out.mcap", topics=[PS], context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(replay)
    executor.add_node(recorder)
    try:
        spin_until(executor, lambda: replay.published[PS] > 0)  # started once subscribed
        started = time.monotonic()
        spin_until(executor, lambda: replay.done and recorder.counts[PS] == n)
        elapsed = time.monotonic() - started
    finally:
        executor.shutdown()
        recorder.destroy_node()
        replay.destroy_node()
    assert elapsed >= 0.15
    with BagReader(tmp_path / "out.mcap") as reader:
        xs = [m.decode().point.x for m in reader.messages()]
    assert xs == pytest.approx([0.5 + 1e-3 * i for i in range(n)])


def test_replay_offers_the_recorded_qos(context: Context, tmp_path: Path) -> None:
    bag = tmp_path / "latched.mcap"
    offer = QosProfile(reliability="best_effort", durability="transient_local")
    with BagWriter(bag) as writer:
        writer.add_topic(PS, PS_TYPE, offered_qos=[offer])
        writer.add_topic("/other", PS_TYPE)  # nothing recorded: RELIABLE/VOLATILE
        writer.write(PS, serialize_message(point(0)), 1)
    replay = ReplayNode(bag=bag, autoplay=False, context=context)
    try:
        observer = Node("observer", context=context)
        offers = {
            topic: observer.get_publishers_info_by_topic(topic)[0].qos_profile
            for topic in (PS, "/other")
        }
        observer.destroy_node()
    finally:
        replay.destroy_node()
    assert offers[PS].reliability == ReliabilityPolicy.BEST_EFFORT
    assert offers[PS].durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert offers["/other"].reliability == ReliabilityPolicy.RELIABLE
    assert offers["/other"].durability == DurabilityPolicy.VOLATILE


def test_replay_rejects_missing_or_bad_bags(context: Context, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="bag"):
        ReplayNode(context=context)
    with pytest.raises(BagError, match="cannot open") as error:
        ReplayNode(bag=tmp_path / "nope.mcap", context=context)
    assert "nope.mcap" in str(error.value)
    text = tmp_path / "notes.mcap"
    text.write_text("not a bag\n")
    with pytest.raises(BagError, match="not an MCAP file"):
        ReplayNode(bag=text, context=context)


def test_replay_process_exits_when_done(context: Context, tmp_path: Path) -> None:
    bag = tmp_path / "short.mcap"
    n = 50
    with BagWriter(bag) as writer:
        writer.add_topic(PS, PS_TYPE)
        for i in range(n):
            writer.write(PS, serialize_message(point(i)), 1_700_000_000_000_000_000 + i * 1000)
    recorder = RecorderNode(output=tmp_path / "copy.mcap", topics=[PS], context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(recorder)
    command = [sys.executable, "-m", "robot_calib.nodes.replay", "--ros-args"]
    command += ["-p", f"bag:={bag}", "-p", "rate:=0.0", "-p", "wait_for_subscribers:=1"]
    proc = subprocess.Popen(
        command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        spin_until(executor, lambda: recorder.counts[PS] == n or proc.poll() is not None)
        stdout, stderr = proc.communicate(timeout=TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        executor.shutdown()
        recorder.destroy_node()
    assert proc.returncode == 0, stderr
    assert f"replayed {n} messages: {PS}={n}" in stdout
    assert recorder.counts[PS] == n
