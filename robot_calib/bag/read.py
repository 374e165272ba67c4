"""Bags -> a `Recording`: read the contract's two topics of each bag and hand their stamps
and values to the measurement model (`robot_calib.measurements`), which pairs them.

Why one module: a bag is read two ways, in bulk (`_read_bulk`) and message by message
(`_read_each`), which must give the same arrays and the same errors (the bulk path gives way
to the other on anything it doubts: `_NoBulk`); they stay side by side with the checks both
apply (`_check_values`), so that a change to one is read against the other.

Bad input raises `BagError` naming the file and the problem (one line, exit status 2).
"""

from __future__ import annotations

import shlex
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from robot_calib.bag.bulk_decode import Columns, decode_columns
from robot_calib.bag.mcap_reader import BagReader
from robot_calib.errors import BagError, InputError, TruncatedBagError, param
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.log import Log
from robot_calib.measurements.recording import (
    MAX_COORDINATE_M,
    MAX_READING_RAD,
    PAIR_TOLERANCE_S,
    Recording,
    implausible_values,
    recording_from_stream,
    without_copies,
)
from robot_calib.measurements.references import ReferenceReads
from robot_calib.measurements.six_dof import PoseReading, StampedMeasurements, join_poses
from robot_calib.measurements.stream import STREAM_ADVICE, JointStream, stream_hint
from robot_calib.messages import (
    JOINT_STATE_TYPE,
    JOINT_STATES_TOPIC,
    POINT_TOPIC,
    POINT_TYPE,
    POSE_TOPIC,
    POSE_TYPE,
    POSE_TYPES,
    QUATERNION_TOLERANCE,
    TEMPERATURE_TOPIC,
    TRACKER_FRAME,
    joint_positions,
    pose_measurement,
    pose_topic_name,
    reference_topic_name,
    stamp_to_ns,
    target_topic,
    target_topic_name,
    velocity_signs,
)
from robot_calib.poses import PRIMARY_TARGET


def _check_topic(reader: BagReader, topic: str, type_name: str) -> None:
    info = reader.topics.get(topic)
    if info is None:
        raise BagError(f"{reader.path}: no topic {topic} (has {', '.join(reader.topics)})")
    if info.type_name != type_name:
        raise BagError(f"{reader.path}: topic {topic} has type {info.type_name}, not {type_name}")
    if info.message_count == 0:
        raise BagError(f"{reader.path}: topic {topic} has no messages")


def _check_no_extra_joints(names: tuple[str, ...], robot: RobotDescription, path: Path) -> None:
    """BagError when a JointState names joints the robot does not have (a 5-joint robot on
    a 6-joint bag would silently ignore a moving joint)."""
    extra = [n for n in names if n not in robot.joint_names]
    if extra:
        raise BagError(
            f"{path}: {JOINT_STATES_TOPIC} has joints {extra} that robot {robot.name} "
            f"({robot.n_joints} joints: {list(robot.joint_names)}) does not have; wrong "
            f"{param('robot')}?"
        )


def _target_topics(
    reader: BagReader, path: Path, warnings: list[str]
) -> tuple[dict[str, int], dict[str, int], list[str]]:
    """The bag's targets: point topics {topic: target index}, 6-DoF pose topics {topic:
    target index} (msgs_doc/six_dof.md) and the target names ('' first). The first target
    needs POINT_TOPIC or POSE_TOPIC; a topic without messages is left out (warning)."""
    point_topics: dict[str, int] = {}
    pose_topics: dict[str, int] = {}
    names: list[str] = [PRIMARY_TARGET]
    if POSE_TOPIC not in reader.topics or POINT_TOPIC in reader.topics:
        _check_topic(reader, POINT_TOPIC, POINT_TYPE)
        point_topics[POINT_TOPIC] = 0
    for topic in sorted(reader.topics):
        point_name, pose_name = target_topic_name(topic), pose_topic_name(topic)
        name = point_name if point_name is not None else pose_name
        if name is None or topic == POINT_TOPIC:
            continue
        if reader.topics[topic].message_count == 0:
            if name:
                warnings.append(f"warning: {path}: {topic} has no messages: left out")
                continue
            if topic == POSE_TOPIC and POINT_TOPIC in point_topics:
                continue
        info = reader.topics[topic]
        if pose_name is not None and info.type_name not in POSE_TYPES:
            raise BagError(
                f"{path}: topic {topic} has type {info.type_name}, not one of "
                f"{', '.join(POSE_TYPES)}"
            )
        if point_name is not None:
            _check_topic(reader, topic, POINT_TYPE)
        if name not in names:
            names.append(name)
        (point_topics if point_name is not None else pose_topics)[topic] = names.index(name)
    return point_topics, pose_topics, names


