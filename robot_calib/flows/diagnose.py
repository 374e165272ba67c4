"""The diagnosis flow: the sim-to-real gap diagnosis of bags or recordings and its files
(DIAGNOSIS.json, the Markdown report with plots, the self-contained HTML report, the best
model's PARAMS.json), written together (`robot-calib diagnose`, the calibrator node, `run`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

from robot_calib.errors import InputError, param
from robot_calib.flows.bags import ReadBags, read_inputs
from robot_calib.kinematics.description import RobotDescription
from robot_calib.log import Log
from robot_calib.measurements import PAIR_TOLERANCE_S

if TYPE_CHECKING:
    from robot_calib.diagnosis.diagnosis import Diagnosis
    from robot_calib.diagnosis.figures import FigureCache
    from robot_calib.diagnosis.ladder import Ladder
    from robot_calib.diagnosis.report import ModelErrors
    from robot_calib.identify.calibration import Calibration
    from robot_calib.measurements import Recording


def diagnose_recordings(
    recording: Recording,
    robot: RobotDescription,
    holdout: Recording | None = None,
    log: Log | None = None,
    tracker_sigma_m: float | None = None,
    on_ladder: Callable[[Ladder, Recording, float | None], object] | None = None,
) -> tuple[Diagnosis, Ladder]:
    """The sim-to-real gap diagnosis of `recording`, scored on `holdout` (else k-fold);
    `tracker_sigma_m`: a stated 1-sigma per axis [m], the floor when the data give none;
    `on_ladder`: called once the ladder is climbed (`diagnose`'s).

    Returns
    -------
    diagnosis : Diagnosis
        The DIAGNOSIS.json document (as `robot_calib.diagnosis.diagnosis.diagnose`).
    ladder : Ladder
        The rungs behind it, each with its calibration and held-out scores.
    """
    from robot_calib.diagnosis.diagnosis import diagnose

    if tracker_sigma_m is not None and not (
        math.isfinite(tracker_sigma_m) and 1e-7 <= tracker_sigma_m < 1e-2
    ):
        raise InputError(
            f"{param('tracker_sigma_m', tracker_sigma_m)}: a 1-sigma per axis in m, 1e-07 "
            "(0.1 um) to 0.01"
        )
    if holdout is not None:  # index the hold-out's targets as the calibration's
        holdout = holdout.with_targets(recording.target_names)
    diagnosis, ladder = diagnose(
        recording,
        robot,
        holdout,
        log=log,
        tracker_sigma_m=tracker_sigma_m,
        on_ladder=on_ladder,
    )
    if on_ladder is None and holdout is not None:
        # the warnings every front end gives (a richer model that generalises worse): the
        # command line's hook (`FiguresWhenClimbed`) adds them with its reports' figures
        _, warnings = compare_before_after(ladder)
        diagnosis = replace(diagnosis, warnings=[*diagnosis.warnings, *warnings])
    return diagnosis, ladder


def diagnose_bags(
    bags: Sequence[str | Path],
    robot: RobotDescription,
    holdout: Sequence[str | Path] = (),
    pair_tolerance: float = PAIR_TOLERANCE_S,
    log: Log | None = None,
    tracker_sigma_m: float | None = None,
    on_ladder: Callable[[Ladder, Recording, float | None], object] | None = None,
) -> tuple[Diagnosis, Ladder, Recording]:
    """The diagnosis of `bags` scored on the `holdout` bags (none: k-fold CV over poses);
    `tracker_sigma_m`, `on_ladder` as in `diagnose_recordings`.

    Returns
    -------
    diagnosis, ladder : Diagnosis, Ladder
        As `diagnose_recordings`.
    recording : Recording
        The paired measurements of `bags` (as `read_bags`); the hold-out's are not kept.
    """
    read = read_inputs(bags, holdout, robot, pair_tolerance, log)
    return diagnose_read(read, robot, log, tracker_sigma_m, on_ladder)


def diagnose_read(
    read: ReadBags,
    robot: RobotDescription,
    log: Log | None = None,
    tracker_sigma_m: float | None = None,
    on_ladder: Callable[[Ladder, Recording, float | None], object] | None = None,
) -> tuple[Diagnosis, Ladder, Recording]:
    """`diagnose_bags` of bags already read (`read_inputs`, `ReadAside.read`): the lines
    their reading kept are logged first."""
    read.replay(log)
    diagnosis, ladder = diagnose_recordings(
        read.recording, robot, read.holdout, log, tracker_sigma_m, on_ladder
    )
    return diagnosis, ladder, read.recording


#: seconds the reading child may take for the bags, then for the reference models (a
#: huge bag on slow storage is read here only after this, a second time)
READ_TIMEOUT_S = 3600.0


class ReadAside:
    """The bags of a diagnosis read by a forked child (`forked.Aside`) while this process
    loads the diagnosis' modules (0.4 s of every start), then the reference models of
    their calibration recording (`identify.calibrate.reference_models`) identified there
    while this process climbs the ladder. The results are those computed here, which is
    what happens when the child fails: the reading's warnings are then logged as they
    come and its error raised here, as a reading here always did. Use it as a context
    manager: the child is ended on the way out."""

    def __init__(
        self,
        bags: Sequence[str | Path],
        holdout: Sequence[str | Path],
        robot: RobotDescription,
        pair_tolerance: float = PAIR_TOLERANCE_S,
        log: Log | None = None,
    ) -> None:
        from robot_calib.forked import Aside

        self._creator = os.getpid()
        self._args = (tuple(bags), tuple(holdout), robot, pair_tolerance)
        self._log = log
        self._read_in_this_process: ReadBags | None = None
        tasks: list[tuple[str, Callable[[], Any]]] = [
            ("read", self._read),
            ("references", self._references),
        ]
        self._aside = Aside(tasks, READ_TIMEOUT_S)

    def _read(self) -> ReadBags:
        """The reading, once per process: in the child its lines kept (its output is not
        this process's), here logged as they come."""
        if self._read_in_this_process is None:
            here = os.getpid() == self._creator
            self._read_in_this_process = read_inputs(*self._args, log=self._log if here else None)
        return self._read_in_this_process

    def _references(self) -> dict[str, Calibration]:
        from robot_calib.identify.calibrate import reference_models

        return reference_models(self.read().recording, self._args[2])

    def read(self) -> ReadBags:
        """The bags read (`read_inputs`; an error of theirs raised here)."""
        value: ReadBags = self._aside.result("read")
        return value

    def references(self, recording: Recording) -> dict[str, Calibration] | None:
        """The reference models of `recording` when it is the calibration recording read
        (the ladder left no tracker blunder out), else None (to be identified on it)."""
        if recording is not self.read().recording:
            return None
        value: dict[str, Calibration] = self._aside.result("references")
        return value

    def __enter__(self) -> ReadAside:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self._aside.close(abort=kind is not None)


#: the figures the helper draws (its twin draws the rest): about half the drawing time
#: (2773 poses, CPU: histogram 0.15 + map 0.31 s; ladder 0.11 + time 0.09 + vectors 0.22 s)
ASIDE_FIRST = ("histogram", "map")


def started_figures() -> FigureCache:
    """A figure cache for `write_diagnosis` whose helper process starts now (when this
    process runs no other thread) and gets matplotlib ready while the diagnosis runs
    (`FiguresAside.started`): call it before reading the bags; close it on every way out
    (a context manager). The modules of the diagnosis and its reports are imported here
    first (this process needs them anyway): the helper inherits them instead of importing
    them again (0.45 s)."""
    import robot_calib.diagnosis.html_report  # noqa: F401 - inherited by the helper
    import robot_calib.diagnosis.report  # noqa: F401 - inherited by the helper
    from robot_calib.flows.figures import FiguresAside

    return FiguresAside.started()


def draw_figures(
    figures: FigureCache,
    ladder: Ladder,
    fitted: Recording,
    floor_mm: float | None,
    compared: Sequence[ModelErrors],
) -> None:
    """Start drawing every figure of both reports (`report_figures`, `page_figures`) in
    other processes (`FiguresAside.draw_aside`: the helper and its twin, two groups of
    about equal cost, 2773 poses: 0.4-0.5 s each, each in the order the HTML page asks
    for them); `fitted`: the measurements the ladder was fitted on, `floor_mm` the noise
    floor [mm] (None: unknown), `compared` the before/after models. Once per cache."""
    from robot_calib.diagnosis.html_report import page_figures
    from robot_calib.diagnosis.report import report_figures

    shown = {key: draw for _, key, _, draw in report_figures(ladder, fitted, floor_mm)}
    shown.update(page_figures(ladder, fitted, compared))
    rest = [key for key in shown if key not in ASIDE_FIRST]
    figures.draw_aside(
        [(key, shown[key]) for key in ASIDE_FIRST], [(key, shown[key]) for key in rest]
    )


class FiguresWhenClimbed:
    """The `on_ladder` hook of `diagnose_bags` / `diagnose_recordings` that starts every
    figure of the reports in `figures` (`draw_figures`) as soon as the ladder is climbed,
    with the before/after comparison they show (`compare_before_after` of the ladder and
    `calibrations`), kept for `write_diagnosis` (`before_after`).

    `references`: the reference models (`reference_models`) of a recording, identified
    meanwhile (`ReadAside.references`; None: not of that recording): used when they are
    of the ladder's, else identified again."""

    def __init__(
        self,
        figures: FigureCache,
        calibrations: Mapping[str, Calibration] | None = None,
        references: Callable[[Recording], Mapping[str, Calibration] | None] | None = None,
    ) -> None:
        self.figures, self.calibrations, self.references = figures, calibrations, references
        self._before_after: tuple[list[ModelErrors], list[str]] | None = None

    def __call__(self, ladder: Ladder, fitted: Recording, floor_mm: float | None) -> None:
        calibrations = self.calibrations
        if self.references is not None and ladder.recording is not None:
            found = self.references(ladder.recording)
            calibrations = {**found, **(calibrations or {})} if found else calibrations
        self._before_after = compare_before_after(ladder, calibrations)
        draw_figures(self.figures, ladder, fitted, floor_mm, self._before_after[0])

    def before_after(self, ladder: Ladder) -> tuple[list[ModelErrors], list[str]]:
        """`compare_before_after` of `ladder`: the one the hook made, else made now."""
        if self._before_after is None:
            self._before_after = compare_before_after(ladder, self.calibrations)
        return self._before_after


def report_path(output: str | Path) -> Path:
    """The Markdown report of DIAGNOSIS.json `output`: beside it, suffix '.md' (its plots
    `<stem>_*.png`). `output` itself may not end in '.md', so the two never collide.

    Returns
    -------
    report : Path
        `output` with the suffix '.md'.
    """
    output = Path(output)
    if output.suffix.lower() == ".md":
        raise InputError(
            f"{param('output', str(output))}: names DIAGNOSIS.json, and its Markdown report goes "
            f"beside it as <name>.md; give e.g. "
            f"{param('output', str(output.with_suffix('.json')))}"
        )
    return output.with_suffix(".md")


def html_report_path(output: str | Path) -> Path:
    """The self-contained HTML report of DIAGNOSIS.json `output`: beside it, suffix
    '.html' (msgs_doc/report.md). `output` itself may not end in '.html'.

    Returns
    -------
    report : Path
        `output` with the suffix '.html'.
    """
    output = Path(output)
    if output.suffix.lower() in (".html", ".htm"):
        raise InputError(
            f"{param('output', str(output))}: names DIAGNOSIS.json, and its HTML report goes "
            f"beside it as <name>.html; give e.g. "
            f"{param('output', str(output.with_suffix('.json')))}"
        )
    return output.with_suffix(".html")


def write_diagnosis(
    diagnosis: Diagnosis,
    ladder: Ladder,
    recording: Recording,
    output: str | Path,
    force: bool = False,
    calibrations: Mapping[str, Calibration] | None = None,
    best: tuple[Calibration, Path] | None = None,
    warnings: Sequence[str] = (),
    compared: list[ModelErrors] | None = None,
    figures: FigureCache | None = None,
    pdf: bool = False,
) -> Path:
    """Write DIAGNOSIS.json at `output`, the Markdown report (+ plots) and the HTML report
    beside it (with `pdf`, also that page printed, `pdf_report_path(output)`), and (without
    `best`) the ladder's chosen rung as `best_params_path(output)`, all together
    (staged, then moved in; an existing file is replaced only with `force`).
    `calibrations`: nominal / cpa models already identified from `recording` (else the HTML
    report identifies them); `best`: the model the HTML report recommends and the PARAMS.json
    it goes to (default: the ladder's chosen rung and `best_params_path(output)`);
    `warnings`: the caller's own warnings, listed in the HTML report; `compared`: the
    before/after comparison if the caller has it (`compare_before_after`); `figures`: the
    cache to draw the figures with (`started_figures`: its helpers started when the run
    began; closed here), else one made here.

    Returns
    -------
    report : Path
        The Markdown report: `report_path(output)` (the HTML one: `html_report_path`).
    """
    from robot_calib.atomic import staged_outputs
    from robot_calib.diagnosis.figures import FigureCache
    from robot_calib.diagnosis.html_report import compare_models, html_report
    from robot_calib.diagnosis.report import plot_paths, write_report
    from robot_calib.identify.params_file import write_json_atomic

    output = Path(output)
    report = report_path(output)
    page = html_report_path(output)
    best_file = best_params_path(output)
    chosen = ladder.rungs[-1]
    recommended, recommended_file = best or (chosen.calibration, best_file)
    with staged_outputs(output.parent, force) as stage:
        write_json_atomic(diagnosis.to_dict(), stage / output.name)
        fitted = ladder.recording if ladder.recording is not None else recording  # no outliers
        figures = FigureCache() if figures is None else figures  # each drawn once for both
        try:
            if compared is None:
                compared = compare_models(ladder, calibrations)
            draw_figures(figures, ladder, fitted, diagnosis.noise.floor_abs_rms_mm, compared)
            (stage / page.name).write_text(
                html_report(
                    diagnosis,
                    ladder,
                    fitted,
                    compared,
                    recommended,
                    recommended_file.name,
                    warnings,
                    figures,
                )
            )
            write_report(
                diagnosis,
                ladder,
                fitted,
                stage / report.name,
                figures,
                compared,
                recommended,
                warnings,
            )
            if pdf:
                from robot_calib.diagnosis.pdf import print_pdf

                print_pdf(stage / page.name, stage / pdf_report_path(output).name)
        except BaseException:
            figures.close(abort=True)  # an error or Ctrl-C here: the children go at once
            raise
        figures.close()
        if best is None:  # run writes its own params_best.json: one best model per folder
            scores = {r.model: r.heldout.absolute_rms_mm for r in ladder.rungs}
            write_json_atomic(
                selected_document(
                    marked_implausible(chosen.calibration, diagnosis),
                    fitted,
                    "the diagnosis ladder's chosen rung",
                    diagnosis.scored_on,
                    scores,
                ),
                stage / best_file.name,
            )
            check_loads(stage / best_file.name, best_file, chosen.calibration, fitted)
        written = {p.name for p in stage.iterdir()}
    if force:  # replaced whole: no figure of the old set that the new report does not have
        for stale in plot_paths(report.with_suffix("")):
            if stale.name not in written:
                stale.unlink(missing_ok=True)
    return report


def pdf_report_path(output: str | Path) -> Path:
    """The PDF report beside DIAGNOSIS.json `output`: the HTML report's name, .pdf
    (`output` itself may not end in '.pdf')."""
    if Path(output).suffix.lower() == ".pdf":
        raise InputError(
            f"{param('output', str(output))}: names DIAGNOSIS.json, and its PDF report goes "
            f"beside it as <name>.pdf; give e.g. "
            f"{param('output', str(Path(output).with_suffix('.json')))}"
        )
    return html_report_path(output).with_suffix(".pdf")


def check_loads(path: Path, name: Path, cal: Calibration, recording: Recording) -> None:
    """Read the PARAMS.json at `path` (to be moved to `name`) back as predict, score,
    compensate and export read it (its model, parameters and learned correction, checked:
    `Calibration.from_dict`), and compare what it predicts at `recording`'s poses with
    `cal`'s: a WrittenFileError when it does not load or predicts otherwise (a writer whose
    reader refuses its output is a bug)."""
    import numpy as np

    from robot_calib.errors import RobotCalibError, WrittenFileError
    from robot_calib.identify.calibration import Calibration

    try:
        back = Calibration.load(path, str(name))
    except RobotCalibError as exc:
        raise WrittenFileError(f"{name} would not load: {exc}") from None
    poses = recording.poses
    gap = float(np.max(np.abs(back.predict(poses) - cal.predict(poses)), initial=0.0))
    if not gap <= WRITTEN_TOLERANCE_M:
        raise WrittenFileError(
            f"{name} would predict {gap * 1e3:.3g} mm from the model it "
            "holds at the calibration poses"
        )


#: what a written PARAMS.json may predict away from the model it was written from [m]
WRITTEN_TOLERANCE_M = 1e-9


def marked_implausible(cal: Calibration, diagnosis: Diagnosis) -> Calibration:
    """`cal` (the best model of `diagnosis`) carrying the diagnosis' implausibility reasons
    too: its PARAMS.json says `plausible: false` with them whenever the diagnosis is
    implausible, so that export, compensate and predict refuse it (without --force)."""
    reasons = tuple(dict.fromkeys([*cal.implausible, *diagnosis.implausible]))
    return cal if reasons == cal.implausible else replace(cal, implausible=reasons)


def best_params_path(output: str | Path) -> Path:
    """The PARAMS.json of the best model beside DIAGNOSIS.json `output`:
    `<name>.params_best.json` (msgs_doc/parameters.md, `selected`)."""
    output = Path(output)
    return output.with_name(f"{output.stem}.params_best.json")


def selected_document(
    cal: Calibration, recording: Recording, how: str, scored_on: str, scores: dict[str, float]
) -> dict[str, Any]:
    """The PARAMS.json document of `cal`, the model selected as the best, with a `selected`
    section: how it was chosen, on what, and every candidate's held-out rms [mm]."""
    doc = cal.to_dict(recording)
    doc["selected"] = {
        "model": cal.label,
        "chosen_as": how,
        "scored_on": scored_on,
        "holdout_abs_rms_mm": scores,
    }
    return doc


def generalisation_warnings(scores: Sequence[tuple[str, float]]) -> list[str]:
    """A warning for every model of `scores` ((name, held-out abs rms [mm]), simplest first)
    that scores worse than the one before it: a richer model that generalises worse."""
    warnings = []
    for (simple, a), (rich, b) in zip(scores, scores[1:]):
        if b > a and f"{b:.4f}" != f"{a:.4f}":  # worse by what is printed, not a tie
            warnings.append(
                f"warning: {rich} generalises worse than {simple} ({b:.4f} vs {a:.4f} mm "
                f"held-out abs rms): its extra parameters fit the calibration poses, not the "
                "robot; the best model is chosen by held-out error"
            )
    return warnings


def compare_before_after(
    ladder: Ladder, calibrations: Mapping[str, Calibration] | None = None
) -> tuple[list[ModelErrors], list[str]]:
    """The HTML report's before/after models (`compare_models`: nominal, cpa, geometric,
    the best rung) and, when they are all scored on hold-out bags, a warning for each that
    generalises worse than the simpler one before it (what `diagnose` says, as `run` does)."""
    from robot_calib.diagnosis.html_report import compare_models

    compared = compare_models(ladder, calibrations)
    if ladder.holdout is None:  # nominal/cpa in-sample, the rungs k-fold: not comparable
        return compared, []
    return compared, generalisation_warnings(
        [(m.model, m.accuracy.absolute_rms_mm) for m in compared]
    )
