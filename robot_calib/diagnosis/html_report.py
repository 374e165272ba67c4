"""The report an engineer reads in two minutes: one self-contained HTML file (figures embedded
as base64 PNG, inline CSS, no script, nothing fetched) built from the typed results
(Diagnosis, Ladder, Recording, Calibration). A verdict first, then accuracy before and
after calibration, the ladder, where the residual lies, 3D residual vectors, ISO 9283,
the parameters, warnings and outliers (msgs_doc/report.md).

Why one module: one page. The inline CSS, the markup helpers and the builders of its
sections serve `html_report` alone and change together when the page does (with
`compare_models`, the before/after table the page opens with).

Units for people, one per quantity: positions and errors in mm, angles in deg, scale
errors in ppm (1 ppm = 1 urad/rad); inside, SI as everywhere.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from typing import TYPE_CHECKING

from robot_calib.accuracy import accuracy
from robot_calib.diagnosis.diagnosis import Diagnosis, percent
from robot_calib.diagnosis.evidence import ordinal
from robot_calib.diagnosis.figures import (
    ANGLE_UNITS,
    FigureCache,
    angle_figure,
    drift_figure,
    error_histogram_figure,
    ladder_figure,
    pyplot,
    quiver_figure,
    residual_map_figure,
    time_figure,
)
from robot_calib.diagnosis.ladder import Ladder
from robot_calib.diagnosis.names import MODEL_CLASS, MODEL_CSS, with_breaks
from robot_calib.diagnosis.noise import noise_basis
from robot_calib.diagnosis.report import (
    NOT_RESOLVED,
    PARAMETER_COLUMNS,
    ModelErrors,
    blank,
    harmonic_cells,
    iso_distance_table,
    iso_pose_table,
    parameter_rows,
    unobservable,
)
from robot_calib.diagnosis.signatures import (
    FAMILIES,
    JointTerms,
    WhereItLies,
    removed_note,
    scan_order_note,
    signature_removed,
    signature_text,
)
from robot_calib.identify.calibrate import REFERENCE_MODELS, reference_models
from robot_calib.identify.calibration import Calibration
from robot_calib.identify.outliers import outlier_counts
from robot_calib.identify.params_file import fixed_reasons
from robot_calib.kinematics.frames import Array
from robot_calib.measurements import Recording

if TYPE_CHECKING:
    from matplotlib.figure import Figure

DEG_PER_URAD = ANGLE_UNITS["deg"] * 1e-6
#: the per-joint tables' last column: what of that joint the best model removed
BEST_MODEL_COLUMN = "best model"
#: SI unit -> (factor, the unit people read); a unit not listed is shown as it is


#: what each reference model (`identify.calibrate.reference_models`) stands for in the table
REFERENCE_ROLES = {"nominal": "before calibration", "cpa": "circle point analysis"}


def compare_models(
    ladder: Ladder, calibrations: Mapping[str, Calibration] | None = None
) -> list[ModelErrors]:
    """Before and after: `nominal` (tracker pose and target fitted, geometry nominal),
    `cpa` (circle point analysis; left out without the sweeps it needs), `geometric` and
    the ladder's best rung. Each is scored on the ladder's hold-out bags (outliers left
    out) when there are some; otherwise geometric and the best rung on the ladder's k-fold
    CV and nominal and CPA in-sample (they fit no more than the tracker pose and target
    besides what the circles give). `calibrations`: already identified nominal / cpa
    models of the same recording (else identified here, each well under a second)."""
    recording = ladder.recording
    holdout = ladder.holdout
    geo = ladder.rungs[0].calibration
    out = []
    if recording is not None:
        given = reference_models(recording, geo.model.robot, calibrations)
        for name in REFERENCE_MODELS:
            cal, role = given.get(name), REFERENCE_ROLES[name]
            if cal is None:
                continue  # no circle sweeps of every joint: CPA impossible, not shown
            if holdout is not None:
                residuals = cal.predict(holdout.poses) - holdout.points
                out.append(_scored(cal.name, role, "hold-out bags", residuals, holdout.points))
            else:
                out.append(_scored(cal.name, role, "in-sample", cal.residuals, recording.points))
    rungs = [(ladder.rungs[0], "geometric" if len(ladder.rungs) > 1 else "geometric = best rung")]
    if len(ladder.rungs) > 1:
        rungs.append((ladder.rungs[-1], "best rung of the ladder"))
    for rung, role in rungs:
        out.append(
            ModelErrors(rung.model, role, ladder.scored_on, rung.heldout_residuals, rung.heldout)
        )
    return out


def _scored(model: str, role: str, scored_on: str, residuals: Array, points: Array) -> ModelErrors:
    return ModelErrors(model, role, scored_on, residuals, accuracy(points, points + residuals))


CSS = (
    """
