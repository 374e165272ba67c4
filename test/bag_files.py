"""Bags of paired measurements written with our writer and rclpy's serialisation, for the
tests that read recordings."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from geometry_msgs.msg import PointStamped
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from robot_calib.bag import BagWriter

JS, PS = "/joint_states", "/laser_tracker/point"
JS_TYPE, PS_TYPE = "sensor_msgs/msg/JointState", "geometry_msgs/msg/PointStamped"
T0 = 1_700_000_000_000_000_000


def stamp_message(msg, ns: int) -> None:  # noqa: ANN001 - any stamped message
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(ns), 1_000_000_000)


def write_measurements(
    path: Path,
    q: np.ndarray,
    points: np.ndarray,
    *,
    point_offsets_s: np.ndarray | None = None,
    names: list[str] | None = None,
    js_type: str = JS_TYPE,
    topics: tuple[str, ...] = (JS, PS),
) -> None:
    """A bag with one JointState and one PointStamped per pose, 1 s apart; point i stamped
    point_offsets_s[i] after its joint state."""
    names = names or [f"joint_a{j}" for j in range(1, 7)]
    offsets = np.zeros(len(q)) if point_offsets_s is None else point_offsets_s
    with BagWriter(path, ros_distro="jazzy") as writer:
        for topic in topics:
            writer.add_topic(topic, js_type if topic == JS else PS_TYPE)
        for i, (qi, pi) in enumerate(zip(q, points)):
            t = T0 + i * 1_000_000_000
            js = JointState(name=names, position=[float(v) for v in qi])
            stamp_message(js, t)
            pt = PointStamped()
            pt.header.frame_id = "laser_tracker"
            pt.point.x, pt.point.y, pt.point.z = (float(v) for v in pi)
            stamp_message(pt, t + offsets[i] * 1e9)
            if JS in topics:
                writer.write(JS, serialize_message(pt if js_type == PS_TYPE else js), t)
            if PS in topics:
                writer.write(PS, serialize_message(pt), t + 1000)
