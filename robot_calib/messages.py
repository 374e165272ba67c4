"""Conversions between the contract's messages and arrays (msgs_doc/specification.md section 1).

Duck-typed on field names, so they serve rclpy messages and messages decoded from a bag
(mcap_ros2) alike; no ROS import here. Quaternions go through scipy's `Rotation`.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from robot_calib.errors import InputError, param
from robot_calib.kinematics.frames import Array

JOINT_STATES_TOPIC = "/joint_states"
POINT_TOPIC = "/laser_tracker/point"
TRACKER_FRAME = "laser_tracker"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
POINT_TYPE = "geometry_msgs/msg/PointStamped"
TARGET_TOPIC = re.compile(r"/laser_tracker/([A-Za-z][A-Za-z0-9_]*)/point")
TEMPERATURE_TOPIC = "/temperature"  # side data (msgs_doc/temperature.md)
TEMPERATURE_TYPE = "sensor_msgs/msg/Temperature"
# 6-DoF probes (msgs_doc/six_dof.md): a pose topic beside a target's point topic
POSE_TOPIC = "/laser_tracker/pose"
POSE_TYPE = "geometry_msgs/msg/PoseStamped"
POSE_COV_TYPE = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE_TYPES = (POSE_TYPE, POSE_COV_TYPE)
TARGET_POSE_TOPIC = re.compile(r"/laser_tracker/(?:([A-Za-z][A-Za-z0-9_]*)/)?pose")
# reference reflectors fixed off the robot, read with the poses (msgs_doc/references.md)
REFERENCE_TOPIC = re.compile(r"/laser_tracker/reference/([A-Za-z][A-Za-z0-9_]*)/point")
QUATERNION_TOLERANCE = 1e-3  # |q| - 1 beyond this is no rotation (a column mix-up)


def target_topic(name: str) -> str:
    """The topic of target `name` ('' = the contract's POINT_TOPIC; msgs_doc/targets.md)."""
    return POINT_TOPIC if not name else f"/laser_tracker/{name}/point"


def target_topic_name(topic: str) -> str | None:
    """The target name of a further target's topic /laser_tracker/NAME/point, else None."""
    match = TARGET_TOPIC.fullmatch(topic)
    return match.group(1) if match else None


def reference_topic(name: str) -> str:
    """The topic of reference reflector `name` (msgs_doc/references.md)."""
    return f"/laser_tracker/reference/{name}/point"


def reference_topic_name(topic: str) -> str | None:
    """The reflector name of a reference topic /laser_tracker/reference/NAME/point, else
    None."""
    match = REFERENCE_TOPIC.fullmatch(topic)
    return match.group(1) if match else None


def pose_topic(name: str) -> str:
    """The 6-DoF topic of target `name` ('' = POSE_TOPIC, else /laser_tracker/NAME/pose)."""
    return POSE_TOPIC if not name else f"/laser_tracker/{name}/pose"


def pose_topic_name(topic: str) -> str | None:
    """The target name of a 6-DoF topic ('' for POSE_TOPIC), None for any other topic."""
    match = TARGET_POSE_TOPIC.fullmatch(topic)
    return None if match is None else match.group(1) or ""


def pose_measurement(msg: Any, where: str) -> tuple[Array, Array, Array]:
    """A PoseStamped or PoseWithCovarianceStamped of a 6-DoF probe -> position (3,) [m],
    orientation (3, 3) in the tracker frame (NaN when the covariance marks it not measured:
    a negative rotation variance) and stated standard deviations (2,) [m, rad] (NaN: not
    stated, i.e. no covariance or a zero one). InputError naming `where` when the
    quaternion is not a unit one."""
    pose = msg.pose.pose if hasattr(msg.pose, "covariance") else msg.pose
    p = np.array([pose.position.x, pose.position.y, pose.position.z], dtype=float)
    o = pose.orientation
    quat = np.array([o.x, o.y, o.z, o.w], dtype=float)
    sigma = np.full(2, np.nan)
    measured = True
    if hasattr(msg.pose, "covariance"):
        diag = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6).diagonal()
        if not np.all(np.isfinite(diag)):
            raise InputError(f"{where}: covariance diagonal not finite: {diag.tolist()}")
        if np.any(diag[:3] > 0) and not np.all(diag[:3] > 0):
            raise InputError(
                f"{where}: position variances {diag[:3].tolist()} partly zero: all three "
                "stated (> 0) or none (0)"
            )
        if np.all(diag[:3] > 0):
            sigma[0] = np.sqrt(diag[:3].mean())
        measured = not np.any(diag[3:] < 0)
        if measured and np.all(diag[3:] > 0):
            sigma[1] = np.sqrt(diag[3:].mean())
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(quat))):
        raise InputError(f"{where}: pose not finite: {p.tolist()} {quat.tolist()}")
    if not measured:
        return p, np.full((3, 3), np.nan), sigma
    from scipy.spatial.transform import Rotation  # scipy only where poses are read

    if abs(np.linalg.norm(quat) - 1.0) > QUATERNION_TOLERANCE:
        raise InputError(
            f"{where}: orientation quaternion (x, y, z, w) {quat.tolist()} has norm "
            f"{np.linalg.norm(quat):.6g}, not 1"
        )
    return p, Rotation.from_quat(quat).as_matrix(), sigma


def orientation_quaternion(rotation: Array) -> tuple[float, float, float, float]:
    """A `geometry_msgs/Quaternion`'s (x, y, z, w) of a probe frame rotation (3, 3) (the
    reading of `pose_measurement`); the identity (0, 0, 0, 1) where it is NaN (not
    measured: the covariance says so)."""
    if not np.all(np.isfinite(rotation)):
        return 0.0, 0.0, 0.0, 1.0
    from scipy.spatial.transform import Rotation  # scipy only where poses are written

    x, y, z, w = (float(v) for v in Rotation.from_matrix(rotation).as_quat())
    return x, y, z, w


def pose_covariance(sigma: Array, oriented: bool) -> list[float]:
    """The 36 covariance entries (row-major x, y, z, rot x, rot y, rot z) of stated
    standard deviations sigma (2,) [m, rad] (NaN: not stated -> 0); rotation variances -1
    when the orientation was not measured (`pose_measurement`'s reading)."""
    cov = np.zeros((6, 6))
    position, rotation = (0.0 if not np.isfinite(v) else float(v) ** 2 for v in sigma)
    cov[range(3), range(3)] = position
    cov[range(3, 6), range(3, 6)] = rotation if oriented else -1.0
    return [float(v) for v in cov.reshape(-1)]


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
        from robot_calib.kinematics.description import robots_with_joint_names

        what = (
            f"are not the robot's joints {list(joint_names)}"
            if len(missing) == len(joint_names)
            else f"lack the robot's joints {missing} (robot: {list(joint_names)})"
        )
        robots = robots_with_joint_names(names)  # a wrong robot is likelier than renaming
        other = (
            f"they are the joints of built-in robot{'s' if len(robots) > 1 else ''} "
            f"{', '.join(robots)}: give {param('robot', robots[0])}"
            f"{' (or another of them)' if len(robots) > 1 else ''}, or "
            if robots
            else ""
        )
        raise InputError(
            f"{where}: JointState names {names} {what}; {other}map them with "
            f"{param('joint_names', f'NAME1,...,NAME{len(joint_names)}')}: the message's "
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
