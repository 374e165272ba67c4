"""Where the residual lies: its structure against each joint angle, approach direction, time,
gravity torque and workspace region (residual = predicted - measured, tracker frame).

For a pose in a sweep of joint j, the residual along the arc divided by the lever arm is the
joint-angle error of joint j that would explain it [rad]; its Fourier content against the
reading, its jump between approach directions (backlash), its slope against the reading
(encoder scale) and its correlation with the gravity torque (compliance) are the
signatures of the joint effects.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from robot_calib.diagnose.frequency import JointSpectrum, joint_spectra
from robot_calib.diagnose.projection import MIN_LEFT, MIN_LEVER_M, model_span
from robot_calib.effects.base import Effect
from robot_calib.effects.compliance import gravity_torques
from robot_calib.effects.eccentricity import fourier_basis
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import Recording
from robot_calib.model import KinematicModel
from robot_calib.records import Record

HARMONICS = 4
MIN_OBSERVABLE_POSES = 3


@dataclass(frozen=True)
class ArcSignature(Record):
    """A joint's error along the arc of its own sweeps, as a joint-angle error [urad], from
    the measurements at least MIN_LEVER_M from its axis; None where fewer than
    MIN_OBSERVABLE_POSES are (`observable` False: the targets sit on or near the axis,
    `lever_mm` the largest of their distances)."""

    joint: int
    arc_rms_urad: float | None
    harmonics_urad: list[float] | None  # harmonics 1..HARMONICS of the reading
    harmonics_significance: list[float] | None  # amplitude / its 1-sigma
    direction_split_urad: float | None  # forth minus back (backlash-like)
    slope_vs_angle_urad_per_rad: float | None  # (scale-like)
    gravity_torque_correlation: float | None  # (compliance-like), -1..1
    observable: bool = True
    lever_mm: float | None = None


@dataclass(frozen=True)
class JointTerms(Record):
    """What each signature family explains of a joint, from every pose, beyond the
    geometry: its value and its significance (sqrt of chi^2 explained, in noise units).
    Not `observable` (values None, significances 0) when most measured points lie within
    MIN_LEVER_M of the joint's axis (`lever_mm`: their median distance)."""

    joint: int
    harmonics_urad: list[float] | None
    harmonics_significance: list[float]
    direction_urad: float | None
    direction_significance: float
    scale_urad_per_rad: float | None
    scale_significance: float
    gravity_urad_per_Nm: float | None
    gravity_significance: float
    observable: bool = True
    lever_mm: float | None = None


@dataclass(frozen=True)
class Signature(Record):
    """The most significant signature: its joint, harmonic (None for the other families),
    value (urad, urad/rad or urad/(N m)), significance and a sentence."""

    joint: int
    harmonic: int | None
    value: float
    significance: float
    text: str


@dataclass(frozen=True)
class TimeTrend(Record):
    rms_by_quartile_mm: list[float]
    slope_mm_per_h: float


@dataclass(frozen=True)
class Workspace(Record):
    rms_by_reach_tertile_mm: list[float]  # near to far from the centre of the points


@dataclass(frozen=True)
class WhereItLies(Record):
    """The 'where' section of DIAGNOSIS.json (msgs_doc/diagnosis.md)."""

    joints: list[ArcSignature]
    joints_from_all_poses: list[JointTerms]
    strongest_signature: Signature | None
    time: TimeTrend
    workspace: Workspace
    noise_sigma_mm: float
    # the frequency scan (diagnose/frequency.py): dominant joint-angle harmonic orders
    harmonic_orders: list[JointSpectrum] = field(default_factory=list)


def arc_angle_errors(model: KinematicModel, params: ParameterVector, recording: Recording,
                     residuals: Array) -> dict[int, tuple[IntArray, Array, Array]]:  # fmt: skip
    """Per joint j with sweeps: (pose index (k,), angle-equivalent error (k,) [rad] =
    residual along the arc of joint j / lever arm, lever arm (k,) [m]), from its sweeps."""
    origins, axes = model.joint_axes(params, recording.poses)
    points = recording.points + residuals  # predicted
    out: dict[int, tuple[IntArray, Array, Array]] = {}
    for j in sorted({s.joint for s in recording.sweeps}):
        idx = np.concatenate([s.index for s in recording.sweeps_of(j)])
        tangent = np.cross(axes[idx, j - 1], points[idx] - origins[idx, j - 1])
        lever2 = np.sum(tangent**2, axis=1)
        out[j] = (idx, np.einsum("na,na->n", residuals[idx], tangent) / lever2, np.sqrt(lever2))
    return out


