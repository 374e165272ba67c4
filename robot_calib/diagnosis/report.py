"""The human report of a diagnosis: Markdown with PNG plots (the ladder, residual against each
joint angle split by approach direction, residual against time), readable without the JSON."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robot_calib.accuracy import Accuracy
from robot_calib.diagnosis.diagnosis import Diagnosis, NoiseReport, percent, small_holdout
from robot_calib.diagnosis.figures import (
    ANGLE_UNITS,
    FigureCache,
    angle_figure,
    drift_figure,
    ladder_figure,
    residual_map_figure,
    time_figure,
)
from robot_calib.diagnosis.ladder import HOLDOUT_K, Ladder
from robot_calib.diagnosis.names import with_breaks
from robot_calib.diagnosis.noise import noise_basis
from robot_calib.diagnosis.signatures import (
    ArcSignature,
    JointTerms,
    WhereItLies,
    removed_note,
    scan_order_note,
    signature_removed,
    signature_text,
)
from robot_calib.identify.outliers import OUTLIER_K, outlier_counts
from robot_calib.kinematics.frames import Array
from robot_calib.measurements import Recording

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from robot_calib.diagnosis.iso9283 import Iso9283
    from robot_calib.identify.calibration import Calibration

#: the figures' file name suffixes: `<stem>_<suffix>.png` (a figure with nothing to show is
#: not written)
PLOT_SUFFIXES = ("ladder", "angle", "map", "time", "drift")


def plot_paths(stem: Path) -> list[Path]:
    """Every PNG a report `<stem>.md` may have beside it (`PLOT_SUFFIXES`)."""
    return [stem.with_name(f"{stem.name}_{suffix}.png") for suffix in PLOT_SUFFIXES]


def report_figures(
    ladder: Ladder, recording: Recording, floor_mm: float | None
) -> list[tuple[str, str, str, Callable[[], Figure | None]]]:
    """The Markdown report's figures: (suffix of its PNG, cache key, title, draw) each,
    the draws picklable (`FigureCache.draw_aside`)."""
    return [
        (
            "ladder",
            "ladder",
            "The ladder: held-out error of each model",
            partial(ladder_figure, ladder, floor_mm),
        ),
        (
            "angle",
            "angle_urad",
            "Residual against each joint angle, by approach direction",
            partial(angle_figure, ladder, recording, "urad"),
        ),
        (
            "map",
            "map",
            "Residual maps: against reach, height and every joint's reading",
            partial(residual_map_figure, ladder, recording),
        ),
        (
            "time",
            "time",
            "Residual against time (in-sample)",
            partial(time_figure, ladder, recording),
        ),
        (
            "drift",
            "drift",
            "The tracker's drift: reference reflectors against time",
            partial(drift_figure, recording),
        ),
    ]


def _plots(
    ladder: Ladder, recording: Recording, stem: Path, floor_mm: float | None, figures: FigureCache
) -> list[tuple[str, str]]:
    """The figures (figures.py) saved as PNGs `<stem>_*.png`: (title, file name) each;
    drawn once in `figures` (the HTML page shows them too)."""
    out = []
    for suffix, key, title, draw in report_figures(ladder, recording, floor_mm):
        png = figures.png(key, draw)
        if png is None:
            continue
        path = stem.with_name(f"{stem.name}_{suffix}.png")
        path.write_bytes(png)
        out.append((title, path.name))
    return out


def harmonic_cells(
    entry: ArcSignature | JointTerms, where: WhereItLies, shown: Callable[[float, float], str]
) -> str:
    """A row's harmonics 1-4, each `shown(amplitude [urad], significance)`; an amplitude
    without a value is NOT_RESOLVED on an arc, and as `blank` says from every pose."""
    if entry.harmonics_urad is None or entry.harmonics_significance is None:
        return unobservable(entry)
    cells = []
    pairs = zip(entry.harmonics_urad, entry.harmonics_significance)
    for k, (a, s) in enumerate(pairs, start=1):
        if a is not None:
            cells.append(shown(a, s))
        elif isinstance(entry, ArcSignature):
            cells.append(NOT_RESOLVED)
        else:
            cells.append(blank(where, entry.joint, "harmonics", k))
    return ", ".join(cells)


def blank(where: WhereItLies, joint: int, family: str, order: int | None = None) -> str:
    """What a per-joint table shows for a term of the joint fit without a value:
    NOT_RESOLVED where it was a candidate these poses do not resolve, '-' where it was none
    (an order the model has, a signal that does not vary)."""
    return NOT_RESOLVED if where.has_term(joint, family, order) else "-"


#: an amplitude the poses do not resolve (`signatures.ArcSignature`, `JointTerms`)
NOT_RESOLVED = "n.r."


def unobservable(entry: ArcSignature | JointTerms) -> str:
    """'not observable (target X mm from the axis)': a joint its targets cannot show."""
    lever = "" if entry.lever_mm is None else f" {entry.lever_mm:.2f} mm"
    return f"not observable (target{lever} from the axis)"


def _value(value: float | None, digits: int, significance: float | None = None) -> str:
    if value is None:
        return "-"
    return f"{value:.{digits}f}" + ("" if significance is None else f" ({significance:.0f}x)")


def _urad(amplitude: float, significance: float) -> str:
    return f"{amplitude:.1f} ({significance:.0f}x)"


def _term(where: WhereItLies, t: JointTerms, family: str, digits: int) -> str:
    """The cell of `family` (direction, scale, gravity) of row `t`: its value with its
    significance, else `blank`."""
    value, significance = t.of_family(family)
    if value is None:
        return blank(where, t.joint, family)
    return _value(value, digits, significance)


def _floor_sentence(noise: NoiseReport) -> str:
    """The report's sentence on the noise floor (or that it is unknown), and the word on a
    stated accuracy the evidence contradicts."""
    said = f" **{noise.warning[0].upper()}{noise.warning[1:]}.**" if noise.warning else ""
    if noise.sigma_mm is None or noise.floor_abs_rms_mm is None:
        return (
            "Noise floor **unknown**: "
            + (
                ""
                if noise.warning
                else "the data have no repeat poses or circle sweeps and no accuracy is stated; "
            )
            + "held-out errors are not compared with a floor."
            + said
        )
    return (
        f"Noise level ({noise_basis(noise.source, noise.n)}): {noise.sigma_mm * 1e3:.1f} um per "
        f"axis; a perfect model would leave {noise.floor_abs_rms_mm:.4f} mm rms on held-out "
        "points." + said
    )


def _times_floor(value_mm: float, floor_mm: float | None) -> str:
    return "unknown" if floor_mm is None else f"{value_mm / floor_mm:.2f}"


def _harmonic_lines(diagnosis: Diagnosis) -> list[str]:
    """The frequency scan of the geometric and the best model's residuals, with what the
    orders usually mean, and the refits the ladder made."""
    out: list[str] = []
    removed = diagnosis.removed_by_best_model
    after = None if diagnosis.unexplained.where is diagnosis.where else diagnosis.unexplained.where
    for title, where in (
        ("geometric", diagnosis.where),
        (diagnosis.physical_model, diagnosis.unexplained.where),
    ):
        found = [s for s in where.harmonic_orders if s.dominant_orders]
        if not found or (title != "geometric" and where is diagnosis.where):
            continue
        out += [
            "",
            f"Joint-angle harmonics in the residuals of {title} (frequency scan of "
            "orders 1-64, beyond what the model absorbs; amplitude, x its uncertainty in "
            "the joint fit of every term, 0 where it does not lower the k-fold error):",
            "",
        ]
        for spectrum in found:
            gone = removed_note(removed, spectrum.joint, spectrum.dominant_orders, ("harmonics",))
            out.append(
                f"- {spectrum.line()}" + (f" ({gone})" if gone and title == "geometric" else "")
            )
            for k, why in zip(spectrum.dominant_orders, spectrum.meaning):
                note = (
                    ""
                    if title != "geometric"
                    else scan_order_note(
                        removed, spectrum.joint, k, after, diagnosis.physical_model
                    )
                )
                out.append(f"  - order {k}: {why}" + (f" ({note})" if note and not gone else ""))
    if diagnosis.refits:
        out += [
            "",
            "Candidates refitted by the ladder:",
            "",
            "| model | linearised [mm] | in-sample rms [mm] | held-out [mm] | outcome |",
            "|---|---|---|---|---|",
        ]
        for r in diagnosis.refits:
            held = "-" if r.heldout_mm is None else f"{r.heldout_mm:.4f}"
            outcome = "rung" if r.accepted else f"rejected: {r.reason}"
            out.append(
                f"| {with_breaks(r.model)} | {r.linearised_mm:.4f} "
                f"| {r.insample_rms_mm:.4f} | {held} | {outcome} |"
            )
    return out


@dataclass(frozen=True)
class ModelErrors:
    """One model of the before/after comparison and its error on the points it is scored
    on: `residuals` (m, 3) predicted - measured [m] in the tracker frame, their accuracy
    figures [mm] and what they are (`scored_on`: hold-out bags, k-fold CV or in-sample)."""

    model: str
    role: str  # why it is in the table: before calibration, CPA, geometric, the best
    scored_on: str
    residuals: Array
    accuracy: Accuracy

    @property
    def errors_mm(self) -> Array:
        """Per-point error |predicted - measured| (m,) [mm]."""
        return np.asarray(np.linalg.norm(self.residuals, axis=1) * 1e3)


#: how a parameter unit is shown to people: factor from SI, unit
HUMAN_UNITS = {
    "m": (1e3, "mm"),
    "rad": (ANGLE_UNITS["deg"], "deg"),
    "1": (1e6, "ppm"),
    "rad/m": (ANGLE_UNITS["deg"], "deg/m"),
    "rad/(N m)": (ANGLE_UNITS["deg"], "deg/(N m)"),
}
PARAMETER_COLUMNS = ("parameter", "unit", "value", "nominal", "deviation", "1-sigma")


def human(unit: str, value: float) -> float:
    """`value` in the SI `unit` as HUMAN_UNITS shows it (mm, deg, ppm)."""
    return value * HUMAN_UNITS.get(unit, (1.0, unit))[0]


def parameter_rows(cal: Calibration) -> list[list[str]]:
    """The parameter table of `cal` (PARAMETER_COLUMNS: value, nominal, deviation, 1-sigma
    in mm / deg / ppm; the 1-sigma 'fixed' for a fixed one), both reports': the geometry,
    the frames and the free effect terms (effect terms the data fixed are listed by
    reason)."""
    rows = []
    for p, value, std in zip(cal.parameters.parameters, cal.parameters.values, cal.std):
        if p.group not in ("geometric", "frames") and not p.free:
            continue
        frame = p.group == "frames"  # the tracker pose and target offsets: no nominal
        rows.append(
            [
                p.name,
                HUMAN_UNITS.get(p.unit, (1.0, p.unit))[1],
                f"{human(p.unit, value):.5f}",
                "-" if frame else f"{human(p.unit, p.nominal):.5f}",
                "-" if frame else f"{human(p.unit, value - p.nominal):.5f}",
                f"{human(p.unit, std):.2g}" if p.free else "fixed",
            ]
        )
    return rows


def iso_pose_table(figures: Sequence[Iso9283]) -> tuple[list[str], list[list[object]]]:
    """ISO 9283 per repeated pose (both reports): the header and a row per pose (its
    first measurement, n, the AP of every model of `figures`, the RP) [mm]; where
    orientations were measured, also AP_a/b/c of every model and RP_a/b/c [deg]."""
    oriented = any(p.rp_abc_deg is not None for p in figures[0].poses)
    header = [
        "pose",
        "first measurement",
        "n",
        *(f"AP {f.model} [mm]" for f in figures),
        "RP [mm]",
        *([*(f"AP a/b/c {f.model} [deg]" for f in figures), "RP a/b/c [deg]"] if oriented else []),
    ]
    rows: list[list[object]] = [
        [
            k + 1,
            p.first_index,
            p.n,
            *(f"{f.poses[k].ap_mm:.4f}" for f in figures),
            f"{p.rp_mm:.4f}",
            *(
                [*(_abc(f.poses[k].ap_abc_deg) for f in figures), _abc(p.rp_abc_deg)]
                if oriented
                else []
            ),
        ]
        for k, p in enumerate(figures[0].poses)
    ]
    return header, rows


def iso_distance_table(figures: Sequence[Iso9283]) -> tuple[list[str], list[list[object]]]:
    """ISO 9283 distance accuracy and repeatability (both reports): a row per model with
    AD and RD [mm] and, with orientations, the largest AD a/b/c and RD a/b/c [deg]."""
    oriented = any(f.distance is not None and f.distance.rd_abc_deg for f in figures)
    header = ["model", "AD [mm]", "RD [mm]"]
    if oriented:
        header += ["AD a/b/c max [deg]", "RD a/b/c max [deg]"]
    rows: list[list[object]] = []
    for f in figures:
        if f.distance is None:
            continue
        d = f.distance
        row: list[object] = [f.model, f"{d.ad_mm:+.4f}", f"{d.rd_mm:.4f}"]
        if oriented:
            row += [
                max_deg(max(d.ad_abc_deg) if d.ad_abc_deg else None),
                max_deg(max(d.rd_abc_deg) if d.rd_abc_deg else None),
            ]
        rows.append(row)
    return header, rows


def max_deg(value: float | None) -> str:
    """A largest orientation figure [deg], '-' without orientations."""
    return "-" if value is None else f"{value:.4f}"


def _abc(values: tuple[float, float, float] | None) -> str:
    """'0.0012 / 0.0008 / 0.0031' [deg], '-' where none."""
    return "-" if values is None else " / ".join(f"{v:.4f}" for v in values)


def _markdown_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> list[str]:
    """A Markdown table's lines."""
    return [
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
        *("| " + " | ".join(str(c) for c in row) + " |" for row in rows),
    ]


