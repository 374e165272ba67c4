"""The main job (`robot-calib run`): simulate + record a calibration bag and a hold-out bag,
calibrate RUN_MODELS, score each on the hold-out poses, diagnose, keep the best model; all
in a new folder, built hidden and renamed when complete."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from robot_calib.diagnosis.header import HeaderFields, report_header
from robot_calib.errors import InputError, param
from robot_calib.flows import (
    DEFAULT_ROBOT,
    RUN_HOLDOUT_POSES,
    RUN_MODELS,
    RUN_PLAN,
    Progress,
)
from robot_calib.flows.bags import read_bags
from robot_calib.flows.calibrate import calibrate_recording
from robot_calib.flows.diagnose import (
    FiguresWhenClimbed,
    check_loads,
    diagnose_recordings,
    generalisation_warnings,
    html_report_path,
    marked_implausible,
    selected_document,
    started_figures,
    write_diagnosis,
)
from robot_calib.flows.simulate import Recorder, Simulation, simulate, simulation_world
from robot_calib.kinematics.description import RobotDescription
from robot_calib.log import Log

if TYPE_CHECKING:
    from robot_calib.accuracy import Accuracy
    from robot_calib.diagnosis.diagnosis import Diagnosis
    from robot_calib.diagnosis.ladder import Ladder
    from robot_calib.identify.calibration import Calibration
    from robot_calib.measurements import Recording
    from robot_calib.sim.world import World


#: hold-out poses `run` simulates at most (a campaign of 100k poses takes ~30 s and ~0.5
#: GB; 1e8 took 14 GB before this limit)
MAX_HOLDOUT_POSES = 100_000


def _quiet(_message: str) -> None:
    """A log that says nothing."""


@dataclass(frozen=True)
class ModelScore:
    """One model of the main job: its calibration and its accuracy on the hold-out bag."""

    calibration: Calibration
    holdout: Accuracy


@dataclass(frozen=True)
class RunResult:
    """The main job's outputs: its folder, the two simulations, every model with its
    hold-out score (PARAMS.json files `params_<model>.json`), the diagnosis and report."""

    folder: Path
    calibration_bag: Simulation
    holdout_bag: Simulation
    recording: Recording
    models: dict[str, ModelScore]
    diagnosis: Diagnosis
    report: Path
    best: str = ""  # the model written as params_best.json (lowest held-out error)
    warnings: tuple[str, ...] = ()  # richer models that generalise worse than simpler ones
    html: Path | None = None  # the self-contained HTML report (diagnosis.html)


def run(
    output_dir: str | Path = "out",
    robot: str = DEFAULT_ROBOT,
    plan: str = RUN_PLAN,
    effects: Sequence[str] | None = None,
    seed: int = 0,
    n_holdout: int = RUN_HOLDOUT_POSES,
    say: Log = _quiet,
    log: Log | None = None,
    progress: Progress | None = None,
    *,
    record: Recorder,
    header: HeaderFields | None = None,
    pdf: bool = False,
) -> RunResult:
    """The main job: simulate + record a calibration bag (`plan`, `effects`; default the
    main job's joint-4 backlash) and `n_holdout` random hold-out poses in the same world
    (`record`: the simulated graph, as `simulate`'s), calibrate RUN_MODELS, score each on
    the hold-out poses, diagnose. Writes a new folder `run-<time>` under `output_dir`; `say`
    gets one line per step. `header`: the report header's fields (default: none given,
    the instrument the simulated tracker); `pdf`: also print the HTML report to PDF.

    Returns
    -------
    result : RunResult
        The main job's outputs, with the following fields:

        folder : Path
            The new folder `output_dir/run-YYYYmmdd-HHMMSS`.
        calibration_bag, holdout_bag : Simulation
            The two simulated recordings (calibration.mcap, holdout.mcap) and their worlds.
        recording : Recording
            The paired measurements of the calibration bag.
        models : dict of str to ModelScore
            Per model of RUN_MODELS: its Calibration (also written as
            `params_<model>.json`) and its Accuracy on the hold-out poses [mm].
        diagnosis : Diagnosis
            The diagnosis of the calibration bag scored on the hold-out bag (written as
            diagnosis.json).
        report : Path
            The Markdown report beside it (diagnosis.md).
        best, warnings : str, tuple of str
            The model written as params_best.json; richer models that generalise worse.
        html : Path
            The self-contained HTML report beside it (diagnosis.html).
    """
    from robot_calib.effects import MAIN_JOB_EFFECTS
    from robot_calib.kinematics.loader import load_robot
    from robot_calib.sim.plans import check_plan

    description = load_robot(robot)  # every input checked before anything is written
    check_plan(plan, description)
    if not 1 <= n_holdout <= MAX_HOLDOUT_POSES or seed < 0:
        raise InputError(
            f"{param('holdout', n_holdout)}, {param('seed', seed)}: need 1 to "
            f"{MAX_HOLDOUT_POSES} poses, seed >= 0"
        )
    effects = MAIN_JOB_EFFECTS if effects is None else effects
    world = simulation_world(None, robot, effects, seed)
    if Path(output_dir).exists() and not Path(output_dir).is_dir():
        raise InputError(f"{output_dir}: exists and is not a folder")
    parent = Path(output_dir)
    created = not parent.exists()
    try:
        parent.mkdir(parents=True, exist_ok=True)
        final = _reserve(parent / time.strftime("run-%Y%m%d-%H%M%S"))
    except OSError as exc:
        raise InputError(f"{output_dir}: cannot write there: {exc.strerror or exc}") from None
    # built in a hidden folder beside it and renamed when complete: an interrupted or failed
    # run leaves nothing (msgs_doc: the overwrite and partial-output policy); the final name
    # is reserved at once (an empty folder), so two runs of one second never collide
    try:
        folder = Path(tempfile.mkdtemp(prefix=".run-", suffix=".partial", dir=parent))

        def final_paths(message: str) -> str:
            """`message` naming the final folder, not the hidden one the run is built in."""
            return message.replace(str(folder), str(final))

        try:
            log_final = None if log is None else (lambda m: log(final_paths(m)))
            result = _run_in(
                folder,
                final,
                description,
                plan,
                world,
                seed,
                n_holdout,
                robot,
                lambda m: say(final_paths(m)),
                log_final,
                progress,
                record,
                header or HeaderFields(),
                pdf,
            )
            _name_final_paths(folder, final)
            os.rename(folder, final)  # onto the empty reserved folder
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
    except BaseException:
        with contextlib.suppress(OSError):
            final.rmdir()  # the reservation (empty)
            if created:
                parent.rmdir()  # a folder this run made, left empty
        raise

    def moved(path: Path) -> Path:
        return final / path.relative_to(folder)

    diagnosis = result.diagnosis
    diagnosis = replace(
        diagnosis,
        implausible=[final_paths(m) for m in diagnosis.implausible],
        warnings=[final_paths(m) for m in diagnosis.warnings],
    )
    return replace(
        result,
        diagnosis=diagnosis,
        folder=final,
        calibration_bag=replace(
            result.calibration_bag,
            bag=moved(result.calibration_bag.bag),
            world_file=moved(result.calibration_bag.world_file),
        ),
        holdout_bag=replace(
            result.holdout_bag,
            bag=moved(result.holdout_bag.bag),
            world_file=moved(result.holdout_bag.world_file),
        ),
        report=moved(result.report),
        html=None if result.html is None else moved(result.html),
    )


def _reserve(name: Path) -> Path:
    """`name`, else `name-2`, `name-3`, ...: the first that did not exist, created empty
    (os.mkdir: atomic, so two runs never take one name)."""
    for k in range(1, 1000):
        candidate = name if k == 1 else name.with_name(f"{name.name}-{k}")
        try:
            candidate.mkdir()
            return candidate
        except FileExistsError:
            continue
    raise InputError(f"{name}: a thousand runs of that second exist already")


def _name_final_paths(folder: Path, final: Path) -> None:
    """The run's text files (reports, PARAMS.json, world files) name the bags and files by
    their final paths in `final`, not by the hidden `folder` they were built in (which is
    gone once renamed): every spelling of `folder` (plain, JSON-escaped, HTML-escaped)
    replaced before the rename."""
    import html
    import json

    from robot_calib.atomic import write_text_atomic

    spellings = {str(folder): str(final)}
    spellings[json.dumps(str(folder))[1:-1]] = json.dumps(str(final))[1:-1]
    spellings[html.escape(str(folder))] = html.escape(str(final))
    for path in sorted(folder.iterdir()):
        if path.suffix not in (".json", ".md", ".html", ".yaml", ".csv", ".txt"):
            continue
        text = path.read_text()
        renamed = text
        for old, new in spellings.items():
            renamed = renamed.replace(old, new)
        if renamed != text:
            write_text_atomic(path, renamed, rewrite=True)


def _run_in(
    folder: Path,
    final: Path,
    description: RobotDescription,
    plan: str,
    world: World,
    seed: int,
    n_holdout: int,
    robot: str,
    say: Log,
    log: Log | None,
    progress: Callable[[str, int, int], None] | None,
    record: Recorder,
    header: HeaderFields,
    pdf: bool,
) -> RunResult:
    """`run`'s work, written into `folder` (renamed to `final` by `run` when complete;
    messages name the final paths)."""
    from robot_calib.accuracy import accuracy
    from robot_calib.identify.params_file import write_json_atomic

    bag, holdout = folder / "calibration.mcap", folder / "holdout.mcap"
    steps = 4
    say(f"[1/{steps}] simulate + record: {plan} in the default world -> {final / bag.name}")
    first = simulate(bag, plan, world, seed, n_holdout, progress, record=record)
    say(
        f"[2/{steps}] simulate + record: {n_holdout} random hold-out poses -> "
        f"{final / holdout.name}"
    )
    truth = simulation_world(first.world_file, robot, (), seed + 1)
    second = simulate(holdout, "random", truth, seed + 1, n_holdout, progress, record=record)
    recording = read_bags([bag], description, log=log)
    held = read_bags([holdout], description, log=log)
    # cpa needs a circle sweep of every joint: a plan of general poses (PLAN.yaml, random)
    # calibrates the other models
    swept = all(recording.sweeps_of(j) for j in range(1, description.n_joints + 1))
    names = [n for n in RUN_MODELS if swept or n != "cpa"]
    say(
        f"[3/{steps}] calibrate: {', '.join(names)}"
        + ("" if swept else " (no cpa: the plan has no circle sweep of every joint)")
    )
    with started_figures() as figures:  # its helpers get ready while the models are fitted
        models = {}
        for name in names:
            cal = calibrate_recording(recording, description, name, log=log)
            write_json_atomic(cal.to_dict(recording), folder / f"params_{name}.json")
            models[name] = ModelScore(cal, accuracy(held.points, cal.predict(held.poses)))
        say(f"[4/{steps}] diagnose the sim-to-real gap (hold-out: {holdout.name})")
        calibrations = {n: m.calibration for n, m in models.items()}
        early = FiguresWhenClimbed(figures, calibrations)  # drawn while written up
        diagnosis, ladder = diagnose_recordings(recording, description, held, log, on_ladder=early)
        best, warnings = _best_model(models, ladder)
        fields = replace(header, instrument=header.instrument or "simulated laser tracker")
        stated = world.noise.tracker_sigma_m  # what the simulated tracker is built with
        diagnosis = replace(
            diagnosis,
            warnings=[*diagnosis.warnings, *warnings],
            header=report_header(description.name, [recording, held], fields, stated),
        )
        report = write_diagnosis(
            diagnosis,
            ladder,
            recording,
            folder / "diagnosis.json",
            calibrations=calibrations,
            best=(best, folder / "params_best.json"),
            warnings=warnings,
            compared=early.before_after(ladder)[0],
            figures=figures,
            pdf=pdf,
        )
    scores = {n: m.holdout.absolute_rms_mm for n, m in models.items()}
    scores.update({r.model: r.heldout.absolute_rms_mm for r in ladder.rungs})
    write_json_atomic(
        selected_document(
            marked_implausible(best, diagnosis),
            recording,
            "the lowest held-out error of the run's models and the diagnosis ladder's rungs",
            "hold-out bag",
            scores,
        ),
        folder / "params_best.json",
    )
    check_loads(folder / "params_best.json", Path("params_best.json"), best, recording)
    return RunResult(
        folder,
        first,
        second,
        recording,
        models,
        diagnosis,
        report,
        best.label,
        tuple(warnings),
        html_report_path(folder / "diagnosis.json"),
    )


def _best_model(models: dict[str, ModelScore], ladder: Ladder) -> tuple[Calibration, list[str]]:
    """The calibration with the lowest held-out rms among `models` and the ladder's rungs,
    and a warning for every richer model that generalises worse than a simpler one
    (geometric behind cpa: its extra parameters fit the sweeps, not the robot)."""
    candidates = [(m.holdout.absolute_rms_mm, n, m.calibration) for n, m in models.items()]
    candidates += [(r.heldout.absolute_rms_mm, r.model, r.calibration) for r in ladder.rungs]
    order = [n for n in RUN_MODELS if n in models]
    warnings = generalisation_warnings([(n, models[n].holdout.absolute_rms_mm) for n in order])
    best = min(candidates, key=lambda c: c[0])
    return best[2], warnings