class _BagMessages(NamedTuple):
    """The measurement messages of one bag, as read: joint-state stamps [ns], readings
    (m, J) [rad] and velocity signs (m, J); the points joined with their 6-DoF poses
    (`join_poses`); the target names; the side topic's (stamp [ns], deg C); warnings."""

    js_ns: IntArray
    q: Array
    velocity_sign: Array
    stamped: StampedMeasurements
    names: list[str]
    celsius: list[tuple[int, float]]
    warnings: list[str]


class _Decoded(NamedTuple):
    """What `_bag_messages` reads from the messages, before joining: joint-state stamps
    [ns] (m,), readings (m, J) [rad], velocity signs (m, J); the points' stamps [ns],
    positions (3,) [m] and target indices in file order; per target the 6-DoF readings by
    stamp; the side topic's (stamp [ns], deg C); the points' and poses' frame ids."""

    js_ns: IntArray
    q: Array
    velocity_sign: Array
    pt_t: list[int]
    pts: list[Array]
    pt_target: list[int]
    poses: list[dict[int, PoseReading]]
    celsius: list[tuple[int, float]]
    frames: set[str]


def _bag_messages(path: Path, robot: RobotDescription, bulk: bool = True) -> _BagMessages:
    """Read the measurement topics of the bag `path` (BagError on unusable input).
    bulk: decode the messages in bulk where they allow it (`_read_bulk`; the same result as
    message by message, which False forces)."""
    if not path.is_file():
        raise BagError(f"{path}: no such bag file")
    warnings: list[str] = []
    try:
        reader = BagReader(path)
    except TruncatedBagError:
        raise BagError(
            f"{path}: truncated MCAP file (no footer: its writer did not close it; run "
            f"`robot-calib repair {shlex.quote(str(path))} -o FIXED.mcap`)"
        ) from None
    with reader:
        _check_topic(reader, JOINT_STATES_TOPIC, JOINT_STATE_TYPE)
        target_topics, pose_topics, names = _target_topics(reader, path, warnings)
        side = [TEMPERATURE_TOPIC] if TEMPERATURE_TOPIC in reader.topics else []
        decoded = (
            _read_bulk(reader, robot, target_topics, pose_topics, side, len(names))
            if bulk
            else None
        )
        if decoded is None:
            decoded = _read_each(reader, path, robot, target_topics, pose_topics, side, len(names))
    js_ns, q, velocity_sign, pt_t, pts, pt_target, poses, celsius, frames = decoded
    if frames != {TRACKER_FRAME}:
        warnings.append(
            f"warning: {path}: tracker point frame_id {sorted(frames)} is not "
            f"'{TRACKER_FRAME}' (used as the tracker frame anyway)"
        )
    stamped = join_poses(
        str(path), names, pt_t, pts, pt_target, poses, set(target_topics.values()), BagError
    )
    return _BagMessages(js_ns, q, velocity_sign, stamped, names, celsius, warnings)


