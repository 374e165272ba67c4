"""Weights of the residuals from the accuracies the tracker stated (msgs_doc/six_dof.md).

Each measurement's position residual (3 rows) is weighted by sigma_ref / sigma_position
and, for a 6-DoF probe, its orientation residual (3 rows, the rotation vector of
predicted * measured^T [rad]) by sigma_ref / sigma_orientation, where sigma_ref is the
median position standard deviation: weighted residuals stay in metres, a measurement
twice as accurate counts four times as much (1 / sigma^2 in the sum of squares), and an
orientation error of sigma_orientation counts as much as a position error of
sigma_position. Where orientations are fitted and some standard deviation is not stated,
the fit solves once with the median of those stated (else the defaults below: a laser
tracker's point, a 6-DoF probe's orientation), then again with the unstated ones taken as
the first solution's residual rms of their kind (one variance component per kind);
without orientations, unstated ones take the median of those stated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robot_calib.kinematics.frames import Array
from robot_calib.poses import Poses

DEFAULT_POSITION_SIGMA_M = 10e-6
DEFAULT_ORIENTATION_SIGMA_RAD = 50e-6


@dataclass(frozen=True)
class RowWeights:
    """position : (n,) factor of each measurement's position residual; orientation : (n,)
    factor of its orientation residual (used where `oriented`); oriented : (n,) which
    measurements have an orientation residual; sigma : (n, 2) the standard deviations the
    weights come from [m, rad] (stated, or filled in)."""

    position: Array
    orientation: Array
    oriented: NDArray[np.bool_]
    sigma: Array
    stated: NDArray[np.bool_]  # (2,) every position / every fitted orientation stated

    @property
    def uniform(self) -> bool:
        """True when the weights change nothing (no orientation, equal position weights)."""
        return not self.oriented.any() and bool(np.all(self.position == 1.0))


def _filled(values: Array, default: float) -> Array:
    """`values` with NaN (not stated) replaced by the median of the others, else `default`."""
    stated = values[np.isfinite(values)]
    return np.where(np.isfinite(values), values, np.median(stated) if len(stated) else default)


def row_weights(
    poses: Poses,
    oriented: NDArray[np.bool_] | None = None,
    fallback: tuple[float, float] | None = None,
) -> RowWeights:
    """The weights of `poses`' residuals; `oriented` (n,): the measurements whose
    orientation is fitted (default: every one with a measured orientation); `fallback`:
    (position [m], orientation [rad]) standard deviations for those not stated (default:
    the median of those stated, else DEFAULT_*)."""
    n = len(poses)
    use = poses.oriented if oriented is None else oriented
    given = np.full((n, 2), np.nan) if poses.sigma is None else poses.sigma
    defaults = fallback or (DEFAULT_POSITION_SIGMA_M, DEFAULT_ORIENTATION_SIGMA_RAD)
    if fallback is None:
        sigma = np.column_stack(
            [_filled(given[:, 0], defaults[0]), _filled(given[:, 1], defaults[1])]
        )
    else:
        sigma = np.where(np.isfinite(given), given, np.array(defaults)[None, :])
    reference = float(np.median(sigma[:, 0])) if n else DEFAULT_POSITION_SIGMA_M
    stated = np.array(
        [np.isfinite(given[:, 0]).all(), np.isfinite(given[use, 1]).all()], dtype=bool
    )
    return RowWeights(reference / sigma[:, 0], reference / sigma[:, 1], use, sigma, stated)


def orientation_errors(predicted: Array, measured: Array) -> Array:
    """Rotation vectors (n, 3) [rad], tracker frame, of predicted * measured^T: the small
    rotation that takes each measured frame (n, 3, 3) onto the predicted one."""
    if not len(predicted):
        return np.zeros((0, 3))
    from scipy.spatial.transform import Rotation  # here: the PARAMS.json readers load no scipy

    return np.asarray(
        Rotation.from_matrix(predicted @ np.transpose(measured, (0, 2, 1))).as_rotvec()
    )
