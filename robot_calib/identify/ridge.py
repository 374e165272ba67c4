"""Ridge least squares with the ridge chosen by generalised cross-validation, from normal
equations accumulated block by block (memory O(P^2) for any number of rows): the fit of the
hybrid correction's structured part (`identify.correction_structured_fit`). The columns are
scaled to unit rms; columns holding only rounding noise are left out (TINY_COLUMN).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robot_calib.kinematics.frames import Array

#: the ridge's grid, relative to the largest eigenvalue of the scaled normal equations (and
#: no structure at all: the ridge's other end); ending at the smallest is said
RIDGE_GRID = tuple(float(v) for v in np.logspace(-12, 0, 49))
#: a candidate ridge may spend at most this share of the rows as degrees of freedom
MAX_DOF_SHARE = 0.5
EIGEN_FLOOR = 1e-13  # eigenvalues below this share of the largest: a null direction
#: a column whose rms over the poses is below this share of the largest column's holds only
#: rounding noise (a load zero by the geometry: frame 1's M_y, a vertical axis's torque,
#: ~1e-15 N m): left out of the fit (coefficient zero; scaled to unit rms it would get a
#: coefficient of 1e11 and make the correction a function of the rounding of q)
TINY_COLUMN = 1e-9


@dataclass(frozen=True)
class Ridge:
    """The structured part's fit: coefficients (P,) in the columns' units (zero for the
    columns left out), the ridge relative to the largest eigenvalue of the scaled normal
    equations (inf: no structure), its degrees of freedom, whether it ended at the grid's
    smallest ridge, and how many columns were left out as rounding noise (TINY_COLUMN)."""

    coefficients: Array
    ridge: float
    dof: float
    at_edge: bool
    left_out: int = 0


def kept_columns(gram: Array, rows: int) -> tuple[Array, NDArray[np.bool_]]:
    """The columns' rms (P,) over `rows` rows of normal equations `gram` (P, P), and which
    carry more than rounding noise (rms above TINY_COLUMN x the largest)."""
    scale = np.sqrt(np.maximum(np.diag(gram), 0.0) / max(rows, 1))
    top = float(scale.max()) if scale.size else 0.0
    return scale, scale > TINY_COLUMN * top


def gcv_ridge(gram: Array, rhs: Array, total: float, rows: int) -> Ridge:
    """The ridge solution of the normal equations (gram (P, P), rhs (P,), y.y `total`, of
    `rows` rows) with the ridge of least generalised cross-validation
    RSS / (rows - dof)^2 over RIDGE_GRID and no structure at all; columns of rounding noise
    (`kept_columns`) left out (coefficient zero)."""
    coefficients = np.zeros(len(rhs))
    scale, kept = kept_columns(gram, rows)
    left_out = int(np.sum(~kept))
    if not kept.any():
        return Ridge(coefficients, math.inf, 0.0, False, left_out)
    scale = scale[kept]
    values, vectors = np.linalg.eigh(gram[np.ix_(kept, kept)] / np.outer(scale, scale))
    keep = values > EIGEN_FLOOR * max(float(values[-1]), 0.0)
    values, vectors = values[keep], vectors[:, keep]
    projected = vectors.T @ (rhs[kept] / scale)  # V^T A^T y
    u_y = projected / np.sqrt(values)  # U^T y
    explained = float(np.sum(u_y**2))
    best = (total / rows**2, math.inf, 0.0)  # no structure: RSS = y.y, dof 0
    top = float(values[-1]) if len(values) else 0.0
    for relative in RIDGE_GRID:
        shrink = values / (values + relative * top)
        dof = float(np.sum(shrink))
        if dof > MAX_DOF_SHARE * rows:
            continue
        rss = max(total - explained, 0.0) + float(np.sum(((1.0 - shrink) * u_y) ** 2))
        gcv = rss / (rows - dof) ** 2
        if gcv < best[0]:
            best = (gcv, relative, dof)
    _, relative, dof = best
    if not math.isfinite(relative):
        return Ridge(coefficients, math.inf, 0.0, False, left_out)
    coefficients[kept] = vectors @ (projected / (values + relative * top)) / scale
    return Ridge(coefficients, relative, dof, relative == RIDGE_GRID[0], left_out)