def _read_each(
    reader: BagReader,
    path: Path,
    robot: RobotDescription,
    target_topics: dict[str, int],
    pose_topics: dict[str, int],
    side: list[str],
    n_targets: int,
) -> _Decoded:
    """The measurement messages decoded one by one (BagError at the first unusable one)."""
    js_t: list[int] = []  # stamps [ns]
    pt_t: list[int] = []
    js_q: list[Array] = []
    js_v: list[Array] = []
    pts: list[Array] = []
    pt_target: list[int] = []
    frames: set[str] = set()
    names_seen: tuple[str, ...] = robot.joint_names
    poses: list[dict[int, PoseReading]] = [{} for _ in range(n_targets)]
    celsius: list[tuple[int, float]] = []  # (stamp [ns], deg C) of the side topic
    for m in reader.messages([JOINT_STATES_TOPIC, *target_topics, *pose_topics, *side]):
        msg = m.decode()
        if m.topic == TEMPERATURE_TOPIC:
            celsius.append((stamp_to_ns(msg.header.stamp), float(msg.temperature)))
            continue
        if m.topic == JOINT_STATES_TOPIC:
            js_q.append(joint_positions(msg, robot.joint_names, f"{path}: {JOINT_STATES_TOPIC}"))
            if tuple(msg.name) != names_seen:  # checked once per set of names
                names_seen = tuple(msg.name)
                _check_no_extra_joints(names_seen, robot, path)
            js_t.append(stamp_to_ns(msg.header.stamp))
            js_v.append(velocity_signs(msg, robot.joint_names))
            continue
        frames.add(msg.header.frame_id)
        if m.topic in pose_topics:
            k = pose_topics[m.topic]
            where = f"{path}: {m.topic} message {len(poses[k]) + 1}"
            stamp = stamp_to_ns(msg.header.stamp)
            if stamp in poses[k]:
                raise BagError(f"{where}: a second pose at stamp {stamp} ns")
            try:
                poses[k][stamp] = pose_measurement(msg, where)
            except InputError as exc:
                raise BagError(str(exc)) from None
            continue
        p = np.array([msg.point.x, msg.point.y, msg.point.z])
        k = target_topics[m.topic]
        if not np.all(np.isfinite(p)):
            raise BagError(
                f"{path}: {m.topic} message {pt_target.count(k) + 1} is not finite: {p}"
            )
        pt_t.append(stamp_to_ns(msg.header.stamp))
        pts.append(p)
        pt_target.append(k)
    n_joints = robot.n_joints
    return _Decoded(
        np.array(js_t, dtype=np.int64),
        np.array(js_q).reshape(-1, n_joints),
        np.array(js_v).reshape(-1, n_joints),
        pt_t,
        pts,
        pt_target,
        poses,
        celsius,
        frames,
    )


class _NoBulk(Exception):
    """The messages are not all of a layout `_read_bulk` reads, or one of them is unusable:
    read them one by one (`_read_each`), which gives the same result or the error."""


def _column(columns: Columns, name: str, kinds: str = "f") -> Array:
    """A bulk-decoded field (`Columns.fields`) of one of the dtype kinds 'f', 'i', 'u'."""
    values = columns.fields.get(name)
    if values is None or values.dtype.kind not in kinds or values.dtype.itemsize > 8:
        raise _NoBulk(name)
    return values


def _stamps(columns: Columns) -> IntArray:
    """header.stamp [ns] of each message (`stamp_to_ns`)."""
    sec = _column(columns, "header.stamp.sec", "iu").astype(np.int64)
    nanosec = _column(columns, "header.stamp.nanosec", "iu").astype(np.int64)
    if columns.fields["header.stamp.sec"].dtype.itemsize > 4:
        raise _NoBulk("64-bit seconds")
    return sec * 1_000_000_000 + nanosec


def _read_bulk(
    reader: BagReader,
    robot: RobotDescription,
    target_topics: dict[str, int],
    pose_topics: dict[str, int],
    side: list[str],
    n_targets: int,
) -> _Decoded | None:
    """What `_read_each` gives, from messages decoded in bulk (`bulk_decode`): None when a
    topic is not all of one layout, or a message is one `_read_each` stops at (a missing
    joint, a non-finite point, ...; reading again one by one raises its error)."""
    topics = [JOINT_STATES_TOPIC, *target_topics, *pose_topics, *side]
    table = reader.channel_messages(topics)
    if table is None:
        return None
    columns: dict[str, Columns] = {}
    index: dict[str, npt.NDArray[Any]] = {}
    for channel in table.values():
        if channel.topic in index:  # several channels of a topic
            return None
        index[channel.topic] = channel.index
        if len(channel):
            decoded = decode_columns(channel)
            if decoded is None:
                return None
            columns[channel.topic] = decoded
    try:
        return _bulk_values(reader, robot, columns, index, target_topics, pose_topics, n_targets)
    except _NoBulk:
        return None


