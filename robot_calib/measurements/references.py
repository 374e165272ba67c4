"""Reference reflectors: fixed SMRs measured with every pose, the tracker's own drift.

A reflector fixed on the robot's base or the floor does not move; where the tracker reads
it elsewhere as the campaign goes on, the tracker's frame moved (warming up, a leg
settling, a knock). With three or more references each read is a rigid motion of the
tracker frame (Kabsch against the references' first places, the median of their first
START_READS reads, per row); with one or two a translation only. Those motions, as 3
rotation-vector and 3 translation components against time, are fitted with polynomials of
DRIFT_DEGREE (a drift is smooth in time: the noise of one read is not a motion):

- steps: where the references all move at once between two reads and stay moved (a
  knocked tracker, a re-levelling: STEP_K times the read-to-read scatter, and the median
  place of the STEP_WINDOW reads after it that far from the median of those before), the
  campaign is cut there and each stretch gets its own drift (a lower degree where it has
  few reads): a step is no drift to spread over the campaign;
- jumps: single reads whose references lie far off the drift (JUMP_K times the median
  read's distance) are left out of it;
- the frame "as at the first read" is the fitted drift's at the first read (not forced to
  the noisy first places), so a still tracker gives no drift and no offset.

The drift is removed from every point measured at that time, the tool's targets included.
What the references scatter about it afterwards is the tracker's own noise (per axis,
degrees of freedom counted): a measured noise floor. A scatter above MAX_SCATTER_M is no
tracker's noise (a reflector moved in its nest, nests swapped): no drift is given then
(`NoDrift`), nothing removed, and the reason said.
"""

from __future__ import annotations

from dataclasses import dataclass, field
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
STEP_K = 8.0  # a move between two reads this many times the median one: a step, if it stays
STEP_WINDOW = 5  # reads on each side whose median places tell a step from a jump
MAX_SCATTER_M = 1e-4  # references scattering more about their drift per axis: no drift
SIGNIFICANT = 6.0  # standard errors of the fitted curve a drift must exceed to be one


@dataclass(frozen=True)
class DriftSegment(Record):
    """One stretch of the campaign between steps: its reads' (first, last) times [s] (it
    holds from its first read on), and the polynomial `coefficients` (6, degree + 1) of
    rotation vector [rad] and translation [m] against time normalised to that range."""

    time_range_s: list[float]
    coefficients: list[list[float]]

    def values(self, time_s: Array) -> Array:
        """(n, 6) the fitted motion at times (n,) [s]."""
        coef = np.asarray(self.coefficients)
        first, last = self.time_range_s
        u = (np.asarray(time_s, dtype=float) - first) / max(last - first, 1e-9)
        return np.asarray(np.vander(u, coef.shape[1], increasing=True) @ coef.T)


