"""Which parameters the data can identify, from the column-scaled Jacobian.

Columns are scaled to unit norm (so metres and radians compare). Taken in priority order
(geometric first, then effects), a parameter whose column is, but for a tiny fraction, a
combination of the columns already accepted moves no measured point in a way of its own:
it is fixed, with the parameters it duplicates as the reason. The condition number and the
observability index of what stays free come from the SVD.

Everything here depends on the Jacobian J (m, p) only through J^T J (column norms, inner
products, singular values, least-squares steps). So each function reduces a tall J first to
the R (p, p) of its QR (J = Q R, R^T R = J^T J), computed block by block (`r_factor`): no
copy of the whole (m, p) Jacobian is made, which is what bounds the memory of large fits.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
import numpy.typing as npt

from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import Parameter, ParameterVector

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
    params: ParameterVector,
    jac_full: Array,
    tolerance: float = RELATIVE_TOLERANCE,
    rows: int | None = None,
) -> tuple[ParameterVector, Identifiability]:
    """Fix free parameters the data cannot identify.

    Parameters
    ----------
    params : the parameter vector (P parameters).
    jac_full : (m, P) d residuals / d every parameter of `params` (full vector order), in
        residual units per parameter unit [m/m, m/rad, ...].
    tolerance : a unit-scaled column whose part outside the accepted columns is below this
        is unidentifiable [1].
    rows : the number of residuals m when jac_full is an R factor of the Jacobian (the
        same J^T J), default jac_full's rows.

    Returns
    -------
    The vector with those fixed (reason recorded), and the analysis of what stays free.

    Greedy Gram-Schmidt in priority order (geometric parameters first, then each effect's
    in its own order): a parameter whose unit-scaled column is, to within `tolerance`, a
    combination of the columns already accepted adds nothing the data can see, and is fixed
    at its current value with the accepted parameters it duplicates as the reason. It runs
    on the columns of R (k, p), k <= p, of the free columns' QR: the same norms and inner
    products as J's, without an (m, p) basis.
    """
    free = np.flatnonzero(params.free)
    order = sorted(map(int, free), key=lambda i: params.parameters[i].group != "geometric")
    m = jac_full.shape[0] if rows is None else rows
    columns = r_factor(jac_full, free)  # column c of it: J[:, free[c]] in Q's coordinates
    position = {int(i): c for c, i in enumerate(free)}
    basis = np.zeros((columns.shape[0], len(order)))  # orthonormal: the accepted parameters
    gs_r = np.zeros((len(order), len(order)))  # accepted (scaled) = basis @ gs_r
    accepted: list[int] = []
    fixed: list[tuple[str, str]] = []
    for i in order:
        column = columns[:, position[i]]
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
            gs_r[:k, k] = coeff
            gs_r[k, k] = left
            accepted.append(i)
            continue
        weights = np.linalg.solve(gs_r[:k, :k], coeff) if k else np.zeros(0)
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
    still_free = [position[int(i)] for i in np.flatnonzero(params.free)]
    return params, describe(columns[:, still_free], tuple(fixed), rows=m)


#: Rows of each block of the blocked QR in `r_factor`: a block (with the R so far) stays in
#: cache, and no copy of a whole tall Jacobian is made.
QR_BLOCK_ROWS = 8192


def r_factor(
    jac: Array, columns: npt.NDArray[np.intp] | None = None, extra: Array | None = None
) -> Array:
    """R of the QR of a tall Jacobian, computed block by block.

    Parameters
    ----------
    jac : (m, P) Jacobian [residual unit per parameter unit].
    columns : optional (p,) indices of the columns to use (default: all P), taken one row
        block at a time instead of copying jac[:, columns] whole.
    extra : optional (m,) vector appended as a last column (e.g. the residuals): R of
        [J | extra], whose last column gives Q^T extra and the norm of the rest.

    Returns
    -------
    R : (k, q), q = p (+ 1 with `extra`), k = q when m > q: upper triangular with
    J = Q R, so R^T R = J^T J: the same singular values, right singular vectors, column
    norms and least-squares solutions as J, at half the cost of J's SVD and without its
    (m, p) U. When m <= q the matrix [J[:, columns] | extra] itself (m, q) is returned.

    The QR runs over blocks of QR_BLOCK_ROWS rows: R_new = R of [R_so_far; next rows]
    (a tall-skinny QR), so memory beyond `jac` is one block, whatever m.
    """
    m = jac.shape[0]
    cols = np.arange(jac.shape[1]) if columns is None else np.asarray(columns, dtype=int)
    q = len(cols) + (extra is not None)

    def rows(start: int, stop: int, top: Array) -> Array:
        block = np.empty((len(top) + stop - start, q), order="F")
        block[: len(top)] = top
        block[len(top) :, : len(cols)] = jac[start:stop][:, cols]
        if extra is not None:
            block[len(top) :, -1] = extra[start:stop]
        return block

    if m <= q:
        return rows(0, m, np.zeros((0, q)))
    r = np.zeros((0, q))
    for start in range(0, m, QR_BLOCK_ROWS):
        r = cast(Array, np.linalg.qr(rows(start, min(start + QR_BLOCK_ROWS, m), r), mode="r"))
    return r


def describe(
    jac_free: Array, fixed: tuple[tuple[str, str], ...] = (), rows: int | None = None
) -> Identifiability:
    """Condition number and observability index of a Jacobian of free parameters.

    Parameters
    ----------
    jac_free : (m, p) Jacobian of the free parameters, or any matrix with the same J^T J
        (e.g. its R factor), then with `rows`.
    fixed : (name, reason) of the parameters fixed by the analysis, passed through.
    rows : number of residuals m of the Jacobian (default: jac_free's rows); the
        observability index divides by sqrt(m).
    """
    if jac_free.shape[1] == 0:
        return Identifiability(1.0, 0.0, 0, fixed)
    r = r_factor(jac_free)
    norms = np.linalg.norm(r, axis=0)  # = J's column norms
    s = np.linalg.svd(r / np.where(norms > 0, norms, 1.0), compute_uv=False)
    m = len(jac_free) if rows is None else rows
    observability = float(np.exp(np.mean(np.log(np.maximum(s, 1e-300)))) / np.sqrt(m))
    return Identifiability(float(s[0] / max(s[-1], 1e-300)), observability, len(s), fixed)


#: A free parameter whose 1-sigma from the data would exceed this (by unit) is not
#: identified in any useful sense: 1 mm for a length, 0.01 rad (0.6 deg) for an angle.
STD_BOUNDS = {
    "m": 1e-3,
    "rad": 1e-2,
    "1": 1e-2,
    "rad/(N m)": 1e-3,
    "1/s": 1e-4,
    "1/K": 1e-4,
    "s": 1e4,
    "rad/m": 1e-4,
}
#: tighter bounds for the parameters of one effect (`Parameter.group`) whose values are
#: small in their unit: gravity_compliance's lumped moments k g m c are a few 1e-4 rad
GROUP_STD_BOUNDS = {"gravity_compliance": 5e-5}
#: and for single parameters: thermal_warmup's ln(time constant), judged at a fit start
#: that may be far from the truth, stays free up to +-2 (a factor 7 on tau), far beyond
#: the 0.01 of a dimensionless scale
NAME_STD_BOUNDS = {"thermal_warmup_ln_tau": 2.0}


def covariance(jac_free: Array, residuals: Array, rows: int | None = None) -> Array:
    """Covariance of the free parameters: sigma^2 (J^T J)^-1, sigma^2 = SSR / (m - p).

    Parameters
    ----------
    jac_free : (m, p) Jacobian of the free parameters, or any matrix with the same J^T J
        (e.g. its R factor), then with `rows`.
    residuals : residuals whose sum of squares is the SSR [m]: (m,), or a shorter vector
        with the same norm when jac_free is an R factor.
    rows : number of residuals m (default: jac_free's rows).

    Returns
    -------
    (p, p) covariance [parameter units squared]; directions with singular values below
    1e-12 of the largest are left out (pseudo-inverse).
    """
    m, p = jac_free.shape
    m = m if rows is None else rows
    sigma2 = float(residuals @ residuals) / max(m - p, 1)
    return sigma2 * unit_covariance(jac_free)


def unit_covariance(jac_free: Array) -> Array:
    """(J^T J)^-1 (p, p) [parameter units squared per residual unit squared]: the
    covariance of the free parameters for residuals of unit variance, from a Jacobian
    (m, p) (or any matrix with the same J^T J); directions with singular values below
    1e-12 of the largest are left out (pseudo-inverse)."""
    _, s, vt = np.linalg.svd(r_factor(jac_free))
    keep = s > s[0] * 1e-12
    scaled = vt[keep].T / s[keep]
    return scaled @ scaled.T


def _std_bound(p: Parameter) -> float:
    """The largest 1-sigma parameter `p` may have and stay free (its own, else its
    group's, else its unit's, else none)."""
    if p.name in NAME_STD_BOUNDS:
        return NAME_STD_BOUNDS[p.name]
    return GROUP_STD_BOUNDS.get(p.group, STD_BOUNDS.get(p.unit, np.inf))


def fix_poorly_determined(
    params: ParameterVector,
    jac_full: Array,
    residuals: Array,
    columns_are_free: bool = False,
    rows: int | None = None,
) -> tuple[ParameterVector, list[tuple[str, str]]]:
    """Fix, one at a time, the free parameter whose predicted 1-sigma most exceeds its
    STD_BOUNDS, until none does.

    Parameters
    ----------
    params : the parameter vector (P parameters).
    jac_full : (m, P) d residuals / d every parameter (or, with `columns_are_free`,
        (m, n_free) d residuals / d the free parameters only, in vector order).
    residuals : (m,) residuals there [m]; the noise level comes from one linearised
        (Gauss-Newton) step from there (no step at a converged solution, where it belongs:
        from a poor start the step falls short and the noise looks far too large).
    rows : the number of residuals m when jac_full and residuals are the R of [J | r]
        (the same J^T J, J^T r, r^T r: e.g. a compressed fit's), default jac_full's rows.

    Returns
    -------
    The vector with those fixed (reason recorded), and (name, reason) of each.

    [J_free | r] is reduced once to the R of its QR (`r_factor`, with r as last column):
    every subset of J's columns and r are Q times the same columns of that R, so the steps,
    their residual norms and the covariances are those of J, from (p + 1)-row matrices.
    """
    fixed: list[tuple[str, str]] = []
    m = jac_full.shape[0] if rows is None else rows
    start_free = np.flatnonzero(params.free)
    if not len(start_free):
        return params, fixed
    columns = None if columns_are_free else start_free
    reduced = r_factor(jac_full, columns, residuals)  # [J_free | r] = Q reduced
    jac_start, res = reduced[:, :-1], reduced[:, -1]
    while True:
        free = np.flatnonzero(params.free)
        if not len(free):
            return params, fixed
        jac = jac_start[:, np.searchsorted(start_free, free)]
        step = np.linalg.lstsq(jac, -res, rcond=1e-12)[0]
        cov = covariance(jac, res + jac @ step, rows=m)
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        bounds = np.array([_std_bound(params.parameters[i]) for i in free])
        ratio = std / bounds
        worst = int(np.argmax(ratio))
        if ratio[worst] <= 1.0:
            return params, fixed
        corr = cov[worst] / np.maximum(std * std[worst], 1e-300)
        partners = [
            params.names[free[k]]
            for k in np.argsort(-np.abs(corr))
            if k != worst and abs(corr[k]) > 0.9
        ][:3]
        unit = params.parameters[free[worst]].unit
        reason = (
            f"not identifiable from these poses: its 1-sigma would be {std[worst]:.2g} {unit}"
            + (f", correlated with {', '.join(partners)}" if partners else "")
        )
        params = params.fixed([params.names[free[worst]]], reason)
        fixed.append((params.names[free[worst]], reason))
