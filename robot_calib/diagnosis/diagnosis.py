"""`robot-calib diagnose`: the ladder, the dominant effect, where the rest lies, as the
DIAGNOSIS.json document of msgs_doc/specification.md section 4 (extended:
msgs_doc/diagnosis.md).

Why one module: the DIAGNOSIS.json document (its record types, `Diagnosis` first) and
`diagnose`, which fills it from the ladder, change together with msgs_doc/diagnosis.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robot_calib.accuracy import NO_PAIR
from robot_calib.diagnosis.concentration import Region, Stretch, regions, stretches
from robot_calib.diagnosis.frequency import MAX_SCAN_ORDER, alias_warnings
from robot_calib.diagnosis.header import ReportHeader
from robot_calib.diagnosis.iso9283 import Iso9283, iso9283, repeat_groups
from robot_calib.diagnosis.ladder import (
    AT_FLOOR,
    N_FOLDS,
    Ladder,
    RefitOutcome,
    Rung,
    run_ladder,
)
from robot_calib.diagnosis.learnable import MIN_LEARNABLE_SHARE, LearnableBound
from robot_calib.diagnosis.noise import LOWER_BOUNDS, STATED, NoiseLevel
from robot_calib.diagnosis.outside import OutsideVocabulary, outside_vocabulary
from robot_calib.diagnosis.signatures import (
    RemovedSignature,
    Signature,
    WhereItLies,
    removed_signatures,
    where_it_lies,
)
from robot_calib.effects.compliance import gravity_torques
from robot_calib.errors import InputError
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.fit import orientation_residuals
from robot_calib.identify.model_spec import ModelSpec
from robot_calib.identify.outliers import Outlier
from robot_calib.identify.plausibility import degrees_reason
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.masses import mass_model_line
from robot_calib.log import Log
from robot_calib.measurements import Recording
from robot_calib.measurements.references import TrackerDrift
from robot_calib.poses import reading_groups
from robot_calib.records import Record

FORMAT = "robot_calib.diagnosis/1"
#: geometric within this factor of the noise floor on held-out data: nothing to diagnose
NULL_FACTOR = 1.5
UNKNOWN = "unknown"  # the verdict for structure no effect of the vocabulary explains
#: a joint signature this significant (sqrt(chi^2) it explains, in units of the residual)
#: is structure even where the floor is unknown and the learned correction learns nothing (a
#: clean recording's strongest signature stays near 3)
SIGNATURE_STRUCTURE = 5.0
#: a remaining signature is structure worth naming only when it moves the points by at least
#: this share of the noise floor (the best held-out rms when the floor is unknown): with
#: 36k poses a 0.5 urad harmonic is 6 sigma and still nothing (`signature_size_mm`)
STRUCTURE_SHARE = 0.1
#: hold-out bags whose best held-out rms exceeds this many times the larger of the noise
#: floor (when known) and the geometric calibration's in-sample rms do not belong to the
#: calibration (another robot, joint names mapped wrongly, another tracker placement): every
#: held-out figure is meaningless (a reason of `Diagnosis.implausible`, exit 3)
FOREIGN_HOLDOUT_FACTOR = 1000.0
#: ... and than this [mm] (1 um: below any tracker; noise-free simulations fit to ~1e-10 mm)
FOREIGN_HOLDOUT_MIN_MM = 1e-3
#: hold-out bags of fewer poses than this: their held-out rms (each uncertain by about
#: 1 / sqrt(6 n): 7 % at 30, 41 % at 1) and the model chosen on them are said to rest on too
#: few poses (`small_holdout`, in every output)
MIN_HOLDOUT_POSES = 30


@dataclass(frozen=True)
class DominantEffect(Record):
    """The effect (a vocabulary name, or 'unknown') and the joints where it lies."""

    effect: str
    joints: list[int]


def percent(share: float) -> str:
    """A share as a whole percentage ('12 %'); never '-0 %' (round() of a float is an int,
    so -0.4 % prints as '0 %')."""
    return f"{round(100 * share)} %"


@dataclass(frozen=True)
class RungScore(Record):
    """One rung of the ladder: held-out figures (seed criterion and absolute) and in-sample."""

    model: str
    holdout_mean_mm: float
    holdout_max_mm: float
    holdout_abs_mean_mm: float
    holdout_abs_max_mm: float
    holdout_abs_rms_mm: float
    insample_mean_mm: float
    insample_abs_rms_mm: float
    free_parameters: int
    # share of the learnable gap this rung closes: (geometric - rung) / (geometric - bound)
    # held-out rms, the bound the lower of the residual model's and the best rung's; None
    # where there is no learnable gap
    learnable_gap_share: float | None = None
    # the hybrid rung (a physical rung plus a learned correction): no effect of its own
    learned: bool = False
    # points the held-out figures are of (None: a document written before it was stored)
    holdout_points: int | None = None

    def holdout_seed_text(self, sep: str = " / ") -> str:
        """The held-out seed criterion 'mean / max' [mm], 'n/a (no pair)' when fewer than
        two points were held out: the 0 stored then measures nothing."""
        if self.holdout_points is not None and self.holdout_points < 2:
            return NO_PAIR
        return f"{self.holdout_mean_mm:.4f}{sep}{self.holdout_max_mm:.4f}"

    @classmethod
    def of(cls, rung: Rung, gap: tuple[float, float] | None = None) -> RungScore:
        """The rung's figures; gap: (geometric's held-out rms, the bound's) [mm]."""
        held = rung.heldout
        fit = rung.insample if rung.insample is not None else rung.calibration.accuracy
        share = None
        if gap is not None and gap[0] > gap[1]:
            share = (gap[0] - held.absolute_rms_mm) / (gap[0] - gap[1])
            if abs(share) < 1e-9:  # geometric itself (the reference): 0, not -1e-16
                share = 0.0
        return cls(
            rung.model,
            held.pairwise_mean_mm,
            held.pairwise_max_mm,
            held.absolute_mean_mm,
            held.absolute_max_mm,
            held.absolute_rms_mm,
            fit.pairwise_mean_mm,
            fit.absolute_rms_mm,
            int(rung.calibration.parameters.free.sum()),
            share,
            rung.learned,
            held.n_points,
        )


