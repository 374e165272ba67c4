"""A recording as the identifier sees it: measurements paired from a bag (CONTRACT.md s. 1).

Each `/laser_tracker/point` is paired with the `/joint_states` nearest in `header.stamp`
(within `pair_tolerance`); approach directions and time since the first measurement follow;
circle sweeps (runs of >= 3 poses where exactly one joint changes) are found. Unpaired
points are counted and reported, never dropped silently. Bad input raises `BagError`
naming the file and the problem (one line, exit status 2 at the CLI).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robot_calib.bag.mcap_reader import BagReader
from robot_calib.errors import BagError, InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.messages import (
    JOINT_STATE_TYPE,
    JOINT_STATES_TOPIC,
    POINT_TOPIC,
    POINT_TYPE,
    TRACKER_FRAME,
    joint_positions,
    stamp_to_ns,
)
from robot_calib.poses import JOINT_CHANGE_TOLERANCE, Poses, approach_directions

PAIR_TOLERANCE_S = 0.05  # contract default
MIN_SWEEP_POSES = 3
MIN_SWEEP_ANGLE_RAD = np.radians(10.0)  # below this a circle's centre is ill-determined
MAX_PLAUSIBLE_RANGE_M = 50.0  # a laser tracker's range; larger coordinates look like mm


@dataclass(frozen=True)
class Sweep:
    """A circle sweep: `index` (k,) into the recording's poses, all turning `joint` (1-based)."""

    joint: int
    index: Array

    @property
    def n_poses(self) -> int:
        return int(len(self.index))


@dataclass(frozen=True)
class Recording:
    """Paired measurements of one or more bags, in visiting order.

    poses : readings q (n, J) [rad], approach directions, time since the first measurement
      of each bag [s]; points : (n, 3) measured target centres, tracker frame [m];
    sweeps : circle sweeps found; bag_index : (n,) which source each pose came from;
    n_unpaired : points without a joint state in tolerance (dropped, reported);
    warnings : labelled problems that did not stop the reading.
    """

    sources: tuple[str, ...]
    poses: Poses
    points: Array
    sweeps: tuple[Sweep, ...]
    bag_index: Array
    n_unpaired: int = 0
    warnings: tuple[str, ...] = field(default=())

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def general(self) -> Array:
        """Boolean mask (n,): poses that belong to no sweep."""
        mask = np.ones(len(self), dtype=bool)
        for s in self.sweeps:
            mask[s.index] = False
        return mask

    def sweeps_of(self, joint: int) -> list[Sweep]:
        return [s for s in self.sweeps if s.joint == joint]

    def summary(self) -> str:
        """One human line: sources, poses, sweeps per joint, unpaired."""
        per_joint = ", ".join(
            f"J{j}:{sum(s.n_poses for s in self.sweeps_of(j))}"
            for j in sorted({s.joint for s in self.sweeps})
        )
        return (
            f"{', '.join(self.sources)}: {len(self)} measurements "
            f"({len(self.sweeps)} sweeps [{per_joint or 'none'}], "
            f"{int(self.general.sum())} general poses), {self.n_unpaired} unpaired"
        )


def find_sweeps(
    q: Array, tolerance: float = JOINT_CHANGE_TOLERANCE, min_poses: int = MIN_SWEEP_POSES
) -> list[Sweep]:
    """Circle sweeps in readings q (n, J) [rad] visited in order: maximal runs of >= min_poses
    consecutive poses in which exactly one joint changes (steps where nothing changes, e.g.
    the turn-around of a forth-and-back sweep, stay inside the run)."""
    q = np.asarray(q, dtype=float)
    changed = np.abs(np.diff(q, axis=0)) > tolerance  # (n-1, J)
    sweeps: list[Sweep] = []
    start, joint = 0, 0
    for k, step in enumerate(changed, start=1):  # the step from pose k-1 to pose k
        moving = np.flatnonzero(step)
        if len(moving) == 0 or (len(moving) == 1 and joint in (0, moving[0] + 1)):
            joint = joint or (int(moving[0]) + 1 if len(moving) else 0)
            continue
        if joint and k - start >= min_poses:
            sweeps.append(Sweep(joint, np.arange(start, k)))
        # One other joint moving: pose k-1 also starts the next sweep; more: pose k does.
        start, joint = (k - 1, int(moving[0]) + 1) if len(moving) == 1 else (k, 0)
    if joint and len(q) - start >= min_poses:
        sweeps.append(Sweep(joint, np.arange(start, len(q))))
    return sweeps


def usable_sweeps(q: Array, where: str, warnings: list[str]) -> list[Sweep]:
    """The sweeps of readings q (n, J) [rad] that span enough angle to fit a circle; the
    others are left as general poses with a warning appended to `warnings`."""
    out = []
    for s in find_sweeps(q):
        span = np.ptp(q[s.index, s.joint - 1])
        if span < MIN_SWEEP_ANGLE_RAD:
            warnings.append(
                f"warning: {where}: sweep of joint {s.joint} at measurements "
                f"{s.index[0] + 1}-{s.index[-1] + 1} spans only {np.degrees(span):.1f} deg: "
                "too small to fit a circle, used as general poses"
            )
            continue
        out.append(s)
    return out


