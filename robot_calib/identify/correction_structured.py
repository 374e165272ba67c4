"""The hybrid model's learned correction: load-driven geometry, then a Gaussian process.

What a physical model leaves of effects outside its vocabulary (a joint's play whose side
gravity chooses, a link twisting under the weight it carries) is mostly geometry that
changes with the load: a small motion of some link frame, proportional to or stepping with
the gravity load that frame carries. So the residual r = predicted - measured [m] at
readings q is first modelled as pose-dependent geometry, linear in its coefficients:

    r(q) = sum_j sum_a D_ja(q) sum_f c_jaf g_jf(q) + sum_p J_p(q) b_p

D_ja (3,) the displacement of the measured point per unit motion a of DH frame j (j = 0..J-1,
the housing of joint j + 1; a = translation along and rotation about its x, y, z axes, in
frame j: rotation about z is an error of joint j + 1's angle, about x and y a tilt of its
axis), on the calibrated model at its parameters; g_jf the load features of frame j:

    1, M_x, M_y, M_z, P_x, P_y, P_z, C_ab (a, b = x, y, z), tanh(M_z / tau_k)
    (k = 1..len(STEP_SHARES))

M (3,) [N m] the gravity moment about frame j's origin of every link beyond it, in frame j
(nominal kinematics and the robot's mass model, a payload included; M_z is joint j + 1's
gravity torque); P (3,) [N m / kg] that of a unit mass at the flange's origin and C_a (3,)
[N m / (kg m)] that of a unit first moment along flange axis a: a tool the mass model does
not know (mass m, centre c in the flange frame) loads frame j by m P + sum_a m c_a C_a, so
its compliance is learned whatever its mass and centre (a KR5 carrying an unknown 3-5 kg
tool 0.1-0.15 m off the joint-6 axis, its upper arm or forearm twisting under it: 9-34 x
the floor geometric, 1.14-1.16 x with these features, 5-21 x without). M makes a
compliance of frame j in every direction, the tanh of M_z a
step where the joint's torque changes sign (play whose side the load chooses; tau_k =
STEP_SHARES x the largest rms of a joint's M_z over the fitted poses: the steps' widths,
the same for every joint); the constant
feature and the calibrated model's own Jacobian columns J_p (its free parameters) let the
fit redo what the physical fit absorbed of the structure. The coefficients are a ridge
least-squares fit, the columns scaled to unit rms and the ridge chosen by generalised
cross-validation on the fitted residuals only (the normal equations accumulated in blocks
of poses: memory O(P^2) for any number of poses); columns that hold only rounding noise
(a load zero by the geometry, e.g. frame 1's M_y or a vertical axis's torque: rms below
TINY_COLUMN x the largest column's) are left out, coefficient zero (scaled to unit rms
they got coefficients of 1e11 and made the correction a function of the rounding of q);
with fewer than MIN_ROWS_PER_COLUMN rows per column the structured part is left out (said
in `method`).

What the structure leaves, the Gaussian process of `identify.correction` learns (its
kernel, hyperparameters and limits). A correction read from a file is checked at its
process's inducing poses (its fitted poses): what it predicts there must stay within
MAX_CORRECTION_M and agree with its stored sizes; where a prediction elsewhere exceeds
MAX_CORRECTION_M it is capped there with a RuntimeWarning.

Measured (simulated UR10, `ur10_out_of_vocabulary(kind, seed=0, n=1000)` and
`ur10_random`, 700 calibration / 300 hold-out poses, held-out rms / noise floor;
`test/identify/test_correction_structured.py`): a 2 mrad gravity-side backlash of joint 2 from
65.0 x (geometric) to 1.11 x (the process alone: 27 x); link 3 twisting out of the arm
plane from 20.5 x to 1.08 x (the process alone: 9.2 x); compliance of joints 2 and 3
(`ur10_random(seed=1)`) from 87.9 x to 1.06 x; gear harmonics the physical rung already
models (1.006 x): 1.006 x, no structure fitted. The largest coefficient 5e-3; the
prediction changes by < 1e-16 m when the readings change by their rounding (q x (1 +
1e-15)), and the compensation's fixed point holds to 1e-9 m.

Where its parts live: the load features and the design matrix in `identify.load_features`
(STEP_SHARES, FEATURES), the ridge in `identify.ridge` (TINY_COLUMN), the fit in
`identify.correction_structured_fit` (MIN_ROWS_PER_COLUMN); here the fitted correction,
what it predicts and names, and its file format.
"""

