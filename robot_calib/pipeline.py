"""The flow as typed functions: simulate -> calibrate bags -> diagnose bags, and `run` (the
main job) on top. The CLI verbs, the calibrator node and scripts call these; each default
(robot, plan, pairing tolerance, models) is written once, here or where its idea lives.

Heavy modules (scipy, mcap, rclpy) are imported inside the function that needs them, so a
caller pays only for what it runs.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError
from robot_calib.identify import DEFAULT_ECC_ORDER, DEFAULT_MODEL
from robot_calib.kinematics.description import RobotDescription
from robot_calib.measurements import PAIR_TOLERANCE_S

if TYPE_CHECKING:
    from robot_calib.accuracy import Accuracy
    from robot_calib.diagnose.diagnosis import Diagnosis
    from robot_calib.diagnose.html_report import ModelErrors
    from robot_calib.diagnose.ladder import Ladder
    from robot_calib.identify.calibration import Calibration
    from robot_calib.identify.latency import StreamCalibration
    from robot_calib.measurements import Recording
    from robot_calib.sim.stream import StreamOptions
    from robot_calib.sim.world import World

Log = Callable[[str], None]
Progress = Callable[[str, int, int], None]  # (plan, poses done, poses in all)

DEFAULT_ROBOT = "kr5_sixx_r650"  # the seed's robot
RUN_PLAN = "paper-test2"  # the main job's calibration plan (seed Test 2)
DEFAULT_PLAN = RUN_PLAN  # `simulate` without --plan: the same as the main job
RUN_HOLDOUT_POSES = 200
RUN_MODELS = ("nominal", "cpa", "geometric")
N_RANDOM_POSES = 200  # poses of the `random` plan


def _quiet(_message: str) -> None:
    """A log that says nothing."""


@dataclass(frozen=True)
class Simulation:
    """A simulated recording: the bag, its world file (the complete truth), messages per
    topic, the effects switched on (labels) and the wall time [s]."""

    bag: Path
    world_file: Path
    counts: dict[str, int]
    effects: tuple[str, ...]
    seconds: float


def simulation_world(
    world: str | Path | None = None,
    robot: str | None = DEFAULT_ROBOT,
    effects: Sequence[str] = (),
    seed: int | None = None,
) -> World:
    """The world of a world file (default: the built-in one; another robot without a file:
    its nominal geometry in the default set-up), with `effects` switched on (text form of
    `simulate --effects`, e.g. 'backlash:4', 'compliance:2=2e-5') and `seed` if given.
    `robot` None: the world's robot; a world file whose robot differs from `robot` is an
    InputError.

    Returns
    -------
    world : World
        The simulated truth: model (the robot with the effects), truth (every true
        parameter value, SI), noise, tracker options (latency, dropout), timing, seed.
    """
    from robot_calib.kinematics.loader import load_robot
    from robot_calib.sim.world import build_world, load_world, parse_sim_effect, with_effect

    if world is None and robot not in (None, DEFAULT_ROBOT):
        out = build_world({"robot": robot, "geometry": "nominal"}, f"--robot {robot}")
    else:
        out = load_world(world)
        wanted = None if robot is None else load_robot(robot)
        if wanted is not None and wanted.reference() != out.model.robot.reference():
            raise InputError(
                f"{out.source}: world robot {out.model.robot.reference()} differs from "
                f"--robot {robot}; give one of them"
            )
    if seed is not None:
        out = replace(out, seed=seed)
    for spec in effects:
        effect, value = parse_sim_effect(spec, out.model.robot.n_joints)
        values = effect.default_values(out.model.robot)
        if value is not None:
            values = {k: value for k in values}
        out = with_effect(out, effect, values)
    return out


def simulate(
    output: str | Path,
    plan: str = DEFAULT_PLAN,
    world: World | None = None,
    seed: int | None = None,
    n_random: int = N_RANDOM_POSES,
    progress: Progress | None = None,
    force: bool = False,
) -> Simulation:
    """Run the simulated graph (sim_robot, sim_tracker, recorder, in-process) over `plan`
    in `world` (default: `simulation_world()`) and record the bag `output` (in an existing
    folder; an existing bag or world file is replaced only with `force`, the world file
    read never) and its world file beside it. Both are written in a staging folder and
    moved in at the end: nothing is left on failure or Ctrl-C. A recording without a
    single tracker point is an InputError.

    Returns
    -------
    simulation : Simulation
        What was recorded, with the following fields:

        bag : Path
            The MCAP bag written (`output`).
        world_file : Path
            The world used (the complete truth), beside the bag: `<bag>.world.yaml`.
        counts : dict of str to int
            Messages recorded per topic.
        effects : tuple of str
            Labels of the effects switched on in `world`.
        seconds : float
            Wall time of the simulation [s].
    """
    from robot_calib.atomic import staged_outputs
    from robot_calib.messages import POINT_TOPIC
    from robot_calib.nodes.simulate import simulate_bag
    from robot_calib.sim.world import save_world

    world = world if world is not None else simulation_world(seed=seed)
    bag, world_file = _simulation_outputs(output, plan, world, force)
    started = time.monotonic()
    with staged_outputs(bag.parent, force) as stage:
        save_world(world, stage / world_file.name)
        counts = simulate_bag(
            stage / bag.name, plan, stage / world_file.name, -1 if seed is None else seed,
            n_random, None if progress is None else partial(progress, plan),
        )  # fmt: skip
        if not counts.get(POINT_TOPIC):
            raise InputError(
                f"{bag}: the simulation recorded no tracker point (dropout probability "
                f"{world.tracker.dropout_probability}); nothing written"
            )
    labels = tuple(e.label for e in world.effects)
    return Simulation(bag, world_file, counts, labels, time.monotonic() - started)


def simulation_inputs(world: World, plan: str | None = None) -> list[str]:
    """The files a simulation or a plan reads, which it may never overwrite: the world file,
    the robot's description file (YAML or URDF) and a PLAN.yaml."""
    from robot_calib.plan.plan_file import is_plan_file

    files = [world.source, world.model.robot.path.split("#", 1)[0]]
    if plan is not None and is_plan_file(plan):
        files.append(plan)
    return [f for f in files if f]


