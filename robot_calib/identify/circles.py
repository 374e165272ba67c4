"""Least-squares plane and circle of a circle sweep (seed section 5, steps 1-5).

1. best-fitting plane (SVD of the centred points); 2. project the points onto it;
3. best-fitting circle in the plane (algebraic fit, refined by Gauss-Newton on the
geometric distance); 4. the centre is a point of the joint axis; 5. the plane normal is
its direction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError
from robot_calib.identify.outliers import OUTLIER_K
from robot_calib.kinematics.frames import Array

MIN_SCREENED_POINTS = 7  # 2 n - 6 >= 8 residual degrees of freedom to judge a point by


@dataclass(frozen=True)
class Circle:
    """A fitted circle in the frame of the input points.

    centre : (3,) [m]; normal : (3,) unit, oriented by the right-hand rule of the sweep's
    visiting order (the joint turning positively about it); radius [m];
    plane_residuals : (n,) signed distances to the plane [m];
    radial_residuals : (n,) in-plane distance to the centre minus radius [m].
    """

    centre: Array
    normal: Array
    radius: float
    plane_residuals: Array
    radial_residuals: Array

    @property
    def rms(self) -> float:
        """Root mean square of the full 3-D point-to-circle residual [m]."""
        return float(np.sqrt(np.mean(self.plane_residuals**2 + self.radial_residuals**2)))

    def distances(self, points: Array) -> Array:
        """(n, 2) signed distance of points (n, 3) [m] to the plane and, in the plane, to
        the circle [m]."""
        rel = np.asarray(points, dtype=float) - self.centre
        height = rel @ self.normal
        radial = np.linalg.norm(rel - height[:, None] * self.normal, axis=1) - self.radius
        return np.column_stack([height, radial])

    def angles(self, points: Array, reference: Array | None = None) -> Array:
        """Angle of each point (n, 3) about the normal [rad], from `reference` (a point)."""
        u = (points[0] if reference is None else reference) - self.centre
        u = u - self.normal * (u @ self.normal)
        u /= np.linalg.norm(u)
        v = np.cross(self.normal, u)
        rel = points - self.centre
        return np.arctan2(rel @ v, rel @ u)


def fit_circle(points: Array, where: str = "sweep") -> Circle:
    """Circle through points (n, 3) [m], n >= 3, visited in order of increasing angle."""
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[0] < 3 or points.shape[1] != 3:
        raise InputError(f"{where}: a circle needs >= 3 points, got shape {points.shape}")
    mean = points.mean(axis=0)
    _, singular, vt = np.linalg.svd(points - mean)
    if singular[1] < 1e-9 * max(singular[0], 1e-300):
        raise InputError(f"{where}: points are collinear, no circle")
    u, v, normal = vt
    local = np.stack([(points - mean) @ u, (points - mean) @ v], axis=1)
    # Algebraic (Kasa) fit: x^2 + y^2 = 2 a x + 2 b y + c.
    design = np.column_stack([2 * local, np.ones(len(local))])
    (a, b, c), *_ = np.linalg.lstsq(design, (local**2).sum(axis=1), rcond=None)
    centre2, radius = np.array([a, b]), float(np.sqrt(c + a * a + b * b))
    for _ in range(20):  # Gauss-Newton on the geometric distance
        rel = local - centre2
        dist = np.linalg.norm(rel, axis=1)
        res = dist - radius
        jac = np.column_stack([-rel / dist[:, None], -np.ones(len(dist))])
        step, *_ = np.linalg.lstsq(jac, -res, rcond=None)
        centre2, radius = centre2 + step[:2], radius + float(step[2])
        if np.max(np.abs(step)) < 1e-13:
            break
    centre = mean + centre2[0] * u + centre2[1] * v
    # Orient the normal so the points advance positively about it.
    rel = points - centre
    turning = np.cross(rel[:-1], rel[1:]).sum(axis=0)
    if turning @ normal < 0:
        normal = -normal
    radial = np.linalg.norm(local - centre2, axis=1) - radius
    return Circle(centre, normal, radius, (points - mean) @ normal, radial)


def _robust_sigma(values: Array) -> float:
    """1.4826 x the median absolute deviation of `values` (any shape) [m], >= 0.1 um."""
    flat = np.asarray(values).reshape(-1)
    return max(1.4826 * float(np.median(np.abs(flat - np.median(flat)))), 1e-7)


def _circle_through(a: Array, b: Array, c: Array) -> Circle | None:
    """The circle through three points (3,) [m] (None when they are collinear); its
    residual arrays are empty (it is a candidate, not a fit)."""
    ab, ac = b - a, c - a
    normal = np.cross(ab, ac)
    area2 = float(normal @ normal)
    if area2 < 1e-24:
        return None
    centre = a + (np.cross(normal, ab) * (ac @ ac) + np.cross(ac, normal) * (ab @ ab)) / (
        2 * area2
    )
    empty = np.zeros(0)
    return Circle(centre, normal / np.sqrt(area2), float(np.linalg.norm(a - centre)), empty, empty)


def robust_circle(
    points: Array,
    where: str = "sweep",
    k: float = OUTLIER_K,
    n_trials: int = 12,
    max_fraction: float = 0.1,
) -> tuple[Circle, NDArray[np.bool_]]:
    """`fit_circle` that leaves out blunders (a lost beam, a reseated target).

    A point 1 m off drags a least-squares circle towards itself, so it is not judged
    against that fit: the start is the circle, of the plain fit and of `n_trials` circles
    through three points spread over the sweep, whose median distance to all the points is
    least (least median of squares); the points within k robust sigmas of it are fitted,
    and the set is updated against that fit until it is stable (a good point misjudged by
    the start comes back). Blunders are few: when more than `max_fraction` of the points
    (and more than one) would go, the arc itself is bent (an effect, e.g. compliance) and
    the plain fit is kept. On clean data the plain fit wins and every point is kept: the result is
    `fit_circle`'s. Below MIN_SCREENED_POINTS points nothing is screened: a circle through
    three of four points fits them exactly, and the fourth would look like a blunder
    whatever its noise (sweeps of 6 poses with 144 deg steps, some of them 360 deg apart).

    Returns
    -------
    circle : Circle
        The fit of the kept points (its residuals are theirs).
    keep : ndarray of bool, shape (n,)
        Which of `points` were kept.
    """
    points = np.asarray(points, dtype=float)
    n = len(points)
    plain = fit_circle(points, where)
    if n < MIN_SCREENED_POINTS:  # too little redundancy to tell a blunder from the noise
        return plain, np.ones(n, dtype=bool)
    candidates = [plain]
    third = n // 3
    for i in np.unique(np.linspace(0, max(third - 1, 0), min(n_trials, third)).astype(int)):
        through = _circle_through(points[i], points[i + third], points[i + 2 * third])
        if through is not None:
            candidates.append(through)
    medians = [np.median(np.linalg.norm(c.distances(points), axis=1)) for c in candidates]
    circle = candidates[int(np.argmin(medians))]
    keep, fitted = np.ones(n, dtype=bool), circle is plain
    for _ in range(5):
        sigma = _robust_sigma(circle.distances(points[keep]))
        again = np.linalg.norm(circle.distances(points), axis=1) <= k * sigma
        if again.sum() < 3 or (fitted and np.array_equal(again, keep)):
            break
        keep, fitted = again, True
        circle = plain if keep.all() else fit_circle(points[keep], where)
    if (~keep).sum() > max(1.0, max_fraction * n):
        return plain, np.ones(n, dtype=bool)
    return circle, keep
