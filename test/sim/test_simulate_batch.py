"""`robot-calib simulate` in bursts: the batched tracker measures what the
streaming one measures, bit for bit; the CDR templates put on the wire the bytes rclpy's
own publishing does; the stepped graph records every pose with its receive time."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from robot_calib.bag.mcap_reader import BagReader
from robot_calib.messages import JOINT_STATES_TOPIC, POINT_TOPIC, stamp_to_ns
from robot_calib.sim import measure
from robot_calib.sim.measure import StreamingTracker, TrackerReading
from robot_calib.sim.world import World, build_world

WORLDS = {
    "default": {},
    "effects": {
        "effects": [
            {"name": "backlash", "joints": [2, 4]},
            {"name": "thermal_drift"},
            {"name": "eccentricity", "joints": [1, 2]},
        ]
    },
    "six_dof": {
        "seed": 3,
        "six_dof": {"first": [20.0, 35.0, -30.0]},
        "targets": {"smr2": [-0.04, 0.05, 0.03]},
    },
    "six_dof_alone": {"six_dof": {"first": [20.0, 35.0, -30.0]}},
    "dropouts": {
        "noise": {"anisotropic": True},
        "tracker": {"dropout_probability": 0.3},
        "targets": {"smr2": [-0.04, 0.05, 0.03]},
    },
    "references_reads_events": {
        "targets": {"smr2": [-0.04, 0.05, 0.03]},
        "references": {"r1": [0.6, 0.7, -0.1], "r2": [0.7, -0.6, -0.1]},
        "tracker": {
            "reads_per_pose": 3,
            "dropout_probability": 0.1,
            "drift_m_per_s": [1e-8, 0.0, 2e-9],
            "drift_rad_per_s": [0.0, 0.0, 5e-9],
        },
        "events": [
            {"kind": "robot", "poses": [30, 31], "offset_m": [0.002, 0.0, 0.0]},
            {"kind": "tracker", "poses": [150, 259], "offset_m": [0.0, 0.001, 0.0]},
        ],
    },
    "point_accuracy": {"noise": {"point_sigma_range_m": [5e-6, 60e-6]}},
}


def _readings(world: World, n: int, seed: int = 5) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    lo, hi = world.model.robot.limits.T
    q = rng.uniform(lo, hi, (n, world.model.robot.n_joints))
    q[10:20] = q[9]  # the robot holding still: directions kept
    stamps_ns = (1.79e18 + np.cumsum(rng.uniform(0.5e9, 2e9, n))).astype(np.int64)
    return q, stamps_ns


def _same(a: TrackerReading | None, b: TrackerReading | None) -> bool:
    return measure._same(a, b)


@pytest.mark.parametrize("name", list(WORLDS))
def test_batched_tracker_measures_what_the_streaming_one_does_bit_for_bit(name: str) -> None:
    world = build_world(WORLDS[name], name)
    q, stamps_ns = _readings(world, 260)
    one = StreamingTracker(world, np.random.default_rng(7))
    batch = StreamingTracker(world, np.random.default_rng(7))
    expected = [one.measure_all(q[k], int(stamps_ns[k]) * 1e-9) for k in range(len(q))]
    got: list[TrackerReading | None] = []
    for start in range(0, len(q), 100):  # bursts: the state carries over
        got += batch.measure_batch(q[start : start + 100], stamps_ns[start : start + 100] * 1e-9)
    assert batch._batch_ok is True
    assert all(_same(a, b) for a, b in zip(expected, got)), name
    assert batch.count == one.count
    assert batch.rng.bit_generator.state == one.rng.bit_generator.state
    assert np.array_equal(batch._direction, one._direction)  # type: ignore[arg-type]
    if name == "dropouts":
        assert sum(r is None for r in got) > 30


def test_a_batch_that_differs_falls_back_to_one_pose_at_a_time(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    world = build_world({}, "default")
    q, stamps_ns = _readings(world, 120)
    real = measure._target_points
    monkeypatch.setattr(measure, "_target_points", lambda *a: np.nextafter(real(*a), np.inf))
    one = StreamingTracker(world, np.random.default_rng(1))
    batch = StreamingTracker(world, np.random.default_rng(1))
    expected = [one.measure_all(q[k], int(stamps_ns[k]) * 1e-9) for k in range(len(q))]
    got = batch.measure_batch(q[:60], stamps_ns[:60] * 1e-9)
    got += batch.measure_batch(q[60:], stamps_ns[60:] * 1e-9)
    assert batch._batch_ok is False
    assert all(_same(a, b) for a, b in zip(expected, got))


def _received(context: Any, msg_type: type, sent: list[Any]) -> list[bytes]:  # noqa: ANN401
    """The raw bytes a subscriber receives of each of `sent` (messages or bytes)."""
    from rclpy.node import Node

    node = Node("cdr_check", context=context)
    try:
        publisher = node.create_publisher(msg_type, "/cdr_check", 10)
        subscription = node.create_subscription(msg_type, "/cdr_check", lambda _: None, 10)
        deadline = time.monotonic() + 5.0
        while publisher.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        for item in sent:
            publisher.publish(item)
        out: list[bytes] = []
        while time.monotonic() < deadline and len(out) < len(sent):
            taken = subscription.handle.take_message(msg_type, True)
            if taken is None:
                time.sleep(0.005)
                continue
            out.append(taken[0])
        return out
    finally:
        node.destroy_node()


def test_cdr_templates_send_the_bytes_of_rclpys_messages(context: Any) -> None:  # noqa: ANN401
    from geometry_msgs.msg import PointStamped
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    from robot_calib.nodes._cdr import (
        ClockEncoder,
        JointStateEncoder,
        PointStampedEncoder,
        decode_joint_state,
    )

    for names in (
        ["joint_a1", "joint_a2", "joint_a3", "joint_a4", "joint_a5", "joint_a6"],
        ["shoulder_pan_joint", "x", "elbow"],
    ):
        encoder = JointStateEncoder(names)
        positions = [0.1 * k - 0.3 for k in range(len(names))]
        msg = encoder.message(1_790_000_000, 123_456_789, positions)
        sent = encoder.encode(1_790_000_000, 123_456_789, positions)
        message, template = _received(context, JointState, [msg, sent])
        assert message == template == sent
        assert encoder.decode(sent) == (1_790_000_000, 123_456_789, tuple(positions))
        assert decode_joint_state(sent) == (1_790_000_000, 123_456_789, names, tuple(positions))
    other = JointStateEncoder(["a", "b"])
    assert other.decode(sent) is None  # another robot's names: not this template
    points = PointStampedEncoder("laser_tracker")
    msg = points.message(5, 6, 1.5, -2.25, 0.1)
    sent = points.encode(5, 6, 1.5, -2.25, 0.1)
    message, template = _received(context, PointStamped, [msg, sent])
    assert message == template == sent
    clock = ClockEncoder()
    msg, sent = clock.message(1_790_000_000, 7), clock.encode(1_790_000_000, 7)
    assert _received(context, Clock, [msg, sent]) == [sent, sent]


def test_the_stepped_graph_records_each_pose_at_its_own_time(tmp_path: Path) -> None:
    """Every joint state and point is recorded with the recorder's clock at its pose: log
    time = the joint state's stamp (the point's stamp precedes it by the latency)."""
    from rclpy.serialization import deserialize_message

    from robot_calib.nodes import simulate
    from robot_calib.nodes.simulate import simulate_bag

    bag = tmp_path / "bursts.mcap"
    burst = simulate.BURST
    simulate.BURST = 7  # several bursts, the last one short
    try:
        counts = simulate_bag(bag, "random", n_random=30)
    finally:
        simulate.BURST = burst
    assert counts == {JOINT_STATES_TOPIC: 30, POINT_TOPIC: 30}
    from geometry_msgs.msg import PointStamped
    from sensor_msgs.msg import JointState

    with BagReader(bag) as reader:
        messages = list(reader.messages())
    assert [m.topic for m in messages] == [JOINT_STATES_TOPIC, POINT_TOPIC] * 30
    for joint, point in zip(messages[::2], messages[1::2]):
        stamp = stamp_to_ns(deserialize_message(joint.data, JointState).header.stamp)
        point_stamp = stamp_to_ns(deserialize_message(point.data, PointStamped).header.stamp)
        assert joint.log_time_ns == point.log_time_ns == stamp
        assert 0 <= stamp - point_stamp <= 2_000_000
    assert [m.sequence for m in messages[::2]] == list(range(1, 31))
