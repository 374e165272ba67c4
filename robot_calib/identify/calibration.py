"""The identified model, `Calibration` (what `identify.calibrate` computes and
`identify.plausibility` judges), its PARAMS.json document both ways (the format itself:
`identify.params_file`) and its human summary.

Below the code that computes it: this module imports neither `calibrate` nor
`plausibility`. Values are SI (m, rad); the summary printed for people is in mm and deg,
labelled.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from robot_calib.accuracy import Accuracy, accuracy, orientation_accuracy
from robot_calib.errors import InputError, RobotCalibError
from robot_calib.identify.identifiability import Identifiability
from robot_calib.identify.params_file import (
    FORMAT,
    correction_of,
    description_section,
    fixed_reasons,
    human_value,
    implausible_of,
    in_sample_accuracy,
    outlier_lines,
    params_from_dict,
    read_document,
)
from robot_calib.identify.reports import Outlier, SolverReport
from robot_calib.kinematics.frames import Array, matrix_to_rpy
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.messages import target_topic
from robot_calib.model import KinematicModel, target_parameters

if TYPE_CHECKING:
    from robot_calib.identify.correction_structured import LearnedCorrection
    from robot_calib.identify.cpa import CPAResult
    from robot_calib.identify.score import Score
    from robot_calib.measurements import Recording
    from robot_calib.poses import Poses

#: what the hybrid model's label adds to its physical model's name (`Calibration.label`)
LEARNED_SUFFIX = "+learned"


@dataclass(frozen=True)
class Calibration:
    """An identified model: its name, forward model, parameters with 1-sigma std (P,) in
    SI units (0 where fixed), in-sample accuracy and the evidence behind it."""

    name: str
    model: KinematicModel
    parameters: ParameterVector
    std: Array
    accuracy: Accuracy
    residuals: Array  # (n, 3) predicted - measured [m]; (0, 3) when read from a file
    identifiability: Identifiability | None = None
    solver: SolverReport = field(default_factory=lambda: SolverReport("none"))
    cpa: CPAResult | None = None
    outliers: tuple[Outlier, ...] = ()  # measurements flagged as blunders, not fitted
    warnings: tuple[str, ...] = ()  # implausible results, labelled (`plausibility`)
    inliers: NDArray[np.bool_] | None = None  # (n,) of the recording given; None: all
    # free parameters that the first target's measurements alone could not identify: what
    # the further targets add (msgs_doc/targets.md); empty with one target
    by_extra_targets: tuple[str, ...] = ()
    # (n, 3) rotation vectors of predicted * measured 6-DoF orientation [rad], tracker
    # frame, NaN where none was fitted; None without 6-DoF measurements
    orientation_residuals: Array | None = None
    # a learned correction of what the model leaves (`identify.correction_structured`,
    # `identify.correction` in files of format 1: the hybrid model); `predict` subtracts
    # its predicted residual; None: the physical model alone
    correction: LearnedCorrection | None = None
    # why the result is nonsense rather than a calibration (`plausibility.implausible_reasons`:
    # readings in degrees, residual > 1000 x noise, parameters beyond physics, worse than the
    # simpler model it extends), one line each; empty: plausible (PARAMS.json `plausible`)
    implausible: tuple[str, ...] = ()
    # the simpler model this one extends, fitted first on the same measurements: its name
    # and in-sample rms per axis [m]; None when none was fitted here (a base model, a start)
    simpler: tuple[str, float] | None = None
    # read from a PARAMS.json: the bags it was fitted on (`recordings`) and the hybrid
    # model's in-sample figures (`hybrid_residuals`; None: none, or not read from a file)
    recordings: tuple[str, ...] = ()
    hybrid_accuracy: Accuracy | None = None

    @property
    def plausible(self) -> bool:
        """False when `implausible` names a reason (PARAMS.json `plausible`)."""
        return not self.implausible

    def applied_accuracy(self) -> tuple[Accuracy, str]:
        """The in-sample figures of the model this calibration applies, and what they are
        (for people): the physical model's, or with a learned correction the hybrid
        model's when known (`hybrid_accuracy`; `hybrid_in_sample` computes them)."""
        if self.correction is None:
            return self.accuracy, "the calibration's in-sample rms"
        if self.hybrid_accuracy is not None:
            return self.hybrid_accuracy, "the hybrid model's in-sample rms"
        return self.accuracy, (
            "the physical model's in-sample rms (the file has no "
            "hybrid_residuals: written before them)"
        )

    def predict(self, poses: Poses) -> Array:
        """Target points (n, 3) [m] in the tracker frame: the model's, minus the learned
        correction's predicted residual when the calibration has one."""
        return self.model.target_points(self.parameters, poses, self.correction)

    @property
    def label(self) -> str:
        """The model's name for people: `name` (the physical model, what `--model` and
        PARAMS.json `model` parse), plus LEARNED_SUFFIX when a learned correction completes
        it (the hybrid model)."""
        return self.name + (LEARNED_SUFFIX if self.correction is not None else "")

    def with_learned_correction(self, recording: Recording) -> Calibration:
        """This calibration with a correction learned from its residuals at the measurements
        of `recording` (its calibration recording) it fitted (load-driven geometry, then a
        Gaussian process: `identify.correction_structured`, the hybrid model); `accuracy`
        and `residuals` stay the physical model's."""
        from robot_calib.identify.correction import fitting_rows
        from robot_calib.identify.correction_structured_fit import fit_structured

        fitted = recording if self.inliers is None else recording.subset(self.inliers)
        keep = np.zeros(len(fitted), dtype=bool)
        keep[fitting_rows(len(fitted))] = True  # at most MAX_FIT_POSES of them
        fitted = fitted.subset(keep)
        residuals = self.model.target_points(self.parameters, fitted.poses) - fitted.points
        learned = fit_structured(self.model, self.parameters, fitted.poses, residuals)
        hybrid = replace(self, correction=learned)
        return replace(hybrid, hybrid_accuracy=hybrid_in_sample(hybrid, recording))

    def to_dict(self, recording: Recording) -> dict[str, Any]:
        """The PARAMS.json document (msgs_doc/parameters.md) of this calibration from
        `recording` (its sources, counts and warnings go into the document)."""
        return calibration_to_dict(self, recording)

    def save(self, path: str | Path, recording: Recording) -> Path:
        """Write this calibration from `recording` as a PARAMS.json at `path` (atomically:
        a failure leaves no half file); the path written. `Calibration.load` reads it."""
        from robot_calib.identify.params_file import write_json_atomic

        path = Path(path)
        write_json_atomic(self.to_dict(recording), path)
        return path

    @classmethod
    def load(cls, path: str | Path, where: str | None = None) -> Calibration:
        """The calibration of a PARAMS.json file (`from_dict`): the one loader every front
        end uses for a whole calibration; messages name `where` (default: `path`)."""
        return load_calibration(path, where)

    def score(self, recording: Recording, *, fitted: Sequence[str] | None = None) -> Score:
        """This calibration's errors on `recording` (held out, or its own): absolute and
        seed-criterion figures [mm], residuals, suspect points (`robot_calib.identify.score`),
        and the warnings every front end gives: far above the applied model's in-sample
        figures, a bag it was fitted on (`fitted`, default: the PARAMS.json's `recordings`),
        far above the tracker's noise (`held_out_warnings`)."""
        from robot_calib.identify.score import held_out_warnings, score

        in_sample, judged_by = self.applied_accuracy()
        fitted = self.recordings if fitted is None else fitted
        scored = score(self, recording, in_sample=in_sample, fitted=fitted, judged_by=judged_by)
        if set(recording.sources) & set(fitted):  # its own measurements: not held out
            return scored
        where = ", ".join(recording.sources)
        noise = held_out_warnings(self, scored.accuracy.absolute_rms_mm, where)
        return replace(scored, warnings=(*scored.warnings, *noise))

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any], where: str = "PARAMS.json") -> Calibration:
        """The calibration of a PARAMS.json document: model, parameters, 1-sigma, in-sample
        accuracy, identifiability (its figures; the parameters it fixed are those fixed in
        the file but free in the model), solver report and learned correction (None without
        a `correction` section). The per-point residuals and the CPA circles are not in the
        file: residuals is empty (0, 3), cpa None."""
        model, params = params_from_dict(doc, where)
        correction = correction_of(doc, model, params, where)  # None: the physical model alone
        acc = in_sample_accuracy(doc, where)
        if acc is None:
            raise InputError(f"{where}: malformed parameter file (no 'residuals')")
        hybrid = in_sample_accuracy(doc, where, "hybrid_residuals")
        recordings = doc.get("recordings", [])
        if not isinstance(recordings, list) or not all(isinstance(r, str) for r in recordings):
            raise InputError(f"{where}: 'recordings' must be a list of bag paths")
        try:
            std = np.array([float(r.get("std", 0.0)) for r in doc["parameters"]])
            solver = SolverReport.from_dict(doc.get("solver") or {"method": "unknown"})
            ident = None
            if "identifiability" in doc:
                figures = doc["identifiability"]
                structural = model.parameters()
                by_data = tuple(
                    (p.name, p.fixed_reason)
                    for p in params.parameters
                    if not p.free and structural.parameters[structural.index(p.name)].free
                )
                ident = Identifiability(
                    float(figures["condition_number"]),
                    float(figures["observability_index"]),
                    int(figures["free_parameters"]),
                    by_data,
                )
        except (KeyError, TypeError, ValueError, RobotCalibError) as exc:
            raise InputError(f"{where}: malformed parameter file ({exc})") from None
        try:
            outliers = tuple(Outlier.from_dict(o) for o in doc.get("outliers", []))
        except (TypeError, RobotCalibError) as exc:
            raise InputError(f"{where}: malformed outliers ({exc})") from None
        return cls(
            str(doc.get("model", "")),
            model,
            params,
            std,
            acc,
            np.empty((0, 3)),
            ident,
            solver,
            outliers=outliers,
            correction=correction,
            implausible=implausible_of(doc, where, model, params),
            recordings=tuple(recordings),
            hybrid_accuracy=hybrid,
        )