body{font:15px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;
 color:#1d2733;background:#f4f6f8;margin:0}
main{max-width:1120px;margin:0 auto;padding:24px 28px 48px;background:#fff}
h1{font-size:24px;margin:0 0 4px}h2{font-size:19px;margin:32px 0 8px;padding-bottom:4px;
 border-bottom:2px solid #dde3ea}h3{font-size:15px;margin:18px 0 6px}
.sub{color:#5b6b7b;margin:0 0 16px}
.verdict{border-left:6px solid #2f6fb0;background:#eef4fb;padding:12px 18px;margin:12px 0}
.verdict.warn{border-left-color:#c0392b;background:#fbefed}
.verdict.ok{border-left-color:#2e8b57;background:#edf7f1}
.verdict dl{display:grid;grid-template-columns:max-content 1fr;gap:4px 16px;margin:0}
.verdict dt{font-weight:600;color:#34495e}.verdict dd{margin:0}
table{border-collapse:collapse;margin:8px 0 12px;font-size:13.5px;
 font-variant-numeric:tabular-nums}
th,td{border:1px solid #d5dce4;padding:4px 8px;text-align:right;vertical-align:top}
th{background:#eef1f5;text-align:center}td:first-child,th:first-child{text-align:left}
td.text{text-align:left;overflow-wrap:break-word;max-width:320px}
tr.best td{background:#fff7d6;font-weight:600}
td.fixed{color:#7a8794}
figure{margin:10px 0 18px}figure img{max-width:100%;border:1px solid #e3e8ee}
figcaption{color:#5b6b7b;font-size:13px}
pre{background:#1d2733;color:#e8eef5;padding:10px 14px;border-radius:4px;overflow-x:auto}
code{font-family:"DejaVu Sans Mono",monospace;font-size:13px}
ul.tight li{margin:2px 0}.muted{color:#7a8794}
td>.note{display:block;text-align:left;color:#2e6b45;min-width:160px}
table.header td{text-align:left}table.header th{text-align:left}
@media print{body{background:#fff}main{max-width:none;padding:0}section{break-inside:auto}
 figure,table{break-inside:avoid}}
"""
    + MODEL_CSS
)


def _e(text: object) -> str:
    """`text` escaped for HTML (every text of the report goes through here)."""
    return html.escape(str(text), quote=True)


class Markup(str):
    """Text already escaped and marked up (`_model`): `_table` writes it as it is."""


def _note(note: str) -> Markup:
    """A per-joint row's note on what the best model removed (`removed_note`), left-aligned,
    breaking at spaces, after '+' or ',' only (it names model terms); '' for none."""
    if not note:
        return Markup("")
    return Markup(f'<span class="{MODEL_CLASS} note">{with_breaks(_e(note))}</span>')


def _model(name: str) -> Markup:
    """A model name that breaks only between its terms or after a comma (names.py), never
    inside a term: escaped, with <wbr> there, in a `MODEL_CLASS` span (CSS `MODEL_CSS`)."""
    return Markup(f'<span class="{MODEL_CLASS}">{with_breaks(_e(name))}</span>')


def _img(fig: Figure | bytes | None, caption: str, dpi: int = 100) -> str:
    """The figure (or its PNG bytes, `FigureCache.png`) as an embedded PNG (a data: URI)
    with its caption; '' for None."""
    if fig is None:
        return ""
    if isinstance(fig, bytes):
        png = fig
    else:
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=dpi)
        pyplot().close(fig)
        png = buffer.getvalue()
    data = base64.b64encode(png).decode("ascii")
    return (
        f'<figure><img alt="{_e(caption)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{_e(caption)}</figcaption></figure>"
    )


def _table(
    head: Sequence[str],
    rows: Sequence[Sequence[object]],
    classes: Sequence[str] = (),
    text_columns: int = 1,
) -> str:
    """An HTML table of escaped cells; `classes`: a class per row ('' none); the first
    `text_columns` columns are text (left-aligned), the others figures."""
    out = ["<table><thead><tr>", *(f"<th>{_e(h)}</th>" for h in head), "</tr></thead><tbody>"]
    for k, row in enumerate(rows):
        cls = classes[k] if k < len(classes) and classes[k] else ""
        out.append(f'<tr class="{cls}">' if cls else "<tr>")
        cells = [c if isinstance(c, Markup) else _e(c) for c in row]
        out += [
            f'<td class="text">{c}</td>' if i < text_columns else f"<td>{c}</td>"
            for i, c in enumerate(cells)
        ]
        out.append("</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def _mm(value: float | None, digits: int = 4) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _deg(urad: float | None, significance: float | None = None) -> str:
    """An angle given in urad, shown in deg (with its significance, x noise)."""
    if urad is None:
        return "-"
    sig = "" if significance is None else f" ({significance:.0f}x)"
    return f"{urad * DEG_PER_URAD:.5f}{sig}"


def _term_deg(where: WhereItLies, t: JointTerms, family: str) -> str:
    """The cell of `family` (direction, scale, gravity) of row `t` in this report's units
    (deg, ppm, deg/(N m)) with its significance, else `report.blank`."""
    value, significance = t.of_family(family)
    if value is None:
        return blank(where, t.joint, family)
    if family == "direction":
        return _deg(value, significance)
    if family == "scale":
        return f"{value:.1f} ({significance:.0f}x)"
    return f"{value * DEG_PER_URAD:.3g} ({significance:.0f}x)"


def _strongest(diagnosis: Diagnosis) -> str:
    """The strongest residual signature as a sentence in this report's units (deg, ppm)."""
    sig = diagnosis.where.strongest_signature
    if sig is None:
        return "none (no joint observable from every pose)"
    noise = f"{sig.significance:.0f} x its uncertainty"
    if sig.harmonic is not None:
        return (
            f"{ordinal(sig.harmonic)} harmonic of joint "
            f"{sig.joint}: {_deg(sig.value)} deg of joint-angle error, {noise}"
        )
    terms = next((t for t in diagnosis.where.joints_from_all_poses if t.joint == sig.joint), None)
    if terms is None or sig.family in ("time", "twist"):  # in mm: the sentence as it is
        return sig.text
    for key, sig_key, words, _ in FAMILIES:
        if getattr(terms, sig_key) == sig.significance:
            value = {
                "direction_urad": f"{_deg(sig.value)} deg",
                "scale_urad_per_rad": f"{sig.value:.1f} ppm",
            }.get(key, f"{sig.value * DEG_PER_URAD:.3g} deg/(N m)")
            return f"joint {sig.joint} error following its {words}: {value}, {noise}"
    return f"joint {sig.joint}, {noise}"


def _parameters(cal: Calibration) -> str:
    """The parameter table of `cal` (values, nominal, deviation, 1-sigma in mm / deg / ppm)
    and the fixed parameters by reason."""
    rows = parameter_rows(cal)
    classes = ["fixed" if row[-1] == "fixed" else "" for row in rows]
    out = [_table(list(PARAMETER_COLUMNS), rows, classes, text_columns=2)]
    ident = cal.identifiability
    if ident is not None:
        out.append(
            f"<p>Identifiability: {ident.n_free} free parameters, condition number "
            f"{ident.condition_number:.1f}, observability index "
            f"{ident.observability_index:.2e}; {len(ident.fixed)} fixed by the data.</p>"
        )
    reasons = fixed_reasons(cal.parameters)
    if reasons:
        out.append("<h3>Fixed parameters and why</h3><ul class='tight'>")
        out += [
            f"<li><b>{_e(reason or 'fixed')}</b>: {_e(', '.join(names))}</li>"
            for reason, names in reasons.items()
        ]
        out.append("</ul>")
    return "".join(out)


def _floor_text(diagnosis: Diagnosis) -> str:
    noise = diagnosis.noise
    if noise.sigma_mm is None or noise.floor_abs_rms_mm is None:
        return "unknown: no repeat poses, circle sweeps or stated tracker accuracy"
    return (
        f"{noise.floor_abs_rms_mm:.4f} mm rms ({noise.sigma_mm:.4f} mm per axis from "
        f"{noise_basis(noise.source, noise.n)})"
    )


def _times_floor(value_mm: float, diagnosis: Diagnosis) -> str:
    floor = diagnosis.noise.floor_abs_rms_mm
    return "-" if floor is None else f"{value_mm / floor:.2f}"


def _verdict(
    diagnosis: Diagnosis,
    compared: Sequence[ModelErrors],
    best: Calibration,
    best_params: str,
    warnings: Sequence[str],
) -> str:
    """The two-minute summary: best model and its held-out error against the floor, the
    named effect, what remains, warnings, and the commands to apply the result."""
    row = next((m for m in compared if m.model == best.label), None)
    error = ""
    if row is not None:
        rms = row.accuracy.absolute_rms_mm
        error = (
            f"{rms:.4f} mm rms ({row.scored_on}), {_times_floor(rms, diagnosis)} x the noise floor"
        )
    before = next((m for m in compared if m.model == "nominal"), None)
    if before is not None and row is not None:
        error += f"; nominal: {before.accuracy.absolute_rms_mm:.4f} mm rms"
    shares = ", ".join(f"{e} {percent(v)}" for e, v in diagnosis.effect_shares())
    ratio = diagnosis.unexplained.ratio_to_noise_floor
    # green when the best model is at the noise floor (warnings are listed either way), red
    # when it is not, or when there are warnings and no floor to judge by
    at_floor = ratio is not None and ratio <= 1.5
    tone = "ok" if at_floor else ("warn" if warnings or ratio is not None else "")
    items = [
        ("Best model", f"{best.label} ({best_params})"),
        ("Held-out error", error or "-"),
        ("Noise floor", _floor_text(diagnosis)),
        (
            "Named effect",
            diagnosis.verdict + (f" (share of the learnable gap: {shares})" if shares else ""),
        ),
        ("What remains", diagnosis.unexplained.note),
        *(
            [("Outside the vocabulary", diagnosis.outside_vocabulary.line())]
            if diagnosis.outside_vocabulary is not None
            else []
        ),
        (
            "Warnings",
            f"{len(warnings)} warning(s), {len(diagnosis.outliers)} flagged outlier(s): see below"
            if warnings or diagnosis.outliers
            else "none",
        ),
    ]
    if diagnosis.implausible:  # nonsense: say so first, and never advise using it
        items.insert(0, ("IMPLAUSIBLE", "; ".join(diagnosis.implausible)))
        body = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in items)
        return (
            f'<section class="verdict warn"><dl>{body}</dl><p><b>Next</b>: fix the data '
            "(units, robot description, joint order) and diagnose again; export, "
            "compensate and predict refuse this result.</p></section>"
        )
    body = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in items)
    commands = (
        f"robot-calib export {best_params} --format urdf -o calibrated.urdf\n"
        f"robot-calib export {best_params} --format dh -o dh_table.csv\n"
        f"robot-calib compensate {best_params} --joints JOINTS.csv -o COMPENSATED.csv"
    )
    return (
        f'<section class="verdict {tone}"><dl>{body}</dl>'
        "<p><b>Next</b>: export the best model for the controller, or correct joint "
        "commands with it (msgs_doc/export.md, msgs_doc/compensate.md):</p>"
        f"<pre><code>{_e(commands)}</code></pre></section>"
    )


def _accuracy(
    diagnosis: Diagnosis,
    compared: Sequence[ModelErrors],
    best: str,
    figures: FigureCache,
    histogram: Callable[[], Figure | None],
) -> str:
    rows = [
        [
            _model(m.model),
            m.role,
            m.scored_on,
            m.accuracy.n_points,
            m.accuracy.pairwise_text(),
            f"{m.accuracy.absolute_mean_mm:.4f}",
            f"{m.accuracy.absolute_rms_mm:.4f}",
            f"{m.accuracy.absolute_max_mm:.4f}",
            _times_floor(m.accuracy.absolute_rms_mm, diagnosis),
        ]
        for m in compared
    ]
    classes = ["best" if m.model == best else "" for m in compared]
    head = [
        "model",
        "",
        "scored on",
        "points",
        "seed criterion mean / max [mm]",
        "abs mean [mm]",
        "abs rms [mm]",
        "abs max [mm]",
        "x noise floor",
    ]
    scored = sorted({m.scored_on for m in compared})
    note = (
        ""
        if scored == ["hold-out bags"]
        else "<p class='muted'>Not all rows are held out: in-sample rows are optimistic; "
        "k-fold rows are each fold predicted by the model fitted without it.</p>"
    )
    return (
        _table(head, rows, classes, text_columns=3)
        + note
        + _img(
            figures.png("histogram", histogram),
            "Per-point error of each model "
            "(absolute distance, tracker frame); dotted: each model's rms",
        )
    )


def _ladder(diagnosis: Diagnosis, ladder: Ladder, figures: FigureCache) -> str:
    rows = []
    for rung in diagnosis.ladder:
        share = rung.learnable_gap_share
        rows.append(
            [
                _model(rung.model),
                rung.free_parameters,
                f"{rung.holdout_seed_text()}",
                f"{rung.holdout_abs_mean_mm:.4f} / {rung.holdout_abs_rms_mm:.4f}",
                _times_floor(rung.holdout_abs_rms_mm, diagnosis),
                "-" if share is None else percent(share),
            ]
        )
    head = [
        "model",
        "free parameters",
        "held-out seed criterion mean / max [mm]",
        "held-out abs mean / rms [mm]",
        "x noise floor",
        "share of the learnable gap",
    ]
    out = [
        f"<p>Scored on {_e(diagnosis.scored_on)}; each rung chosen on "
        f"{_e(diagnosis.selected_on)}.</p>",
        _table(head, rows),
    ]
    shares = diagnosis.effect_shares()
    if shares:
        out.append(
            "<p>Share of the learnable gap each effect closed: "
            + _e(", ".join(f"{e} {percent(v)}" for e, v in shares))
            + ".</p>"
        )
    if diagnosis.learnable is not None:
        note = diagnosis.bound_note()
        out.append(
            f"<p>{_e(diagnosis.learnable.line())}"
            f"{'; ' + _e(note) if note else ''}. Method: "
            f"{_e(diagnosis.learnable.method)}.</p>"
        )
    out.append(
        _img(
            figures.png("ladder", lambda: ladder_figure(ladder, diagnosis.noise.floor_abs_rms_mm)),
            "Held-out rms of each rung, the noise floor and the learnable bound",
        )
    )
    return "".join(out)


def _where(
    diagnosis: Diagnosis, ladder: Ladder, recording: Recording, figures: FigureCache
) -> str:
    where, removed = diagnosis.where, diagnosis.removed_by_best_model
    out = []
    if where.joints:
        out.append(
            "<h3>Per joint, from its circle sweeps (geometric model)</h3>"
            "<p>Angle-equivalent error along each sweep's arc; a joint is observable "
            "only through targets at least 5 mm from its axis.</p>"
        )
        rows = [
            [
                j.joint,
                _deg(j.arc_rms_urad),
                harmonic_cells(j, where, _deg),
                _deg(j.direction_split_urad),
                _mm(j.slope_vs_angle_urad_per_rad, 1),
                _mm(j.gravity_torque_correlation, 2),
                _note(removed_note(removed, j.joint)),
            ]
            for j in where.joints
        ]
        out.append(
            _table(
                [
                    "joint",
                    "rms [deg]",
                    "harmonics 1-4 [deg] (x uncertainty)",
                    "forth-back split [deg]",
                    "slope vs angle [ppm]",
                    "corr. with gravity torque",
                    BEST_MODEL_COLUMN,
                ],
                rows,
            )
        )
    else:
        out.append(
            "<p>No circle sweeps in the recording (no run of poses in which one "
            "joint moves alone): no per-joint arc figures.</p>"
        )
    out.append(
        "<h3>Per joint, from every pose</h3><p>Joint-angle error terms, all fitted together "
        "with the model's own parameters (what they absorb does not count); in brackets: x "
        "their own uncertainty, 0 where a term does not lower the error of poses left out "
        f"(k-fold); {NOT_RESOLVED}: not resolvable from these poses.</p>"
    )
    rows = [
        [
            t.joint,
            harmonic_cells(t, where, _deg),
            _term_deg(where, t, "direction") if t.observable else unobservable(t),
            _term_deg(where, t, "scale"),
            _term_deg(where, t, "gravity"),
            _note(removed_note(removed, t.joint)),
        ]
        for t in where.joints_from_all_poses
    ]
    out.append(
        _table(
            [
                "joint",
                "harmonics 1-4 [deg]",
                "direction (backlash) [deg]",
                "scale [ppm]",
                "gravity [deg/(N m)]",
                BEST_MODEL_COLUMN,
            ],
            rows,
        )
    )
    found = [s for s in where.harmonic_orders if s.dominant_orders]
    after = None if diagnosis.unexplained.where is diagnosis.where else diagnosis.unexplained.where
    if found:
        out.append(
            "<h3>Joint-angle harmonics (frequency scan, geometric model)</h3><p>Orders "
            "1-64 of each joint's reading, beyond what the geometry absorbs.</p>"
        )
        rows = [
            [
                s.joint,
                k,
                f"{a * DEG_PER_URAD:.5f}",
                f"{z:.0f}",
                why,
                _note(scan_order_note(removed, s.joint, k, after, diagnosis.physical_model)),
            ]
            for s in found
            for k, a, z, why in zip(
                s.dominant_orders, s.dominant_urad, s.dominant_significance, s.meaning
            )
        ]
        out.append(
            _table(
                [
                    "joint",
                    "order [per turn]",
                    "amplitude [deg]",
                    "x its uncertainty (joint fit)",
                    "usually",
                    BEST_MODEL_COLUMN,
                ],
                rows,
            )
        )
    reach = ", ".join(f"{v:.4f}" for v in where.workspace.rms_by_reach_tertile_mm)
    gone = signature_removed(where.strongest_signature, removed)
    strongest = _strongest(diagnosis) + (f" ({gone})" if gone else "")
    out.append(
        f"<p><b>Strongest structure</b>: {_e(strongest)}. Against time: "
        f"{_e(where.time.line())}. "
        f"By reach (near to far): {reach} mm.</p>"
    )
    if where.twists():
        out.append(
            "<p><b>Links twisting under the load</b>:</p><ul>"
            + "".join(f"<li>{_e(signature_text(t))}</li>" for t in where.twists())
            + "</ul>"
        )
    out.append(
        _img(
            angle_figure(ladder, recording, "deg"),
            "Geometric model: arc error against each joint's reading, by approach direction",
        )
    )
    out.append(
        _img(
            figures.png("map", lambda: residual_map_figure(ladder, recording)),
            "In-sample |residual| against reach, height and every joint's reading",
        )
    )
    out.append(
        _img(
            figures.png("time", lambda: time_figure(ladder, recording)),
            "In-sample |residual| against time",
        )
    )
    if diagnosis.tracker_drift:
        out.append(
            "<h3>The tracker's drift (reference reflectors)</h3><ul class='tight'>"
            + "".join(f"<li>{_e(d.line())}</li>" for d in diagnosis.tracker_drift)
            + "</ul>"
        )
        out.append(
            _img(
                figures.png("drift", lambda: drift_figure(recording)),
                "Reference reflectors: displacement from their first place as read "
                "(dots) and as the fitted drift moves them (lines)",
            )
        )
    return "".join(out)


def vectors_figure(ladder: Ladder, recording: Recording) -> Figure:
    """3D residual vectors of geometric and the best rung at the points they are scored on."""
    held = ladder.holdout
    points = held.points if held is not None else recording.points
    rungs = (ladder.rungs[0], ladder.rungs[-1])[: len(ladder.rungs)]
    rows = rungs[-1].scored_rows  # a subset scored (100k poses): both panels on it
    residuals = [
        (
            r.model,
            r.heldout_residuals
            if r.scored_rows is not None or rows is None
            else r.heldout_residuals[rows],
        )
        for r in rungs
    ]
    return quiver_figure(
        ladder, rungs[-1].scored(points) if held is None else points, residuals, ladder.scored_on
    )


def page_figures(
    ladder: Ladder, recording: Recording, compared: Sequence[ModelErrors]
) -> list[tuple[str, Callable[[], Figure | None]]]:
    """The HTML page's own figures (the Markdown report's, `report.report_figures`, it
    shows too): (cache key, draw) each, the draws picklable (`FigureCache.draw_aside`)."""
    scored = " / ".join(sorted({m.scored_on for m in compared}))
    errors = [(m.model, m.errors_mm) for m in compared]
    return [
        ("histogram", partial(error_histogram_figure, errors, scored)),
        ("vectors", partial(vectors_figure, ladder, recording)),
    ]


def _iso(diagnosis: Diagnosis) -> str:
    if not diagnosis.iso9283:
        return (
            "<p class='muted'>No repeated poses (readings measured at least 3 times): no "
            "ISO 9283 figures. The <code>iso9283</code> plan records them.</p>"
        )
    figures = diagnosis.iso9283
    oriented = figures[0].rp_orientation_max_deg is not None
    rows = [
        [
            _model(f.model),
            len(f.poses),
            f"{f.ap_max_mm:.4f}",
            f"{f.rp_max_mm:.4f}",
            *(
                [
                    f"{f.ap_orientation_max_deg or 0.0:.4f}",
                    f"{f.rp_orientation_max_deg or 0.0:.4f}",
                ]
                if oriented
                else []
            ),
        ]
        for f in figures
    ]
    header = ["model", "repeated poses", "AP max [mm]", "RP max [mm]"]
    if oriented:
        header += ["AP a/b/c max [deg]", "RP a/b/c max [deg]"]
    what = (
        "positions and orientations (ISO 9283 a, b, c: about x, y, z)" if oriented else "positions"
    )
    out = [
        f"<p>Pose accuracy AP and repeatability RP ({what}), {_e(figures[0].scored_on)}, "
        "before (nominal) and after calibration.</p>",
        _table(header, rows),
    ]
    out.append(_table(*iso_pose_table(figures)))
    if figures[0].distance is not None:
        first = figures[0].distance
        out.append(
            "<p>Distance accuracy AD and repeatability RD (ISO 9283 7.3) between the "
            f"repeated poses first measured at {first.first_index_a} and "
            f"{first.first_index_b}, over {first.n} cycles.</p>"
        )
        out.append(_table(*iso_distance_table(figures)))
    return "".join(out)


def _problems(diagnosis: Diagnosis, warnings: Sequence[str]) -> str:
    out = ["<ul class='tight'>", *(f"<li>{_e(w)}</li>" for w in warnings), "</ul>"]
    if not warnings:
        out = ["<p>No warnings.</p>"]
    if diagnosis.outliers:
        rows = [
            [
                o.bag,
                o.index,
                o.target or "-",
                o.kind,
                "-" if o.stamp_ns is None else f"{o.stamp_ns * 1e-9:.3f}",
                f"{o.size_m * 1e3:.3f}",
                f"{o.sigmas:.0f}",
                "-" if o.references_m is None else f"{o.references_m * 1e3:.3f}",
                ", ".join(f"{c:+.2f}" for c in o.direction),
            ]
            for o in diagnosis.outliers
        ]
        out.append(
            f"<h3>Flagged outliers ({_e(outlier_counts(diagnosis.outliers))}; never "
            "fitted, never explained as an effect of the robot)</h3>"
        )
        out.append(
            _table(
                [
                    "bag",
                    "point",
                    "target",
                    "tracker or robot",
                    "stamp [s]",
                    "size [mm]",
                    "robust sigmas",
                    "reference reflectors off [mm]",
                    "direction (tracker frame)",
                ],
                rows,
            )
        )
    else:
        out.append("<p>No measurement flagged as an outlier.</p>")
    if diagnosis.reads_line():
        out.append(f"<p><b>Calibration data</b>: {_e(diagnosis.reads_line())}.</p>")
    if diagnosis.mass_model:
        out.append(f"<p><b>Mass model of the gravity effects</b>: {_e(diagnosis.mass_model)}.</p>")
    places = diagnosis.concentration_lines()
    if places:
        out.append(
            "<h3>Where the residual concentrates</h3><ul class='tight'>"
            + "".join(f"<li>{_e(place)}</li>" for place in places)
            + "</ul>"
        )
    return "".join(out)


def _header(diagnosis: Diagnosis) -> str:
    """The report's header (`ReportHeader`) as a table, '' without one."""
    if diagnosis.header is None:
        return ""
    rows = "".join(
        f"<tr><th>{_e(label)}</th><td>{_e(text)}</td></tr>"
        for label, text in diagnosis.header.rows()
    )
    return f"<table class='header'>{rows}</table>"


def html_report(
    diagnosis: Diagnosis,
    ladder: Ladder,
    recording: Recording,
    compared: Sequence[ModelErrors],
    best: Calibration,
    best_params: str,
    warnings: Sequence[str] = (),
    figures: FigureCache | None = None,
) -> str:
    """The report as one HTML document (str). `recording`: the calibration measurements
    the ladder was fitted on (outliers left out); `compared`: `compare_models`; `best`: the
    model chosen and `best_params` the PARAMS.json it is written to; `warnings`: every
    warning of the run (the recording's and the diagnosis' are added here); `figures`:
    the figures already drawn for the Markdown report (default: none yet)."""
    figures = FigureCache() if figures is None else figures
    own = dict(page_figures(ladder, recording, compared))
    every = list(
        dict.fromkeys(
            [*recording.warnings, *diagnosis.warnings, *warnings, *diagnosis.learnable_warnings()]
        )
    )
    held = f" ({', '.join(diagnosis.holdout)})" if diagnosis.holdout else ""
    sections = [
        (
            "accuracy",
            "Accuracy before and after calibration",
            _accuracy(diagnosis, compared, best.label, figures, own["histogram"]),
        ),
        (
            "ladder",
            "The ladder: which effects, and each one's share",
            _ladder(diagnosis, ladder, figures),
        ),
        ("where", "Where the residual lies", _where(diagnosis, ladder, recording, figures)),
        (
            "vectors",
            "3D residual vectors",
            _img(
                figures.png("vectors", own["vectors"]),
                "Residual vectors (predicted - measured) at the measured points, robot base "
                "frame; one scale for all panels (in the title); colour: |residual|",
            ),
        ),
        ("iso9283", "ISO 9283 pose accuracy and repeatability", _iso(diagnosis)),
        ("parameters", f"Parameters of the best model ({best.label})", _parameters(best)),
        ("warnings", "Warnings and flagged outliers", _problems(diagnosis, every)),
    ]
    nav = " · ".join(f'<a href="#{key}">{_e(title)}</a>' for key, title, _ in sections)
    body = "".join(
        f'<section id="{key}"><h2>{_e(title)}</h2>{content}</section>'
        for key, title, content in sections
    )
    return (
        '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>robot_calib report: {_e(best.label)}</title><style>{CSS}</style></head>"
        f"<body><main><h1>{'IMPLAUSIBLE: ' if diagnosis.implausible else ''}Calibration "
        "report</h1><p class='sub'>Robot "
        f"{_e(best.model.robot.name)}; recordings {_e(', '.join(diagnosis.recordings))}; "
        f"scored on {_e(diagnosis.scored_on)}{_e(held)}. Units: positions and errors in mm, "
        "angles in deg, scale errors in ppm.</p>"
        + _header(diagnosis)
        + _verdict(diagnosis, compared, best, best_params, every)
        + f"<p class='sub'>{nav}</p>"
        + body
        + "</main></body></html>\n"
    )