@dataclass(frozen=True)
class TrackerDrift(Record):
    """The tracker's drift seen by `references` (their names): `max_mm` the largest
    displacement it gives a reference over the campaign against the first read, `end_mm`
    at the last read, `noise_mm` the references' scatter about it per axis (1-sigma),
    `rigid` True with 3+ references (rotation and translation), else translation only;
    `segments` the fitted motion per stretch between steps, `time_range_s` (first, last)
    [s] of the reads."""

    references: list[str]
    max_mm: float
    end_mm: float
    noise_mm: float
    rigid: bool
    segments: list[DriftSegment]
    time_range_s: list[float]
    reads: int = 0  # poses with every reference read (the drift's data)
    poses: int = 0  # poses in all
    # (R, 3) [m, tracker frame] the references' first places (median of the first reads)
    start_m: list[list[float]] = field(default_factory=list)
    # reads where the references jumped together (JUMP_K), left out of the drift
    jumps: int = 0
    # steps: the time [s] of the first read after each, and how far the references moved
    # there [mm]
    step_times_s: list[float] = field(default_factory=list)
    step_mm: list[float] = field(default_factory=list)
    # the displacement the fit gives a reference by noise alone (SIGNIFICANT standard errors
    # of the fitted curve, 3-D) [mm]: a drift below it is none (`significant`)
    uncertainty_mm: float = 0.0

    @property
    def significant(self) -> bool:
        """True when the drift exceeds what the fit gives by noise alone, or has steps:
        only then is it removed from the points."""
        return bool(self.step_mm) or self.max_mm > self.uncertainty_mm

    def line(self) -> str:
        """'reference reflectors A, B, C: tracker drift up to 0.059 mm (0.041 at the end)
        ...'."""
        kind = "rotation and translation" if self.rigid else "translation only (3 or more "
        kind += "" if self.rigid else "references give its rotation too)"
        seen = (
            f" (read together at {self.reads} of {self.poses} poses)"
            if self.reads < self.poses
            else ""
        )
        if self.jumps:
            seen += (
                f" ({self.jumps} read(s) where they jumped together, the tracker's frame "
                "moved at one pose, left out of the drift)"
            )
        if self.step_mm:
            at = ", ".join(
                f"{mm:.4f} mm at {t - self.time_range_s[0]:.0f} s"
                for t, mm in zip(self.step_times_s, self.step_mm)
            )
            seen += (
                f" ({len(self.step_mm)} step(s) where the tracker's frame moved at once "
                f"and stayed: {at}; each stretch's drift fitted on its own)"
            )
        scatter = (
            "their scatter about it (the tracker's noise at fixed reflectors; the "
            f"tool's points add the SMR's and the robot's): {self.noise_mm:.4f} mm per "
            "axis"
        )
        if not self.significant:
            return (
                f"reference reflectors {', '.join(self.references)}{seen}: no drift of the "
                f"tracker beyond the uncertainty of its estimate (up to {self.max_mm:.4f} mm "
                f"fitted, {self.uncertainty_mm:.4f} mm by noise alone): nothing removed; "
                f"{scatter}"
            )
        return (
            f"reference reflectors {', '.join(self.references)}{seen}: the tracker "
            f"drifted up to {self.max_mm:.4f} mm at them ({self.end_mm:.4f} mm at the end; "
            f"{kind}; {self.uncertainty_mm:.4f} mm by noise alone), removed from every "
            f"measured point; {scatter}"
        )

    def _fitted(self, time_s: Array) -> Array:
        """(n, 6) the fitted motion at times (n,) [s]: each time in its stretch."""
        t = np.asarray(time_s, dtype=float)
        starts = np.array([s.time_range_s[0] for s in self.segments])
        which = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
        out = np.zeros((len(t), 6))
        for k, segment in enumerate(self.segments):
            rows = which == k
            if rows.any():
                out[rows] = segment.values(t[rows])
        return out

    def motion(self, time_s: Array) -> tuple[Rotation, Array]:
        """The tracker frame's motion at times (n,) [s] relative to the first read: rotation
        and translation (n, 3) [m] taking a point as read at the first read to where it is
        read then."""
        now_r, now_t = _motion(self._fitted(time_s))
        first_r, first_t = _motion(self._fitted(np.array(self.time_range_s[:1])))
        turn = now_r * first_r.inv()
        return turn, now_t - turn.apply(np.tile(first_t[0], (len(now_t), 1)))

    def removed(self, time_s: Array, points: Array) -> Array:
        """Points (n, 3) [m, tracker frame] read at times (n,) [s], as the tracker would
        have read them at the first read (NaN rows stay NaN)."""
        rotation, translation = self.motion(time_s)
        return rotation.inv().apply(np.asarray(points, dtype=float) - translation)

    def expected(self, time_s: Array) -> Array:
        """(R, n, 3) [m, tracker frame] where the drift puts each reference at times (n,)
        (the fitted motion applied to their first places)."""
        rotation, translation = _motion(self._fitted(time_s))
        return np.stack(
            [
                rotation.apply(np.tile(p, (len(translation), 1))) + translation
                for p in np.asarray(self.start_m, dtype=float)
            ]
        )