def calibration_to_dict(cal: Calibration, recording: Recording) -> dict[str, Any]:
    """The JSON document of a calibration (see msgs_doc/parameters.md)."""
    robot = cal.model.robot
    records = cal.parameters.to_dict()
    for record, std in zip(records, cal.std):
        record["std"] = float(std)
    doc: dict[str, Any] = {
        "format": FORMAT,
        "model": cal.name,
        "robot": robot.reference(),
        "robot_fingerprint": robot.fingerprint(),
        **({"robot_description": section} if (section := description_section(robot)) else {}),
        **(
            {"payload": {"mass_kg": robot.payload_kg, "com_m": list(robot.payload_com_m)}}
            if robot.payload_kg
            else {}
        ),
        "effects": [e.to_dict() for e in cal.model.effects],
        "parameters": records,
        "fixed": [
            {"name": p.name, "reason": p.fixed_reason}
            for p in cal.parameters.parameters
            if not p.free
        ],
        "residuals": cal.accuracy.to_dict(),
        "solver": cal.solver.to_dict(),
        "recordings": list(recording.sources),
        "measurements": {
            "paired": len(recording),
            "unpaired": recording.n_unpaired,
            "sweeps": len(recording.sweeps),
            "general_poses": int(recording.general.sum()),
        },
        "warnings": list(recording.warnings) + list(cal.warnings),
        "plausible": cal.plausible,
        "implausible": list(cal.implausible),
        "outliers": [o.to_dict() for o in cal.outliers],
        "targets": [
            {
                "name": name,
                "topic": target_topic(name),
                "measurements": int(np.sum(recording.poses.target_index == k)),
                "offset_m": [cal.parameters[p] for p in target_parameters(name)],
                **(
                    {
                        "six_dof": True,
                        "probe_rpy_deg": np.degrees(
                            matrix_to_rpy(cal.model.tool_rotations(cal.parameters)[k])
                        ).tolist(),
                    }
                    if name in cal.model.oriented
                    else {}
                ),
            }
            for k, name in enumerate(cal.model.targets)
        ],
    }
    if cal.orientation_residuals is not None:
        figures = orientation_accuracy(cal.orientation_residuals)
        if figures is not None:
            doc["orientation_residuals"] = figures.to_dict()
    if cal.correction is not None:  # the hybrid model's learned part
        doc["correction"] = cal.correction.to_dict()
        doc["hybrid_residuals"] = hybrid_in_sample(cal, recording).to_dict()
    if len(cal.model.targets) > 1:
        doc["identifiable_only_with_extra_targets"] = list(cal.by_extra_targets)
    if cal.identifiability is not None:
        ident = cal.identifiability
        doc["identifiability"] = {
            "condition_number": ident.condition_number,
            "observability_index": ident.observability_index,
            "free_parameters": ident.n_free,
            "fixed_by_data": len(ident.fixed),
        }
    if cal.cpa is not None:
        doc["cpa"] = {
            "q_ref": cal.cpa.q_ref.tolist(),
            "sweeps": [
                {
                    "joint": s.joint,
                    "points": s.n_points,
                    "span_deg": float(np.degrees(s.span_rad)),
                    "radius_m": s.circle.radius,
                    "rms_m": s.circle.rms,
                    "plane_rms_m": float(np.sqrt(np.mean(s.circle.plane_residuals**2))),
                    "radial_rms_m": float(np.sqrt(np.mean(s.circle.radial_residuals**2))),
                }
                for s in cal.cpa.sweeps
            ],
            "axes": [
                {"point_m": a.point.tolist(), "direction": a.direction.tolist()}
                for a in cal.cpa.axes
            ],
        }
    return doc


