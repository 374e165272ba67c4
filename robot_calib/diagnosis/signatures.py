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
from dataclasses import dataclass, field, replace

import numpy as np

from robot_calib.diagnosis.evidence import (
    FAMILY_WORDS,
    STRUCTURE_Z,
    UNITS,
    Evidence,
    TermEvidence,
    joint_evidence,
)
from robot_calib.diagnosis.frequency import JointSpectrum, joint_spectra
from robot_calib.diagnosis.projection import MIN_LEVER_M
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
    # harmonics 1..HARMONICS of the reading along the arc; None where the arc does not
    # resolve the order (its amplitude's 1-sigma over MAX_ARC_AMPLIFICATION times that of
    # a full, evenly sampled turn: a short arc lets harmonics run to any size)
    harmonics_urad: list[float | None] | None
    # each order's significance: the joint fit's (`JointTerms`: one number per term)
    harmonics_significance: list[float] | None
    direction_split_urad: float | None  # forth minus back (backlash-like)
    slope_vs_angle_urad_per_rad: float | None  # (scale-like)
    gravity_torque_correlation: float | None  # (compliance-like), -1..1
    observable: bool = True
    lever_mm: float | None = None


@dataclass(frozen=True)
class JointTerms(Record):
    """What each signature family explains of a joint, from every pose, beyond the
    geometry and every other joint's terms (`evidence.joint_evidence`): its value (None:
    not resolvable from these poses) and its significance (x its own uncertainty in the
    joint fit; 0 where it does not lower the k-fold error). Not `observable` (values None,
    significances 0) when most measured points lie within MIN_LEVER_M of the joint's axis
    (`lever_mm`: their median distance)."""

    joint: int
    harmonics_urad: list[float | None] | None
    harmonics_significance: list[float]
    direction_urad: float | None
    direction_significance: float
    scale_urad_per_rad: float | None
    scale_significance: float
    gravity_urad_per_Nm: float | None
    gravity_significance: float
    observable: bool = True
    lever_mm: float | None = None

    def of_family(self, family: str) -> tuple[float | None, float]:
        """(value, significance) of a one-signal family (a key of FAMILY_FIELDS)."""
        return getattr(self, FAMILY_FIELDS[family]), getattr(self, f"{family}_significance")


@dataclass(frozen=True)
class Signature(Record):
    """The most significant signature: its joint, harmonic (None for the other families),
    value (in `evidence.UNITS` of its family: urad, urad/rad, urad/(N m), or mm for a twist
    or a drift with time), significance and a sentence; `family` its evidence family
    ('' in documents written before it was recorded)."""

    joint: int
    harmonic: int | None
    value: float
    significance: float
    text: str
    family: str = ""


@dataclass(frozen=True)
class TimeTrend(Record):
    """The residual's size against time: rms by quartile of time [mm], the slope of the
    residual's norm [mm/h] (a description: in a campaign of sweeps the residual's size
    follows the joints swept, not time), and the significance of a drift with time in the
    joint fit (`evidence`: x its uncertainty beside every joint term, 0 where it does not
    lower the k-fold error): whether time itself explains anything."""

    rms_by_quartile_mm: list[float]
    slope_mm_per_h: float
    drift_significance: float | None = None  # None: no time span, no drift term

    def line(self) -> str:
        """'rms by quartile a, b, c, d mm, trend 0.172 mm/h (a drift with time: 1 x its
        uncertainty)'; without a drift term, no word of it."""
        quartiles = ", ".join(f"{v:.4f}" for v in self.rms_by_quartile_mm)
        z = self.drift_significance
        drift = (
            ""
            if z is None
            else f" (a drift with time: {z:.0f} x its uncertainty)"
            if z >= STRUCTURE_Z
            else f" (no drift with time beyond its uncertainty: {z:.0f} x)"
        )
        return f"rms by quartile {quartiles} mm, trend {self.slope_mm_per_h:.3f} mm/h{drift}"


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
    # the frequency scan (diagnosis/frequency.py): dominant joint-angle harmonic orders,
    # their amplitudes and significances those of the joint fit (`evidence`)
    harmonic_orders: list[JointSpectrum] = field(default_factory=list)
    # every candidate term of the joint fit (`evidence.joint_evidence`), time included
    evidence: list[TermEvidence] = field(default_factory=list)
    evidence_scatter_mm: float | None = None  # what the joint fit leaves, per component

    def twists(self) -> list[TermEvidence]:
        """The links twisting under the load (`evidence` terms of family 'twist' at
        STRUCTURE_Z or more), strongest first: no per-joint table has them."""
        found = [t for t in self.evidence if t.family == "twist" and t.significance >= STRUCTURE_Z]
        return sorted(found, key=lambda t: -t.significance)

    def has_term(self, joint: int, family: str, order: int | None = None) -> bool:
        """True when the joint fit had this term as a candidate (`evidence`)."""
        return any(
            t.joint == joint and t.family == family and t.order == order for t in self.evidence
        )