def harmonic_amplitudes(
    q: Array, values: Array, sigma: Array | float, order: int = HARMONICS
) -> tuple[Array, Array]:
    """Amplitudes (order,) of harmonics 1..order of values(q) (least squares with a mean)
    and their 1-sigma from noise `sigma` on each value: over a partial turn the harmonics
    are nearly collinear and their amplitudes are uncertain, which the sigma shows."""
    weights = np.broadcast_to(1.0 / np.asarray(sigma, dtype=float), q.shape)
    design = fourier_basis(q, order) * weights[:, None]
    coef = np.linalg.lstsq(design, values * weights, rcond=None)[0].astype(np.float64, copy=False)
    var = np.diag(np.linalg.pinv(design.T @ design))
    return np.hypot(coef[1::2], coef[2::2]), np.sqrt((var[1::2] + var[2::2]) / 2.0)


def joint_terms(model: KinematicModel, params: ParameterVector, recording: Recording,
                residuals: Array, noise_sigma_m: float) -> list[JointTerms]:  # fmt: skip
    """From every pose (sweeps or not), per joint, what each signature explains of the
    residual beyond what the model's own free parameters can absorb: a joint-angle error
    shaped as harmonic k = 1..4 of the reading, as the approach direction (backlash), the
    reading (scale) or the gravity torque (compliance). Each family is tested on its own
    against the geometry (so families do not trade huge opposite coefficients): its value,
    and its significance sqrt(chi^2 explained) in units of the noise."""
    poses, n_joints = recording.poses, model.robot.n_joints
    span = model_span(model, params, poses, recording.points + residuals, noise_sigma_m)
    motion = span.motion
    r = span.project_off(residuals.reshape(-1) / noise_sigma_m)
    tau = gravity_torques(model.robot, poses.q)

    def explain(signals: list[Array], j: int) -> tuple[Array, float]:
        """Coefficients [rad per unit signal] and sqrt(chi^2 explained) of one family;
        zeros where a column keeps less than MIN_LEFT of its norm once the model's own
        columns are projected off (collinear with the model: any value would be noise)."""
        cols = np.stack([(motion[:, j, :] * s[:, None]).reshape(-1) for s in signals], 1)
        cols = cols / noise_sigma_m
        norms = np.linalg.norm(cols, axis=0)
        cols = span.project_off(cols)
        if np.any(np.linalg.norm(cols, axis=0) < MIN_LEFT * np.maximum(norms, 1e-300)):
            return np.zeros(len(signals)), 0.0
        coef = np.linalg.lstsq(cols, r, rcond=1e-10)[0].astype(np.float64, copy=False)
        return coef, float(np.linalg.norm(cols @ coef))

    def family(signal: Array, j: int) -> tuple[float, float]:
        """Value [urad per unit signal] and significance of a one-signal family."""
        if np.ptp(signal) <= 1e-9:
            return 0.0, 0.0
        coef, z = explain([signal], j)
        return float(coef[0] * 1e6), z

    out = []
    for j in range(n_joints):
        lever = float(span.lever_m[j])
        if lever < MIN_LEVER_M:
            zeros = [0.0] * HARMONICS
            out.append(JointTerms(j + 1, None, zeros, None, 0.0, None, 0.0, None, 0.0,
                                  False, lever * 1e3))  # fmt: skip
            continue
        qj = poses.q[:, j]
        amps, sig = [], []
        for k in range(1, HARMONICS + 1):
            coef, z = explain([np.cos(k * qj), np.sin(k * qj)], j)
            amps.append(float(np.hypot(*coef) * 1e6))
            sig.append(z)
        out.append(
            JointTerms(
                j + 1,
                amps,
                sig,
                *family(poses.direction[:, j], j),
                *family(qj, j),
                *family(tau[:, j], j),
                True,
                lever * 1e3,
            )  # fmt: skip
        )
    return out


FAMILIES = (  # (field of the value, field of the significance, words, unit)
    ("direction_urad", "direction_significance", "approach direction (backlash-like)", "urad"),
    ("scale_urad_per_rad", "scale_significance", "reading (scale-like)", "urad/rad"),
    ("gravity_urad_per_Nm", "gravity_significance", "gravity torque (compliance-like)",
     "urad/(N m)"),
)  # fmt: skip


#: the per-joint signature families: the harmonics, then one per FAMILIES entry, in order
#: (`Effect.signature_family`, `RemovedSignature.family`)
SIGNATURE_FAMILIES = ("harmonics", "direction", "scale", "gravity")