def hybrid_in_sample(cal: Calibration, recording: Recording) -> Accuracy:
    """The in-sample figures of the hybrid model (`cal`'s physical model minus its learned
    correction) at the measurements of `recording` it was fitted on (its inliers when the
    calibration screened outliers of this recording): PARAMS.json `hybrid_residuals`."""
    inliers = cal.inliers
    fitted = recording.with_targets(cal.model.targets)
    if inliers is not None and len(inliers) == len(fitted):
        fitted = fitted.subset(inliers)
    return accuracy(fitted.points, cal.predict(fitted.poses))


def load_calibration(path: str | Path, where: str | None = None) -> Calibration:
    """The `Calibration` of a PARAMS.json file (see `Calibration.from_dict`); messages name
    `where` (default: `path`)."""
    path = Path(path)
    return Calibration.from_dict(read_document(path), str(path) if where is None else where)


def probe_lines(cal: Calibration) -> list[str]:
    """Each 6-DoF probe's frame in the flange frame for people: roll, pitch, yaw [deg]
    (Rz Ry Rx) and the quaternion (the parameters themselves are a rotation vector)."""
    from scipy.spatial.transform import Rotation

    out = []
    tools = cal.model.tool_rotations(cal.parameters)
    for name in cal.model.oriented:
        tool = tools[cal.model.targets.index(name)]
        where = target_topic(name).replace("/point", "")
        out.append(
            f"probe frame in the flange ({where}): roll, pitch, yaw "
            f"{', '.join(f'{v:.4f}' for v in np.degrees(matrix_to_rpy(tool)))} deg; "
            "quaternion x, y, z, w "
            f"{', '.join(f'{v:.6f}' for v in Rotation.from_matrix(tool).as_quat())}"
        )
    return out