def arc_angle_errors(
    model: KinematicModel, params: ParameterVector, recording: Recording, residuals: Array
) -> dict[int, tuple[IntArray, Array, Array]]:
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


def joint_terms(
    model: KinematicModel,
    params: ParameterVector,
    recording: Recording,
    residuals: Array,
    evidence: Evidence | None = None,
) -> list[JointTerms]:
    """From every pose (sweeps or not), per joint, the evidence of each joint-angle term
    (`evidence.joint_evidence`: harmonic k = 1..4 of the reading, the approach direction
    (backlash), the reading (scale), the gravity torque (compliance), all fitted jointly
    with the model's own parameters and with each other): its value (None where these
    poses do not resolve it) and its significance (x its own uncertainty; 0 where it does
    not lower the k-fold error). `evidence`: already computed on these residuals."""
    if evidence is None:
        evidence = joint_evidence(model, params, recording, residuals)
    out = []
    for j in range(model.robot.n_joints):
        lever = evidence.levers_m[j]
        if lever < MIN_LEVER_M:
            zeros = [0.0] * HARMONICS
            out.append(
                JointTerms(j + 1, None, zeros, None, 0.0, None, 0.0, None, 0.0, False, lever * 1e3)
            )
            continue

        harmonics = [_of(evidence, j + 1, "harmonics", k) for k in range(1, HARMONICS + 1)]
        out.append(
            JointTerms(
                j + 1,
                [v for v, _ in harmonics],
                [z for _, z in harmonics],
                *_of(evidence, j + 1, "direction"),
                *_of(evidence, j + 1, "scale"),
                *_of(evidence, j + 1, "gravity"),
                True,
                lever * 1e3,
            )
        )
    return out


def _of(
    evidence: Evidence, joint: int, family: str, order: int | None = None
) -> tuple[float | None, float]:
    """(value, significance) of a term of the joint fit; (None, 0) for no such candidate."""
    term = evidence.term(joint, family, order)
    return (None, 0.0) if term is None else (term.value, term.significance)


#: the one-signal families of `JointTerms`: family -> the field of its value
FAMILY_FIELDS = {
    "direction": "direction_urad",
    "scale": "scale_urad_per_rad",
    "gravity": "gravity_urad_per_Nm",
}
FAMILIES = tuple(  # (field of the value, field of the significance, words, unit)
    (field_name, f"{family}_significance", FAMILY_WORDS[family], UNITS[family])
    for family, field_name in FAMILY_FIELDS.items()
)


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


def removed_note(
    removed: Sequence[RemovedSignature],
    joint: int,
    orders: Iterable[int] = range(1, HARMONICS + 1),
    families: Iterable[str] = SIGNATURE_FAMILIES,
) -> str:
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


def scan_order_note(
    removed: Sequence[RemovedSignature],
    joint: int,
    order: int,
    after: WhereItLies | None,
    after_model: str,
) -> str:
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


def strongest_signature(evidence: Evidence) -> Signature | None:
    """The term of the highest significance in the joint fit (`evidence`), with a sentence;
    None when no term counts. A drift with time is joint 0."""
    best = evidence.strongest()
    if best is None:
        return None
    return Signature(
        best.joint,
        best.order,
        float(best.value or 0.0),
        best.significance,
        signature_text(best),
        best.family,
    )


def signature_text(term: TermEvidence) -> str:
    """'2nd harmonic of joint 3 (41.0 urad of joint-angle error, 12 x its uncertainty)',
    'a drift with time (0.021 mm rms over the recording, 9 x its uncertainty)', ..."""
    z = f"{term.significance:.0f} x its uncertainty"
    together = "" if term.separable else f"; {INSEPARABLE}"
    if term.value is None:
        return f"{term.words()} ({z}{together})"
    if term.family in ("time", "twist"):
        return f"{term.words()} ({term.value:.4f} mm rms over the recording, {z}{together})"
    if term.family == "harmonics":
        return f"{term.words()} ({term.value:.1f} urad of joint-angle error, {z}{together})"
    return f"{term.words()}: {term.value:.1f} {UNITS[term.family]}, {z}{together}"


#: said of a term the poses do not tell apart from other terms of its joint
INSEPARABLE = "these poses do not tell it from its joint's other terms"