from __future__ import annotations

import math
import warnings as python_warnings
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from robot_calib.errors import InputError, check_keys
from robot_calib.identify.correction import (
    MAX_CORRECTION_M,
    GaussianProcessCorrection,
    Hyperparameters,
)
from robot_calib.identify.load_features import (
    FEATURES,
    MOTIONS,
    STEP_SHARES,
    pose_blocks,
    structured_design,
)
from robot_calib.identify.ridge import kept_columns
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses
from robot_calib.records import Record

FORMAT = "robot_calib.correction/2"
CORRECTION_KEYS = (
    "format",
    "method",
    "n_targets",
    "fitted_poses",
    "rms_m",
    "structured",
    "gaussian_process",
    "warnings",
)
STRUCTURED_KEYS = (
    "rms_m",
    "parameters",
    "jacobian_columns",
    "step_tau_nm",
    "coefficients",
    "ridge",
    "degrees_of_freedom",
    "strongest",
)
#: the loaded correction's rms at the process's inducing poses may differ from the stored
#: rms_m by this share (plus ABS_RMS_TOLERANCE_M) when those are all the fitted poses
#: (rounding), SUBSET_RMS_TOLERANCE when they are a subset of them (sampling)
RMS_TOLERANCE, SUBSET_RMS_TOLERANCE, ABS_RMS_TOLERANCE_M = 1e-6, 0.3, 1e-9
PARAMETER_TOLERANCE = 1e-12  # relative: the stored parameters are the file's

_MEANING = {
    "rz": "joint {j}'s angle changes with the gravity load it carries (play or a compliance "
    "whose side the load chooses)",
    "rx": "joint {j}'s axis tilts with the load (the link carrying it bends or twists out of "
    "its plane)",
    "ry": "joint {j}'s axis tilts with the load (the link carrying it bends or twists out of "
    "its plane)",
    "x": "joint {j}'s housing shifts with the load",
    "y": "joint {j}'s housing shifts with the load",
    "z": "joint {j}'s housing shifts along its axis with the load",
}


@dataclass(frozen=True)
class LoadMotion(Record):
    """One load-driven motion of a structured correction (`StructuredCorrection.strongest`,
    DIAGNOSIS.json `outside_vocabulary.motions`): the joint whose housing moves, the motion
    (x, y, z translations along, rx, ry, rz rotations about its frame's axes), what of the
    correction at the points only it explains, rms [um] (the drop of the fit's explained
    sum of squares when it is left out), and what it usually is."""

    joint: int
    motion: str
    rms_um: float
    meaning: str


