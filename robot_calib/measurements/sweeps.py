"""Circle sweeps (msgs_doc/specification.md section 1): runs of >= 3 consecutive poses in which
exactly one
joint changes. Found from the readings, or from the joint variables of a robot whose readings
are coupled (`RobotDescription.joint_variables`, passed in by the caller); the rest are
general poses."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.poses import JOINT_CHANGE_TOLERANCE

MIN_SWEEP_POSES = 3
MIN_SWEEP_ANGLE_RAD = np.radians(10.0)  # below this a circle's centre is ill-determined


@dataclass(frozen=True)
class Sweep:
    """A circle sweep: `index` (k,) into the recording's poses, all turning `joint` (1-based)."""

    joint: int
    index: IntArray

    @property
    def n_poses(self) -> int:
        return int(len(self.index))

    def shifted(self, offset: int) -> Sweep:
        """The same sweep with its pose indices moved by `offset` (concatenated sources)."""
        return Sweep(self.joint, self.index + offset)


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


def usable_sweeps(
    q: Array, where: str, warnings: list[str], rows: IntArray | None = None
) -> list[Sweep]:
    """The sweeps of readings q (n, J) [rad] that span enough angle to fit a circle; the
    others are left as general poses with a warning appended to `warnings`. `rows` (n,):
    the recording's measurement index of each row of q (the sweeps' indices are mapped to
    them; None: 0..n-1), for the measurements of one target among several."""
    out = []
    for found in find_sweeps(q):
        span = np.ptp(q[found.index, found.joint - 1])
        s = found if rows is None else Sweep(found.joint, rows[found.index])
        if span < MIN_SWEEP_ANGLE_RAD:
            warnings.append(
                f"warning: {where}: sweep of joint {s.joint} at measurements "
                f"{s.index[0] + 1}-{s.index[-1] + 1} spans only {np.degrees(span):.1f} deg: "
                "too small to fit a circle, used as general poses"
            )
            continue
        out.append(s)
    return out