def _extra_sections(
    compared: Sequence[ModelErrors], best: Calibration | None, warnings: Sequence[str]
) -> list[str]:
    """What the HTML report says besides: accuracy before and after calibration (the
    nominal 'before' row included), the best model's parameters, every warning."""
    lines: list[str] = []
    if compared:
        lines += [
            "",
            "## Accuracy before and after calibration",
            "",
            *_markdown_table(
                [
                    "model",
                    "role",
                    "scored on",
                    "absolute mean / rms / max [mm]",
                    "seed criterion mean / max [mm]",
                ],
                [
                    [
                        with_breaks(m.model),
                        m.role,
                        m.scored_on,
                        f"{m.accuracy.absolute_mean_mm:.4f} / {m.accuracy.absolute_rms_mm:.4f}"
                        f" / {m.accuracy.absolute_max_mm:.4f}",
                        m.accuracy.pairwise_text(),
                    ]
                    for m in compared
                ],
            ),
        ]
    if best is not None:
        lines += [
            "",
            f"## Parameters of the best model ({best.label})",
            "",
            *_markdown_table(PARAMETER_COLUMNS, parameter_rows(best)),
        ]
    lines += ["", "## Warnings", ""]
    lines += [f"- {w}" for w in warnings] if warnings else ["No warnings."]
    return lines