def simulate_stream(
    output: str | Path,
    plan: str = "random",
    world: World | None = None,
    seed: int | None = None,
    n_random: int = 20,
    options: StreamOptions | None = None,
    force: bool = False,
) -> Simulation:
    """A stream recording (continuous tracking, msgs_doc/stream.md) of a smooth move through
    the poses of `plan` in `world` (`sim.stream.simulate_stream`, no ROS graph), written as
    the bag `output` with its world file beside it (staged as `simulate`'s). The world file
    holds the truth of the robot; the stream's own truth (latency, rates) is `options`.

    Returns
    -------
    simulation : Simulation
        As `simulate`'s.
    """
    from robot_calib.atomic import staged_outputs
    from robot_calib.bag.csv_import import write_stream_bag
    from robot_calib.sim.plans import make_plan
    from robot_calib.sim.stream import StreamOptions, simulate_stream
    from robot_calib.sim.world import save_world

    world = world if world is not None else simulation_world(seed=seed)
    bag, world_file = _simulation_outputs(output, plan, world, force)
    started = time.monotonic()
    rng = np.random.default_rng(world.seed if seed is None else seed)
    model = world.model
    waypoints = make_plan(plan, model, model.parameters(), rng, n_random).q
    sim = simulate_stream(world, waypoints, options or StreamOptions(), rng)
    with staged_outputs(bag.parent, force) as stage:
        save_world(world, stage / world_file.name)
        s = sim.stream
        counts = write_stream_bag(
            stage / bag.name, s.js_ns, s.q, sim.velocity, s.point_ns, s.points,
            model.robot.joint_names, force=True,
        )  # fmt: skip
    labels = tuple(e.label for e in world.effects)
    return Simulation(bag, world_file, counts, labels, time.monotonic() - started)