@dataclass(frozen=True)
class Unexplained(Record):
    """What remains after the best rung, and where it lies."""

    holdout_mean_mm: float
    holdout_abs_rms_mm: float
    noise_floor_abs_rms_mm: float | None  # None: the floor is unknown
    ratio_to_noise_floor: float | None
    note: str
    where: WhereItLies
    geometric_ratio_to_noise_floor: float | None = None  # geometric's held-out rms / floor


@dataclass(frozen=True)
class NoiseReport(Record):
    """The noise floor of the verdict (msgs_doc/diagnosis.md, `noise`); sigma and floor
    None when unknown (no repeat poses, circle sweeps or stated accuracy)."""

    sigma_mm: float | None
    source: str
    n: int
    floor_abs_rms_mm: float | None
    floor_abs_mean_mm: float | None
    ladder_sigma_mm: float
    ladder_source: str
    floor_known: bool = True
    # a stated accuracy against the evidence: unused beside measured noise, far
    # above it or the geometric fit's residual (a unit slip), refuted; '' when none
    warning: str = ""


@dataclass(frozen=True)
class CandidateScore(Record):
    model: str
    linearised_holdout_rms_mm: float


@dataclass(frozen=True)
class Diagnosis(Record):
    """DIAGNOSIS.json (msgs_doc/specification.md section 4, extended: msgs_doc/diagnosis.md)."""

    dominant_effect: DominantEffect | None
    ladder: list[RungScore]
    unexplained: Unexplained
    noise: NoiseReport
    scored_on: str
    selected_on: str
    where: WhereItLies
    candidates: list[list[CandidateScore]]
    recordings: list[str]
    holdout: list[str]
    # flagged measurements, never fitted: tracker blunders and poses where the robot was off
    # (every target together)
    outliers: list[Outlier] = field(default_factory=list)
    # stretches of consecutive measurements far above the rest (`concentration`), every
    # measurement's residual under the best model, flagged ones included
    stretches: list[Stretch] = field(default_factory=list)
    # regions of a joint's readings far above the rest whenever measured (`concentration`)
    regions: list[Region] = field(default_factory=list)
    # which masses the gravity effects used and where they came from (`masses`)
    mass_model: str = ""
    # the calibration's measurements and the distinct poses they were read at
    # (`poses.reading_groups`: re-reads, several targets and repeats of a pose are one);
    # 0 in documents written before they were recorded
    measurements: int = 0
    poses: int = 0
    # the tracker's drift per calibration recording with reference reflectors (removed
    # from every point before fitting; msgs_doc/references.md)
    tracker_drift: list[TrackerDrift] = field(default_factory=list)

    def learnable_warnings(self) -> list[str]:
        """The learned correction's own warnings (hyperparameters at an edge), as the
        reports list them: the console's learnable-bound line only counts them."""
        if self.learnable is None:
            return []
        return [f"learnable bound (learned correction): {w}" for w in self.learnable.warnings]

    def concentration_lines(self) -> list[str]:
        """Where the residual concentrates, a line each: the stretches, then the regions."""
        return [s.line() for s in self.stretches] + [r.line() for r in self.regions]

    def reads_line(self) -> str:
        """'1134 measurements at 378 poses (3.0 per pose: every measurement of a pose,
        re-read, revisited or of another target, shares its fold in every k-fold and
        split)', '' for documents without the counts."""
        if not self.poses:
            return ""
        per = self.measurements / self.poses
        return f"{self.measurements} measurements at {self.poses} poses ({per:.1f} per pose" + (
            ": every measurement of a pose, re-read, revisited or of another target, "
            "shares its fold in every k-fold and split)"
            if per > 1
            else ")"
        )

    warnings: list[str] = field(default_factory=list)  # implausible geometric calibration
    learnable: LearnableBound | None = None  # what a residual model reaches held out
    # ISO 9283 AP/RP of the repeated poses: before (nominal) and after (the best rung)
    iso9283: list[Iso9283] = field(default_factory=list)
    # every candidate the ladder refitted: its scores and why it was or was not a rung
    refits: list[RefitOutcome] = field(default_factory=list)
    # the geometric calibration's implausibility reasons (identify.plausibility): readings
    # in degrees, a residual 1000 x the noise, ...; empty: plausible
    implausible: list[str] = field(default_factory=list)
    # the hybrid rung far below the best physical one: what lies outside the vocabulary
    outside_vocabulary: OutsideVocabulary | None = None
    # the per-joint signature families of `where` (geometric's residuals) the chosen model
    # has an effect for: what it removed (the reports say so in those rows); empty: none
    removed_by_best_model: list[RemovedSignature] = field(default_factory=list)
    # what a quality system files the report under: date, robot and serial, instrument,
    # operator, temperatures, software, command (None: a diagnosis not written as a report)
    header: ReportHeader | None = None
    format: str = FORMAT

    def to_dict(self) -> dict[str, Any]:
        doc = super().to_dict()
        return {"format": doc.pop("format"), **doc}  # the format first, as always written

    @classmethod
    def from_dict(cls, data: Any) -> Diagnosis:  # noqa: ANN401 - JSON
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise InputError(f"not a robot_calib diagnosis (format {FORMAT})")
        return super().from_dict(data)

    @property
    def physical_model(self) -> str:
        """The model name of the last physical rung (the hybrid rung's physical part when
        it won: the effects the diagnosis names and where the rest lies)."""
        return [r for r in self.ladder if not r.learned][-1].model

    def effect_shares(self) -> list[tuple[str, float]]:
        """(the effect each rung added, its own share of the learnable gap): the rung's
        share minus the one before (refits are joint, so an effect's share is what adding
        it changed); empty without a learnable gap."""
        out = []
        for before, rung in zip(self.ladder, self.ladder[1:]):
            if rung.learnable_gap_share is None or before.learnable_gap_share is None:
                continue
            added = ModelSpec.parse(rung.model).added_to(ModelSpec.parse(before.model))
            out.append((added, rung.learnable_gap_share - before.learnable_gap_share))
        return out

    def bound_note(self) -> str | None:
        """Where the learnable bound of the shares comes from when it is not the kernel
        ridge's (`learnable_gap`: the lower of the two): the best rung's, else None."""
        if self.learnable is None or not self.ladder or not self.learnable.bounds:
            return None  # no bound at all: its figure is not quoted
        best = min(r.holdout_abs_rms_mm for r in self.ladder if not r.learned)
        if round(best, 4) >= round(self.learnable.holdout_abs_rms_mm, 4):  # ties as shown
            return None
        return (
            f"the shares' bound is the best rung's {best:.4f} mm, below the learned correction's "
            f"{self.learnable.holdout_abs_rms_mm:.4f} mm: a physical model learned more than "
            "the residual model"
        )

    @property
    def verdict(self) -> str:
        """One phrase: the dominant effect and its joints, or null."""
        dom = self.dominant_effect
        if dom is None:
            if self.implausible:
                return "none (the result is implausible: see IMPLAUSIBLE)"
            if self.noise.floor_known and self.noise.source.startswith(STATED):
                return (
                    "null (geometric reaches the noise level; that floor rests on the "
                    f"{self.noise.source} alone, not on repeat poses or circle fits)"
                )
            if self.noise.floor_known and self.noise.source in LOWER_BOUNDS:
                ratio = self.unexplained.geometric_ratio_to_noise_floor
                above = "" if ratio is None else f"{ratio:.2f} x "
                return (
                    f"null (no structure found: geometric is {above}a floor of the "
                    f"tracker's noise alone, {self.noise.source.split(' (')[0]}, which the "
                    "robot's repeatability and the SMR's centring add to; the learned "
                    "correction learns nothing held out and no joint signature stands "
                    "out)"
                )
            if self.noise.floor_known:
                return "null (geometric reaches the noise level)"
            return (
                "null (noise floor unknown; the learned correction learns nothing held out and no "
                "joint signature stands out)"
            )
        if dom.effect == UNKNOWN:
            named = f"{UNKNOWN} (outside the vocabulary) on joints {dom.joints}"
        else:
            named = f"{dom.effect} on joints {dom.joints}"
        out = self.outside_vocabulary
        if out is None:
            return named
        where = f" (load-driven, joints {out.joints})" if out.joints else ""
        return (
            f"{named}; most of what remains lies outside the vocabulary{where}: "
            f"{out.physical_abs_rms_mm:.4f} -> {out.hybrid_abs_rms_mm:.4f} mm held-out with a "
            "learned correction"
        )

    def save(self, path: str | Path) -> Path:
        """Write this diagnosis as DIAGNOSIS.json at `path` (atomically); the path written.
        (`robot-calib diagnose` also writes the Markdown and HTML reports beside it.)"""
        from robot_calib.identify.params_file import write_json_atomic

        path = Path(path)
        write_json_atomic(self.to_dict(), path)
        return path

    def summary(self) -> str:
        """A few human lines: the verdict, the ladder (held-out, seed criterion), what
        remains."""
        rungs = "; ".join(f"{r.model} {r.holdout_seed_text(sep='/')} mm" for r in self.ladder)
        blunders = (
            f" {len(self.outliers)} measurement(s) left out as tracker blunders: "
            + "; ".join(o.line() for o in self.outliers)
            + "."
            if self.outliers
            else ""
        )
        floor = self.noise.floor_abs_rms_mm
        floor_text = "unknown" if floor is None else f"{floor:.4f} mm rms"
        bound = f" {self.learnable.line()}." if self.learnable is not None else ""
        return (
            f"dominant effect: {self.verdict}. Ladder (held-out seed criterion mean/max, "
            f"{self.scored_on}): {rungs}. Noise floor {floor_text}.{bound} "
            f"{self.unexplained.note}.{blunders}"
        )