def signature_family(sig: Signature) -> str:
    """The family (SIGNATURE_FAMILIES) of a strongest signature: its harmonic, else the
    FAMILIES entry whose words its sentence holds; '' for none."""
    if sig.harmonic is not None:
        return SIGNATURE_FAMILIES[0]
    for family, (_, _, words, _) in zip(SIGNATURE_FAMILIES[1:], FAMILIES):
        if words in sig.text:
            return family
    return ""


@dataclass(frozen=True)
class RemovedSignature(Record):
    """A per-joint signature family the chosen (best) model has an effect for (DIAGNOSIS.json
    `removed_by_best_model`): what `where` finds of it on `joint` in the geometric model's
    residuals the best model removed. `family`: one of SIGNATURE_FAMILIES; `effect`: the
    best model's term that models it (e.g. 'backlash:4'); `orders`: the joint-angle
    harmonic orders it models (family 'harmonics' only, else empty)."""

    joint: int
    family: str
    effect: str
    orders: list[int] = field(default_factory=list)


def removed_signatures(effects: Sequence[Effect]) -> list[RemovedSignature]:
    """Every (joint, family) the model of `effects` removes: each effect's
    `signature_family` on each of its joints, and its `harmonic_orders` there."""
    out = []
    for effect in effects:
        for j in effect.joints:
            if effect.signature_family:
                out.append(RemovedSignature(j, effect.signature_family, effect.spec))
            orders = effect.harmonic_orders(j)
            if orders:
                out.append(RemovedSignature(j, SIGNATURE_FAMILIES[0], effect.spec, sorted(orders)))
    return out


REMOVED = "removed by the best model"


def removed_note(removed: Sequence[RemovedSignature], joint: int,
                 orders: Iterable[int] = range(1, HARMONICS + 1),
                 families: Iterable[str] = SIGNATURE_FAMILIES) -> str:  # fmt: skip
    """'removed by the best model: direction (backlash:4); harmonics 2 (transmission_error:
    4:order=2)': what of joint `joint`'s `families` the best model removes (`removed`), the
    harmonics only for the `orders` shown (the tables' 1-4, a frequency scan's picked
    orders); '' when nothing."""
    wanted, shown = set(families), set(orders)
    parts = []
    for r in removed:
        if r.joint != joint or r.family not in wanted:
            continue
        if r.family == SIGNATURE_FAMILIES[0]:
            common = sorted(shown.intersection(r.orders))
            if common:
                parts.append(f"harmonics {', '.join(map(str, common))} ({r.effect})")
        else:
            parts.append(f"{r.family} ({r.effect})")
    return f"{REMOVED}: {'; '.join(parts)}" if parts else ""


def scan_order_note(removed: Sequence[RemovedSignature], joint: int, order: int,
                    after: WhereItLies | None, after_model: str) -> str:  # fmt: skip
    """What became of order `order` of joint `joint` found in the geometric model's
    frequency scan: 'removed by the best model: ...' when the best model has an effect
    with it (`removed_note`), else 'not in the residuals of M: an image of what M models'
    when the physical model M's own scan (`after`, None or geometric's: not known) no longer
    finds it (an unmodelled effect of another joint projects onto a joint's harmonics; a
    reader must not take it for a gear), else ''."""
    note = removed_note(removed, joint, (order,), ("harmonics",))
    if note or after is None:
        return note
    still = any(joint == s.joint and order in s.dominant_orders for s in after.harmonic_orders)
    return "" if still else f"not in the residuals of {after_model}: an image of what it models"


def signature_removed(sig: Signature | None, removed: Sequence[RemovedSignature]) -> str:
    """`removed_note` for a strongest signature (its joint, family and harmonic order):
    'removed by the best model: ...' when the best model has an effect for it, else ''."""
    family = "" if sig is None else signature_family(sig)
    if sig is None or not family:
        return ""
    orders = () if sig.harmonic is None else (sig.harmonic,)
    return removed_note(removed, sig.joint, orders, (family,))


def ordinal(k: int) -> str:
    """'1st', '2nd', '11th', '21st', ..."""
    if k % 100 in (11, 12, 13):
        return f"{k}th"
    return f"{k}{ {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th') }"


def strongest_signature(terms: list[JointTerms]) -> Signature | None:
    """The most significant family of `joint_terms` over all joints, with a sentence."""
    best: tuple[float, int, int | None, float, str] | None = None
    for entry in terms:
        j = entry.joint
        if not entry.observable or entry.harmonics_urad is None:
            continue
        pairs = zip(entry.harmonics_urad, entry.harmonics_significance)
        for k, (amp, sig) in enumerate(pairs, start=1):
            text = (f"{ordinal(k)} harmonic of joint {j} ({amp:.1f} urad of "
                    f"joint-angle error, {sig:.0f} x its noise)")  # fmt: skip
            if best is None or sig > best[0]:
                best = (sig, j, k, amp, text)
        for key, sig_key, words, unit in FAMILIES:
            sig, value = getattr(entry, sig_key), getattr(entry, key)
            if best is None or sig > best[0]:
                text = (f"joint {j} error following its {words}: {value:.1f} {unit}, "
                        f"{sig:.0f} x its noise")  # fmt: skip
                best = (sig, j, None, value, text)
    if best is None:
        return None
    sig, j, harmonic, value, text = best
    return Signature(j, harmonic, value, sig, text)


