"""Measurements as arrays -> a bag of the contract: one JointState and one PointStamped per
pose (and what a pose may carry besides: a temperature, further targets' points, a 6-DoF
probe's pose), CDR-serialised and written through `BagWriter`; also a stream's bag
(msgs_doc/specification.md, msgs_doc/stream.md). `import` writes its CSV rows with it
(`csv_import`), `split` its two halves, the simulation of a stream its stream.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from robot_calib.atomic import staged_outputs
from robot_calib.bag.mcap_writer import BagWriter
from robot_calib.bag.ros2_formats import typestore
from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.messages import (
    JOINT_STATE_TYPE,
    JOINT_STATES_TOPIC,
    POINT_TOPIC,
    POINT_TYPE,
    POSE_COV_TYPE,
    POSE_TYPE,
    TEMPERATURE_TOPIC,
    TEMPERATURE_TYPE,
    TRACKER_FRAME,
    ns_to_sec_nanosec,
    pose_covariance,
    pose_topic,
    reference_topic,
    target_topic,
)

START_NS = 1_700_000_000_000_000_000  # stamp of the first pose when no time is given
STEP_NS = 1_000_000_000
# a time column whose first value is at least this [s] (March 1973 on) is absolute time,
# Unix epoch seconds: written as it is (two halves of one file keep their own stamps)
EPOCH_MIN_S = 1e8


SixDof = tuple[Array, Array]  # rotation (n, 3, 3) and sigma (n, 2) [m, rad] of one target


def write_measurement_bag(
    output: str | Path,
    q: Array,
    points: Array,
    joint_names: tuple[str, ...],
    time: Array | None = None,
    force: bool = False,
    direction: Array | None = None,
    temperature: Array | None = None,
    extra_points: Mapping[str, Array] | None = None,
    six_dof: Mapping[str, SixDof] | None = None,
    references: Mapping[str, Array] | None = None,
) -> dict[str, int]:
    """A contract bag: one JointState and one PointStamped per pose, stamped in row order
    (`time` [s]: absolute Unix time from EPOCH_MIN_S on, else from the first pose; without
    `time` 1 s apart; see `write_measurements`). Written
    under a temporary name and moved in when complete (an existing `output` is replaced
    only with `force`): a failure or Ctrl-C leaves nothing. Returns messages per topic."""
    output = Path(output)
    if time is None:
        start, offsets = START_NS, np.arange(len(q)) * STEP_NS
    elif len(time) and time[0] >= EPOCH_MIN_S:  # absolute Unix time: as it is
        start, offsets = 0, np.round(np.asarray(time) * 1e9).astype(np.int64)
    else:
        start, offsets = START_NS, np.round((time - time[0]) * 1e9).astype(np.int64)
    if np.any(np.diff(offsets) <= 0):
        raise InputError("time column must increase from row to row")
    with staged_outputs(output.parent, force) as stage:
        return write_measurements(
            stage / output.name,
            q,
            points,
            joint_names,
            start + offsets,
            direction,
            temperature,
            extra_points,
            six_dof,
            references,
        )


def write_measurements(
    path: Path,
    q: Array,
    points: Array,
    joint_names: tuple[str, ...],
    stamps_ns: IntArray,
    direction: Array | None = None,
    temperature: Array | None = None,
    extra_points: Mapping[str, Array] | None = None,
    six_dof: Mapping[str, SixDof] | None = None,
    references: Mapping[str, Array] | None = None,
) -> dict[str, int]:
    """Write a contract bag at `path` directly (callers stage it): per pose i a JointState
    (readings q (n, J) [rad] of `joint_names`) and a PointStamped (points (n, 3) [m],
    tracker frame), both stamped stamps_ns[i] [ns] (non-decreasing). `direction` (n, J)
    +1/-1: each joint's approach direction, written as the sign of the JointState velocity
    (the contract's direct form), so that a subset of poses keeps the directions they were
    measured with. `temperature` (n,) [deg C]: a sensor_msgs/Temperature per pose on
    TEMPERATURE_TOPIC, stamped as the pose (side data, msgs_doc/temperature.md; NaN: none
    at that pose).
    `extra_points` {NAME: (n, 3) [m]}: further targets measured at the same poses, each on
    /laser_tracker/NAME/point stamped as its pose (a NaN row: not measured at that pose;
    msgs_doc/targets.md). `six_dof` {NAME: (rotation (n, 3, 3), sigma (n, 2))}: what a 6-DoF
    probe measured at target NAME besides its point, written beside the point as a pose on
    /laser_tracker/(NAME/)pose: a PoseWithCovarianceStamped where standard deviations are
    stated, else a PoseStamped (msgs_doc/six_dof.md). `references` {NAME: (n, 3) [m]}: the
    reference reflectors read at each pose as read (the tracker's drift in them), each on
    /laser_tracker/reference/NAME/point stamped as its pose (msgs_doc/references.md).
    Returns messages per topic."""
    if len(joint_names) != q.shape[1]:
        raise InputError(f"{q.shape[1]} joint columns for a robot with {len(joint_names)} joints")
    store = typestore(JOINT_STATE_TYPE, POINT_TYPE, TEMPERATURE_TYPE, POSE_TYPE, POSE_COV_TYPE)
    types = store.types
    poses = _pose_writers(store, six_dof or {})
    with BagWriter(path) as writer:
        writer.add_topic(JOINT_STATES_TOPIC, JOINT_STATE_TYPE)
        writer.add_topic(POINT_TOPIC, POINT_TYPE)
        if temperature is not None:
            writer.add_topic(TEMPERATURE_TOPIC, TEMPERATURE_TYPE)
        extra = {  # a target never measured here gets no topic (an empty one says nothing)
            target_topic(k): np.asarray(v, dtype=float)
            for k, v in (extra_points or {}).items()
            if np.isfinite(v).all(axis=1).any()
        } | {reference_topic(k): np.asarray(v, dtype=float) for k, v in (references or {}).items()}
        for topic in extra:
            writer.add_topic(topic, POINT_TYPE)
        for pose in poses:
            writer.add_topic(pose.topic, pose.type_name)
        velocities = np.zeros((len(q), 0)) if direction is None else np.asarray(direction)
        for k, (qi, pi, stamp_ns, vi) in enumerate(zip(q, points, stamps_ns, velocities)):
            stamp = types["builtin_interfaces/msg/Time"](*ns_to_sec_nanosec(int(stamp_ns)))
            serialized = joint_state_cdr(store, int(stamp_ns), joint_names, qi, vi)
            writer.write(JOINT_STATES_TOPIC, serialized, int(stamp_ns))
            for topic, xyz in ((POINT_TOPIC, pi), *((t, v[k]) for t, v in extra.items())):
                if not np.all(np.isfinite(xyz)):
                    continue  # this target not measured at this pose
                writer.write(topic, point_cdr(store, int(stamp_ns), xyz), int(stamp_ns) + 1)
            for pose in poses:
                xyz = points[k] if not pose.name else extra_points_of(extra_points, pose.name, k)
                pose_cdr = pose.serialize(k, xyz, stamp)
                if pose_cdr is not None:
                    writer.write(pose.topic, pose_cdr, int(stamp_ns) + 1)
            if temperature is not None and np.isfinite(temperature[k]):  # side data
                msg = types[TEMPERATURE_TYPE](
                    header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
                    temperature=float(temperature[k]),
                    variance=0.0,
                )
                temperature_cdr = store.serialize_cdr(msg, TEMPERATURE_TYPE)
                writer.write(TEMPERATURE_TOPIC, temperature_cdr, int(stamp_ns) + 2)
        writer.close()
        return writer.counts


def joint_state_cdr(
    store: Any, stamp_ns: int, joint_names: tuple[str, ...], q: Array, velocity: Array
) -> bytes:
    """A sensor_msgs/JointState as CDR bytes: readings q (J,) [rad] of `joint_names`,
    `velocity` (J,) [rad/s] (or its signs; empty: none), stamped stamp_ns [ns]."""
    types = store.types
    stamp = types["builtin_interfaces/msg/Time"](*ns_to_sec_nanosec(stamp_ns))
    js = types[JOINT_STATE_TYPE](
        header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
        name=list(joint_names),
        position=np.asarray(q, dtype=float),
        velocity=np.asarray(velocity, dtype=float),
        effort=np.empty(0),
    )
    return bytes(store.serialize_cdr(js, JOINT_STATE_TYPE))


def point_cdr(store: Any, stamp_ns: int, xyz: Array) -> bytes:
    """A geometry_msgs/PointStamped in the tracker frame as CDR bytes: xyz (3,) [m],
    stamped stamp_ns [ns]."""
    types = store.types
    stamp = types["builtin_interfaces/msg/Time"](*ns_to_sec_nanosec(stamp_ns))
    pt = types[POINT_TYPE](
        header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=TRACKER_FRAME),
        point=types["geometry_msgs/msg/Point"](*map(float, xyz)),
    )
    return bytes(store.serialize_cdr(pt, POINT_TYPE))


def write_stream_bag(
    output: str | Path,
    js_ns: IntArray,
    q: Array,
    velocity: Array,
    point_ns: IntArray,
    points: Array,
    joint_names: tuple[str, ...],
    force: bool = False,
) -> dict[str, int]:
    """A contract bag of a stream (msgs_doc/stream.md): a JointState per js_ns (m,) [ns]
    (readings q (m, J) [rad], velocity (m, J) [rad/s]) and a PointStamped per point_ns
    (n,) [ns] (points (n, 3) [m], tracker frame), in stamp order, log time = stamp.
    Staged: nothing is left on failure (an existing `output` replaced only with `force`).
    Returns messages per topic."""
    output = Path(output)
    store = typestore(JOINT_STATE_TYPE, POINT_TYPE)
    messages = sorted(
        [(int(t), 0, k) for k, t in enumerate(js_ns)]
        + [(int(t), 1, k) for k, t in enumerate(point_ns)]
    )
    with staged_outputs(output.parent, force) as stage, BagWriter(stage / output.name) as writer:
        writer.add_topic(JOINT_STATES_TOPIC, JOINT_STATE_TYPE)
        writer.add_topic(POINT_TOPIC, POINT_TYPE)
        for stamp_ns, kind, k in messages:
            if kind == 0:
                cdr = joint_state_cdr(store, stamp_ns, joint_names, q[k], velocity[k])
                writer.write(JOINT_STATES_TOPIC, cdr, stamp_ns)
            else:
                writer.write(POINT_TOPIC, point_cdr(store, stamp_ns, points[k]), stamp_ns)
        writer.close()
        return writer.counts


def extra_points_of(extra_points: Mapping[str, Array] | None, name: str, k: int) -> Array:
    """Point k (3,) [m] of further target `name` (NaN when it has none)."""
    values = (extra_points or {}).get(name)
    return np.full(3, np.nan) if values is None else np.asarray(values[k], dtype=float)


@dataclass(frozen=True)
class _PoseWriter:
    """Serialises the 6-DoF messages of one target (`write_measurements`)."""

    name: str
    quat: Array  # (n, 4) x, y, z, w of the measured rotations, NaN rows: not measured
    sigma: Array  # (n, 2) [m, rad], NaN: not stated
    store: Any  # rosbags Typestore with the pose types

    @property
    def topic(self) -> str:
        return pose_topic(self.name)

    @property
    def type_name(self) -> str:
        return POSE_COV_TYPE if np.isfinite(self.sigma).any() else POSE_TYPE

    def serialize(self, k: int, xyz: Array, stamp: Any) -> bytes | None:
        """Row k's message (position xyz (3,) [m]), None when row k has neither a point,
        nor an orientation or stated accuracy."""
        oriented = bool(np.all(np.isfinite(self.quat[k])))
        if not np.all(np.isfinite(xyz)) or not (oriented or np.isfinite(self.sigma[k]).any()):
            return None
        t = self.store.types
        quat = self.quat[k] if oriented else [0.0, 0.0, 0.0, 1.0]
        pose = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](*map(float, xyz)),
            orientation=t["geometry_msgs/msg/Quaternion"](*map(float, quat)),
        )
        header = t["std_msgs/msg/Header"](stamp=stamp, frame_id=TRACKER_FRAME)
        if self.type_name == POSE_TYPE:
            msg = t[POSE_TYPE](header=header, pose=pose)
        else:
            cov = np.array(pose_covariance(self.sigma[k], oriented))
            msg = t[POSE_COV_TYPE](
                header=header,
                pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
            )
        return bytes(self.store.serialize_cdr(msg, self.type_name))


def _pose_writers(store: Any, six_dof: Mapping[str, SixDof]) -> list[_PoseWriter]:
    """One writer per target with any orientation or stated accuracy."""
    out = []
    for name, (rotation, sigma) in six_dof.items():
        rotation, sigma = np.asarray(rotation, dtype=float), np.asarray(sigma, dtype=float)
        oriented = np.isfinite(rotation).all(axis=(1, 2))
        if oriented.any() or np.isfinite(sigma).any():
            quat = np.full((len(rotation), 4), np.nan)
            if oriented.any():  # all at once: scipy's per-call overhead is most of the cost
                quat[oriented] = Rotation.from_matrix(rotation[oriented]).as_quat()
            out.append(_PoseWriter(name, quat, sigma, store))
    return out
