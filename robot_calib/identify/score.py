"""How well a calibration predicts measurements it was not fitted on (`robot-calib score`,
`Calibration.score`): absolute errors in the tracker frame (the tracker has not moved since
the calibration, msgs_doc/specification.md section 1) and the seed's frame-free pairwise
criterion, with a per-point table for plots. A score far above the calibration's own
in-sample residual, and orientations that one side has and the other cannot use, are said
in warnings."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from robot_calib.accuracy import Accuracy, OrientationAccuracy, accuracy, orientation_accuracy
from robot_calib.atomic import write_text_atomic
from robot_calib.identify.fit import orientation_residuals
from robot_calib.identify.outliers import OUTLIER_K, outlier_mask, robust_sigma
from robot_calib.kinematics.frames import Array
from robot_calib.measurements import Recording
from robot_calib.messages import target_topic
from robot_calib.model import Calibrated, KinematicModel

if TYPE_CHECKING:
    from robot_calib.identify.cpa import CPAResult

#: a held-out rms this many times the calibration's in-sample rms, and above
#: IMPLAUSIBLE_MM, is no generalisation gap: the calibration does not describe these data
IMPLAUSIBLE_FACTOR = 10.0
IMPLAUSIBLE_MM = 1.0
IMPLAUSIBLE_HINT = "wrong robot, wrong bag, or the tracker moved since the calibration?"

#: the in-sample residual per axis may exceed the noise by this factor before a warning
#: (an unmodelled joint effect such as 2 mrad of backlash leaves about 10 x)
RESIDUAL_FACTOR = 20.0
#: tracker + target noise per axis [m] assumed when the data cannot tell (no circle fits)
DEFAULT_NOISE_M = 10e-6
#: the circle fits' noise is taken as at least this [m]: no tracker resolves finer
MIN_NOISE_M = 1e-6


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
    # 'warning: ...' lines (`score_warnings`), for every output: stdout, stderr, the table
    warnings: tuple[str, ...] = ()

    def lines(self, where: str) -> list[str]:
        """Human lines: absolute mean / rms / max and the seed criterion, in mm, the
        orientation figures, then the warnings."""
        acc = self.accuracy
        out = [
            f"{where}: {acc.n_points} points, absolute error mean {acc.absolute_mean_mm:.4f} / "
            f"rms {acc.absolute_rms_mm:.4f} / max {acc.absolute_max_mm:.4f} mm; "
            + acc.seed_text("seed criterion (pairwise distances)")
        ]
        if self.orientation is not None:
            out.append(f"{where}: {self.orientation.line()}")
        return out + list(self.warnings)


def score(
    calibration: Calibrated,
    recording: Recording,
    *,
    in_sample: Accuracy | None = None,
    fitted: Sequence[str | Path] = (),
    judged_by: str = "the calibration's in-sample rms",
) -> Score:
    """`calibration` (its model at its parameters, less its learned correction: the hybrid
    model's points; orientations have none) scored on every measurement of `recording` (of
    the model's targets; InputError naming a target the model has not identified).
    in_sample, fitted: the calibration's own figures and recordings (PARAMS.json
    `residuals` or, with a learned correction, `hybrid_residuals`: the model actually
    applied; `recordings`), to flag a score far above them, or of a bag it was fitted on
    (`score_warnings`). judged_by: what `in_sample` is, for the warning."""
    model, params = calibration.model, calibration.parameters
    correction = calibration.correction
    recording = recording.with_targets(model.targets)
    predicted = model.target_points(params, recording.poses, correction)
    residuals = predicted - recording.points
    n_suspect = int(outlier_mask(residuals, robust_sigma(residuals)).sum())
    rotation = orientation_residuals(model, params, recording.poses)
    figures = accuracy(recording.points, predicted)
    warnings = score_warnings(figures, in_sample, fitted, model, recording, judged_by)
    if n_suspect:
        warnings.append(
            f"warning: {n_suspect} point(s) beyond {OUTLIER_K:g} robust sigmas of the "
            "others: tracker blunders, or the model does not hold there"
        )
    return Score(
        figures,
        residuals,
        n_suspect,
        rotation,
        None if rotation is None else orientation_accuracy(rotation),
        tuple(warnings),
    )


def score_warnings(
    held_out: Accuracy,
    in_sample: Accuracy | None,
    fitted: Sequence[str | Path],
    model: KinematicModel,
    recording: Recording,
    judged_by: str = "the calibration's in-sample rms",
) -> list[str]:
    """'warning: ...' lines for a score that cannot be taken at face value: a bag among the
    `fitted` recordings (same path or name: the score is in-sample); an absolute rms above
    IMPLAUSIBLE_FACTOR x the `in_sample` rms and above IMPLAUSIBLE_MM (the calibration does
    not describe these data); 6-DoF orientations that the recording has and the model does
    not use, or the model expects and the recording lacks. `recording` indexed by the
    model's targets; `judged_by`: what `in_sample` is (the hybrid model's, physical +
    learned correction, when one is applied)."""
    out = []
    known = [Path(str(f)) for f in fitted]  # as given then (maybe relative)
    for bag in map(Path, recording.sources):
        if any(bag.resolve() == f.resolve() or bag.name == f.name for f in known):
            out.append(
                f"warning: {bag} looks like a bag this calibration was fitted on (same "
                "path or name): its score would be in-sample, not held out"
            )
    where = ", ".join(recording.sources)
    if in_sample is not None:
        rms, fitted_rms = held_out.absolute_rms_mm, in_sample.absolute_rms_mm
        if rms > IMPLAUSIBLE_MM and rms > IMPLAUSIBLE_FACTOR * fitted_rms:
            times = f"{rms / fitted_rms:.0f} x" if fitted_rms > 0 else "far above"
            out.append(
                f"warning: {where}: absolute error rms {rms:.4f} mm is {times} "
                f"{judged_by} {fitted_rms:.4f} mm: implausible for held-out "
                f"data: {IMPLAUSIBLE_HINT}"
            )
    measured = {recording.target_names[int(k)] for k in np.unique(recording.poses.target_index)}
    oriented = recording.oriented_targets
    unused = [target_topic(t) for t in oriented if t not in model.oriented]
    if unused:
        out.append(
            f"warning: {where}: 6-DoF orientations at {', '.join(unused)}, but the "
            "calibration has no probe there (its targets lack six_dof: true): the "
            "orientations are not scored, only the points"
        )
    lacking = [target_topic(t) for t in model.oriented if t in measured and t not in oriented]
    if lacking:
        out.append(
            f"warning: {where}: no 6-DoF orientations at {', '.join(lacking)}, where the "
            "calibration has a probe (six_dof: true): its orientation is not scored, only "
            "the points"
        )
    return out


def write_points_table(result: Score, recording: Recording, path: str | Path) -> None:
    """Per-point CSV: source bag, message index, measured x, y, z [m], residual dx, dy, dz
    (predicted - measured) [m], its norm [m] and the target's topic; with 6-DoF
    measurements also the orientation error's rotation vector rx, ry, rz and angle [rad]
    (empty where none); written atomically. The score's warnings come first, as lines
    starting with '# ' (comment lines: pandas `comment='#'`, numpy `comments='#'`)."""
    text = io.StringIO(newline="")
    for warning in result.warnings:
        text.write(f"# {warning}\r\n")  # as csv.writer ends its lines
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


class WithCircles(Protocol):
    """A calibration whose CPA's circle fits (None: no CPA ran) tell the tracker's noise."""

    @property
    def cpa(self) -> CPAResult | None: ...


def noise_per_axis(cal: WithCircles, stated_sigma_m: float | None = None) -> tuple[float, str]:
    """What the tracker alone leaves per axis [m], and where that figure comes from: the
    circle fits of the sweeps (pooled rms over 3 components, at least MIN_NOISE_M) when
    CPA ran, else the
    user's stated accuracy `stated_sigma_m` [m] (`--tracker-accuracy`), else the assumed
    DEFAULT_NOISE_M."""
    if cal.cpa is not None and cal.cpa.sweeps:
        total = sum(
            float(np.sum(s.circle.plane_residuals**2 + s.circle.radial_residuals**2))
            for s in cal.cpa.sweeps
        )
        count = sum(2 * len(s.circle.plane_residuals) for s in cal.cpa.sweeps)
        # exact (simulated) points fit their circles to round-off: no tracker's noise
        return max(float(np.sqrt(total / count)), MIN_NOISE_M), "circle fits"
    if stated_sigma_m is not None:
        return float(stated_sigma_m), "stated tracker accuracy (given by the user)"
    return DEFAULT_NOISE_M, "assumed tracker noise"


def held_out_warnings(cal: WithCircles, held_out_rms_mm: float, where: str) -> list[str]:
    """A warning when the calibration's held-out absolute rms [mm] (measurements it was
    not fitted on, from `where`) is more than RESIDUAL_FACTOR times the noise per axis
    (`noise_per_axis`; the rms over 3 axes compared per axis, as in-sample), else none."""
    noise, source = noise_per_axis(cal)
    per_axis = held_out_rms_mm * 1e-3 / np.sqrt(3.0)
    if per_axis <= RESIDUAL_FACTOR * noise:
        return []
    return [
        f"warning: {where}: held-out residual {per_axis * 1e3:.4f} mm per axis is "
        f"{per_axis / noise:.0f} x the noise ({noise * 1e3:.4f} mm, {source}): the model "
        "does not generalise to these poses (an unmodelled effect: see `robot-calib "
        "diagnose`), or the tracker moved since the calibration"
    ]
