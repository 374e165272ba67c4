"""Is a calibration plausible? Labelled warnings for results that converge yet are wrong:
a wrong `--robot`, two joints' readings swapped, readings in degrees, a stuck encoder, a
residual far above what the tracker can explain. A fit that is wrong must say so.

Each check is a pure function of the recording, the robot and the calibration; the
warnings go to stdout, PARAMS.json `warnings` and the calibrator node's summary.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from robot_calib.errors import InputError
from robot_calib.identify.params_file import (
    PHYSICAL_ANGLE_RAD,
    PHYSICAL_LENGTH_M,
    beyond_physics,
    far_from_nominal_values,
)
from robot_calib.identify.score import (
    RESIDUAL_FACTOR,
    noise_per_axis,
)
from robot_calib.identify.weights import DEFAULT_ORIENTATION_SIGMA_RAD
from robot_calib.kinematics.description import RobotDescription
from robot_calib.measurements import Recording
from robot_calib.poses import JOINT_CHANGE_TOLERANCE

if TYPE_CHECKING:
    from robot_calib.identify.calibration import Calibration

#: a geometric parameter this far from nominal is no manufacturing tolerance
FAR_LENGTH_M = 0.020
FAR_ANGLE_RAD = np.radians(2.0)
#: readings beyond the joint limits by more than this [rad] are reported
LIMIT_MARGIN_RAD = np.radians(2.0)
HINT = "a wrong robot description, two joints' readings swapped, or readings in other units?"


def recording_warnings(recording: Recording, robot: RobotDescription) -> list[str]:
    """Stuck joints (never moving while others do), readings outside the joint limits, and
    readings that look like degrees (beyond 2 pi and beyond the joint's own limits: a
    Yaskawa GP25's T axis turns +-455 deg)."""
    out: list[str] = []
    q = recording.poses.q
    moving = np.ptp(q, axis=0) > JOINT_CHANGE_TOLERANCE
    names = robot.joint_names
    if not moving.any() and len(q):
        out.append(
            f"warning: no joint moves: all {len(q)} measurements are of one pose; nothing "
            "of the robot can be identified"
        )
    if moving.any():
        for j in (int(k) for k in np.flatnonzero(~moving)):
            out.append(
                f"warning: joint {j + 1} ({names[j]}) never moves while others do "
                f"(reading {q[0, j]:.6f} rad throughout): a stuck encoder? its parameters "
                "cannot be identified"
            )
    in_degrees = dict(degree_like_joints(recording, robot))
    for j in range(robot.n_joints):
        if j + 1 in in_degrees:
            peak = in_degrees[j + 1]
            out.append(
                f"warning: joint {j + 1} ({names[j]}) readings reach {peak:.1f} rad "
                f"({np.degrees(peak):.0f} deg): they look like degrees; the contract wants rad"
            )
            continue
        lo, hi = robot.limits[j]
        outside = int(
            np.sum((q[:, j] < lo - LIMIT_MARGIN_RAD) | (q[:, j] > hi + LIMIT_MARGIN_RAD))
        )
        if outside:
            out.append(
                f"warning: joint {j + 1} ({names[j]}): {outside} of {len(q)} readings outside "
                f"its limits [{np.degrees(lo):.0f}, {np.degrees(hi):.0f}] deg ({robot.name}): "
                "another robot?"
            )
    return out


MIN_FLANGE_SPREAD_M = 0.05  # poses that move the flange this much (rms) must move the points
COLLAPSED_SPREAD = 0.01  # points spread below this share of the flange's: one point measured


def check_points_spread(recording: Recording, robot: RobotDescription) -> None:
    """InputError when the tracker points barely move (rms about their centroid below
    COLLAPSED_SPREAD x the nominal flange's) while the poses move the flange by
    MIN_FLANGE_SPREAD_M or more: the tracker measured one point again and again (frozen,
    or a pivot about the target), and a fit would collapse the robot to explain it."""
    from robot_calib.model import KinematicModel

    if len(recording) < 3:
        return
    model = KinematicModel(robot, ())
    flange = model.flange2base(model.parameters(), recording.poses)[:, :3, 3]
    spread_flange = float(np.sqrt(np.mean(np.sum((flange - flange.mean(0)) ** 2, axis=1))))
    for target in np.unique(recording.poses.target_index):
        pts = recording.points[recording.poses.target_index == target]
        spread = float(np.sqrt(np.mean(np.sum((pts - pts.mean(0)) ** 2, axis=1))))
        if spread_flange >= MIN_FLANGE_SPREAD_M and spread < COLLAPSED_SPREAD * spread_flange:
            raise InputError(
                f"{', '.join(recording.sources)}: the tracker points stay within "
                f"{spread * 1e3:.4f} mm (rms) while the poses move the flange "
                f"{spread_flange * 1e3:.0f} mm (nominal model): the tracker measured one "
                "point (frozen, or a pivot about the target); nothing to calibrate from"
            )


def degree_like_joints(recording: Recording, robot: RobotDescription) -> list[tuple[int, float]]:
    """The joints (1-based) whose readings look like degrees, each with its largest |reading|
    [rad as read]: beyond 2 pi and beyond the joint's own limits (a Yaskawa GP25's T axis
    turns +-455 deg), by more than LIMIT_MARGIN_RAD."""
    q = recording.poses.q
    if not len(q):
        return []
    peaks = np.max(np.abs(q), axis=0)
    return [
        (j + 1, float(peaks[j]))
        for j in range(robot.n_joints)
        if peaks[j] > max(2 * np.pi, *np.abs(robot.limits[j])) + LIMIT_MARGIN_RAD
    ]


def degrees_reason(recording: Recording, robot: RobotDescription, what: str = "readings") -> str:
    """'`what` of joint(s) 1 (57.3 rad), ... look like degrees; the contract wants rad' for
    the joints `degree_like_joints` finds, '' when none."""
    degrees = degree_like_joints(recording, robot)
    if not degrees:
        return ""
    joints = ", ".join(f"{j} ({peak:.1f} rad)" for j, peak in degrees)
    return f"{what} of joint(s) {joints} look like degrees; the contract wants rad"


def far_from_nominal(
    cal: Calibration,
    length_m: float,
    angle_rad: float,
    free_only: bool = False,
    deg_digits: int = 1,
) -> list[str]:
    """'a2 +882.0 mm', 'theta4 +64.6 deg', ...: the geometric parameters of `cal` (free
    ones only with `free_only`) more than `length_m` [m] or `angle_rad` [rad] from nominal."""
    return far_from_nominal_values(cal.parameters, length_m, angle_rad, free_only, deg_digits)


def calibration_warnings(
    cal: Calibration, geometry_fitted: bool = True, stated_sigma_m: float | None = None
) -> list[str]:
    """Geometric parameters far from nominal, and (when the geometry was fitted: not for
    the nominal model or CPA, whose residual is the gap calibration closes) an in-sample
    residual far above the noise, each with what usually causes it."""
    out: list[str] = []
    far = far_from_nominal(cal, FAR_LENGTH_M, FAR_ANGLE_RAD, free_only=True, deg_digits=2)
    if far:
        out.append(
            f"warning: parameters far from nominal ({cal.model.robot.name}): "
            f"{', '.join(far)}: {HINT}"
        )
    if geometry_fitted and len(cal.residuals):
        noise, source = noise_per_axis(cal, stated_sigma_m)
        per_axis = float(np.sqrt(np.mean(cal.residuals**2)))
        if per_axis > RESIDUAL_FACTOR * noise:
            out.append(
                f"warning: in-sample residual {per_axis * 1e3:.4f} mm per axis is "
                f"{per_axis / noise:.0f} x the noise ({noise * 1e3:.4f} mm, {source}): "
                "the model misses something large: an unmodelled effect (see `robot-calib "
                f"diagnose`), {HINT}"
            )
    return out


#: Beyond these a result is no robot of this table at all, but nonsense (PARAMS.json
#: `plausible: false`, `calibrate` exit 3): a geometric parameter this far from nominal
#: after the canonical form (`identify.canonical`: angles within pi of nominal, DH flips
#: undone) ...
#: (PHYSICAL_LENGTH_M, PHYSICAL_ANGLE_RAD: identify.params_file, re-checked on reading)
#: ... an in-sample residual per axis this many times the noise (`noise_per_axis`) ...
IMPLAUSIBLE_RESIDUAL_FACTOR = 1000.0
#: ... an in-sample rms per axis above that of the simpler model it extends (fitted on the
#: same measurements) by more than this fraction: the weak prior (`identify.prior`) may
#: cost the data a little, a fit that diverged costs far more
WORSE_TOLERANCE = 1e-3


def implausible_reasons(
    cal: Calibration,
    recording: Recording,
    geometry_fitted: bool = True,
    simpler: tuple[str, float] | None = None,
) -> list[str]:
    """One line per sign that `cal` is nonsense rather than a calibration, empty when none:
    readings that look like degrees; an in-sample residual beyond IMPLAUSIBLE_RESIDUAL_FACTOR
    times the noise (when the geometry was fitted); a geometric parameter beyond
    PHYSICAL_LENGTH_M or PHYSICAL_ANGLE_RAD of nominal; an in-sample rms per axis worse than
    that of `simpler` (its model name and in-sample rms per axis [m] on the same
    measurements) by more than WORSE_TOLERANCE. The lines carry no 'warning:' label:
    `calibrate`'s exit 3 says "fitted, implausible: LINE"."""
    out: list[str] = []
    robot = cal.model.robot
    degrees = degrees_reason(recording, robot)
    if degrees:
        out.append(degrees)
    per_axis = float(np.sqrt(np.mean(cal.residuals**2))) if len(cal.residuals) else 0.0
    if geometry_fitted and len(cal.residuals):
        noise, source = noise_per_axis(cal)  # never a stated figure: a typo is no nonsense
        if per_axis > IMPLAUSIBLE_RESIDUAL_FACTOR * noise:
            out.append(
                f"in-sample residual {per_axis * 1e3:.4g} mm per axis is {per_axis / noise:.0f}"
                f" x the noise ({noise * 1e3:.4f} mm, {source}): {HINT}"
            )
    beyond = far_from_nominal(cal, PHYSICAL_LENGTH_M, PHYSICAL_ANGLE_RAD)
    if beyond:
        out.append(beyond_physics(robot.name, beyond))
    if simpler is not None and len(cal.residuals):
        name, simpler_rms = simpler
        if per_axis > simpler_rms * (1.0 + WORSE_TOLERANCE):
            out.append(
                f"in-sample {per_axis * 1e3:.4f} mm per axis, worse than the {name} model it "
                f"extends ({simpler_rms * 1e3:.4f} mm on the same measurements): the fit "
                "diverged"
            )
    return out


#: a 6-DoF probe's orientation residual per axis beyond RESIDUAL_FACTOR times its stated
#: (or default) standard deviation, and beyond this floor, is no measurement noise: the
#: floor with the geometry fitted, and with it nominal (cpa, nominal: a real robot's
#: uncalibrated orientation error stays below a few mrad; a column mix-up gives ~1 rad)
ORIENTATION_FLOOR_RAD = 1e-3
ORIENTATION_FLOOR_NOMINAL_RAD = 30e-3


def inconsistent_orientations(
    cal: Calibration, recording: Recording, geometry_fitted: bool = True
) -> str | None:
    """A warning when the fitted 6-DoF orientations disagree with the points far beyond
    their accuracy (a column mix-up: quaternion order, roll-pitch-yaw order or convention),
    None otherwise. The caller then calibrates from the points alone."""
    if cal.orientation_residuals is None:
        return None
    rows = np.all(np.isfinite(cal.orientation_residuals), axis=1)
    if not rows.any():
        return None
    per_axis = float(np.sqrt(np.mean(cal.orientation_residuals[rows] ** 2)))
    sigma = recording.poses.sigma
    stated = sigma[:, 1][np.isfinite(sigma[:, 1])] if sigma is not None else np.zeros(0)
    noise = float(np.median(stated)) if len(stated) else DEFAULT_ORIENTATION_SIGMA_RAD
    said = "stated" if len(stated) else "assumed"
    floor = ORIENTATION_FLOOR_RAD if geometry_fitted else ORIENTATION_FLOOR_NOMINAL_RAD
    if per_axis <= max(RESIDUAL_FACTOR * noise, floor):
        return None
    return (
        f"warning: {', '.join(recording.sources)}: the 6-DoF orientations disagree with the "
        f"points: residual {per_axis * 1e3:.3g} mrad per axis ({per_axis / noise:.0f} x the "
        f"{said} {noise * 1e6:.0f} urad): check the orientation columns (quaternion order "
        "x, y, z, w: where is w?; roll-pitch-yaw order and convention, units); calibrated "
        "from the points alone"
    )


#: residual rms over the stated standard deviation (per kind) beyond which the stated
#: accuracies, and the 1-sigma figures computed from them, are not to be trusted
STATED_FACTOR = 3.0


def stated_accuracy_warnings(cal: Calibration, recording: Recording) -> list[str]:
    """A warning per kind (position, orientation) whose in-sample residual rms per axis is
    more than STATED_FACTOR times (or less than 1 / STATED_FACTOR of) the median standard
    deviation the tracker stated: the weights rest on those figures."""
    sigma = recording.poses.sigma
    if sigma is None or not len(cal.residuals):
        return []
    if cal.inliers is not None and len(cal.inliers) == len(sigma):
        sigma = sigma[cal.inliers]  # the residuals are those of the measurements fitted
    if len(sigma) != len(cal.residuals):
        return []
    kinds = [("position", cal.residuals, sigma[:, 0], 1e3, "mm")]
    if cal.orientation_residuals is not None:
        kinds.append(("orientation", cal.orientation_residuals, sigma[:, 1], 1e6, "urad"))
    out = []
    for kind, residuals, stated, scale, unit in kinds:
        rows = np.all(np.isfinite(residuals), axis=1) & np.isfinite(stated)
        if not rows.any():
            continue
        rms = float(np.sqrt(np.mean(residuals[rows] ** 2)))
        said = float(np.median(stated[rows]))
        factor = rms / said
        if factor > STATED_FACTOR or factor < 1.0 / STATED_FACTOR:
            out.append(
                f"warning: {cal.name}: {kind} residual {rms * scale:.4g} {unit} per axis is "
                f"{factor:.2g} x "
                f"the stated accuracy ({said * scale:.4g} {unit}): the weights and 1-sigma "
                "figures rest on the stated figures; check their units, or the model misses "
                "something (see `robot-calib diagnose`)"
            )
    return out