def learnable_gap(ladder: Ladder) -> tuple[float, float] | None:
    """(geometric's held-out rms, the bound's) [mm]: the bound is the lower of the residual
    model's and the best rung's (a physical model that beats the residual model shows more
    was learnable); None when it is not MIN_LEARNABLE_SHARE below geometric."""
    bound = ladder.learnable
    if bound is None:
        return None
    geometric = bound.geometric_abs_rms_mm
    lowest = min([bound.holdout_abs_rms_mm] + [r.heldout.absolute_rms_mm for r in ladder.rungs])
    if geometric - lowest < MIN_LEARNABLE_SHARE * geometric:
        return None
    return geometric, lowest


def physical_rungs(ladder: Ladder) -> list[Rung]:
    """The ladder's rungs without the hybrid one (a physical rung plus a learned
    correction: `ladder._learn_the_rest`)."""
    return [r for r in ladder.rungs if not r.learned]


def dominant_effect(
    ladder: Ladder, where: WhereItLies, noise: NoiseLevel, outside: OutsideVocabulary | None = None
) -> DominantEffect | None:
    """The effect that removed most of what `geometric` left (with its joints); None when
    geometric is already at the noise level, or, the floor unknown, when neither the
    residual model learns more than geometric held out (`Ladder.learnable`) nor a joint
    signature reaches SIGNATURE_STRUCTURE: never because geometric fits itself; 'unknown'
    with the joint of the learned correction's strongest load-driven motion when `outside`
    (the hybrid rung far below the physical ones) has one, else of the strongest residual
    signature, when structure remains that no candidate explains."""
    rungs = physical_rungs(ladder)  # a learned correction is no effect
    floor_mm = noise.floor_rms_m * 1e3
    gains: dict[str, float] = {}
    joints: dict[str, set[int]] = {}
    for before, rung in zip(rungs, rungs[1:]):
        added = rung.effects[-1]
        gain = before.heldout.absolute_rms_mm - rung.heldout.absolute_rms_mm
        gains[added.name] = gains.get(added.name, 0.0) + gain
        joints.setdefault(added.name, set()).update(added.joints)
    if gains:
        name = max(gains, key=gains.__getitem__)
        return DominantEffect(name, sorted(joints[name]))
    if noise.independent and rungs[0].heldout.absolute_rms_mm <= NULL_FACTOR * floor_mm:
        return None  # at the noise level
    strongest = where.strongest_signature
    learnt = ladder.learnable is not None and ladder.learnable.structure_left
    signed = strongest is not None and strongest.significance >= SIGNATURE_STRUCTURE
    if (not noise.independent or noise.lower_bound) and not learnt and not signed:
        return None  # floor unknown or the tracker's alone, nothing learnable, no signature
    if outside is not None and outside.motions:  # what the learned correction found
        return DominantEffect(UNKNOWN, [outside.motions[0].joint])
    # a drift with time (joint 0) names no joint
    return DominantEffect(UNKNOWN, [strongest.joint] if strongest and strongest.joint else [])


