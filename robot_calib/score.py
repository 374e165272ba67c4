"""`robot-calib score`: how well a calibration (PARAMS.json) predicts measurements it was
not fitted on: absolute errors in the tracker frame (the tracker has not moved since the
calibration, CONTRACT.md section 1) and the seed's frame-free pairwise criterion, with a
per-point table for plots."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robot_calib.accuracy import Accuracy, OrientationAccuracy, accuracy, orientation_accuracy
from robot_calib.atomic import write_text_atomic
from robot_calib.identify.fit import orientation_residuals
from robot_calib.identify.outliers import OUTLIER_K, outlier_mask, robust_sigma
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import Recording
from robot_calib.messages import target_topic
from robot_calib.model import KinematicModel


@dataclass(frozen=True)
class Score:
    """accuracy : both criteria [mm]; residuals : (n, 3) predicted - measured, tracker frame
    [m]; n_suspect : points beyond OUTLIER_K robust sigmas (blunders, or a model that does
    not hold there), counted, not removed."""

    accuracy: Accuracy
    residuals: Array
    n_suspect: int
    # 6-DoF measurements (msgs_doc/six_dof.md): (n, 3) rotation vectors of predicted *
    # measured orientation [rad], NaN where none; their figures (None: none)
    orientation_residuals: Array | None = None
    orientation: OrientationAccuracy | None = None

    def lines(self, where: str) -> list[str]:
        """Human lines: absolute mean / rms / max and the seed criterion, in mm."""
        acc = self.accuracy
        out = [
            f"{where}: {acc.n_points} points, absolute error mean {acc.absolute_mean_mm:.4f} / "
            f"rms {acc.absolute_rms_mm:.4f} / max {acc.absolute_max_mm:.4f} mm; seed criterion "
            f"(pairwise distances) mean {acc.pairwise_mean_mm:.4f} / max "
            f"{acc.pairwise_max_mm:.4f} mm"
        ]
        if self.orientation is not None:
            out.append(f"{where}: {self.orientation.line()}")
        if self.n_suspect:
            out.append(
                f"warning: {self.n_suspect} point(s) beyond {OUTLIER_K:g} robust sigmas of "
                "the others: tracker blunders, or the model does not hold there"
            )
        return out


def score(model: KinematicModel, params: ParameterVector, recording: Recording) -> Score:
    """The calibration `model` at `params` scored on every measurement of `recording`
    (of the model's targets; InputError naming a target the model has not identified)."""
    recording = recording.with_targets(model.targets)
    predicted = model.target_points(params, recording.poses)
    residuals = predicted - recording.points
    n_suspect = int(outlier_mask(residuals, robust_sigma(residuals)).sum())
    rotation = orientation_residuals(model, params, recording.poses)
    return Score(
        accuracy(recording.points, predicted),
        residuals,
        n_suspect,
        rotation,
        None if rotation is None else orientation_accuracy(rotation),
    )


def write_points_table(result: Score, recording: Recording, path: str | Path) -> None:
    """Per-point CSV: source bag, message index, measured x, y, z [m], residual dx, dy, dz
    (predicted - measured) [m], its norm [m] and the target's topic; with 6-DoF
    measurements also the orientation error's rotation vector rx, ry, rz and angle [rad]
    (empty where none); written atomically."""
    text = io.StringIO(newline="")
    writer = csv.writer(text)
    header = ["bag", "index", "x_m", "y_m", "z_m", "dx_m", "dy_m", "dz_m", "error_m", "target"]
    rotation = result.orientation_residuals
    if rotation is not None:
        header += ["rx_rad", "ry_rad", "rz_rad", "angle_rad"]
    writer.writerow(header)
    targets = [target_topic(t) for t in recording.target_names]
    indices = recording.message_indices()
    norms = np.linalg.norm(result.residuals, axis=1)
    for i, (point, residual) in enumerate(zip(recording.points, result.residuals)):
        writer.writerow(
            [recording.sources[int(recording.bag_index[i])], int(indices[i])]
            + [repr(float(v)) for v in (*point, *residual, norms[i])]
            + [targets[int(recording.poses.target_index[i])]]
            + ([] if rotation is None else _rotation_cells(rotation[i]))
        )
    write_text_atomic(path, text.getvalue())


def _rotation_cells(error: Array) -> list[str]:
    """rx, ry, rz, angle [rad] of one orientation error (3,), empty cells when NaN."""
    if not np.all(np.isfinite(error)):
        return ["", "", "", ""]
    return [repr(float(v)) for v in (*error, np.linalg.norm(error))]