def _bulk_values(
    reader: BagReader,
    robot: RobotDescription,
    columns: dict[str, Columns],
    index: dict[str, npt.NDArray[Any]],
    target_topics: dict[str, int],
    pose_topics: dict[str, int],
    n_targets: int,
) -> _Decoded:
    """`_read_bulk`'s values from the decoded columns (_NoBulk where `_read_each` raises)."""
    n_joints = robot.n_joints
    js_ns: npt.NDArray[Any] = np.zeros(0, dtype=np.int64)
    q = velocity_sign = np.zeros((0, n_joints))
    js = columns.get(JOINT_STATES_TOPIC)
    if js is not None:
        names = list(js.first.name)
        if any(n not in names for n in robot.joint_names):
            raise _NoBulk("joint names")
        if tuple(names) != robot.joint_names and any(n not in robot.joint_names for n in names):
            raise _NoBulk("extra joints")
        position = _column(js, "position")
        if position.ndim != 2 or position.shape[1] != len(names) or position.dtype != np.float64:
            raise _NoBulk("positions")
        at = [names.index(n) for n in robot.joint_names]
        q = position[:, at]
        if not np.all(np.isfinite(q)):
            raise _NoBulk("positions not finite")
        velocity = _column(js, "velocity")
        if velocity.ndim != 2 or velocity.dtype != np.float64:
            raise _NoBulk("velocity")
        velocity_sign = (
            np.sign(velocity[:, at])
            if velocity.shape[1] == len(names)
            else np.zeros((len(position), n_joints))
        )
        js_ns = _stamps(js)
    frames: set[str] = set()
    point_parts: list[tuple[npt.NDArray[Any], ...]] = []
    for topic, k in target_topics.items():
        points = columns.get(topic)
        if points is None:
            continue
        xyz = np.stack([_column(points, f"point.{a}") for a in "xyz"], axis=1)
        if xyz.dtype != np.float64 or not np.all(np.isfinite(xyz)):
            raise _NoBulk("points")
        frames.add(points.first.header.frame_id)
        point_parts.append((index[topic], _stamps(points), xyz, np.full(len(xyz), k)))
    order = np.argsort(np.concatenate([p[0] for p in point_parts] or [np.zeros(0)]), kind="stable")
    pt_t = np.concatenate([p[1] for p in point_parts] or [np.zeros(0, np.int64)])[order]
    pts = np.concatenate([p[2] for p in point_parts] or [np.zeros((0, 3))])[order]
    pt_target = np.concatenate([p[3] for p in point_parts] or [np.zeros(0, np.int64)])[order]
    poses: list[dict[int, PoseReading]] = [{} for _ in range(n_targets)]
    for topic, k in pose_topics.items():
        pose = columns.get(topic)
        if pose is not None:
            frames.add(pose.first.header.frame_id)
            poses[k] = _bulk_poses(reader, topic, pose)
    celsius: list[tuple[int, float]] = []
    temperature = columns.get(TEMPERATURE_TOPIC)
    if temperature is not None:
        celsius = list(
            zip(_stamps(temperature).tolist(), _column(temperature, "temperature").tolist())
        )
    return _Decoded(
        js_ns,
        q,
        velocity_sign,
        pt_t.tolist(),
        list(pts),
        pt_target.tolist(),
        poses,
        celsius,
        frames,
    )