def _spectra_of(spectra: list[JointSpectrum], evidence: Evidence) -> list[JointSpectrum]:
    """The scan's picked orders with the joint fit's amplitude and significance of each
    (one number per term wherever it is shown; the scan's own figures pick the orders)."""
    out = []
    for spectrum in spectra:
        amps, zs = [], []
        for k, amp in zip(spectrum.dominant_orders, spectrum.dominant_urad):
            term = evidence.term(spectrum.joint, "harmonics", k)
            amps.append(amp if term is None or term.value is None else float(term.value))
            zs.append(0.0 if term is None else float(term.significance))
        out.append(replace(spectrum, dominant_urad=amps, dominant_significance=zs))
    return out


#: an arc's harmonic amplitude is shown only where its 1-sigma is at most this many times
#: that of the same order over a full, evenly sampled turn of as many points
MAX_ARC_AMPLIFICATION = 10.0


#: poses the signatures are computed on at most (a fixed random subset above)
WHERE_POSES = 20000


def where_it_lies(
    model: KinematicModel,
    params: ParameterVector,
    recording: Recording,
    residuals: Array,
    noise_sigma_m: float,
    spectra: list[JointSpectrum] | None = None,
) -> WhereItLies:
    """Where the residual lies (units in the field names); `spectra`: the frequency scan
    of these residuals when already made (else it is made here). Above WHERE_POSES poses
    from a fixed random subset of them (statistics whose precision 20k poses give). Every
    term's significance is that of the joint fit (`evidence.joint_evidence`, with the
    scan's picked orders among its terms), wherever it is shown."""
    keep = recording.sample_mask(WHERE_POSES)
    if keep is not None:
        recording, residuals = recording.subset(keep), residuals[keep]
    if spectra is None:
        spectra = joint_spectra(model, params, recording, residuals)
    orders = {s.joint: [k for k in s.dominant_orders if k > HARMONICS] for s in spectra}
    evidence = joint_evidence(model, params, recording, residuals, orders)
    q, direction = recording.poses.q, recording.poses.direction
    joints = []
    tau = gravity_torques(model.robot, q)
    for j, (idx, err, lever) in arc_angle_errors(model, params, recording, residuals).items():
        seen = lever >= MIN_LEVER_M
        if seen.sum() < MIN_OBSERVABLE_POSES:
            joints.append(
                ArcSignature(
                    j, None, None, None, None, None, None, False, float(lever.max() * 1e3)
                )
            )
            continue
        idx, err, lever = idx[seen], err[seen], lever[seen]
        qj = q[idx, j - 1]
        forth = direction[idx, j - 1] > 0
        # None where the sweeps do not measure it: one approach direction only, a reading
        # that does not change, a gravity torque that does not (a vertical axis: none)
        split = (
            float(err[forth].mean() - err[~forth].mean()) * 1e6
            if forth.any() and (~forth).any()
            else None
        )
        slope = float(np.polyfit(qj, err, 1)[0]) * 1e6 if np.ptp(qj) > 0 else None
        t = tau[idx, j - 1]
        corr = float(np.corrcoef(t, err)[0, 1]) if np.ptp(t) > 1e-3 else None
        amps, amp_sigma = harmonic_amplitudes(qj, err, 1.0)
        full_turn = np.sqrt(2.0 / len(qj))  # an order's 1-sigma over a full, even turn
        shown: list[float | None] = [
            float(a * 1e6) if sd <= MAX_ARC_AMPLIFICATION * full_turn else None
            for a, sd in zip(amps, amp_sigma)
        ]
        significance = []
        for k in range(1, HARMONICS + 1):
            term = evidence.term(j, "harmonics", k)
            significance.append(0.0 if term is None else term.significance)
        joints.append(
            ArcSignature(
                j,
                float(np.sqrt(np.mean(err**2)) * 1e6),
                shown,
                significance,
                split,
                slope,
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
    all_poses = joint_terms(model, params, recording, residuals, evidence)
    drift = evidence.term(0, "time")
    return WhereItLies(
        joints,
        all_poses,
        strongest_signature(evidence),
        TimeTrend(
            [float(np.sqrt(np.mean(norm[i] ** 2)) * 1e3) for i in quartiles],
            _slope_mm_per_h(time, norm),
            None if drift is None else drift.significance,
        ),
        Workspace([float(np.sqrt(np.mean(norm[i] ** 2)) * 1e3) for i in tertiles]),
        noise_sigma_m * 1e3,
        _spectra_of(spectra, evidence),
        evidence.terms,
        evidence.scatter_m * 1e3,
    )


def _slope_mm_per_h(time: Array, norm: Array) -> float:
    """The slope of the residual's norm `norm` (n,) [m] against `time` (n,) [s], [mm/h]
    (0 without a time span)."""
    if len(time) < 2 or np.ptp(time) <= 0:
        return 0.0
    return float(np.polyfit(time, norm, 1)[0] * 3.6e6)