def _check_topic(reader: BagReader, topic: str, type_name: str) -> None:
    info = reader.topics.get(topic)
    if info is None:
        raise BagError(f"{reader.path}: no topic {topic} (has {', '.join(reader.topics)})")
    if info.type_name != type_name:
        raise BagError(f"{reader.path}: topic {topic} has type {info.type_name}, not {type_name}")
    if info.message_count == 0:
        raise BagError(f"{reader.path}: topic {topic} has no messages")


def velocity_signs(msg: Any, joint_names: tuple[str, ...]) -> Array:
    """Signs (J,) of a JointState's velocities of `joint_names` (matched by name); zeros
    (unknown) where the message has no velocity per joint."""
    if len(msg.velocity) != len(msg.name):
        return np.zeros(len(joint_names))
    names = list(msg.name)
    return np.sign([float(msg.velocity[names.index(n)]) for n in joint_names])


def _check_metres(points: Array, where: str, error: type[Exception]) -> None:
    """Raise `error` when points (n, 3) look like millimetres rather than metres."""
    if len(points) and np.median(np.linalg.norm(points, axis=1)) > MAX_PLAUSIBLE_RANGE_M:
        raise error(
            f"{where}: {POINT_TOPIC} points are {np.median(np.abs(points)):.0f} units from the "
            "tracker: they look like millimetres; the contract wants metres"
        )


def _read_bag(
    path: Path, robot: RobotDescription
) -> tuple[Array, Array, Array, Array, Array, list[str]]:
    """Joint-state stamps (m,) [ns], readings (m, J), velocity signs (m, J) (0 = unknown),
    point stamps (n,) [ns], points (n, 3) [m] of one bag in stamp order, and warnings."""
    warnings: list[str] = []
    with BagReader(path) as reader:
        _check_topic(reader, JOINT_STATES_TOPIC, JOINT_STATE_TYPE)
        _check_topic(reader, POINT_TOPIC, POINT_TYPE)
        js_t, js_q, js_v, pt_t, pts = [], [], [], [], []
        frames: set[str] = set()
        for m in reader.messages([JOINT_STATES_TOPIC, POINT_TOPIC]):
            msg = m.decode()
            if m.topic == JOINT_STATES_TOPIC:
                q = joint_positions(msg, robot.joint_names, f"{path}: {JOINT_STATES_TOPIC}")
                js_t.append(stamp_to_ns(msg.header.stamp))
                js_q.append(q)
                js_v.append(velocity_signs(msg, robot.joint_names))
            else:
                p = np.array([msg.point.x, msg.point.y, msg.point.z])
                if not np.all(np.isfinite(p)):
                    raise BagError(
                        f"{path}: {POINT_TOPIC} message {len(pts) + 1} is not finite: {p}"
                    )
                frames.add(msg.header.frame_id)
                pt_t.append(stamp_to_ns(msg.header.stamp))
                pts.append(p)
    points = np.array(pts)
    _check_metres(points, str(path), BagError)
    if frames != {TRACKER_FRAME}:
        warnings.append(
            f"warning: {path}: {POINT_TOPIC} frame_id {sorted(frames)} is not "
            f"'{TRACKER_FRAME}' (used as the tracker frame anyway)"
        )
    js_order = np.argsort(js_t, kind="stable")
    pt_order = np.argsort(pt_t, kind="stable")
    return (
        np.array(js_t)[js_order],
        np.array(js_q)[js_order],
        np.array(js_v)[js_order],
        np.array(pt_t)[pt_order],
        points[pt_order],
        warnings,
    )


def pair_nearest(reference_ns: Array, query_ns: Array, tolerance_ns: int) -> Array:
    """Index into sorted `reference_ns` of the stamp nearest each of `query_ns`, -1 where
    none lies within `tolerance_ns`; shape of `query_ns`."""
    right = np.clip(np.searchsorted(reference_ns, query_ns), 1, len(reference_ns) - 1)
    left = right - 1
    if len(reference_ns) == 1:
        left = right = np.zeros_like(query_ns)
    pick = np.where(
        np.abs(reference_ns[left] - query_ns) <= np.abs(reference_ns[right] - query_ns),
        left,
        right,
    )
    return np.where(np.abs(reference_ns[pick] - query_ns) <= tolerance_ns, pick, -1)


def _pair(
    js_t: Array,
    js_q: Array,
    js_v: Array,
    pt_t: Array,
    pts: Array,
    pair_tolerance: float,
    where: str,
    warnings: list[str],
) -> tuple[Array, Array, Array, Array, int]:
    """The contract's pairing of one source whose joint states (stamps (m,) [ns], readings
    (m, J) [rad], velocity signs (m, J), 0 = unknown) and points (stamps (n,) [ns], (n, 3) [m])
    are each in stamp order: readings, approach directions, time since the first paired point
    [s] and points of the paired measurements, and the number of points dropped (warned)."""
    if len(js_t) == 0:
        pick = np.full(len(pt_t), -1)
    else:
        pick = pair_nearest(js_t, pt_t, int(round(pair_tolerance * 1e9)))
    ok = pick >= 0
    if not ok.all():
        warnings.append(
            f"warning: {where}: {int((~ok).sum())} of {len(ok)} points have no joint "
            f"state within {pair_tolerance} s: dropped"
        )
    q = js_q[pick[ok]]
    velocity = js_v[pick[ok]]
    direction = np.where(velocity != 0, velocity, approach_directions(q))
    time = (pt_t[ok] - pt_t[ok][0]) * 1e-9 if ok.any() else np.zeros(0)
    return q, direction, time, pts[ok], int((~ok).sum())