@dataclass(frozen=True)
class StructuredCorrection:
    """A fitted hybrid correction: load-driven geometry, then a Gaussian process of the rest.

    model, parameters : the calibrated physical model and its parameters (the structured
        columns are its frames and Jacobian at the poses)
    columns : names of the model's parameters whose Jacobian columns are structured columns
    step_tau : shape (J, K), the steps' widths tau per frame [N m]
    coefficients : shape (J * 6 * F + len(columns),), the structured coefficients [m or rad
        per feature unit, then per parameter unit]; zeros: no structure
    ridge, dof : the ridge (relative; inf: no structure) and its degrees of freedom
    structured_rms_m : rms norm of the structured part at the fitted poses [m]
    gp : the Gaussian process of what the structure leaves (`identify.correction`: its
        hyperparameters, length scales, noise, number of targets and of fitted poses)
    rms_m, method, warnings : as `GaussianProcessCorrection`'s
    """

    model: KinematicModel
    parameters: ParameterVector
    columns: tuple[str, ...]
    step_tau: Array
    coefficients: Array
    ridge: float
    dof: float
    structured_rms_m: float
    gp: GaussianProcessCorrection
    rms_m: float
    method: str
    warnings: tuple[str, ...] = ()

    @property
    def n_joints(self) -> int:
        return int(self.model.robot.n_joints)

    @property
    def n_targets(self) -> int:
        return self.gp.n_targets

    @property
    def n_fitted(self) -> int:
        return self.gp.n_fitted

    @property
    def hyper(self) -> Hyperparameters:
        """The Gaussian process's hyperparameters (a warm start for another fit)."""
        return self.gp.hyper

    @property
    def length_scales_deg(self) -> list[float | None]:
        return self.gp.length_scales_deg

    @property
    def noise_mm(self) -> float:
        return self.gp.noise_mm

    def structured(self, poses: Poses) -> Array:
        """The structured part's predicted residual (n, 3) [m, tracker frame]."""
        out = np.zeros((len(poses), 3))
        if not np.any(self.coefficients):
            return out
        for rows in pose_blocks(len(poses)):
            design = structured_design(
                self.model, self.parameters, self.columns, self.step_tau, poses.subset(rows)
            )
            out[rows] = design @ self.coefficients
        return out

    def _raw(self, poses: Poses) -> Array:
        """The structure plus the process at `poses` (n, 3) [m], uncapped."""
        if poses.q.shape[1] != self.n_joints:
            raise InputError(
                f"learned correction: poses of {poses.q.shape[1]} joints, the "
                f"correction was fitted on {self.n_joints}"
            )
        return self.gp.predict(poses) + self.structured(poses)

    def predict(self, poses: Poses) -> Array:
        """The predicted residual (predicted - measured) at `poses`: shape (n, 3) [m,
        tracker frame], the structure plus the process; subtract it from the model's points.
        A pose where it exceeds MAX_CORRECTION_M (far from any fitted pose: a loaded
        correction is refused when it does at its own poses) is capped there, with a
        RuntimeWarning saying how many and how far."""
        out = self._raw(poses)
        size = np.linalg.norm(out, axis=1, keepdims=True)
        beyond = size[:, 0] > MAX_CORRECTION_M
        if not beyond.any():
            return out
        python_warnings.warn(
            f"learned correction: {int(beyond.sum())} of {len(poses)} poses predicted beyond "
            f"{MAX_CORRECTION_M * 1e3:.0f} mm (up to {float(size.max()) * 1e3:.3g} mm), "
            "capped there: far from the calibration poses",
            RuntimeWarning,
            stacklevel=2,
        )
        return out * np.minimum(1.0, MAX_CORRECTION_M / np.maximum(size, 1e-300))

    def strongest(self, poses: Poses, count: int = 3) -> list[LoadMotion]:
        """The `count` load-driven motions (a frame's motion times its load features: one
        group of columns each) that explain most of the structured part at `poses`, in
        turn: the ridge fit (the fit's ridge, the columns' normal equations at `poses`) of
        the structured part on the geometry (every constant feature and Jacobian column)
        and the motions chosen so far, each further motion ranked by how much the explained
        sum of squares drops when it is left out of that fit with it (`LoadMotion.rms_um`:
        the square root of that drop per pose). The drops add up to what the load-driven
        motions explain: collinear motions that cancel each other count once, and of two
        motions that explain the same (joint 2 turning with its gravity torque, the base
        tilting with the moment it carries) the one that explains it alone is named."""
        if not math.isfinite(self.ridge) or not np.any(self.coefficients):
            return []
        size, n_rows = len(self.coefficients), 3 * len(poses)
        gram = np.zeros((size, size))
        for rows in pose_blocks(len(poses)):
            flat = structured_design(
                self.model, self.parameters, self.columns, self.step_tau, poses.subset(rows)
            ).reshape(-1, size)
            gram += flat.T @ flat
        scale, kept = kept_columns(gram, n_rows)
        index = np.flatnonzero(kept)
        scale = scale[index]
        scaled = gram[np.ix_(index, index)] / np.outer(scale, scale)
        rhs = scaled @ (self.coefficients[index] * scale)  # A^T y of the structured part
        total = float((self.coefficients[index] * scale) @ rhs)  # y = A c: y.y
        ridge = self.ridge * float(np.linalg.eigvalsh(scaled)[-1])

        def unexplained(columns: IntArray) -> float:
            """y.y - the explained sum of squares of the ridge fit of y on `columns`."""
            normal = scaled[np.ix_(columns, columns)]
            b = np.linalg.solve(normal + ridge * np.eye(len(columns)), rhs[columns])
            return total - 2.0 * float(b @ rhs[columns]) + float(b @ normal @ b)

        n_features = len(FEATURES)
        load = (index % n_features != 0) & (index < self.n_joints * 6 * n_features)
        group = index // n_features  # (frame, motion) of every column
        chosen = ~load
        left = unexplained(np.flatnonzero(chosen))
        out: list[LoadMotion] = []
        candidates = [int(g) for g in np.unique(group[load])]
        while candidates and len(out) < count:
            after = [
                unexplained(np.flatnonzero(chosen | (load & (group == g)))) for g in candidates
            ]
            best = int(np.argmin(after))
            g = candidates.pop(best)
            joint, motion = g // 6 + 1, MOTIONS[g % 6]
            rms_um = math.sqrt(max(left - after[best], 0.0) / len(poses)) * 1e6
            out.append(LoadMotion(joint, motion, rms_um, _MEANING[motion].format(j=joint)))
            chosen |= load & (group == g)
            left = after[best]
        return out

    def line(self) -> str:
        """One human line: size, the structured part's, the process's."""
        return (
            f"learned correction: {self.rms_m * 1e3:.4f} mm rms at its {self.n_fitted} "
            f"calibration poses: load-driven geometry {self.structured_rms_m * 1e3:.4f} mm "
            f"({self.dof:.0f} degrees of freedom), then a Gaussian process of the rest ("
            + self.gp.line().removeprefix("learned correction: ")
            + ")"
        )

    def to_dict(self) -> dict[str, Any]:
        """PARAMS.json `correction` of format 2 (msgs_doc/parameters.md)."""
        return {
            "format": FORMAT,
            "method": self.method,
            "n_targets": self.n_targets,
            "fitted_poses": self.n_fitted,
            "rms_m": self.rms_m,
            "structured": {
                "rms_m": self.structured_rms_m,
                "parameters": {
                    p.name: float(v)
                    for p, v in zip(self.parameters.parameters, self.parameters.values)
                },
                "jacobian_columns": list(self.columns),
                "step_tau_nm": self.step_tau.tolist(),
                "coefficients": self.coefficients.tolist(),
                "ridge": None if math.isinf(self.ridge) else self.ridge,
                "degrees_of_freedom": self.dof,
            },
            "gaussian_process": self.gp.to_dict(),
            "warnings": list(self.warnings),
        }

    @classmethod
    def from_dict(
        cls,
        data: Mapping[str, Any],
        model: KinematicModel,
        where: str = "correction",
        parameters: ParameterVector | None = None,
    ) -> StructuredCorrection:
        """The correction of a `to_dict` mapping for `model` (the file's physical model) and,
        when given, `parameters` (the file's: the stored ones must be these); InputError
        naming `where` and the field when it is of another format, lacks a field, names
        parameters the model has not, has arrays of inconsistent shapes, values that are not
        finite or out of range, or when what it predicts at its process's inducing poses (the
        fitted poses, or a subset of them) goes beyond MAX_CORRECTION_M or disagrees with
        its stored rms_m."""
        if not isinstance(data, Mapping) or data.get("format") != FORMAT:
            found = data.get("format") if isinstance(data, Mapping) else type(data).__name__
            raise InputError(
                f"{where}: not a learned correction of format {FORMAT} (format {found!r})"
            )
        check_keys(data, CORRECTION_KEYS, where)
        part = data.get("structured")
        if not isinstance(part, Mapping):
            raise InputError(f"{where}: malformed learned correction: no `structured` section")
        check_keys(part, STRUCTURED_KEYS, f"{where}: structured")
        process = GaussianProcessCorrection.from_dict(
            data.get("gaussian_process", {}), f"{where}: gaussian_process"
        )
        try:
            values = {str(k): float(v) for k, v in dict(part["parameters"]).items()}
            columns = tuple(str(c) for c in part["jacobian_columns"])
            step_tau = np.array(part["step_tau_nm"], dtype=float)
            coefficients = np.array(part["coefficients"], dtype=float)
            ridge = math.inf if part["ridge"] is None else float(part["ridge"])
            dof, structured_rms = float(part["degrees_of_freedom"]), float(part["rms_m"])
            n_targets, n_fitted = int(data["n_targets"]), int(data["fitted_poses"])
            rms = float(data["rms_m"])
            warnings = tuple(str(v) for v in data.get("warnings", []))
            method = str(data["method"])
        except KeyError as exc:
            raise InputError(f"{where}: malformed learned correction (no field {exc})") from None
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: malformed learned correction ({exc})") from None
        nominal = model.parameters()
        unknown = sorted(set(values) ^ {p.name for p in nominal.parameters})
        if unknown:
            raise InputError(
                f"{where}: learned correction: parameters {unknown[:5]} do not match the model's"
            )
        n_joints = model.robot.n_joints
        size = n_joints * 6 * len(FEATURES) + len(columns)
        problems = [
            (
                step_tau.shape != (n_joints, len(STEP_SHARES)),
                f"step_tau_nm must be a ({n_joints}, {len(STEP_SHARES)}) table",
            ),
            (bool(step_tau.size) and not bool(np.all(step_tau > 0)), "step_tau_nm must be > 0"),
            (coefficients.shape != (size,), f"coefficients must have {size} values"),
            (not set(columns) <= set(values), "jacobian_columns must name parameters"),
            (
                not np.isfinite(coefficients).all()
                or not np.isfinite(step_tau).all()
                or not all(math.isfinite(v) for v in (*values.values(), dof, structured_rms, rms)),
                "values not finite",
            ),
            (not ridge >= 0, "structured.ridge must be >= 0 (null: no structure)"),
            (not dof >= 0, "structured.degrees_of_freedom must be >= 0"),
            (n_targets < 1 or n_fitted < 1, "n_targets and fitted_poses must be >= 1"),
            (
                math.isinf(ridge) and bool(np.any(coefficients)),
                "structured.coefficients must be zero with ridge null (no structure)",
            ),
            (
                n_targets != process.n_targets or n_joints != process.n_joints,
                "the Gaussian process has another number of joints or targets",
            ),
            (
                n_fitted != process.n_fitted,
                "fitted_poses differs from the Gaussian process's fitted_poses",
            ),
        ]
        for bad, what in problems:
            if bad:
                raise InputError(f"{where}: malformed learned correction: {what}")
        if not 0 <= rms <= MAX_CORRECTION_M or not 0 <= structured_rms <= MAX_CORRECTION_M:
            raise InputError(f"{where}: implausible learned correction: rms_m beyond 0..10 mm")
        stored = nominal.with_values(values)
        if parameters is not None:
            theirs = dict(zip(parameters.names, parameters.values))
            differ = [
                k
                for k, v in values.items()
                if k not in theirs or abs(v - theirs[k]) > PARAMETER_TOLERANCE * max(1.0, abs(v))
            ]
            if differ:
                raise InputError(
                    f"{where}: learned correction: structured.parameters "
                    f"{differ[:3]} differ from the file's parameters"
                )
        out = cls(
            model,
            stored,
            columns,
            step_tau,
            coefficients,
            ridge,
            dof,
            structured_rms,
            process,
            rms,
            method,
            warnings,
        )
        out.check_at_fitted_poses(where)
        return out

    def _at_own_poses(self) -> tuple[Poses, Array, Array]:
        """Its process's inducing poses (their readings as the file stores them) and what
        it predicts there (n, 3) [m]: the structured part and the whole, uncapped (not
        finite where it is broken)."""
        gp = self.gp
        poses = replace(Poses.from_readings(gp.inducing_q), target=gp.inducing_target)
        with np.errstate(all="ignore"):
            return poses, self.structured(poses), self._raw(poses)

    def with_own_rms(self) -> StructuredCorrection:
        """This correction with its stored rms (structured.rms_m, rms_m) measured as the
        loader checks them, when its inducing poses are all its fitted poses: at the
        readings as stored (rounded, `GaussianProcessCorrection.inducing_q`), not at the fitted
        ones, so that a file this writes passes its own check whatever the conditioning of
        the structured part (a ridge of 1e-12 amplifies the 1e-12 rad rounding of the
        readings far above a relative 1e-6)."""
        if len(self.gp.inducing_q) != self.n_fitted:
            return self
        _, structured, total = self._at_own_poses()
        return replace(self, structured_rms_m=rms_norm(structured), rms_m=rms_norm(total))

    def check_at_fitted_poses(self, where: str) -> None:
        """InputError naming `where` when what this correction predicts at its process's
        inducing poses (every fitted pose, or a random subset above the process's
        MAX_POINTS) is not finite, goes beyond MAX_CORRECTION_M, or its rms (of the
        structured part, of the whole) disagrees with the stored structured.rms_m, rms_m."""
        poses, structured, total = self._at_own_poses()
        size = np.linalg.norm(total, axis=1)
        if not (np.isfinite(total).all() and np.isfinite(structured).all()):
            raise InputError(
                f"{where}: implausible learned correction: it predicts "
                "non-finite values at its own poses"
            )
        if float(size.max()) > MAX_CORRECTION_M:
            raise InputError(
                f"{where}: implausible learned correction: it predicts "
                f"{float(size.max()) * 1e3:.3g} mm at its own poses (at most "
                f"{MAX_CORRECTION_M * 1e3:.0f} mm)"
            )
        share = RMS_TOLERANCE if len(poses) == self.n_fitted else SUBSET_RMS_TOLERANCE
        for field, found, stored in (
            ("structured.rms_m", rms_norm(structured), self.structured_rms_m),
            ("rms_m", rms_norm(total), self.rms_m),
        ):
            if abs(found - stored) > share * stored + ABS_RMS_TOLERANCE_M:
                raise InputError(
                    f"{where}: implausible learned correction: {field} "
                    f"{stored * 1e3:.4g} mm, it predicts {found * 1e3:.4g} mm rms "
                    "at its own poses"
                )


#: the learned correction (what makes the hybrid model), in one of its two forms: a Gaussian
#: process alone (files of format 1) or load-driven geometry and a process (format 2)
LearnedCorrection = GaussianProcessCorrection | StructuredCorrection


def correction_from_dict(
    data: Mapping[str, Any],
    model: KinematicModel,
    where: str = "correction",
    parameters: ParameterVector | None = None,
) -> LearnedCorrection:
    """A PARAMS.json `correction` of either format (1: the process alone, still read);
    `parameters`: the file's (format 2 stores those it was fitted at: they must be these)."""
    if isinstance(data, Mapping) and data.get("format") == FORMAT:
        return StructuredCorrection.from_dict(data, model, where, parameters)
    return GaussianProcessCorrection.from_dict(data, where)


def rms_norm(values: Array) -> float:
    """The rms of the rows' norms of values (n, 3) [m] (0 for no rows)."""
    return float(np.sqrt(np.mean(np.sum(values**2, axis=1)))) if len(values) else 0.0