def summary(cal: Calibration, recording: Recording) -> str:
    """Human summary: measurements, parameters (mm/deg) with 1-sigma, fixed, residuals."""
    lines = [recording.summary(), f"model: {cal.label}"]
    if cal.implausible:
        lines.append("IMPLAUSIBLE (plausible: false): " + "; ".join(cal.implausible))
    if cal.identifiability is not None:
        ident = cal.identifiability
        lines.append(
            f"identifiability: {ident.n_free} free parameters, condition number "
            f"{ident.condition_number:.1f}, observability index {ident.observability_index:.2e}"
            f", {len(ident.fixed)} fixed by the data"
        )
    lines.append(f"{'parameter':<22}{'value':>14}{'nominal':>14}{'deviation':>12}{'1-sigma':>11}")
    for p, value, std in zip(cal.parameters.parameters, cal.parameters.values, cal.std):
        if p.group not in ("geometric", "frames") and not p.free:
            continue  # effect terms the data fixed at 0: listed once below
        v, unit = human_value(p.name, p.unit, value)
        n, _ = human_value(p.name, p.unit, p.nominal)
        s, _ = human_value(p.name, p.unit, std)
        sigma = f"{s:11.5f}" if p.free else "      fixed"
        # the tracker pose and the target offsets have no nominal: no deviation to show
        deviation = f"{'-':>12}" if p.group == "frames" else f"{v - n:12.5f}"
        nominal = f"{'-':>14}" if p.group == "frames" else f"{n:14.5f}"
        lines.append(f"{p.name + ' [' + unit + ']':<22}{v:14.5f}{nominal}{deviation}{sigma}")
    for reason, names in fixed_reasons(cal.parameters).items():
        shown = ", ".join(names[:8]) + (f" (+{len(names) - 8} more)" if len(names) > 8 else "")
        lines.append(f"fixed ({reason}): {shown}")
    lines += probe_lines(cal)
    lines.append(f"residuals (in-sample): {cal.accuracy.line()}")
    if cal.orientation_residuals is not None:
        figures = orientation_accuracy(cal.orientation_residuals)
        if figures is not None:
            lines.append(f"residuals (in-sample): {figures.line()}")
    lines += outlier_lines(cal.outliers)
    if cal.correction is not None:  # the hybrid model's learned part
        lines += [cal.correction.line(), *cal.correction.warnings]
    lines += list(cal.warnings)
    if cal.solver.time_s is not None:
        lines.append(cal.solver.line())
    return "\n".join(lines)