def diagnose(
    recording: Recording,
    robot: RobotDescription,
    holdout: Recording | None = None,
    log: Log | None = None,
    tracker_sigma_m: float | None = None,
    on_ladder: Callable[[Ladder, Recording, float | None], object] | None = None,
) -> tuple[Diagnosis, Ladder]:
    """The sim-to-real gap diagnosis of `recording`: the model ladder (geometric, then the
    effects that lower the held-out error), scored on `holdout` (None: k-fold over poses);
    the noise floor from the data, else `tracker_sigma_m` (a stated 1-sigma per axis [m]),
    else unknown. `on_ladder` is called as soon as the ladder is climbed, with it, the
    measurements it was fitted on (outliers left out) and the noise floor [mm] (None:
    unknown; as `Diagnosis.noise.floor_abs_rms_mm`): the reports' figures can start.

    Returns
    -------
    diagnosis : Diagnosis
        The DIAGNOSIS.json document (msgs_doc/diagnosis.md), with the following fields:

        dominant_effect : DominantEffect or None
            The effect ('unknown' if none of the vocabulary) and its joints; None when
            the geometric model reaches the noise level.
        ladder : list of RungScore
            Per rung, in the order added: held-out and in-sample errors [mm], free
            parameters.
        unexplained : Unexplained
            Held-out error of the best rung [mm], the noise floor [mm], their ratio, a
            note and where the rest lies.
        noise : NoiseReport
            The noise level [mm] and its source, and the floor it implies [mm].
        scored_on, selected_on : str
            What the rungs were scored and selected on (hold-out bags, k-fold CV).
        where : WhereItLies
            Per-joint signatures of the geometric model's residuals.
        candidates : list of list of CandidateScore
            Per round of the ladder, the candidates' linearised held-out rms [mm].
        recordings, holdout : list of str
            The sources of `recording` and of `holdout`.
    ladder : Ladder
        The rungs (each with its Calibration and held-out residuals (m, 3) [m]), the noise
        level used [m] and the candidates of every round (model, score [m]).
    """
    ladder = run_ladder(recording, robot, holdout, log, tracker_sigma_m)
    whole = recording  # every measurement, the ones flagged as blunders included
    few = small_holdout(ladder.holdout)
    if few and log is not None:
        log(few)
    sources, holdout_sources = list(recording.sources), holdout
    recording = ladder.recording if ladder.recording is not None else recording  # no outliers
    best = ladder.rungs[-1]  # the chosen model: the hybrid when it won
    physical = physical_rungs(ladder)
    last = physical[-1]  # where its residual lies: the physical model's
    noise = ladder.noise  # the verdict's floor: independent evidence only, never a residual
    floor_mm = noise.floor_rms_m * 1e3 if noise.independent else None
    if on_ladder is not None:
        on_ladder(ladder, recording, floor_mm)
    geo = ladder.rungs[0].calibration
    where = where_it_lies(
        geo.model,
        geo.parameters,
        recording,
        geo.residuals,
        ladder.noise.sigma_m,
        ladder.spectra.get("geometric"),
    )
    after = (
        where
        if len(physical) == 1
        else where_it_lies(
            last.calibration.model,
            last.calibration.parameters,
            recording,
            last.calibration.residuals,
            ladder.noise.sigma_m,
            ladder.spectra.get(last.model),
        )
    )
    ratio = None if floor_mm is None else best.heldout.absolute_rms_mm / floor_mm
    learnable = ladder.learnable
    foreign = foreign_holdout(ladder, geo.accuracy.absolute_rms_mm, floor_mm)
    outside = None if foreign else outside_vocabulary(ladder, recording)
    reference_mm = floor_mm if floor_mm is not None else best.heldout.absolute_rms_mm
    sig = after.strongest_signature
    sized = sig is not None and sig.significance >= 3
    if sig is not None and sized:
        size = signature_size_mm(sig, after, recording, robot)
        sized = size is None or size >= STRUCTURE_SHARE * reference_mm
    structure = f"; strongest structure: {sig.text}" if sig and sized else ""
    if foreign:
        note = f"no verdict: {foreign}"
    elif ratio is None:
        why = (
            "the stated tracker accuracy is refuted by the geometric fit's residual: see "
            "the warning"
            if ladder.noise.warning
            else "no repeat poses, circle sweeps or "
            "stated tracker accuracy; state the tracker's accuracy"
        )
        note = (
            f"noise floor unknown ({why}): held-out errors are not compared with one"
            + (f"; {learnable.line()}" if learnable is not None else "")
            + structure
        )
    elif best.learned and floor_mm is not None:
        note = _hybrid_note(best.model, ratio, last, floor_mm, structure, outside)
    elif ratio <= AT_FLOOR:
        note = f"at the noise level: held-out rms {ratio:.2f} x the noise floor"
    else:
        note = (
            f"held-out rms {ratio:.2f} x the noise floor remains"
            + (
                "; it lies outside the vocabulary: no effect of it reduces it further (joint-"
                f"angle harmonics scanned up to order {MAX_SCAN_ORDER}, as far as the readings "
                "resolve them)"
                if structure
                else "; no effect of the vocabulary reduces it further"
            )
            + structure.replace("strongest structure", "strongest remaining structure")
        )
    misses = best.calibration.predict(whole.poses) - whole.points  # every measurement
    found = stretches(whole, misses, floor_mm, robot.joint_names)
    diagnosis = Diagnosis(
        dominant_effect=None if foreign else dominant_effect(ladder, where, noise, outside),
        ladder=[RungScore.of(r, learnable_gap(ladder)) for r in ladder.rungs],
        unexplained=Unexplained(
            best.heldout.pairwise_mean_mm,
            best.heldout.absolute_rms_mm,
            floor_mm,
            ratio,
            note,
            after,
            None if floor_mm is None else ladder.rungs[0].heldout.absolute_rms_mm / floor_mm,
        ),
        noise=NoiseReport(
            noise.sigma_m * 1e3 if noise.independent else None,
            noise.source if noise.independent else "unknown",
            noise.n if noise.independent else 0,
            floor_mm,
            noise.floor_mean_m * 1e3 if noise.independent else None,
            ladder.noise.sigma_m * 1e3,
            ladder.noise.source,
            noise.independent,
            ladder.noise.warning,
        ),
        scored_on=ladder.scored_on,
        selected_on=f"{N_FOLDS}-fold CV over poses"
        + (" + hold-out bags (equal weight)" if holdout is not None else ""),
        where=where,
        candidates=[[CandidateScore(m, s * 1e3) for m, s in rnd] for rnd in ladder.candidates],
        recordings=sources,
        holdout=[] if holdout_sources is None else list(holdout_sources.sources),
        outliers=list(ladder.outliers),
        stretches=found,
        regions=regions(whole, misses, floor_mm, robot.joint_names, found),
        mass_model=mass_model_line(robot),
        measurements=len(whole),
        poses=len(np.unique(reading_groups(whole.poses.q))),
        tracker_drift=[r.drift for r in whole.references if r.drift is not None],
        warnings=list(geo.warnings)
        + ([ladder.noise.warning] if ladder.noise.warning else [])
        + ([few] if few else [])
        + alias_warnings(last.effects, recording, ladder.holdout),
        learnable=learnable,
        outside_vocabulary=outside,
        iso9283=_iso9283(ladder, recording, robot),
        refits=list(ladder.refits),
        removed_by_best_model=removed_signatures(best.effects),
        implausible=list(geo.implausible)
        + _holdout_in_degrees(holdout_sources, robot)
        + ([foreign] if foreign else []),
    )
    return diagnosis, ladder