def _strongest(signature: Signature | None, spectra: list[JointSpectrum]) -> Signature | None:
    """The stronger of the families' strongest `signature` and the frequency scan's most
    significant picked order (its significance is in units of the residual's scatter,
    never above the noise units of the families for the same structure)."""
    best = signature
    for spectrum in spectra:
        for k, amp, z, why in zip(spectrum.dominant_orders, spectrum.dominant_urad,
                                  spectrum.dominant_significance, spectrum.meaning):  # fmt: skip
            if best is None or z > best.significance:
                text = (
                    f"{ordinal(k)} harmonic of joint {spectrum.joint} "
                    f"({amp:.1f} urad of joint-angle error, {z:.0f} x its noise; {why})"
                )
                best = Signature(spectrum.joint, k, amp, z, text)
    return best


#: poses the signatures are computed on at most (a fixed random subset above)
WHERE_POSES = 20000


def where_it_lies(model: KinematicModel, params: ParameterVector, recording: Recording,
                  residuals: Array, noise_sigma_m: float,
                  spectra: list[JointSpectrum] | None = None) -> WhereItLies:  # fmt: skip
    """Where the residual lies (units in the field names); `spectra`: the frequency scan
    of these residuals when already made (else it is made here). Above WHERE_POSES poses
    from a fixed random subset of them (statistics whose precision 20k poses give)."""
    keep = recording.sample_mask(WHERE_POSES)
    if keep is not None:
        recording, residuals = recording.subset(keep), residuals[keep]
    q, direction = recording.poses.q, recording.poses.direction
    joints = []
    tau = gravity_torques(model.robot, q)
    for j, (idx, err, lever) in arc_angle_errors(model, params, recording, residuals).items():
        seen = lever >= MIN_LEVER_M
        if seen.sum() < MIN_OBSERVABLE_POSES:
            joints.append(ArcSignature(j, None, None, None, None, None, None, False,
                                       float(lever.max() * 1e3)))  # fmt: skip
            continue
        idx, err, lever = idx[seen], err[seen], lever[seen]
        qj = q[idx, j - 1]
        forth = direction[idx, j - 1] > 0
        split = (
            float(err[forth].mean() - err[~forth].mean())
            if forth.any() and (~forth).any()
            else 0.0
        )
        slope = float(np.polyfit(qj, err, 1)[0]) if np.ptp(qj) > 0 else 0.0
        t = tau[idx, j - 1]
        corr = float(np.corrcoef(t, err)[0, 1]) if np.ptp(t) > 1e-3 else 0.0
        amps, amp_sigma = harmonic_amplitudes(qj, err, noise_sigma_m / lever)
        joints.append(
            ArcSignature(
                j,
                float(np.sqrt(np.mean(err**2)) * 1e6),
                [float(a * 1e6) for a in amps],
                [float(a / s) for a, s in zip(amps, amp_sigma)],
                split * 1e6,
                slope * 1e6,
                corr,
                True,
                float(np.median(lever) * 1e3),
            )
        )
    norm = np.linalg.norm(residuals, axis=1)
    time = recording.poses.time
    quartiles = np.array_split(np.argsort(time, kind="stable"), 4)
    reach = np.linalg.norm((recording.points - recording.points.mean(axis=0))[:, :2], axis=1)
    tertiles = np.array_split(np.argsort(reach, kind="stable"), 3)
    all_poses = joint_terms(model, params, recording, residuals, noise_sigma_m)
    if spectra is None:
        spectra = joint_spectra(model, params, recording, residuals)
    return WhereItLies(
        joints,
        all_poses,
        _strongest(strongest_signature(all_poses), spectra),
        TimeTrend(
            [float(np.sqrt(np.mean(norm[i] ** 2)) * 1e3) for i in quartiles],
            float(np.polyfit(time, norm, 1)[0] * 3.6e6) if np.ptp(time) > 0 else 0.0,
        ),
        Workspace([float(np.sqrt(np.mean(norm[i] ** 2)) * 1e3) for i in tertiles]),
        noise_sigma_m * 1e3,
        spectra,
    )