def _poses_one_by_one(topic: str, pose: Columns, stamps: IntArray) -> dict[int, PoseReading]:
    """The readings of a PoseWithCovarianceStamped topic: `pose_measurement` per message,
    given the bulk-decoded fields (_NoBulk where it raises)."""
    base = "pose.pose."
    position = np.stack([_column(pose, f"{base}position.{a}") for a in "xyz"], axis=1)
    quat = np.stack([_column(pose, f"{base}orientation.{a}") for a in "xyzw"], axis=1)
    covariance = _column(pose, "pose.covariance")
    readings: dict[int, PoseReading] = {}
    for stamp, p, o, c in zip(stamps.tolist(), position.tolist(), quat.tolist(), covariance):
        msg = SimpleNamespace(
            pose=SimpleNamespace(
                pose=SimpleNamespace(
                    position=SimpleNamespace(x=p[0], y=p[1], z=p[2]),
                    orientation=SimpleNamespace(x=o[0], y=o[1], z=o[2], w=o[3]),
                ),
                covariance=c,
            )
        )
        try:
            readings[stamp] = pose_measurement(msg, topic)
        except InputError:
            raise _NoBulk("a pose pose_measurement rejects") from None
    return readings


def _bulk_poses(reader: BagReader, topic: str, pose: Columns) -> dict[int, PoseReading]:
    """The 6-DoF readings of a PoseStamped topic by stamp, as `pose_measurement` gives them
    message by message (_NoBulk for another type or a message it rejects)."""
    stamps = _stamps(pose)
    if len(np.unique(stamps)) != len(stamps):
        raise _NoBulk("a second pose at a stamp")
    if reader.topics[topic].type_name != POSE_TYPE:
        return _poses_one_by_one(topic, pose, stamps)
    position = np.stack([_column(pose, f"pose.position.{a}") for a in "xyz"], axis=1)
    quat = np.stack([_column(pose, f"pose.orientation.{a}") for a in "xyzw"], axis=1)
    if position.dtype != np.float64 or quat.dtype != np.float64:
        raise _NoBulk("pose types")
    if not (np.all(np.isfinite(position)) and np.all(np.isfinite(quat))):
        raise _NoBulk("pose not finite")
    near = np.abs(np.linalg.norm(quat, axis=1) - 1.0) > QUATERNION_TOLERANCE / 2
    for i in np.flatnonzero(near):  # the norm as pose_measurement takes it (batches round apart)
        if abs(np.linalg.norm(quat[i]) - 1.0) > QUATERNION_TOLERANCE:
            raise _NoBulk("not a unit quaternion")
    from scipy.spatial.transform import Rotation

    rotation = Rotation.from_quat(quat).as_matrix()
    sigma = np.full((len(stamps), 2), np.nan)
    return {t: (p, r, s) for t, p, r, s in zip(stamps.tolist(), position, rotation, sigma)}


def read_bag(
    path: Path, robot: RobotDescription, pair_tolerance: float = PAIR_TOLERANCE_S
) -> Recording:
    """The paired measurements of one bag (its own time origin and direction history),
    with a warning suggesting `--stream` when the bag looks like a stream (`stream_hint`)."""
    js_ns, q, velocity_sign, stamped, names, celsius, warnings = _bag_messages(path, robot)
    _check_values(path, q, stamped, names)
    warnings = warnings + _backwards_stamps(path, js_ns)
    order = np.argsort(js_ns, kind="stable")
    # a stream is told by one target's points per joint state: several targets measured at
    # each pose of a static bag are no stream
    per_target = (
        len(stamped.point_ns)
        if len(names) <= 1
        else int(np.bincount(stamped.point_target, minlength=len(names)).max())
    )
    hint = stream_hint(
        js_ns[order], q[order], per_target, str(path), np.asarray(stamped.point_ns, dtype=np.int64)
    )
    if hint and len(names) > 1:  # a stream is read for a single target (read_stream)
        advice = (
            f"(points per target); {param('stream', True)} reads the single target of "
            f"{POINT_TOPIC}: measure each pose at rest (msgs_doc/stream.md)"
        )
        hint = hint.replace(f": {STREAM_ADVICE}", f" {advice}")
    warnings = warnings + ([hint] if hint else [])
    rec = recording_from_stream(
        js_ns,
        q,
        velocity_sign,
        stamped.point_ns,
        stamped.points,
        pair_tolerance,
        source=str(path),
        error=BagError,
        robot=robot,
        point_target=stamped.point_target if len(names) > 1 else None,
        target_names=tuple(names),
        rotation=stamped.rotation,
        sigma=stamped.sigma,
        temperature=_temperature_at(path, celsius, stamped.point_ns),
        received=np.arange(len(js_ns)),  # the file's order: as the recorder received them
    )
    rec = without_copies(rec, str(path))
    references = _reference_reads(path)
    if references is not None:
        rec = rec.without_drift(references)
        if references.drift is None:
            warnings.append(
                f"warning: {path}: reference reflectors "
                f"{', '.join(references.names)}: {references.note}: the tracker's "
                "drift is not removed"
            )
    return replace(rec, warnings=tuple(warnings) + rec.warnings)