def _simulation_outputs(
    output: str | Path, plan: str, world: World, force: bool
) -> tuple[Path, Path]:
    """The bag and world file paths of a simulation (`output_path`'s policy), after
    checking `plan` against the world's robot."""
    from robot_calib.sim.plans import check_plan

    check_plan(plan, world.model.robot)
    inputs = simulation_inputs(world, plan)
    bag = output_path(output, "the bag", inputs, force)
    world_file = output_path(bag.with_suffix(".world.yaml"), "the world file", inputs, force)
    return bag, world_file


def output_path(
    raw: str | Path, what: str, inputs: Sequence[str | Path] = (), force: bool = False
) -> Path:
    """The path of a file to write (the overwrite policy of every verb): its folder must
    exist and be writable, it must not be a folder, it must not be one of the command's
    `inputs` (an input is never overwritten, even with `force`), and it must not exist
    unless `force`; InputError naming the path otherwise.

    Returns
    -------
    path : Path
        `raw` as a Path.
    """
    path = Path(raw)
    if not path.parent.is_dir():
        raise InputError(f"{path.parent}: no such folder for {what}")
    if path.is_dir():
        raise InputError(f"{path}: is a folder; give a file name for {what}")
    if path.exists() and any(
        Path(p).exists() and path.resolve() == Path(p).resolve() for p in inputs
    ):
        raise InputError(f"{path}: is an input of this command; will not overwrite it")
    if not os.access(path.parent, os.W_OK | os.X_OK):
        raise InputError(f"{path.parent}: folder not writable; cannot write {what} there")
    if not force:
        from robot_calib.atomic import refuse_incomplete

        refuse_incomplete(path)  # a set killed half-moved: said as such, not "exists"
    if path.exists() and not force:
        raise InputError(f"{path}: exists; will not overwrite it (use --force)")
    if not force:  # still new at the final rename, or refused (a second command wrote it)
        from robot_calib.atomic import claim_new

        claim_new(path)
    return path


def read_bags(
    bags: Sequence[str | Path],
    robot: RobotDescription,
    pair_tolerance: float = PAIR_TOLERANCE_S,
    log: Log | None = None,
) -> Recording:
    """The paired measurements of `bags` (msgs_doc/specification.md section 1).

    Returns
    -------
    recording : Recording
        As `robot_calib.bag.read.read_recording`: poses (n), points (n, 3) [m], sweeps,
        the bag of each pose, unpaired points and warnings.
    """
    from robot_calib.bag.read import read_recording

    check_distinct_bags(bags)
    recording = read_recording(bags, robot, pair_tolerance, log=log)
    check_distinct_recordings(recording)
    return recording


def check_distinct_bags(bags: Sequence[str | Path], holdout: Sequence[str | Path] = ()) -> None:
    """InputError naming the bag when one is given twice, or as calibration and hold-out
    bag (a "held-out" score would be in-sample, and sigmas would shrink by sqrt 2)."""
    seen: list[tuple[Path, str]] = []
    for raw, role in [(b, "calibration") for b in bags] + [(b, "hold-out") for b in holdout]:
        path = Path(raw)
        for other, other_role in seen:
            same = (
                path.exists() and other.exists() and os.path.samefile(path, other)
            ) or path.resolve() == other.resolve()
            if same:
                how = "twice" if role == other_role else "as calibration and as hold-out bag"
                raise InputError(f"{path}: the same bag given {how} (as {other}); give it once")
        seen.append((path, role))


def check_distinct_recordings(*recordings: Recording) -> None:
    """InputError when two sources (bags) of `recordings` hold the same measurements, as a
    copy of a bag under another name does: half or more of one's measurements (readings
    and point, to 1 nrad / 1 nm: a tracker never measures a point twice alike) are also the
    other's, whatever their stamps (the path check, `check_distinct_bags`, cannot see a
    copy; two halves of one CSV imported apart share synthetic stamps, not measurements)."""
    sources = [
        (rec.sources[b], _measurement_keys(rec, rec.bag_index == b))
        for rec in recordings
        for b in range(len(rec.sources))
    ]
    for k, (first, keys) in enumerate(sources):
        for second, others in sources[k + 1 :]:
            shared = len(keys & others)
            if keys and others and shared >= 0.5 * min(len(keys), len(others)):
                raise InputError(
                    f"{second}: {shared} of its measurements (readings and point) are also in "
                    f"{first}: the same measurements twice (a copy?); give them once"
                )


