"""Where the residual concentrates: stretches of the campaign whose residual is far above
the rest.

A set-up that changed during a campaign (the tracker nudged, an SMR re-seated, the robot
in a region it misses) leaves a run of consecutive measurements off by millimetres while
the rest fit to micrometres. Each of them alone looks like a tracker blunder and is
flagged as one; together they are one event, with a place and a time. Here the best
model's residuals of every measurement (flagged ones included) are averaged per pose and
read in the order measured, bag by bag: a run of MIN_RUN or more consecutive poses each
more than HIGH_FACTOR times the campaign's median (and than HIGH_FACTOR times the noise
floor, when it is known) is a stretch. It is named with its bag and points (0-based, as
the outlier list names them), its mean residual against the rest's, whether the points
moved the same way (the mean direction's length over the mean length: SAME_WAY or more),
and the joints whose readings stay within NARROW of their range over the campaign there
("joint 1 near -150 deg").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.measurements import Recording
from robot_calib.records import Record

MIN_RUN = 5  # consecutive poses that make a stretch
HIGH_FACTOR = 5.0  # a measurement's residual above this times the median is high
SAME_WAY = 0.9  # |mean residual vector| / mean |residual| of points that moved together
NARROW = 0.2  # a joint whose readings span this share of their campaign range: "near"
MAX_STRETCHES = 5  # stretches named (the largest)


@dataclass(frozen=True)
class Stretch(Record):
    """A run of consecutive poses of one bag far above the rest: `bag`, the 0-based indices
    of its first and last tracker-point messages there (as the outlier lines count them),
    how many `poses`, their mean residual and the rest's [mm], the direction they share
    (unit, tracker frame, measured minus predicted as the outlier list gives it; empty when
    they did not move together), and per joint whose readings stayed narrow there, its
    mean reading [deg]."""

    bag: str
    first_point: int
    last_point: int
    poses: int
    mean_mm: float
    rest_mean_mm: float
    direction: list[float]
    near_deg: dict[str, float]

    def line(self) -> str:
        """'run.mcap points 0-11 (12 poses in a row, in the order measured): 5.00 mm mean
        against 0.01 mm elsewhere, all the same way (+0.80, -0.60, +0.00); joint_a1 near
        -150 deg: a change of the set-up (tracker moved, target re-seated) or a place the
        model misses, not 12 independent blunders'."""
        way = (
            ", all the same way (" + ", ".join(f"{v:+.2f}" for v in self.direction) + ")"
            if self.direction
            else ""
        )
        near = (
            "; " + ", ".join(f"{joint} near {deg:.0f} deg" for joint, deg in self.near_deg.items())
            if self.near_deg
            else ""
        )
        return (
            f"{self.bag} points {self.first_point}-{self.last_point} ({self.poses} poses in a "
            f"row, in the order measured): {self.mean_mm:.2f} mm mean against "
            f"{self.rest_mean_mm:.4f} mm elsewhere{way}{near}: a change of the set-up "
            "(tracker moved, target re-seated) or a place the model misses, not "
            f"{self.poses} independent blunders"
        )


@dataclass(frozen=True)
class _PoseResiduals:
    """The residual norms of every measurement, per pose: `pose` (n,) each measurement's
    pose (`Recording.pose_index`), `first_row` (P,) each pose's first measurement, `norm`
    (n,) [m] each measurement's, `pose_norm` (P,) [m] each pose's mean, and `threshold`
    [m] above which a pose is high (HIGH_FACTOR x their median, and x the noise floor when
    known)."""

    pose: IntArray
    first_row: IntArray
    norm: Array
    pose_norm: Array
    threshold: float


def _per_pose(
    recording: Recording, residuals: Array, floor_mm: float | None
) -> _PoseResiduals | None:
    """`_PoseResiduals` of `recording`'s residuals (n, 3) [m]; None with fewer than
    2 x MIN_RUN poses (nothing to stand out from)."""
    norm = np.linalg.norm(residuals, axis=1)
    pose = recording.pose_index()
    n_poses = int(pose.max()) + 1 if len(pose) else 0
    if n_poses < 2 * MIN_RUN:
        return None
    count = np.bincount(pose, minlength=n_poses)
    pose_norm = np.bincount(pose, weights=norm, minlength=n_poses) / np.maximum(count, 1)
    threshold = HIGH_FACTOR * float(np.median(pose_norm))
    if floor_mm is not None:
        threshold = max(threshold, HIGH_FACTOR * floor_mm * 1e-3)
    first_row = np.full(n_poses, -1)
    first_row[pose[::-1]] = np.arange(len(pose))[::-1]  # each pose's first measurement
    return _PoseResiduals(pose, first_row, norm, pose_norm, threshold)