def _reference_reads(path: Path) -> ReferenceReads | None:
    """The reference reflectors of the bag (msgs_doc/references.md), with the drift they
    show; None when it has none. BagError for a wrong type or a point not finite."""
    with BagReader(path) as reader:
        topics = {
            t: name
            for t in sorted(reader.topics)
            if (name := reference_topic_name(t)) is not None and reader.topics[t].message_count
        }
        if not topics:
            return None
        for topic in topics:
            _check_topic(reader, topic, POINT_TYPE)
        names = tuple(topics.values())
        reads: dict[int, Array] = {}
        for m in reader.messages(list(topics)):
            msg = m.decode()
            p = np.array([msg.point.x, msg.point.y, msg.point.z], dtype=float)
            if not np.all(np.isfinite(p)):
                raise BagError(f"{path}: {m.topic}: a point that is not finite: {p}")
            row = reads.setdefault(stamp_to_ns(msg.header.stamp), np.full((len(names), 3), np.nan))
            row[names.index(topics[m.topic])] = p
    stamps = np.array(sorted(reads), dtype=np.int64)
    points = np.stack([reads[int(t)] for t in stamps], axis=1)  # (R, m, 3)
    return ReferenceReads.estimated(0, names, stamps, points)


def _check_values(path: Path, q: Array, stamped: StampedMeasurements, names: list[str]) -> None:
    """BagError naming the bag, topic and message when a joint reading or a tracker
    coordinate is beyond any plausible value (MAX_READING_RAD, MAX_COORDINATE_M): a
    corrupt number (1e300) would otherwise reach the fit (an SVD that never returns)."""
    bad = implausible_values(q, MAX_READING_RAD)
    if len(bad):
        k = int(bad[0])
        raise BagError(
            f"{path}: {JOINT_STATES_TOPIC} message {k + 1}: reading {q[k].tolist()} is beyond "
            f"+-{MAX_READING_RAD:g} rad, no joint angle in rad or deg (a corrupt value?)"
        )
    bad = implausible_values(stamped.points, MAX_COORDINATE_M)
    if len(bad):
        k = int(bad[0])
        t = int(stamped.point_target[k]) if len(stamped.point_target) else 0
        nth = int(np.sum(np.asarray(stamped.point_target[:k]) == t)) + 1
        raise BagError(
            f"{path}: {target_topic(names[t] if t < len(names) else PRIMARY_TARGET)} message "
            f"{nth}: point {stamped.points[k].tolist()} m is beyond +-{MAX_COORDINATE_M:g} m "
            "of the tracker, no measured point (a corrupt value?)"
        )


