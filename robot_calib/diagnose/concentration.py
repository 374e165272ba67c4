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

from robot_calib.kinematics.frames import Array
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
        way = (", all the same way (" + ", ".join(f"{v:+.2f}" for v in self.direction) + ")"
               if self.direction else "")  # fmt: skip
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


def stretches(recording: Recording, residuals: Array, floor_mm: float | None,
              joint_names: Sequence[str]) -> list[Stretch]:  # fmt: skip
    """The stretches (module docstring) of `recording`'s residuals (n, 3) [m] (predicted -
    measured, every measurement), largest mean first; `floor_mm` the noise floor (abs rms
    [mm]) or None; `joint_names` (J,) the robot's. Poses (`Recording.pose_index`) are
    judged by their measurements' mean residual, each bag in its own time order."""
    norm = np.linalg.norm(residuals, axis=1)
    pose = recording.pose_index()
    n_poses = int(pose.max()) + 1 if len(pose) else 0
    if n_poses < 2 * MIN_RUN:
        return []
    count = np.bincount(pose, minlength=n_poses)
    pose_norm = np.bincount(pose, weights=norm, minlength=n_poses) / np.maximum(count, 1)
    threshold = HIGH_FACTOR * float(np.median(pose_norm))
    if floor_mm is not None:
        threshold = max(threshold, HIGH_FACTOR * floor_mm * 1e-3)
    first_row = np.full(n_poses, -1)
    first_row[pose[::-1]] = np.arange(len(pose))[::-1]  # each pose's first measurement
    bag, time = recording.bag_index[first_row], recording.poses.time[first_row]
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
        narrow = {joint_names[j]: float(np.degrees(np.mean(q[rows, j])))
                  for j in range(q.shape[1])
                  if span[j] > 0 and np.ptp(q[rows, j]) <= NARROW * span[j]}  # fmt: skip
        out.append(Stretch(recording.sources[int(recording.bag_index[rows[0]])],
                           int(message[rows].min()), int(message[rows].max()), len(poses),
                           mean * 1e3, float(norm[rest].mean()) * 1e3,
                           [float(v) for v in mean_vec / np.linalg.norm(mean_vec)] if same
                           else [], narrow))  # fmt: skip
    return sorted(out, key=lambda s: -s.mean_mm)[:MAX_STRETCHES]