def _measurement_keys(rec: Recording, rows: NDArray[np.bool_]) -> set[bytes]:
    """Each measurement of `rec` at `rows` as a key: its readings [nrad] and point [nm]."""
    values = np.column_stack([rec.poses.q[rows], rec.points[rows]])
    ok = np.all(np.isfinite(values), axis=1)
    scaled = np.round(values[ok] * 1e9).astype(np.int64)
    return {row.tobytes() for row in scaled}


def calibrate_recording(
    recording: Recording,
    robot: RobotDescription,
    model: str = DEFAULT_MODEL,
    ecc_order: int = DEFAULT_ECC_ORDER,
    objective: str = "absolute",
    log: Log | None = None,
) -> Calibration:
    """Identify `model` from paired measurements (a bag's, or live topics').

    Returns
    -------
    calibration : Calibration
        As `robot_calib.identify.calibrate.calibrate`.
    """
    from robot_calib.identify.calibrate import calibrate

    if objective == "seed":
        check_seed_objective_memory(len(recording), robot, model, ecc_order)
    return calibrate(recording, robot, model, ecc_order, log=log, objective=objective)


SEED_OBJECTIVE_MEMORY_LIMIT = 2 * 1024**3  # bytes of pairwise rows `--objective seed` may take


def seed_objective_bytes(n_points: int, n_params: int) -> int:
    """Memory [bytes] of the seed objective's pairwise rows for `n_points` and `n_params`
    parameters: per pair of points, the two points' Jacobians, their difference (3 x P
    each) and the distance row (P), float64; O(n_points^2)."""
    pairs = n_points * (n_points - 1) // 2
    return pairs * (3 * 3 * n_params + n_params) * 8


def check_seed_objective_memory(
    n_points: int, robot: RobotDescription, model: str, ecc_order: int = DEFAULT_ECC_ORDER
) -> None:
    """InputError when `--objective seed` on `n_points` would need more than
    SEED_OBJECTIVE_MEMORY_LIMIT, naming the largest number of points that fits."""
    from robot_calib.identify.calibrate import parse_model
    from robot_calib.model import KinematicModel

    _, effects = parse_model(model, robot, ecc_order)
    n_params = len(KinematicModel(robot, tuple(effects)).parameters().names)
    need = seed_objective_bytes(n_points, n_params)
    if need <= SEED_OBJECTIVE_MEMORY_LIMIT:
        return
    allowed = n_points
    while seed_objective_bytes(allowed, n_params) > SEED_OBJECTIVE_MEMORY_LIMIT:
        allowed = int(allowed * 0.99)
    while seed_objective_bytes(allowed + 1, n_params) <= SEED_OBJECTIVE_MEMORY_LIMIT:
        allowed += 1
    gib = 1024**3
    raise InputError(
        f"--objective seed on {n_points} points needs {need / gib:.1f} GiB for its pairwise "
        f"rows (limit {SEED_OBJECTIVE_MEMORY_LIMIT / gib:.0f} GiB: at most {allowed} points "
        f"with {n_params} parameters); use --objective absolute (O(N)) or fewer points"
    )


def calibrate_bags(
    bags: Sequence[str | Path],
    robot: RobotDescription,
    model: str = DEFAULT_MODEL,
    ecc_order: int = DEFAULT_ECC_ORDER,
    objective: str = "absolute",
    pair_tolerance: float = PAIR_TOLERANCE_S,
    log: Log | None = None,
) -> tuple[Calibration, Recording]:
    """Identify `model` from `bags`. A bad model name fails before any bag is read.

    Returns
    -------
    calibration : Calibration
        As `robot_calib.identify.calibrate.calibrate`: parameters (P) with their 1-sigma,
        in-sample accuracy [mm], residuals (n, 3) [m], identifiability, solver report.
    recording : Recording
        The paired measurements of `bags` it was identified from (as `read_bags`).
    """
    from robot_calib.identify.calibrate import parse_model

    parse_model(model, robot, ecc_order)
    recording = read_bags(bags, robot, pair_tolerance, log)
    cal = calibrate_recording(recording, robot, model, ecc_order, objective, log)
    return cal, recording