def _motion(values: Array) -> tuple[Rotation, Array]:
    """Rotation and translation (n, 3) [m] of drift values (n, 6): rotation vector [rad],
    then translation."""
    from scipy.spatial.transform import Rotation  # scipy on use: readers of help stay light

    return Rotation.from_rotvec(values[:, :3]), values[:, 3:]


class NoDrift(ValueError):
    """The references give no drift (too few reads, or a scatter no tracker has)."""


class TooFewReads(NoDrift):
    """The references were read together at too few poses for a drift."""


def estimate_drift(names: list[str], time_s: Array, references: Array) -> TrackerDrift:
    """The drift (module docstring) of references (R, n, 3) [m, tracker frame] read at
    times (n,) [s] (NaN where a reference was not read); TooFewReads with fewer than
    MIN_READS reads of every reference, NoDrift when they scatter about it beyond
    MAX_SCATTER_M."""
    from scipy.spatial.transform import Rotation

    refs = np.asarray(references, dtype=float)
    t = np.asarray(time_s, dtype=float)
    read = np.isfinite(refs).all(axis=2).all(axis=0)  # rows with every reference
    if int(read.sum()) < MIN_READS:
        each = np.isfinite(refs).all(axis=2).sum(axis=1)
        seldom = ", ".join(f"{n} at {int(c)}" for n, c in zip(names, each) if c < MIN_READS)
        each_text = f" ({seldom} of {refs.shape[1]})" if seldom else ""
        raise TooFewReads(
            f"references read together at {int(read.sum())} poses: a drift needs "
            f"{MIN_READS}{each_text}"
        )
    refs, t = refs[:, read], t[read]
    rigid = len(names) >= 3
    start = np.median(refs[:, :START_READS], axis=1)  # (R, 3): first places
    motions = np.zeros((len(t), 6))
    for k in range(len(t)):
        if rigid:
            rotation, _ = Rotation.align_vectors(
                refs[:, k] - refs[:, k].mean(0), start - start.mean(0)
            )
            motions[k, :3] = rotation.as_rotvec()
            motions[k, 3:] = refs[:, k].mean(0) - rotation.apply(start.mean(0))
        else:
            motions[k, 3:] = np.mean(refs[:, k] - start, axis=0)
    cuts, sizes = _steps(refs)
    use = np.ones(len(t), dtype=bool)
    drift = _fitted(names, rigid, t, motions, use, start, cuts)
    # reads where the references jumped together (the tracker's frame moved at one pose, a
    # knocked nest) are no drift: left out of it, fitted again
    off = np.linalg.norm(refs - drift.expected(t), axis=2).max(axis=0)  # (n,)
    jumped = off > max(JUMP_K * float(np.median(off)), MIN_JUMP_M)
    if jumped.any() and int((~jumped).sum()) >= MIN_READS:
        drift = _fitted(names, rigid, t, motions, ~jumped, start, cuts)
    else:
        jumped[:] = False
    moved = drift.expected(t)  # (R, n, 3)
    first = moved[:, :1]
    shift = np.linalg.norm(moved - first, axis=2)
    leftover = (refs - moved)[:, ~jumped]
    n_coef = sum(6 * len(s.coefficients[0]) for s in drift.segments)
    dof = max(leftover.size - n_coef - start.size, 1)
    noise = float(np.sqrt(np.sum(leftover**2) / dof))
    if noise > MAX_SCATTER_M:
        raise NoDrift(
            f"the references scatter by {noise * 1e3:.4f} mm per axis about their "
            f"smoothest drift (a tracker's noise is below {MAX_SCATTER_M * 1e3:g} "
            "mm): a reflector moved in its nest or nests swapped? No drift "
            "removed"
        )
    # a fitted curve of D + 1 terms through m reads of noise sigma per axis wanders by about
    # sigma sqrt((D + 1) / m) per axis (more near its ends): what a still tracker shows
    wander = max(
        noise * np.sqrt(3.0 * len(s.coefficients[0]) / max(int((~jumped).sum()), 1))
        for s in drift.segments
    )
    return TrackerDrift(
        list(names),
        float(shift.max()) * 1e3,
        float(shift[:, -1].max()) * 1e3,
        noise * 1e3,
        rigid,
        drift.segments,
        [float(t[0]), float(t[-1])],
        int(read.sum()),
        len(read),
        start.tolist(),
        int(jumped.sum()),
        [float(t[c]) for c in cuts],
        sizes,
        SIGNIFICANT * wander * 1e3,
    )