def read_recording(
    paths: Sequence[str | Path],
    robot: RobotDescription,
    pair_tolerance: float = PAIR_TOLERANCE_S,
    require_points: int = 1,
    log: Callable[[str], None] | None = None,
) -> Recording:
    """Read and pair the measurements of one or more bags (each bag its own time origin and
    direction history). Raises BagError on unusable input; warnings go to `log` and into the
    result."""
    if not paths:
        raise InputError("no bag given")
    q_all, d_all, t_all, p_all, idx_all, sweeps = [], [], [], [], [], []
    warnings: list[str] = []
    unpaired = offset = 0
    for b, raw in enumerate(paths):
        path = Path(raw)
        if not path.is_file():
            raise BagError(f"{path}: no such bag file")
        js_t, js_q, js_v, pt_t, pts, bag_warnings = _read_bag(path, robot)
        warnings += bag_warnings
        q, direction, time, points, dropped = _pair(
            js_t, js_q, js_v, pt_t, pts, pair_tolerance, str(path), warnings
        )
        unpaired += dropped
        if len(q) < require_points:
            raise BagError(f"{path}: no tracker point pairs with a joint state")
        q_all.append(q)
        d_all.append(direction)
        t_all.append(time)
        p_all.append(points)
        idx_all.append(np.full(len(q), b))
        sweeps += [Sweep(s.joint, s.index + offset) for s in usable_sweeps(q, str(path), warnings)]
        offset += len(q)
    for w in warnings:
        if log:
            log(w)
    return Recording(
        tuple(str(p) for p in paths),
        Poses(np.concatenate(q_all), np.concatenate(d_all), np.concatenate(t_all)),
        np.concatenate(p_all),
        tuple(sweeps),
        np.concatenate(idx_all),
        unpaired,
        tuple(warnings),
    )


def recording_from_arrays(
    q: Array, points: Array, time: Array | None = None, source: str = "arrays"
) -> Recording:
    """A recording of measurements already paired in memory (one source, visiting order):
    q (n, J) [rad], points (n, 3) [m], time (n,) [s]."""
    poses = Poses.from_readings(q, time=time)
    warnings: list[str] = []
    sweeps = usable_sweeps(poses.q, source, warnings)
    return Recording(
        (source,),
        poses,
        np.asarray(points, dtype=float),
        tuple(sweeps),
        np.zeros(len(poses), dtype=int),
        0,
        tuple(warnings),
    )


def recording_from_stream(
    js_ns: Array,
    q: Array,
    velocity_sign: Array,
    point_ns: Array,
    points: Array,
    pair_tolerance: float = PAIR_TOLERANCE_S,
    source: str = "live",
) -> Recording:
    """A recording of one source from messages received live, paired as a bag is.

    js_ns (m,) joint-state stamps [ns], q (m, J) readings [rad], velocity_sign (m, J) (+1/-1,
    0 = no velocity); point_ns (n,) point stamps [ns], points (n, 3) tracker frame [m]; each
    in any order (sorted here by stamp). Raises InputError when no point pairs.
    """
    js_ns, point_ns = np.asarray(js_ns, dtype=np.int64), np.asarray(point_ns, dtype=np.int64)
    q, velocity_sign = np.asarray(q, dtype=float), np.asarray(velocity_sign, dtype=float)
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(point_ns) != len(points) or len(js_ns) != len(q) or q.shape != velocity_sign.shape:
        raise InputError(
            f"{source}: stamps and values differ in length (joint states {len(js_ns)} vs "
            f"{q.shape}, points {len(point_ns)} vs {points.shape})"
        )
    _check_metres(points, source, InputError)
    js_order = np.argsort(js_ns, kind="stable")
    pt_order = np.argsort(point_ns, kind="stable")
    warnings: list[str] = []
    q, direction, time, points, unpaired = _pair(
        js_ns[js_order],
        q[js_order],
        velocity_sign[js_order],
        point_ns[pt_order],
        points[pt_order],
        pair_tolerance,
        source,
        warnings,
    )
    if len(q) == 0:
        raise InputError(
            f"{source}: none of {len(point_ns)} tracker points has a joint state within "
            f"{pair_tolerance} s ({len(js_ns)} joint states received)"
        )
    sweeps = usable_sweeps(q, source, warnings)
    return Recording(
        (source,),
        Poses(q, direction, time),
        points,
        tuple(sweeps),
        np.zeros(len(q), dtype=int),
        unpaired,
        tuple(warnings),
    )