def calibrate_stream_bag(
    bags: Sequence[str | Path],
    robot: RobotDescription,
    model: str = DEFAULT_MODEL,
    ecc_order: int = DEFAULT_ECC_ORDER,
    latency_s: float | None = None,
    max_points: int | None = None,
    max_gap_s: float | None = None,
    log: Log | None = None,
) -> StreamCalibration:
    """Identify `model` from one stream bag (continuous tracking, msgs_doc/stream.md): the
    joint readings interpolated to the point stamps + `latency_s` [s] (None: identified);
    at most `max_points` points fitted (None: STREAM_MAX_POINTS), points in joint-state gaps
    longer than `max_gap_s` [s] (None: STREAM_MAX_GAP_S) dropped. A bad model name fails
    before the bag is read; more than one bag is an InputError (one latency per bag).

    Returns
    -------
    stream_calibration : StreamCalibration
        As `robot_calib.identify.latency.calibrate_stream`: the calibration, the paired
        points it was fitted on, the pairing, the latency used and how it was found.
    """
    from robot_calib.bag.read import read_stream
    from robot_calib.identify.calibrate import parse_model
    from robot_calib.identify.latency import calibrate_stream
    from robot_calib.measurements.stream import STREAM_MAX_GAP_S, STREAM_MAX_POINTS

    parse_model(model, robot, ecc_order)
    if len(bags) != 1:
        raise InputError(f"--stream calibrates one bag (its own latency); got {len(bags)}")
    if model.split("+")[0] == "cpa":
        raise InputError(f"--stream --model {model}: a stream has no circle sweeps; use an "
                         "LM model (nominal, geometric, geometric+EFFECT)")  # fmt: skip
    stream = read_stream(Path(bags[0]), robot)
    return calibrate_stream(
        stream, robot, model, latency_s,
        max_points=STREAM_MAX_POINTS if max_points is None else max_points,
        max_gap_s=STREAM_MAX_GAP_S if max_gap_s is None else max_gap_s,
        ecc_order=ecc_order, log=log,
    )  # fmt: skip


def diagnose_recordings(
    recording: Recording,
    robot: RobotDescription,
    holdout: Recording | None = None,
    log: Log | None = None,
    tracker_sigma_m: float | None = None,
) -> tuple[Diagnosis, Ladder]:
    """The sim-to-real gap diagnosis of `recording`, scored on `holdout` (else k-fold);
    `tracker_sigma_m`: a stated 1-sigma per axis [m], the floor when the data give none.

    Returns
    -------
    diagnosis : Diagnosis
        The DIAGNOSIS.json document (as `robot_calib.diagnose.diagnosis.diagnose`).
    ladder : Ladder
        The rungs behind it, each with its calibration and held-out scores.
    """
    from robot_calib.diagnose.diagnosis import diagnose

    if holdout is not None:  # index the hold-out's targets as the calibration's
        holdout = holdout.with_targets(recording.target_names)
    return diagnose(recording, robot, holdout, log=log, tracker_sigma_m=tracker_sigma_m)