def _steps(refs: Array) -> tuple[list[int], list[float]]:
    """The steps of the references (R, n, 3) [m] (module docstring): the index of the
    first read after each, and how far they moved there [mm]."""
    n = refs.shape[1]
    if n < 2 * STEP_WINDOW:
        return [], []
    moves = np.linalg.norm(np.diff(refs, axis=1), axis=2).max(axis=0)  # (n - 1,)
    scale = max(float(np.median(moves)), MIN_JUMP_M / STEP_K)
    cuts: list[int] = []
    sizes: list[float] = []
    for k in np.flatnonzero(moves > STEP_K * scale):
        before = refs[:, max(k + 1 - STEP_WINDOW, 0) : k + 1]
        after = refs[:, k + 1 : k + 1 + STEP_WINDOW]
        if before.shape[1] < 2 or after.shape[1] < 2:
            continue  # too near an end to tell a step from a jump
        shift = float(
            np.linalg.norm(np.median(after, axis=1) - np.median(before, axis=1), axis=1).max()
        )
        if shift > STEP_K * scale and (not cuts or k + 1 - cuts[-1] >= 2):
            cuts.append(int(k) + 1)
            sizes.append(shift * 1e3)
    return cuts, sizes


def _fitted(
    names: list[str],
    rigid: bool,
    t: Array,
    motions: Array,
    use: NDArray[np.bool_],
    start: Array,
    cuts: list[int],
) -> TrackerDrift:
    """The drift whose stretches (cut at the reads `cuts`) are the polynomials fitted to
    the per-read motions (n, 6) at times t (n,) [s] of the rows `use` (each stretch's
    degree at most DRIFT_DEGREE, lower where it has few reads; figures left 0)."""
    bounds = [0, *cuts, len(t)]
    segments = []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        rows = np.zeros(len(t), dtype=bool)
        rows[lo:hi] = True
        rows &= use
        if not rows.any():
            rows[lo:hi] = True
        degree = int(min(DRIFT_DEGREE, max(int(rows.sum()) // 2 - 1, 0)))
        span = [float(t[lo]), float(t[hi - 1])]
        u = (t[rows] - span[0]) / max(span[1] - span[0], 1e-9)
        basis = np.vander(u, degree + 1, increasing=True)
        coef = np.linalg.lstsq(basis, motions[rows], rcond=None)[0]  # (degree + 1, 6)
        segments.append(DriftSegment(span, coef.T.tolist()))
    return TrackerDrift(
        list(names),
        0.0,
        0.0,
        0.0,
        rigid,
        segments,
        [float(t[0]), float(t[-1])],
        start_m=start.tolist(),
    )


@dataclass(frozen=True)
class ReferenceReads:
    """The reference reflectors of one source as read (msgs_doc/references.md).

    source : the source's index in its recording (`Recording.bag_index`)
    names : the reflectors' names (R,)
    stamp_ns : (m,) the stamps of the poses they were read at [ns]
    points : (R, m, 3) [m, tracker frame] as read (NaN: not read at that pose)
    drift : the tracker's drift they show (`estimate_drift` on the stamps in seconds), None
      when they give none (`note` says why: too few reads, a scatter no tracker has)
    """

    source: int
    names: tuple[str, ...]
    stamp_ns: IntArray
    points: Array
    drift: TrackerDrift | None
    note: str = ""

    @classmethod
    def estimated(
        cls, source: int, names: tuple[str, ...], stamp_ns: IntArray, points: Array
    ) -> ReferenceReads:
        """The reads with the drift they show (None with a `note` when they cannot give
        one)."""
        try:
            drift = estimate_drift(list(names), _seconds(stamp_ns), points)
        except NoDrift as exc:
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