def stretches(
    recording: Recording, residuals: Array, floor_mm: float | None, joint_names: Sequence[str]
) -> list[Stretch]:
    """The stretches (module docstring) of `recording`'s residuals (n, 3) [m] (predicted -
    measured, every measurement), largest mean first; `floor_mm` the noise floor (abs rms
    [mm]) or None; `joint_names` (J,) the robot's. Poses (`Recording.pose_index`) are
    judged by their measurements' mean residual, each bag in its own time order."""
    per = _per_pose(recording, residuals, floor_mm)
    if per is None:
        return []
    pose, norm, pose_norm, threshold = per.pose, per.norm, per.pose_norm, per.threshold
    bag, time = recording.bag_index[per.first_row], recording.poses.time[per.first_row]
    runs = []
    for b in np.unique(bag):
        mine = np.flatnonzero(bag == b)
        mine = mine[np.argsort(time[mine], kind="stable")]
        high = pose_norm[mine] > threshold
        start = None
        for k, flag in enumerate([*high, False]):
            if flag and start is None:
                start = k
            elif not flag and start is not None:
                if k - start >= MIN_RUN:
                    runs.append(mine[start:k])
                start = None
    q = recording.poses.q
    span = np.ptp(q, axis=0)
    message = recording.message_indices()
    out = []
    for poses in runs:
        rows = np.flatnonzero(np.isin(pose, poses))
        rest = ~np.isin(pose, poses)
        mean_vec = -residuals[rows].mean(axis=0)  # measured - predicted: where they moved
        mean = float(norm[rows].mean())
        same = float(np.linalg.norm(mean_vec)) >= SAME_WAY * mean
        narrow = {
            joint_names[j]: float(np.degrees(np.mean(q[rows, j])))
            for j in range(q.shape[1])
            if span[j] > 0 and np.ptp(q[rows, j]) <= NARROW * span[j]
        }
        out.append(
            Stretch(
                recording.sources[int(recording.bag_index[rows[0]])],
                int(message[rows].min()),
                int(message[rows].max()),
                len(poses),
                mean * 1e3,
                float(norm[rest].mean()) * 1e3,
                [float(v) for v in mean_vec / np.linalg.norm(mean_vec)] if same else [],
                narrow,
            )
        )
    return sorted(out, key=lambda s: -s.mean_mm)[:MAX_STRETCHES]


#: a joint-space region: at least this share of the poses whose reading lies in a window
#: of NARROW of the joint's range is high, and at least MIN_RUN of them
REGION_SHARE = 0.8


@dataclass(frozen=True)
class Region(Record):
    """A region of one joint's readings where the poses' residual is far above the rest,
    whenever they were measured (`regions`): the joint, its readings' range there [deg],
    how many poses and how many of them high, their mean residual and the rest's [mm]."""

    joint: str
    low_deg: float
    high_deg: float
    poses: int
    high_poses: int
    mean_mm: float
    rest_mean_mm: float

    def line(self) -> str:
        """'joint_a2 from -120 to -95 deg: 14 poses, 13 of them high, 0.85 mm mean against
        0.0120 mm elsewhere: a place the model misses (or the set-up there)'."""
        return (
            f"{self.joint} from {self.low_deg:.0f} to {self.high_deg:.0f} deg: "
            f"{self.poses} poses, {self.high_poses} of them high, {self.mean_mm:.2f} mm "
            f"mean against {self.rest_mean_mm:.4f} mm elsewhere: a place the model "
            "misses (or the set-up there)"
        )


def regions(
    recording: Recording,
    residuals: Array,
    floor_mm: float | None,
    joint_names: Sequence[str],
    taken: Sequence[Stretch] = (),
) -> list[Region]:
    """The regions of joint space whose poses' residual (`_per_pose`, under the best model)
    is high whenever they were measured: per joint, the window (at most NARROW of its
    range, from one high pose's reading to another's) holding the most high poses, at
    least MIN_RUN of them and REGION_SHARE of its poses;
    poses of the `taken` stretches are left out (named already). The regions of every
    joint that holds one, most high poses first (MAX_STRETCHES)."""
    per = _per_pose(recording, residuals, floor_mm)
    if per is None:
        return []
    pose_norm = per.pose_norm
    q = recording.poses.q[per.first_row]  # (P, J)
    keep = np.ones(len(pose_norm), dtype=bool)
    points = recording.message_indices()[per.first_row]
    sources = [recording.sources[int(b)] for b in recording.bag_index[per.first_row]]
    for stretch in taken:
        mine = np.array([source == stretch.bag for source in sources])
        keep &= ~(mine & (points >= stretch.first_point) & (points <= stretch.last_point))
    high = (pose_norm > per.threshold) & keep
    out = []
    for j in range(q.shape[1]):
        width = NARROW * float(np.ptp(q[:, j]))
        if width <= 0 or high.sum() < MIN_RUN:
            continue
        best: tuple[int, float, float] | None = None
        levels = np.unique(q[high, j])
        for k, start in enumerate(levels):  # windows from one high reading to another
            end = levels[k:][levels[k:] <= start + width][-1]
            inside = keep & (q[:, j] >= start) & (q[:, j] <= end)
            count = int((inside & high).sum())
            if (
                count >= MIN_RUN
                and count >= REGION_SHARE * inside.sum()
                and (best is None or count > best[0])
            ):
                best = (count, float(start), float(end))
        if best is None:
            continue
        count, lo, hi = best
        inside = keep & (q[:, j] >= lo) & (q[:, j] <= hi)
        out.append(
            Region(
                joint_names[j],
                float(np.degrees(lo)),
                float(np.degrees(hi)),
                int(inside.sum()),
                count,
                float(pose_norm[inside].mean()) * 1e3,
                float(pose_norm[~inside].mean()) * 1e3,
            )
        )
    return sorted(out, key=lambda r: -r.high_poses)[:MAX_STRETCHES]
