"""Where the residual concentrates: stretches of the campaign whose residual is far above
the rest.

A set-up that changed during a campaign (the tracker nudged, an SMR re-seated, the robot
in a region it misses) leaves a run of consecutive measurements off by millimetres while
the rest fit to micrometres. Each of them alone looks like a tracker blunder and is
flagged as one; together they are one event, with a place and a time. Here the best
model's residuals of every measurement (flagged ones included) are read in the order
measured: a run of MIN_RUN or more consecutive measurements each more than HIGH_FACTOR
times the campaign's median residual (and than HIGH_FACTOR times the noise floor, when it
is known) is a stretch. It is named with its measurements (1-based, as the outlier list
names them), its mean residual against the rest's, whether the points moved the same
way (the mean direction's length over the mean length: SAME_WAY or more), and the joints
whose readings stay within NARROW of their range over the campaign there ("joint 1 near
-150 deg").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from robot_calib.kinematics.frames import Array
from robot_calib.measurements import Recording
from robot_calib.records import Record

MIN_RUN = 5  # consecutive measurements that make a stretch
HIGH_FACTOR = 5.0  # a measurement's residual above this times the median is high
SAME_WAY = 0.9  # |mean residual vector| / mean |residual| of points that moved together
NARROW = 0.2  # a joint whose readings span this share of their campaign range: "near"
MAX_STRETCHES = 5  # stretches named (the largest)


@dataclass(frozen=True)
class Stretch(Record):
    """A run of consecutive measurements far above the rest: `first`, `last` (1-based, in
    the order measured), their mean residual and the rest's [mm], the direction they share
    (unit, tracker frame, measured minus predicted as the outlier list gives it; empty when
    they did not move together), and per joint whose
    readings stayed narrow there, its mean reading [deg]."""

    first: int
    last: int
    mean_mm: float
    rest_mean_mm: float
    direction: list[float]
    near_deg: dict[str, float]

    def line(self) -> str:
        """'measurements 1-12 (12 in a row, in the order measured): 5.00 mm mean against
        0.01 mm elsewhere, all the same way (+0.80, -0.60, +0.00); joint 1 near -150 deg: a
        change of the set-up (tracker moved, target re-seated) or a region the model
        misses, not 12 independent blunders'."""
        count = self.last - self.first + 1
        way = (", all the same way (" + ", ".join(f"{v:+.2f}" for v in self.direction) + ")"
               if self.direction else "")  # fmt: skip
        near = (
            "; " + ", ".join(f"{joint} near {deg:.0f} deg" for joint, deg in self.near_deg.items())
            if self.near_deg
            else ""
        )
        return (
            f"measurements {self.first}-{self.last} ({count} in a row, in the order "
            f"measured): {self.mean_mm:.2f} mm mean against {self.rest_mean_mm:.4f} mm "
            f"elsewhere{way}{near}: a change of the set-up (tracker moved, target "
            f"re-seated) or a place the model misses, not {count} independent blunders"
        )


def stretches(recording: Recording, residuals: Array, floor_mm: float | None,
              joint_names: Sequence[str]) -> list[Stretch]:  # fmt: skip
    """The stretches (module docstring) of `recording`'s residuals (n, 3) [m] (predicted -
    measured, every measurement), largest mean first; `floor_mm` the noise floor (abs rms
    [mm]) or None; `joint_names` (J,) the robot's."""
    norm = np.linalg.norm(residuals, axis=1)
    n = len(norm)
    if n < 2 * MIN_RUN:
        return []
    order = np.argsort(recording.poses.time, kind="stable")
    threshold = HIGH_FACTOR * float(np.median(norm))
    if floor_mm is not None:
        threshold = max(threshold, HIGH_FACTOR * floor_mm * 1e-3)
    high = norm[order] > threshold
    runs, start = [], None
    for k, flag in enumerate([*high, False]):
        if flag and start is None:
            start = k
        elif not flag and start is not None:
            if k - start >= MIN_RUN:
                runs.append(order[start:k])
            start = None
    out = []
    q = recording.poses.q
    span = np.ptp(q, axis=0)
    for rows in runs:
        rest = np.ones(n, dtype=bool)
        rest[rows] = False
        mean_vec = -residuals[rows].mean(axis=0)  # measured - predicted: where they moved
        mean = float(norm[rows].mean())
        same = float(np.linalg.norm(mean_vec)) >= SAME_WAY * mean
        narrow = {joint_names[j]: float(np.degrees(np.mean(q[rows, j])))
                  for j in range(q.shape[1])
                  if span[j] > 0 and np.ptp(q[rows, j]) <= NARROW * span[j]}  # fmt: skip
        out.append(Stretch(int(rows.min()) + 1, int(rows.max()) + 1, mean * 1e3,
                           float(norm[rest].mean()) * 1e3,
                           [float(v) for v in mean_vec / np.linalg.norm(mean_vec)] if same
                           else [], narrow))  # fmt: skip
    return sorted(out, key=lambda s: -s.mean_mm)[:MAX_STRETCHES]
