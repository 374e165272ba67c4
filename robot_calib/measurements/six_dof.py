"""6-DoF measurements joined to their points (msgs_doc/six_dof.md), wherever the stamped
messages come from (a bag, live topics): a pose belongs to the point of the same target
and stamp; a target measured by poses alone takes its points from them.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import NamedTuple

import numpy as np

from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.messages import pose_topic, target_topic

POSE_POINT_TOLERANCE_M = 1e-6  # a pose's position and its point's: the same measurement

PoseReading = tuple[Array, Array, Array]
"""One pose message as `messages.pose_measurement` reads it: position (3,) [m], rotation
(3, 3) in the tracker frame (NaN: not measured), stated standard deviations (2,) [m, rad]."""


class StampedMeasurements(NamedTuple):
    """Every point of a source with what its 6-DoF probe measured, in the order read.

    point_ns : (n,) header stamps [ns]; points : (n, 3) tracker frame [m];
    point_target : (n,) index of each point's target; rotation : (n, 3, 3) the probe
    frame (NaN rows: a point without one; None: no orientation at all); sigma : (n, 2)
    stated standard deviations [m, rad] (NaN: not stated; None with `rotation`).
    """

    point_ns: IntArray
    points: Array
    point_target: IntArray
    rotation: Array | None
    sigma: Array | None


def join_poses(
    source: str,
    target_names: Sequence[str],
    point_ns: Sequence[int],
    points: Sequence[Array],
    point_target: Sequence[int],
    poses: Sequence[Mapping[int, PoseReading]],
    with_points: Collection[int],
    error: type[Exception] = InputError,
) -> StampedMeasurements:
    """The points (n,) [ns], (n, 3) [m] of targets `point_target` (n,) (indices into
    `target_names`) joined with the 6-DoF messages `poses` (per target: {stamp [ns]:
    `PoseReading`}). A target not in `with_points` (no point topic, or none received) gets
    its points from its poses, appended in the order read. Raises `error` naming `source` and
    the topics when a pose and the point of its stamp are more than POSE_POINT_TOLERANCE_M
    apart, or a pose has no point of its stamp."""
    stamps = list(point_ns)
    xyz = [np.asarray(p, dtype=float) for p in points]
    target = list(point_target)
    for k, by_stamp in enumerate(poses):
        if k not in with_points:
            for stamp, (position, _, _) in by_stamp.items():
                stamps.append(stamp)
                xyz.append(position)
                target.append(k)
    rotation: Array | None = None
    sigma: Array | None = None
    if any(poses):
        rotation = np.full((len(xyz), 3, 3), np.nan)
        sigma = np.full((len(xyz), 2), np.nan)
        used = [0] * len(target_names)
        for i, (stamp, p, k) in enumerate(zip(stamps, xyz, target)):
            found = poses[k].get(stamp) if k < len(poses) else None
            if found is None:
                continue
            if np.linalg.norm(found[0] - p) > POSE_POINT_TOLERANCE_M:
                raise error(
                    f"{source}: {pose_topic(target_names[k])} at stamp {stamp} ns is at "
                    f"{found[0].tolist()} but {target_topic(target_names[k])} at {p.tolist()} m"
                )
            rotation[i], sigma[i] = found[1], found[2]
            used[k] += 1
        for k, by_stamp in enumerate(poses):
            if len(by_stamp) > used[k]:
                raise error(
                    f"{source}: {len(by_stamp) - used[k]} of {len(by_stamp)} messages of "
                    f"{pose_topic(target_names[k])} have no {target_topic(target_names[k])} "
                    "message of their stamp"
                )
    return StampedMeasurements(
        np.array(stamps, dtype=np.int64),
        np.array(xyz, dtype=float).reshape(-1, 3),
        np.array(target, dtype=np.int64),
        rotation,
        sigma,
    )
