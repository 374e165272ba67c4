"""What the least-squares fit minimises, from predicted points and their Jacobian.

- `absolute` (default): predicted - measured, 3 rows per pose, tracker frame: O(N).
- `SeedObjective`: the seed paper's (section 6, eq. 18): for every pair of points, the
  predicted distance minus the measured one, plus the distances to fixed anchor points (the
  CPA centres of circles 1, 3 and 5, which keep the cloud from drifting): O(N^2) rows.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from robot_calib.kinematics.frames import Array


class Objective(Protocol):
    """residuals(predicted (n, 3), jac (n, 3, P), measured (n, 3)) -> (r (m,), J (m, P))."""

    @property
    def name(self) -> str: ...

    def n_rows(self, n_points: int) -> int:
        """How many residuals `residuals` gives for n_points measured points."""
        ...

    def residuals(self, predicted: Array, jac: Array, measured: Array) -> tuple[Array, Array]: ...


@dataclass(frozen=True)
class AbsoluteObjective:
    name: str = "absolute"

    def n_rows(self, n_points: int) -> int:
        return 3 * n_points

    def residuals(self, predicted: Array, jac: Array, measured: Array) -> tuple[Array, Array]:
        return (predicted - measured).reshape(-1), jac.reshape(-1, jac.shape[-1])


@dataclass(frozen=True)
class SeedObjective:
    """anchors : (k, 3) fixed points in the tracker frame [m] (seed: circle centres 1, 3, 5)."""

    anchors: Array
    name: str = "seed pairwise distances"

    def n_rows(self, n_points: int) -> int:
        return n_points * (n_points - 1) // 2 + len(self.anchors) * n_points

    def residuals(self, predicted: Array, jac: Array, measured: Array) -> tuple[Array, Array]:
        n = len(predicted)
        i, j = np.triu_indices(n, 1)
        d_pred = predicted[i] - predicted[j]
        dist = np.linalg.norm(d_pred, axis=1)
        unit = d_pred / np.maximum(dist, 1e-12)[:, None]
        r_pairs = dist - np.linalg.norm(measured[i] - measured[j], axis=1)
        j_pairs = np.einsum("ma,map->mp", unit, jac[i] - jac[j])
        rows_r, rows_j = [r_pairs], [j_pairs]
        for anchor in self.anchors:
            to_pred = predicted - anchor
            dist_a = np.linalg.norm(to_pred, axis=1)
            rows_r.append(dist_a - np.linalg.norm(measured - anchor, axis=1))
            rows_j.append(np.einsum("na,nap->np", to_pred / dist_a[:, None], jac))
        return np.concatenate(rows_r), np.concatenate(rows_j)
