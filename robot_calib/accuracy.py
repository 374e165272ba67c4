"""Accuracy figures (msgs_doc/specification.md section 5): the seed paper's pairwise-distance
criterion,
which needs no common frame, and the absolute point error where the tracker pose is known.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.records import Record

_PAIR_BLOCK = 2048  # rows per block: memory O(block * N), time O(N^2)
#: above this the pairwise figures come from a fixed-size random sample of pairs: the mean's
#: relative standard error is then below 0.3 % (300k pairs), its cost O(1) in the points
#: (the ladder evaluates accuracy dozens of times; all pairs of 2773 points took 1 s each)
MAX_EXACT_POINTS = 1500
SAMPLED_PAIRS = 300_000
NO_PAIR = "n/a (no pair)"  # the seed criterion of fewer than 2 points: it measures nothing


@dataclass(frozen=True)
class Accuracy(Record):
    """Seed criterion over all N(N-1)/2 pairs and absolute distances, in mm for humans."""

    n_points: int
    pairwise_mean_mm: float
    pairwise_max_mm: float
    absolute_mean_mm: float
    absolute_rms_mm: float
    absolute_max_mm: float

    def pairwise_text(self, width: int = 0) -> str:
        """'0.0123 / 0.0456' (the seed criterion's mean / max [mm]; the mean right- and the
        max left-aligned to `width`, a table's column), or 'n/a (no pair)' for fewer than 2
        points: the 0 the figures hold then measures nothing."""
        if self.n_points < 2:
            return f"{NO_PAIR:>{2 * width + 3}}"
        return f"{self.pairwise_mean_mm:>{width}.4f} / {self.pairwise_max_mm:<{width}.4f}"

    def seed_text(self, label: str = "seed criterion") -> str:
        """'seed criterion mean 0.0123 / max 0.0456 mm', or '... n/a (no pair of points)'
        (`label` names the criterion)."""
        if self.n_points < 2:
            return f"{label} n/a (no pair of points)"
        mean, worst = self.pairwise_mean_mm, self.pairwise_max_mm
        return f"{label} mean {mean:.4f} / max {worst:.4f} mm"

    def line(self) -> str:
        return (
            f"{self.seed_text()}"
            f", absolute mean {self.absolute_mean_mm:.4f} / max {self.absolute_max_mm:.4f} mm"
            f" ({self.n_points} points)"
        )


def pairwise_errors(measured: Array, predicted: Array) -> tuple[float, float]:
    """Mean and max [m] over all pairs i<j of | |m_i - m_j| - |p_i - p_j| |, for measured and
    predicted points (N, 3) each in its own frame (seed section 5). Above MAX_EXACT_POINTS
    points, over SAMPLED_PAIRS random pairs (the mean unbiased, the max a lower bound)."""
    n = len(measured)
    if n < 2:
        return 0.0, 0.0
    if n > MAX_EXACT_POINTS:  # O(N^2) pairs: a fixed random sample (the max is then a bound)
        i, j = _sampled_pairs(n)
        points = np.ascontiguousarray(measured, dtype=float)  # the bytes as _distances reads
        between = _distances(points.tobytes(), points.shape)  # the same data: cached
        diff = np.abs(between - np.linalg.norm(predicted[i] - predicted[j], axis=1))
        return float(diff.mean()), float(diff.max())
    total, worst, count = 0.0, 0.0, 0
    for start in range(0, n - 1, _PAIR_BLOCK):
        rows = slice(start, min(start + _PAIR_BLOCK, n - 1))
        dm = np.linalg.norm(measured[rows, None, :] - measured[None, :, :], axis=-1)
        dp = np.linalg.norm(predicted[rows, None, :] - predicted[None, :, :], axis=-1)
        diff = np.abs(dm - dp)
        upper = np.arange(rows.start, rows.stop)[:, None] < np.arange(n)[None, :]
        total += float(diff[upper].sum())
        worst = max(worst, float(diff[upper].max()))
        count += int(upper.sum())
    return total / count, worst


@lru_cache(maxsize=4)
def _sampled_pairs(n: int) -> tuple[IntArray, IntArray]:
    """The SAMPLED_PAIRS random pairs (i, j), i != j, of n points: the same for every n
    (seed 0), read-only (a ladder scores dozens of models on the same points)."""
    i, j = np.random.default_rng(0).integers(0, n, (2, SAMPLED_PAIRS))
    keep = i != j
    i, j = i[keep], j[keep]
    i.flags.writeable = j.flags.writeable = False
    return i, j


@lru_cache(maxsize=4)
def _distances(points: bytes, shape: tuple[int, ...]) -> Array:
    """|p_i - p_j| [m] over `_sampled_pairs` of the points (their bytes and shape (n, 3):
    a key by value, never by identity), read-only."""
    values = np.frombuffer(points, dtype=float).reshape(shape)
    i, j = _sampled_pairs(shape[0])
    out = np.linalg.norm(values[i] - values[j], axis=1)
    out.flags.writeable = False
    return out


def accuracy(measured: Array, predicted: Array) -> Accuracy:
    """Both criteria for measured and predicted points (N, 3) [m] in the tracker frame."""
    mean, worst = pairwise_errors(measured, predicted)
    absolute = np.linalg.norm(predicted - measured, axis=1)
    return Accuracy(
        len(measured),
        mean * 1e3,
        worst * 1e3,
        float(absolute.mean() * 1e3),
        float(np.sqrt(np.mean(absolute**2)) * 1e3),
        float(absolute.max() * 1e3),
    )


@dataclass(frozen=True)
class OrientationAccuracy(Record):
    """Angle between predicted and measured 6-DoF probe frames (the rotation vector's
    norm: all three axes together) over n measurements, and the rms per axis (comparable
    with a per-axis standard deviation: the angle's rms is sqrt(3) x that for equal
    noise on every axis), in urad for humans (1 urad = 0.0573 mdeg)."""

    n_measurements: int
    mean_urad: float
    rms_urad: float
    max_urad: float
    per_axis_rms_urad: float

    def line(self) -> str:
        return (
            f"orientation error angle mean {_angle(self.mean_urad)} / rms "
            f"{_angle(self.rms_urad)} / max {_angle(self.max_urad)}; per axis rms "
            f"{_angle(self.per_axis_rms_urad)} ({self.n_measurements} 6-DoF measurements)"
        )


def _angle(urad: float) -> str:
    """A small angle for humans: urad below 10 mrad, else deg."""
    if urad < 1e4:
        return f"{urad:.1f} urad"
    return f"{np.degrees(urad * 1e-6):.2f} deg"


def orientation_accuracy(errors: Array) -> OrientationAccuracy | None:
    """Figures of rotation vectors errors (n, 3) [rad] (NaN rows: no orientation; None
    when there is none)."""
    rows = np.all(np.isfinite(errors), axis=1)
    if not rows.any():
        return None
    angle = np.linalg.norm(errors[rows], axis=1) * 1e6
    return OrientationAccuracy(
        int(rows.sum()),
        float(angle.mean()),
        float(np.sqrt(np.mean(angle**2))),
        float(angle.max()),
        float(np.sqrt(np.mean(errors[rows] ** 2)) * 1e6),
    )
