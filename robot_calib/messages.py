"""Conversions between the contract's messages and arrays (CONTRACT.md section 1).

Duck-typed on field names, so they serve rclpy messages and messages decoded from a bag
(mcap_ros2) alike; no ROS import here.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array

JOINT_STATES_TOPIC = "/joint_states"
POINT_TOPIC = "/laser_tracker/point"
TRACKER_FRAME = "laser_tracker"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
POINT_TYPE = "geometry_msgs/msg/PointStamped"
TARGET_TOPIC = re.compile(r"/laser_tracker/([A-Za-z][A-Za-z0-9_]*)/point")


def target_topic(name: str) -> str:
    """The topic of target `name` ('' = the contract's POINT_TOPIC; msgs_doc/targets.md)."""
    return POINT_TOPIC if not name else f"/laser_tracker/{name}/point"


def target_topic_name(topic: str) -> str | None:
    """The target name of a further target's topic /laser_tracker/NAME/point, else None."""
    match = TARGET_TOPIC.fullmatch(topic)
    return match.group(1) if match else None


def stamp_to_ns(stamp: Any) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_sec_nanosec(ns: int) -> tuple[int, int]:
    """Integer nanoseconds -> (sec, nanosec) of builtin_interfaces/Time."""
    return ns // 1_000_000_000, ns % 1_000_000_000


def joint_positions(
    msg: Any, joint_names: tuple[str, ...], where: str = JOINT_STATES_TOPIC
) -> Array:
    """Readings (J,) [rad] of `joint_names` from a JointState (matched by name, any order)."""
    names = list(msg.name)
    missing = [n for n in joint_names if n not in names]
    if missing:
        what = (
            f"are not the robot's joints {list(joint_names)}"
            if len(missing) == len(joint_names)
            else f"lack the robot's joints {missing} (robot: {list(joint_names)})"
        )
        raise InputError(
            f"{where}: JointState names {names} {what}; map them with --joint-names "
            f"NAME1,...,NAME{len(joint_names)} (node parameter joint_names): the message's "
            f"names of joints 1..{len(joint_names)} in order"
        )
    if len(msg.position) != len(names):
        raise InputError(
            f"{where}: JointState has {len(names)} names but {len(msg.position)} positions"
        )
    q = np.array([msg.position[names.index(n)] for n in joint_names], dtype=float)
    if not np.all(np.isfinite(q)):
        raise InputError(f"{where}: JointState positions not finite: {q.tolist()}")
    return q


def velocity_signs(msg: Any, joint_names: tuple[str, ...]) -> Array:
    """Signs (J,) of a JointState's velocities of `joint_names` (matched by name); zeros
    (unknown) where the message has no velocity per joint."""
    if len(msg.velocity) != len(msg.name):
        return np.zeros(len(joint_names))
    names = list(msg.name)
    return np.sign([float(msg.velocity[names.index(n)]) for n in joint_names])