def write_report(
    diagnosis: Diagnosis,
    ladder: Ladder,
    recording: Recording,
    path: Path,
    figures: FigureCache | None = None,
    compared: Sequence[ModelErrors] = (),
    best: Calibration | None = None,
    warnings: Sequence[str] = (),
) -> None:
    """Markdown report `path` (+ PNGs beside it named after it); `figures`: where the
    figures are drawn once for both reports (default: a new one); `compared`, `best`,
    `warnings`: as the HTML report's (`html_report`): the accuracy before and after
    calibration, the parameters of the model chosen, the caller's warnings (the
    recording's and the diagnosis' are added here)."""
    noise, where = diagnosis.noise, diagnosis.where
    removed = diagnosis.removed_by_best_model
    figures = FigureCache() if figures is None else figures
    plots = _plots(ladder, recording, path.with_suffix(""), noise.floor_abs_rms_mm, figures)
    dom = diagnosis.dominant_effect
    verdict = (
        f"{diagnosis.verdict}: no dominant unmodelled effect"
        if dom is None
        else f"dominant effect: **{dom.effect}** on joint(s) {dom.joints or '-'}"
    )
    lines = [
        "# Sim-to-real gap diagnosis" + (" — IMPLAUSIBLE" if diagnosis.implausible else ""),
        "",
        *(
            [*(f"- **{label}**: {text}" for label, text in diagnosis.header.rows()), ""]
            if diagnosis.header is not None
            else []
        ),
        f"Recordings: {', '.join(diagnosis.recordings)}; scored on {diagnosis.scored_on}"
        + (f" ({', '.join(diagnosis.holdout)})" if diagnosis.holdout else "")
        + ".",
        "",
        *(
            [f"**{few[0].upper()}{few[1:]}.**", ""]
            if (few := small_holdout(ladder.holdout))
            else []
        ),
        f"**Verdict** — {verdict}.",
        "",
        *(
            [
                f"**{diagnosis.outside_vocabulary.line()[0].upper()}"
                f"{diagnosis.outside_vocabulary.line()[1:]}**.",
                "",
            ]
            if diagnosis.outside_vocabulary is not None
            else []
        ),
        *(
            [
                f"**IMPLAUSIBLE** — {'; '.join(diagnosis.implausible)}: fix the data (units, "
                "robot description, joint order) and diagnose again.",
                "",
            ]
            if diagnosis.implausible
            else []
        ),
        _floor_sentence(noise),
        "",
        "| model | held-out seed criterion mean / max [mm] "
        "| held-out absolute mean / rms [mm] | x noise floor | share of the learnable gap |",
        "|---|---|---|---|---|",
    ]
    for rung in diagnosis.ladder:
        share = rung.learnable_gap_share
        lines.append(
            f"| {with_breaks(rung.model)} "
            f"| {rung.holdout_seed_text()} "
            f"| {rung.holdout_abs_mean_mm:.4f} / {rung.holdout_abs_rms_mm:.4f} "
            f"| {_times_floor(rung.holdout_abs_rms_mm, noise.floor_abs_rms_mm)} "
            f"| {'-' if share is None else percent(share)} |"
        )
    if diagnosis.learnable is not None:
        bound = diagnosis.learnable
        lines += [
            "",
            f"Learnable bound: {bound.line().removeprefix('learnable bound: ')}"
            f"{'; ' + note if (note := diagnosis.bound_note()) else ''}. "
            f"Method: {bound.method}. The last column: the share of that learnable gap "
            "(geometric's held-out rms minus the bound) each rung closes"
            + (
                ": by effect "
                + ", ".join(f"{e} {percent(v)}" for e, v in diagnosis.effect_shares())
                if diagnosis.effect_shares()
                else ""
            )
            + ".",
        ]
    if diagnosis.iso9283:
        lines += [
            "",
            "ISO 9283 pose accuracy (AP) and repeatability (RP) of the repeated poses, "
            f"{diagnosis.iso9283[0].scored_on}, before and after calibration:",
            "",
            "| model | poses | AP max [mm] | RP max [mm] | AP a/b/c max [deg] | "
            "RP a/b/c max [deg] |",
            "|---|---|---|---|---|---|",
        ]
        lines += [
            f"| {with_breaks(f.model)} | {len(f.poses)} | {f.ap_max_mm:.4f} | {f.rp_max_mm:.4f} "
            f"| {max_deg(f.ap_orientation_max_deg)} | {max_deg(f.rp_orientation_max_deg)} |"
            for f in diagnosis.iso9283
        ]
        lines += ["", *_markdown_table(*iso_pose_table(diagnosis.iso9283))]
        if diagnosis.iso9283[0].distance is not None:
            lines += [
                "",
                "Distance accuracy (AD) and repeatability (RD), ISO 9283 7.3:",
                "",
                *_markdown_table(*iso_distance_table(diagnosis.iso9283)),
            ]
    if diagnosis.outliers:
        lines += [
            "",
            f"Left out of the fit ({outlier_counts(diagnosis.outliers)}; beyond {OUTLIER_K:g} "
            f"robust sigmas of the calibration, {HOLDOUT_K:g} of the hold-out; never "
            "explained as an effect of the robot; an effect outside the vocabulary can look "
            "like one: check them):",
            "",
        ]
        lines += [f"- {o.line()}" for o in diagnosis.outliers]
    places = diagnosis.concentration_lines()
    if places:
        lines += [
            "",
            "Where the residual concentrates (every measurement, flagged ones "
            "included, under the best model):",
            "",
            *(f"- {p}" for p in places),
        ]
    if diagnosis.mass_model:
        lines += ["", f"Mass model of the gravity effects: {diagnosis.mass_model}."]
    if diagnosis.reads_line():
        lines += ["", f"Calibration data: {diagnosis.reads_line()}."]
    for drift in diagnosis.tracker_drift:
        lines += ["", f"Tracker drift: {drift.line()}."]
    lines += [
        "",
        f"What remains: {diagnosis.unexplained.note}.",
        "",
        "## Where the residual lies",
        "",
    ]
    if where.joints:
        lines += [
            "Geometric model, per joint from its sweeps (angle-equivalent error along the "
            "arc; a joint is observable only through targets at least 5 mm from its axis):",
            "",
            "| joint | rms [urad] | harmonics 1-4 [urad] (x their uncertainty) "
            "| forth-back split [urad] | slope vs angle [urad/rad] | corr. with gravity torque "
            "| best model |",
            "|---|---|---|---|---|---|---|",
        ]
        for j in where.joints:
            lines.append(
                f"| {j.joint} | {_value(j.arc_rms_urad, 1)} | "
                f"{harmonic_cells(j, where, _urad)} | "
                f"{_value(j.direction_split_urad, 1)} | "
                f"{_value(j.slope_vs_angle_urad_per_rad, 1)} | "
                f"{_value(j.gravity_torque_correlation, 2)} | {removed_note(removed, j.joint)} |"
            )
    else:
        lines.append(
            "No circle sweeps in the recording (no run of poses in which one joint moves "
            "alone): no per-joint arc figures; the per-joint terms below come from every pose."
        )
    lines += [
        "",
        "From every pose, as joint-angle error terms, all fitted together with the model's own "
        "parameters (what they can absorb does not count); in brackets: x their own "
        "uncertainty, 0 where a term does not lower the error of poses left out (k-fold); "
        f"{NOT_RESOLVED}: not resolvable from these poses:",
        "",
        "| joint | harmonics 1-4 [urad] | direction (backlash) [urad] "
        "| scale [urad/rad] | gravity [urad/(N m)] | best model |",
        "|---|---|---|---|---|---|",
    ]
    for t in where.joints_from_all_poses:
        lines.append(
            f"| {t.joint} | {harmonic_cells(t, where, _urad)} "
            f"| {_term(where, t, 'direction', 1) if t.observable else unobservable(t)} "
            f"| {_term(where, t, 'scale', 1)} "
            f"| {_term(where, t, 'gravity', 2)} "
            f"| {removed_note(removed, t.joint)} |"
        )
    if where.strongest_signature:
        gone = signature_removed(where.strongest_signature, removed)
        lines += [
            "",
            f"Strongest structure: {where.strongest_signature.text}"
            + (f" ({gone})." if gone else "."),
        ]
    if where.twists():
        lines += [
            "",
            "Links twisting under the load:",
            "",
            *(f"- {signature_text(t)}" for t in where.twists()),
        ]
    lines += _harmonic_lines(diagnosis)
    lines += [
        "",
        f"Against time: {where.time.line()}. By reach (near to far): "
        + ", ".join(f"{v:.4f}" for v in where.workspace.rms_by_reach_tertile_mm)
        + " mm.",
        "",
    ]
    for title, name in plots:
        lines += [f"### {title}", "", f"![{title}]({name})", ""]
    every = list(
        dict.fromkeys(
            [*recording.warnings, *diagnosis.warnings, *warnings, *diagnosis.learnable_warnings()]
        )
    )
    lines += _extra_sections(compared, best, every)
    path.write_text("\n".join(lines) + "\n")
