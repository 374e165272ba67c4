"""Reference reflectors: fixed SMRs measured with every pose, the tracker's own drift.

A reflector fixed on the robot's base or the floor does not move; where the tracker reads
it elsewhere as the campaign goes on, the tracker's frame moved (warming up, a leg
settling). With three or more references each read is a rigid motion of the tracker frame
(Kabsch, per row); with one or two a translation only. Those motions, as 3 rotation-vector
and 3 translation components against time, are fitted with polynomials of DRIFT_DEGREE
(a drift is smooth in time: the noise of one read is not a motion), taken relative to the
campaign's first read, and removed from every point measured at that time, the tool's
targets included. What the references scatter about the smooth drift afterwards is the
tracker's own noise (per axis, degrees of freedom counted): a measured noise floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from robot_calib.kinematics.frames import Array
from robot_calib.records import Record

DRIFT_DEGREE = 3  # polynomial degree of each drift component against time
MIN_READS = 2 * (DRIFT_DEGREE + 1)  # reads of the references a drift needs
START_READS = 5  # reads averaged for the references' first positions


@dataclass(frozen=True)
class TrackerDrift(Record):
    """The tracker's drift seen by `references` (their names): `max_mm` the largest
    displacement it gives a reference over the campaign against the first read, `end_mm`
    at the last read, `noise_mm` the references' scatter about it per axis (1-sigma),
    `rigid` True with 3+ references (rotation and translation), else translation only;
    `coefficients` (6, DRIFT_DEGREE + 1) of rotation vector [rad] and translation [m]
    against the normalised time, `time_range_s` (first, last) [s]."""

    references: list[str]
    max_mm: float
    end_mm: float
    noise_mm: float
    rigid: bool
    coefficients: list[list[float]]
    time_range_s: list[float]
    reads: int = 0  # poses with every reference read (the drift's data)
    poses: int = 0  # poses in all

    def line(self) -> str:
        """'reference reflectors A, B, C: tracker drift up to 0.059 mm (0.041 at the end)
        ...'."""
        kind = "rotation and translation" if self.rigid else "translation only (3 or more "
        kind += "" if self.rigid else "references give its rotation too)"
        seen = (f" (read together at {self.reads} of {self.poses} poses)"
                if self.reads < self.poses else "")  # fmt: skip
        return (f"reference reflectors {', '.join(self.references)}{seen}: the tracker "
                "drifted up "
                f"to {self.max_mm:.4f} mm at them ({self.end_mm:.4f} mm at the end; {kind}), "
                "removed from every measured point; their scatter about it (the tracker's "
                f"noise at fixed reflectors; the tool's points add the SMR's and the robot's): "
                f"{self.noise_mm:.4f} mm per axis")  # fmt: skip

    def motion(self, time_s: Array) -> tuple[Rotation, Array]:
        """The tracker frame's motion at times (n,) [s] since the first read: rotation and
        translation (n, 3) [m] taking a point as first read to where it is read then."""
        return _motion(_time_basis(time_s, self.time_range_s) @ np.asarray(self.coefficients).T)

    def removed(self, time_s: Array, points: Array) -> Array:
        """Points (n, 3) [m, tracker frame] read at times (n,) [s], as the tracker would
        have read them at the first read (NaN rows stay NaN)."""
        rotation, translation = self.motion(time_s)
        return rotation.inv().apply(np.asarray(points, dtype=float) - translation)


def _time_basis(time_s: Array, time_range_s: list[float]) -> Array:
    """(n, DRIFT_DEGREE + 1) powers of the times (n,) [s] normalised to the campaign's
    (first, last) [s]."""
    first, last = time_range_s
    u = (np.asarray(time_s, dtype=float) - first) / max(last - first, 1e-9)
    return np.vander(u, DRIFT_DEGREE + 1, increasing=True)


def _motion(values: Array) -> tuple[Rotation, Array]:
    """Rotation and translation (n, 3) [m] of drift values (n, 6): rotation vector [rad],
    then translation."""
    return Rotation.from_rotvec(values[:, :3]), values[:, 3:]


def estimate_drift(names: list[str], time_s: Array, references: Array) -> TrackerDrift:
    """The drift (module docstring) of references (R, n, 3) [m, tracker frame] read at
    times (n,) [s] (NaN where a reference was not read); ValueError with fewer than
    MIN_READS reads of every reference."""
    refs = np.asarray(references, dtype=float)
    t = np.asarray(time_s, dtype=float)
    read = np.isfinite(refs).all(axis=2).all(axis=0)  # rows with every reference
    if int(read.sum()) < MIN_READS:
        raise ValueError(f"references read together at {int(read.sum())} poses: a drift needs "
                         f"{MIN_READS}")  # fmt: skip
    refs, t = refs[:, read], t[read]
    rigid = len(names) >= 3
    start = np.mean(refs[:, :START_READS], axis=1)  # (R, 3): first positions
    motions = np.zeros((len(t), 6))
    for k in range(len(t)):
        if rigid:
            rotation, _ = Rotation.align_vectors(refs[:, k] - refs[:, k].mean(0),
                                                 start - start.mean(0))  # fmt: skip
            motions[k, :3] = rotation.as_rotvec()
            motions[k, 3:] = refs[:, k].mean(0) - rotation.apply(start.mean(0))
        else:
            motions[k, 3:] = np.mean(refs[:, k] - start, axis=0)
    span = [float(t[0]), float(t[-1])]
    basis = _time_basis(t, span)
    coef = np.linalg.lstsq(basis, motions, rcond=None)[0]  # (D + 1, 6)
    coef[0] -= (basis[:1] @ coef)[0]  # relative to the first read
    rotation, translation = _motion(basis @ coef)
    moved = np.stack([rotation.apply(p) + translation for p in start])  # (R, n, 3)
    shift = np.linalg.norm(moved - start[:, None], axis=2)
    leftover = refs - moved
    dof = max(leftover.size - coef.size - start.size, 1)
    noise = float(np.sqrt(np.sum(leftover**2) / dof))
    return TrackerDrift(list(names), float(shift.max()) * 1e3, float(shift[:, -1].max()) * 1e3,
                        noise * 1e3, rigid, coef.T.tolist(), span, int(read.sum()),
                        len(read))  # fmt: skip