def diagnose_bags(
    bags: Sequence[str | Path],
    robot: RobotDescription,
    holdout: Sequence[str | Path] = (),
    pair_tolerance: float = PAIR_TOLERANCE_S,
    log: Log | None = None,
    tracker_sigma_m: float | None = None,
) -> tuple[Diagnosis, Ladder, Recording]:
    """The diagnosis of `bags` scored on the `holdout` bags (none: k-fold CV over poses);
    `tracker_sigma_m` as in `diagnose_recordings`.

    Returns
    -------
    diagnosis, ladder : Diagnosis, Ladder
        As `diagnose_recordings`.
    recording : Recording
        The paired measurements of `bags` (as `read_bags`); the hold-out's are not kept.
    """
    check_distinct_bags(bags, holdout)
    recording = read_bags(bags, robot, pair_tolerance, log)
    held = read_bags(holdout, robot, pair_tolerance, log) if holdout else None
    if held is not None:
        check_distinct_recordings(recording, held)
    diagnosis, ladder = diagnose_recordings(recording, robot, held, log, tracker_sigma_m)
    return diagnosis, ladder, recording


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
            f"-o {output}: names DIAGNOSIS.json, and its Markdown report goes beside it as "
            f"<name>.md; give e.g. -o {output.with_suffix('.json')}"
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
            f"-o {output}: names DIAGNOSIS.json, and its HTML report goes beside it as "
            f"<name>.html; give e.g. -o {output.with_suffix('.json')}"
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
) -> Path:
    """Write DIAGNOSIS.json at `output`, the Markdown report (+ plots) and the HTML report
    beside it, and (without `best`) the ladder's chosen rung as `best_params_path(output)`,
    all together
    (staged, then moved in; an existing file is replaced only with `force`).
    `calibrations`: nominal / cpa models already identified from `recording` (else the HTML
    report identifies them); `best`: the model the HTML report recommends and the PARAMS.json
    it goes to (default: the ladder's chosen rung and `best_params_path(output)`);
    `warnings`: the caller's own warnings, listed in the HTML report; `compared`: the
    before/after comparison if the caller has it (`compare_before_after`).

    Returns
    -------
    report : Path
        The Markdown report: `report_path(output)` (the HTML one: `html_report_path`).
    """
    from robot_calib.atomic import staged_outputs
    from robot_calib.diagnose.figures import FigureCache
    from robot_calib.diagnose.html_report import compare_models, html_report
    from robot_calib.diagnose.report import plot_paths, write_report
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
        figures = FigureCache()  # each figure drawn once for both reports
        write_report(diagnosis, ladder, fitted, stage / report.name, figures)
        if compared is None:
            compared = compare_models(ladder, calibrations)
        (stage / page.name).write_text(
            html_report(diagnosis, ladder, fitted, compared, recommended,
                        recommended_file.name, warnings, figures)
        )  # fmt: skip
        if best is None:  # run writes its own params_best.json: one best model per folder
            scores = {r.model: r.heldout.absolute_rms_mm for r in ladder.rungs}
            write_json_atomic(
                selected_document(marked_implausible(chosen.calibration, diagnosis), fitted,
                                  "the diagnosis ladder's chosen rung", diagnosis.scored_on,
                                  scores),
                stage / best_file.name,
            )  # fmt: skip
        written = {p.name for p in stage.iterdir()}
    if force:  # replaced whole: no figure of the old set that the new report does not have
        for stale in plot_paths(report.with_suffix("")):
            if stale.name not in written:
                stale.unlink(missing_ok=True)
    return report


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
) -> RunResult:
    """The main job: simulate + record a calibration bag (`plan`, `effects`; default the
    main job's joint-4 backlash) and `n_holdout` random hold-out poses in the same world,
    calibrate RUN_MODELS, score each on the hold-out poses, diagnose. Writes a new folder
    `run-<time>` under `output_dir`; `say` gets one line per step.

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
    if n_holdout < 1 or seed < 0:
        raise InputError(f"--holdout {n_holdout}, --seed {seed}: need >= 1 poses, seed >= 0")
    effects = MAIN_JOB_EFFECTS if effects is None else effects
    world = simulation_world(None, robot, effects, seed)
    if Path(output_dir).exists() and not Path(output_dir).is_dir():
        raise InputError(f"{output_dir}: exists and is not a folder")
    final = Path(output_dir) / time.strftime("run-%Y%m%d-%H%M%S")
    if final.exists():
        raise InputError(f"{final}: exists (a run started the same second); run again")
    final.parent.mkdir(parents=True, exist_ok=True)
    # built in a hidden folder beside it and renamed when complete: an interrupted or failed
    # run leaves nothing (msgs_doc: the overwrite and partial-output policy)
    folder = Path(tempfile.mkdtemp(prefix=".run-", suffix=".partial", dir=final.parent))
    try:
        result = _run_in(folder, final, description, plan, world, seed, n_holdout,
                         robot, say, log, progress)  # fmt: skip
        _name_final_paths(folder, final)
        os.rename(folder, final)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise

    def moved(path: Path) -> Path:
        return final / path.relative_to(folder)

    return replace(
        result,
        folder=final,
        calibration_bag=replace(result.calibration_bag, bag=moved(result.calibration_bag.bag),
                                world_file=moved(result.calibration_bag.world_file)),
        holdout_bag=replace(result.holdout_bag, bag=moved(result.holdout_bag.bag),
                            world_file=moved(result.holdout_bag.world_file)),
        report=moved(result.report),
        html=None if result.html is None else moved(result.html),
    )  # fmt: skip


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
    say: Callable[[str], None],
    log: Log | None,
    progress: Callable[[str, int, int], None] | None,
) -> RunResult:
    """`run`'s work, written into `folder` (renamed to `final` by `run` when complete;
    messages name the final paths)."""
    from robot_calib.accuracy import accuracy
    from robot_calib.identify.params_file import write_json_atomic

    bag, holdout = folder / "calibration.mcap", folder / "holdout.mcap"
    steps = 4
    say(f"[1/{steps}] simulate + record: {plan} in the default world -> {final / bag.name}")
    first = simulate(bag, plan, world, seed, n_holdout, progress)
    say(f"[2/{steps}] simulate + record: {n_holdout} random hold-out poses -> "
        f"{final / holdout.name}")  # fmt: skip
    truth = simulation_world(first.world_file, robot, (), seed + 1)
    second = simulate(holdout, "random", truth, seed + 1, n_holdout, progress)
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
    models = {}
    for name in names:
        cal = calibrate_recording(recording, description, name, log=log)
        write_json_atomic(cal.to_dict(recording), folder / f"params_{name}.json")
        models[name] = ModelScore(cal, accuracy(held.points, cal.predict(held.poses)))
    say(f"[4/{steps}] diagnose the sim-to-real gap (hold-out: {holdout.name})")
    diagnosis, ladder = diagnose_recordings(recording, description, held, log)
    best, warnings = _best_model(models, ladder)
    diagnosis = replace(diagnosis, warnings=[*diagnosis.warnings, *warnings])
    report = write_diagnosis(
        diagnosis, ladder, recording, folder / "diagnosis.json",
        calibrations={n: m.calibration for n, m in models.items()},
        best=(best, folder / "params_best.json"), warnings=warnings,
    )  # fmt: skip
    scores = {n: m.holdout.absolute_rms_mm for n, m in models.items()}
    scores.update({r.model: r.heldout.absolute_rms_mm for r in ladder.rungs})
    write_json_atomic(
        selected_document(marked_implausible(best, diagnosis), recording,
                          "the lowest held-out error of the run's models and "
                          "the diagnosis ladder's rungs", "hold-out bag", scores),
        folder / "params_best.json",
    )  # fmt: skip
    return RunResult(folder, first, second, recording, models, diagnosis, report, best.label,
                     tuple(warnings), html_report_path(folder / "diagnosis.json"))  # fmt: skip


def generalisation_warnings(scores: Sequence[tuple[str, float]]) -> list[str]:
    """A warning for every model of `scores` ((name, held-out abs rms [mm]), simplest first)
    that scores worse than the one before it: a richer model that generalises worse."""
    warnings = []
    for (simple, a), (rich, b) in zip(scores, scores[1:]):
        if b > a:
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
    from robot_calib.diagnose.html_report import compare_models

    compared = compare_models(ladder, calibrations)
    if ladder.holdout is None:  # nominal/cpa in-sample, the rungs k-fold: not comparable
        return compared, []
    return compared, generalisation_warnings(
        [(m.model, m.accuracy.absolute_rms_mm) for m in compared]
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