def _hybrid_note(
    hybrid: str,
    ratio: float,
    physical: Rung,
    floor_mm: float,
    structure: str,
    outside: OutsideVocabulary | None,
) -> str:
    """The 'what remains' note when the hybrid rung `hybrid` won (held-out `ratio` x the
    floor): what the physical model leaves (its ratio, its strongest structure), what the
    hybrid leaves, and where the difference lies (`outside`, DIAGNOSIS.json
    `outside_vocabulary`), never the physical model's structure as what remains."""
    left = physical.heldout.absolute_rms_mm / floor_mm
    hybrid_part = (
        f"at the noise level with the hybrid model {hybrid}: held-out rms {ratio:.2f} "
        "x the noise floor"
        if ratio <= AT_FLOOR
        else f"held-out rms {ratio:.2f} x the noise floor remains with the hybrid model {hybrid}"
    )
    physical_part = (
        f"; the physical model {physical.model} alone leaves {left:.2f} x"
        + structure.replace("; strongest structure", " (its strongest structure")
        + (")" if structure else "")
    )
    if outside is not None:
        closed = (
            "; the learned correction closes most of that: it lies outside the "
            "vocabulary (see outside_vocabulary"
            + (f": load-driven, joints {outside.joints})" if outside.joints else ")")
        )
    else:
        closed = "; the learned correction closes part of that"
    return hybrid_part + physical_part + closed