def _backwards_stamps(path: Path, js_ns: IntArray) -> list[str]:
    """A warning when the joint states' header stamps (in file order, the order the
    recorder received them) go backwards: the poses are paired and timed by their stamps,
    their approach directions (backlash) follow the receive order (the order the robot
    visited them)."""
    back = np.flatnonzero(np.diff(np.asarray(js_ns, dtype=np.int64)) < 0)
    if not len(back):
        return []
    k = int(back[0]) + 1
    return [
        f"warning: {path}: {JOINT_STATES_TOPIC}: {len(back)} of {len(js_ns)} stamps go "
        f"backwards against the receive order (first: message {k + 1}, "
        f"{(int(js_ns[k - 1]) - int(js_ns[k])) / 1e6:.3f} ms before the message received "
        "before it): a clock jump or re-stamped messages? Points are paired and timed by "
        "their stamps; the approach directions (backlash) follow the receive order"
    ]


def read_stream(path: Path, robot: RobotDescription) -> JointStream:
    """The raw stream of one bag for continuous tracking (msgs_doc/stream.md): joint
    states and the points of the contract's single target, unpaired (`stream_recording`
    pairs them at a latency), with the side topic's temperature at each point. BagError
    for a bag with further targets, 6-DoF poses or reference reflectors (not supported in
    stream mode)."""
    js_ns, q, velocity_sign, stamped, names, celsius, _ = _bag_messages(path, robot)
    if len(names) > 1 or stamped.rotation is not None:
        raise BagError(
            f"{path}: {param('stream', True)} reads the single target of {POINT_TOPIC}; this bag "
            f"has further targets or 6-DoF poses ({len(names)} target(s))"
        )
    with BagReader(path) as reader:
        references = [t for t in reader.topics if reference_topic_name(t) is not None]
    if references:
        raise BagError(
            f"{path}: {param('stream', True)} does not read reference reflectors "
            f"({references[0]}): the tracker's drift they show would stay in the "
            "points; read the bag as poses at rest "
            "(msgs_doc/references.md)"
        )
    try:
        return JointStream.from_messages(
            js_ns,
            q,
            velocity_sign,
            stamped.point_ns,
            stamped.points,
            str(path),
            _temperature_at(path, celsius, stamped.point_ns),
        )
    except InputError as exc:
        raise BagError(str(exc)) from None


def _temperature_at(
    path: Path, celsius: list[tuple[int, float]], point_ns: IntArray
) -> Array | None:
    """The side topic's temperature [deg C] at each point stamp (n,) [ns], linear between
    its messages (held beyond the first and last); None without the topic. BagError when a
    temperature is not finite."""
    if not celsius:
        return None
    stamps, values = (np.array(v) for v in zip(*sorted(celsius)))
    if not np.all(np.isfinite(values)):
        raise BagError(f"{path}: {TEMPERATURE_TOPIC} has a temperature that is not finite")
    return np.interp(np.asarray(point_ns, dtype=float), stamps.astype(float), values)


def read_recording(
    paths: Sequence[str | Path],
    robot: RobotDescription,
    pair_tolerance: float = PAIR_TOLERANCE_S,
    log: Log | None = None,
) -> Recording:
    """Read and pair the measurements of one or more bags (each bag its own time origin and
    direction history). Raises BagError on unusable input; warnings go to `log` and into the
    result.

    Returns
    -------
    recording : Recording
        The bags' paired measurements concatenated in the order of `paths` (fields as in
        `recording_from_stream`): sources the bag paths; bag_index (n,) the position of
        each pose's bag in `paths`; n_unpaired and warnings summed over the bags (plus a
        warning for a point frame_id other than the tracker frame).
    """
    if not paths:
        raise InputError("no bag given")
    recording = Recording.concatenate([read_bag(Path(p), robot, pair_tolerance) for p in paths])
    for w in recording.warnings:
        if log:
            log(w)
    return recording


def other_topics(path: Path) -> list[str]:
    """The bag's topics that are neither measurements (joint states, points, poses) nor the
    side topic TEMPERATURE_TOPIC (msgs_doc/temperature.md): what a rewrite of its
    measurements (`split`) does not carry."""
    with BagReader(path) as reader:
        return [
            t
            for t in reader.topics
            if t not in (JOINT_STATES_TOPIC, TEMPERATURE_TOPIC, POINT_TOPIC)
            and target_topic_name(t) is None
            and pose_topic_name(t) is None
            and reference_topic_name(t) is None
        ]
