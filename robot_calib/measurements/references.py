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

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.records import Record

if TYPE_CHECKING:
    from scipy.spatial.transform import Rotation

DRIFT_DEGREE = 3  # polynomial degree of each drift component against time
MIN_READS = 2 * (DRIFT_DEGREE + 1)  # reads of the references a drift needs
START_READS = 5  # reads whose median is the references' first positions
JUMP_K = 8.0  # a read this many times the median read's distance from the drift: a jump
MIN_JUMP_M = 1e-5  # ... and at least this far [m] (exact data: no jump at round-off)


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
    # (R, 3) [m, tracker frame] the references' positions at the first read
    start_m: list[list[float]] = field(default_factory=list)
    # reads where the references jumped together (JUMP_K), left out of the drift
    jumps: int = 0

    def line(self) -> str:
        """'reference reflectors A, B, C: tracker drift up to 0.059 mm (0.041 at the end)
        ...'."""
        kind = "rotation and translation" if self.rigid else "translation only (3 or more "
        kind += "" if self.rigid else "references give its rotation too)"
        seen = (f" (read together at {self.reads} of {self.poses} poses)"
                if self.reads < self.poses else "")  # fmt: skip
        if self.jumps:
            seen += (f" ({self.jumps} read(s) where they jumped together, the tracker's frame "
                     "moved at one pose, left out of the drift)")  # fmt: skip
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

    def expected(self, time_s: Array) -> Array:
        """(R, n, 3) [m, tracker frame] where the drift puts each reference at times (n,)."""
        rotation, translation = self.motion(time_s)
        return np.stack([rotation.apply(np.tile(p, (len(translation), 1))) + translation
                         for p in np.asarray(self.start_m, dtype=float)])  # fmt: skip


def _time_basis(time_s: Array, time_range_s: list[float]) -> Array:
    """(n, DRIFT_DEGREE + 1) powers of the times (n,) [s] normalised to the campaign's
    (first, last) [s]."""
    first, last = time_range_s
    u = (np.asarray(time_s, dtype=float) - first) / max(last - first, 1e-9)
    return np.vander(u, DRIFT_DEGREE + 1, increasing=True)


def _motion(values: Array) -> tuple[Rotation, Array]:
    """Rotation and translation (n, 3) [m] of drift values (n, 6): rotation vector [rad],
    then translation."""
    from scipy.spatial.transform import Rotation  # scipy on use: readers of help stay light

    return Rotation.from_rotvec(values[:, :3]), values[:, 3:]


class TooFewReads(ValueError):
    """The references were read together at too few poses for a drift."""


def estimate_drift(names: list[str], time_s: Array, references: Array) -> TrackerDrift:
    """The drift (module docstring) of references (R, n, 3) [m, tracker frame] read at
    times (n,) [s] (NaN where a reference was not read); TooFewReads with fewer than
    MIN_READS reads of every reference."""
    from scipy.spatial.transform import Rotation

    refs = np.asarray(references, dtype=float)
    t = np.asarray(time_s, dtype=float)
    read = np.isfinite(refs).all(axis=2).all(axis=0)  # rows with every reference
    if int(read.sum()) < MIN_READS:
        raise TooFewReads(f"references read together at {int(read.sum())} poses: a drift needs "
                         f"{MIN_READS}")  # fmt: skip
    refs, t = refs[:, read], t[read]
    rigid = len(names) >= 3
    start = np.median(refs[:, :START_READS], axis=1)  # (R, 3): first positions
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
    drift = _fitted(names, rigid, span, t, motions, np.ones(len(t), dtype=bool), start)
    # reads where the references jumped together (the tracker's frame moved at one pose, a
    # knocked nest) are no drift: left out of it, fitted again
    off = np.linalg.norm(refs - drift.expected(t), axis=2).max(axis=0)  # (n,)
    jumped = off > max(JUMP_K * float(np.median(off)), MIN_JUMP_M)
    if jumped.any() and int((~jumped).sum()) >= MIN_READS:
        drift = _fitted(names, rigid, span, t, motions, ~jumped, start)
    else:
        jumped[:] = False
    moved = drift.expected(t)  # (R, n, 3)
    shift = np.linalg.norm(moved - start[:, None], axis=2)
    leftover = (refs - moved)[:, ~jumped]
    dof = max(leftover.size - 6 * (DRIFT_DEGREE + 1) - start.size, 1)
    noise = float(np.sqrt(np.sum(leftover**2) / dof))
    return replace(drift, max_mm=float(shift.max()) * 1e3, end_mm=float(shift[:, -1].max()) * 1e3,
                   noise_mm=noise * 1e3, reads=int(read.sum()), poses=len(read),
                   jumps=int(jumped.sum()))  # fmt: skip


def _fitted(names: list[str], rigid: bool, span: list[float], t: Array, motions: Array,
            use: NDArray[np.bool_], start: Array) -> TrackerDrift:  # fmt: skip
    """The drift whose components are the polynomials fitted to the per-read motions
    (n, 6) at times t (n,) [s] of the rows `use`, relative to the first read (figures
    left 0 for the caller)."""
    basis = _time_basis(t, span)
    coef = np.linalg.lstsq(basis[use], motions[use], rcond=None)[0]  # (D + 1, 6)
    coef[0] -= (basis[:1] @ coef)[0]  # relative to the first read
    return TrackerDrift(list(names), 0.0, 0.0, 0.0, rigid, coef.T.tolist(), span,
                        start_m=start.tolist())  # fmt: skip


@dataclass(frozen=True)
class ReferenceReads:
    """The reference reflectors of one source as read (msgs_doc/references.md).

    source : the source's index in its recording (`Recording.bag_index`)
    names : the reflectors' names (R,)
    stamp_ns : (m,) the stamps of the poses they were read at [ns]
    points : (R, m, 3) [m, tracker frame] as read (NaN: not read at that pose)
    drift : the tracker's drift they show (`estimate_drift` on the stamps in seconds), None
      when they are too few for one (`note` says why)
    """

    source: int
    names: tuple[str, ...]
    stamp_ns: IntArray
    points: Array
    drift: TrackerDrift | None
    note: str = ""

    @classmethod
    def estimated(cls, source: int, names: tuple[str, ...], stamp_ns: IntArray,
                  points: Array) -> ReferenceReads:  # fmt: skip
        """The reads with the drift they show (None with a `note` when they cannot give
        one)."""
        try:
            drift = estimate_drift(list(names), _seconds(stamp_ns), points)
        except TooFewReads as exc:
            return cls(source, names, stamp_ns, points, None, str(exc))
        return cls(source, names, stamp_ns, points, drift)

    def leftover_m(self) -> Array:
        """(m,) [m] per pose, the largest distance of a reference read there from where the
        drift puts it (NaN where none was read, or without a drift): a tracker that jumped
        at one pose moves its references there too."""
        if self.drift is None:
            return np.full(len(self.stamp_ns), np.nan)
        expected: Array = self.drift.expected(_seconds(self.stamp_ns))
        gap = np.linalg.norm(self.points - expected, axis=2)
        gap = np.where(np.isfinite(gap), gap, -np.inf).max(axis=0)
        return np.where(np.isfinite(gap), gap, np.nan)


def _seconds(stamp_ns: IntArray) -> Array:
    """Stamps (n,) [ns] as seconds (n,) [s], float64."""
    return np.asarray(stamp_ns, dtype=np.float64) * 1e-9