def signature_size_mm(
    sig: Signature, where: WhereItLies, recording: Recording, robot: RobotDescription
) -> float | None:
    """The rms [mm] the signature `sig` moves the measured points by: its joint-angle error
    (a harmonic's amplitude / sqrt 2; the approach direction's value; the reading's or the
    gravity torque's value times that signal's standard deviation over `recording`) times the
    median lever of its joint (`where.joints_from_all_poses`); None when unknown."""
    terms = {t.joint: t for t in where.joints_from_all_poses}
    entry = terms.get(sig.joint)
    if entry is None or entry.lever_mm is None:
        return None
    q = recording.poses.q[:, sig.joint - 1]
    if sig.harmonic is not None:
        angle = abs(sig.value) / np.sqrt(2.0)
    elif "approach direction" in sig.text:
        angle = abs(sig.value)
    elif "reading (scale-like)" in sig.text:
        angle = abs(sig.value) * float(np.std(q))
    elif "gravity torque" in sig.text:
        tau = gravity_torques(robot, recording.poses.q[:: max(1, len(q) // 5000)])
        angle = abs(sig.value) * float(np.std(tau[:, sig.joint - 1]))
    else:
        return None
    return angle * 1e-6 * entry.lever_mm


def foreign_holdout(ladder: Ladder, insample_mm: float, floor_mm: float | None) -> str:
    """Why the hold-out bags do not belong to this calibration: the lowest held-out rms of
    the rungs above FOREIGN_HOLDOUT_FACTOR times the noise floor `floor_mm`, or, the floor
    unknown (None), times the geometric calibration's in-sample rms `insample_mm` [mm] (and
    above FOREIGN_HOLDOUT_FACTOR x FOREIGN_HOLDOUT_MIN_MM); '' when it is not, or without
    hold-out bags (k-fold)."""
    if ladder.holdout is None or not ladder.rungs:
        return ""
    held = min(r.heldout.absolute_rms_mm for r in ladder.rungs)
    reference = max(floor_mm if floor_mm else insample_mm, FOREIGN_HOLDOUT_MIN_MM)
    if not held > FOREIGN_HOLDOUT_FACTOR * reference:
        return ""
    floor = (
        f"{held / floor_mm:.0f} x the noise floor ({floor_mm:.4f} mm; limit "
        f"{FOREIGN_HOLDOUT_FACTOR:.0f} x) and "
        if floor_mm
        else ""
    )
    limit = "" if floor_mm else f"; limit {FOREIGN_HOLDOUT_FACTOR:.0f} x, the floor unknown"
    return (
        f"held-out rms {held:.4g} mm is {floor}{held / max(insample_mm, 1e-12):.0f} x the "
        f"geometric calibration's in-sample rms ({insample_mm:.4f} mm{limit}): the hold-out "
        f"bags ({', '.join(ladder.holdout.sources)}) do not belong to this calibration "
        "(another robot, joint names or order mapped wrongly, another tracker placement?): "
        "every held-out figure is meaningless"
    )


def small_holdout(holdout: Recording | None) -> str:
    """The warning for hold-out bags of fewer than MIN_HOLDOUT_POSES poses (a rung's
    held-out rms over n poses is uncertain by about 1 / sqrt(6 n) of itself: half the
    variance of 3 n squared components); '' for more, or without hold-out bags (k-fold).
    Poses, not measurements: re-reads and targets of one pose (`reading_groups`) are one."""
    if holdout is None:
        return ""
    n = int(reading_groups(holdout.poses.q).max()) + 1 if len(holdout) else 0
    if n >= MIN_HOLDOUT_POSES:
        return ""
    if n == 0:
        return (
            f"warning: the hold-out bags ({', '.join(holdout.sources)}) hold no pose: "
            "nothing is scored on them"
        )
    return (
        f"warning: the hold-out bags ({', '.join(holdout.sources)}) hold {n} pose(s), fewer "
        f"than {MIN_HOLDOUT_POSES}: each held-out rms is uncertain by about "
        f"{100 / np.sqrt(6 * n):.0f} % and the model chosen on them (the dominant effect "
        "included) may be chance; record more hold-out poses, or score without a hold-out "
        "(k-fold over the calibration's poses)"
    )


def _holdout_in_degrees(holdout: Recording | None, robot: RobotDescription) -> list[str]:
    """Why hold-out bags whose readings look like degrees make every held-out figure
    nonsense (a reason of `Diagnosis.implausible`); empty otherwise."""
    reason = "" if holdout is None else degrees_reason(holdout, robot, "hold-out readings")
    return [f"{reason}: every held-out figure is meaningless"] if reason else []


def _iso9283(ladder: Ladder, recording: Recording, robot: RobotDescription) -> list[Iso9283]:
    """ISO 9283 figures before (the nominal model, its tracker pose and target fitted on
    the calibration recording) and after calibration (the best rung), on the hold-out
    bags' repeated poses, else the calibration recording's; empty without repeats."""
    candidates = [(ladder.holdout, "hold-out bags"), (recording, "calibration recording")]
    found = next(
        (
            (scored, where, groups)
            for scored, where in candidates
            if scored is not None and (groups := repeat_groups(scored))
        ),
        None,
    )
    if found is None:
        return []
    scored, where, groups = found
    nominal = calibrate(recording, robot, "nominal", screen_outliers=False)
    best = ladder.rungs[-1]
    out = []
    for name, cal in (("nominal", nominal), (best.model, best.calibration)):
        turned = orientation_residuals(cal.model, cal.parameters, scored.poses)
        figures = iso9283(scored, cal.predict(scored.poses), name, where, groups, turned)
        if figures is not None:
            out.append(figures)
    return out
