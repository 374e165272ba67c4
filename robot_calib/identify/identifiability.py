"""Which parameters the data can identify, from the column-scaled Jacobian.

Columns are scaled to unit norm (so metres and radians compare). Taken in priority order
(geometric first, then effects), a parameter whose column is, but for a tiny fraction, a
combination of the columns already accepted moves no measured point in a way of its own:
it is fixed, with the parameters it duplicates as the reason. The condition number and the
observability index of what stays free come from the SVD.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector

#: A unit column whose part outside the accepted columns is below this is unidentifiable:
#: 1e-6 is far below what tracker noise can resolve over a robot's reach.
RELATIVE_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Identifiability:
    """condition_number and observability_index (Borm-Menq O1 = geometric mean of the
    singular values / sqrt(rows)) of the column-scaled Jacobian of the free parameters;
    fixed: (name, reason) of each parameter fixed by this analysis."""

    condition_number: float
    observability_index: float
    n_free: int
    fixed: tuple[tuple[str, str], ...]


def fix_unidentifiable(
    params: ParameterVector, jac_full: Array, tolerance: float = RELATIVE_TOLERANCE
) -> tuple[ParameterVector, Identifiability]:
    """Fix free parameters the data cannot identify. jac_full : (m, P), d residuals / d every
    parameter of `params` (full vector order). Returns the vector with those fixed (reason
    recorded) and the analysis of what stays free.

    Greedy Gram-Schmidt in priority order (geometric parameters first, then each effect's
    in its own order): a parameter whose unit-scaled column is, to within `tolerance`, a
    combination of the columns already accepted adds nothing the data can see, and is fixed
    at its current value with the accepted parameters it duplicates as the reason.
    """
    free = np.flatnonzero(params.free)
    order = sorted(free, key=lambda i: params.parameters[i].group != "geometric")
    m = jac_full.shape[0]
    basis = np.zeros((m, len(order)))  # orthonormal columns of the accepted parameters
    r_factor = np.zeros((len(order), len(order)))  # accepted (scaled) = basis @ r_factor
    accepted: list[int] = []
    fixed: list[tuple[str, str]] = []
    for i in order:
        column = jac_full[:, i]
        norm = np.linalg.norm(column)
        name = params.names[i]
        if norm == 0.0:
            fixed.append((name, "not identifiable: moves no measured point"))
            continue
        column = column / norm
        k = len(accepted)
        coeff = basis[:, :k].T @ column
        rest = column - basis[:, :k] @ coeff
        extra = basis[:, :k].T @ rest  # second pass: Gram-Schmidt stays orthogonal
        coeff += extra
        rest -= basis[:, :k] @ extra
        left = np.linalg.norm(rest)
        if left > tolerance:
            basis[:, k] = rest / left
            r_factor[:k, k] = coeff
            r_factor[k, k] = left
            accepted.append(i)
            continue
        weights = np.linalg.solve(r_factor[:k, :k], coeff) if k else np.zeros(0)
        top = np.argsort(-np.abs(weights))[:4]
        partners = [params.names[accepted[t]] for t in top if abs(weights[t]) > 1e-3]
        fixed.append(
            (
                name,
                "not identifiable from these poses: moves the points like "
                f"{' + '.join(partners) or 'nothing'} (unexplained part {left:.1e})",
            )
        )
    for name, reason in fixed:
        params = params.fixed([name], reason)
    return params, describe(jac_full[:, params.free], tuple(fixed))


def r_factor(jac: Array) -> Array:
    """R (p, p) of a tall Jacobian's QR (J = Q R): same singular values and right singular
    vectors as J (J^T J = R^T R) at half the cost of J's SVD, and without its (m, p) U."""
    return np.linalg.qr(jac, mode="r") if jac.shape[0] > jac.shape[1] else jac


def describe(jac_free: Array, fixed: tuple[tuple[str, str], ...] = ()) -> Identifiability:
    """Condition number and observability index of a Jacobian (m, p) of free parameters."""
    if jac_free.shape[1] == 0:
        return Identifiability(1.0, 0.0, 0, fixed)
    norms = np.linalg.norm(jac_free, axis=0)
    s = np.linalg.svd(r_factor(jac_free / np.where(norms > 0, norms, 1.0)), compute_uv=False)
    observability = float(np.exp(np.mean(np.log(np.maximum(s, 1e-300)))) / np.sqrt(len(jac_free)))
    return Identifiability(float(s[0] / max(s[-1], 1e-300)), observability, len(s), fixed)


#: A free parameter whose 1-sigma from the data would exceed this (by unit) is not
#: identified in any useful sense: 1 mm for a length, 0.01 rad (0.6 deg) for an angle.
STD_BOUNDS = {"m": 1e-3, "rad": 1e-2, "1": 1e-2, "rad/(N m)": 1e-3, "1/s": 1e-4}


def covariance(jac_free: Array, residuals: Array) -> Array:
    """Covariance (p, p) of the free parameters: sigma^2 (J^T J)^-1, sigma^2 = SSR/(m - p)."""
    m, p = jac_free.shape
    sigma2 = float(residuals @ residuals) / max(m - p, 1)
    _, s, vt = np.linalg.svd(r_factor(jac_free))
    keep = s > s[0] * 1e-12
    scaled = vt[keep].T / s[keep]
    return sigma2 * scaled @ scaled.T


def fix_poorly_determined(
    params: ParameterVector, jac_full: Array, residuals: Array
) -> tuple[ParameterVector, list[tuple[str, str]]]:
    """Fix, one at a time, the free parameter whose predicted 1-sigma most exceeds its
    STD_BOUNDS, until none does. jac_full (m, P) and residuals (m,) at the start point; the
    noise level comes from one linearised (Gauss-Newton) step from there."""
    fixed: list[tuple[str, str]] = []
    while True:
        free = np.flatnonzero(params.free)
        if not len(free):
            return params, fixed
        jac = jac_full[:, free]
        step = np.linalg.lstsq(jac, -residuals, rcond=1e-12)[0]
        cov = covariance(jac, residuals + jac @ step)
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        bounds = np.array([STD_BOUNDS.get(params.parameters[i].unit, np.inf) for i in free])
        ratio = std / bounds
        worst = int(np.argmax(ratio))
        if ratio[worst] <= 1.0:
            return params, fixed
        corr = cov[worst] / np.maximum(std * std[worst], 1e-300)
        partners = [params.names[free[k]] for k in np.argsort(-np.abs(corr))
                    if k != worst and abs(corr[k]) > 0.9][:3]  # fmt: skip
        unit = params.parameters[free[worst]].unit
        reason = (
            f"not identifiable from these poses: its 1-sigma would be {std[worst]:.2g} {unit}"
            + (f", correlated with {', '.join(partners)}" if partners else "")
        )
        params = params.fixed([params.names[free[worst]]], reason)
        fixed.append((params.names[free[worst]], reason))
