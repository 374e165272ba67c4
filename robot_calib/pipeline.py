"""The flow as typed functions: simulate -> calibrate bags -> diagnose bags, and `run` (the
main job) on top. The CLI verbs, the calibrator node and scripts call these; each default
(robot, plan, pairing tolerance, models) is written once, here or where its idea lives.

Heavy modules (scipy, mcap, rclpy) are imported inside the function that needs them, so a
caller pays only for what it runs.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

from robot_calib.errors import InputError
from robot_calib.identify import DEFAULT_ECC_ORDER, DEFAULT_MODEL
from robot_calib.kinematics.description import RobotDescription
from robot_calib.measurements import PAIR_TOLERANCE_S

if TYPE_CHECKING:
    from robot_calib.accuracy import Accuracy
    from robot_calib.diagnose.diagnosis import Diagnosis
    from robot_calib.diagnose.ladder import Ladder
    from robot_calib.identify.calibrate import Calibration
    from robot_calib.measurements import Recording
    from robot_calib.sim.world import World

Log = Callable[[str], None]
Progress = Callable[[str, int, int], None]  # (plan, poses done, poses in all)

DEFAULT_ROBOT = "kr5_sixx_r650"  # the seed's robot
DEFAULT_PLAN = "paper-test3"  # `simulate` without --plan
RUN_PLAN = "paper-test2"  # the main job's calibration plan (seed Test 2)
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
    robot: str = DEFAULT_ROBOT,
    effects: Sequence[str] = (),
    seed: int | None = None,
) -> World:
    """The world of a world file (default: the built-in one; another robot without a file:
    its nominal geometry in the default set-up), with `effects` switched on (text form of
    `simulate --effects`, e.g. 'backlash:4', 'compliance:2=2e-5') and `seed` if given.

    Returns
    -------
    world : World
        The simulated truth: model (the robot with the effects), truth (every true
        parameter value, SI), noise, tracker options (latency, dropout), timing, seed.
    """
    from robot_calib.sim.world import build_world, load_world, parse_sim_effect, with_effect

    if world is None and robot != DEFAULT_ROBOT:
        out = build_world({"robot": robot, "geometry": "nominal"}, f"--robot {robot}")
    else:
        out = load_world(world)
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
) -> Simulation:
    """Run the simulated graph (sim_robot, sim_tracker, recorder, in-process) over `plan`
    in `world` (default: `simulation_world()`) and record the bag `output` (a new file in
    an existing folder) and its world file beside it. Nothing is left on failure.

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
    from robot_calib.nodes.simulate import simulate_bag
    from robot_calib.sim.plans import PLAN_NAMES
    from robot_calib.sim.world import save_world

    if plan not in PLAN_NAMES:
        raise InputError(f"--plan {plan}: unknown plan (known: {', '.join(PLAN_NAMES)})")
    bag = new_file_path(output, "the bag")
    world_file = new_file_path(bag.with_suffix(".world.yaml"), "the world file")
    world = world if world is not None else simulation_world(seed=seed)
    save_world(world, world_file)
    started = time.monotonic()
    try:
        counts = simulate_bag(
            bag, plan, world_file, -1 if seed is None else seed, n_random,
            None if progress is None else partial(progress, plan),
        )  # fmt: skip
    except BaseException:  # nothing written half-way: a partial simulation is no recording
        world_file.unlink(missing_ok=True)
        bag.unlink(missing_ok=True)
        raise
    labels = tuple(e.label for e in world.effects)
    return Simulation(bag, world_file, counts, labels, time.monotonic() - started)


def output_path(raw: str | Path, what: str, inputs: Sequence[str | Path] = ()) -> Path:
    """The path of a file to write: its folder must exist, it must not be a folder, and it
    must not be one of the command's `inputs` (an input is never overwritten); InputError
    naming the path otherwise.

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
    if path.exists() and any(path.resolve() == Path(p).resolve() for p in inputs):
        raise InputError(f"{path}: is an input of this command; will not overwrite it")
    return path


def new_file_path(raw: str | Path, what: str) -> Path:
    """The path of a recording to create: its folder must exist, the file must not (a
    recording is never overwritten; InputError otherwise).

    Returns
    -------
    path : Path
        `raw` as a Path.
    """
    path = Path(raw)
    if path.exists():
        raise InputError(f"{path}: exists, will not overwrite a recording")
    return output_path(path, what)


def read_bags(
    bags: Sequence[str | Path],
    robot: RobotDescription,
    pair_tolerance: float = PAIR_TOLERANCE_S,
    log: Log | None = None,
) -> Recording:
    """The paired measurements of `bags` (CONTRACT.md section 1).

    Returns
    -------
    recording : Recording
        As `robot_calib.bag.read.read_recording`: poses (n), points (n, 3) [m], sweeps,
        the bag of each pose, unpaired points and warnings.
    """
    from robot_calib.bag.read import read_recording

    return read_recording(bags, robot, pair_tolerance, log=log)


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

    return calibrate(recording, robot, model, ecc_order, log=log, objective=objective)


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


def diagnose_recordings(
    recording: Recording,
    robot: RobotDescription,
    holdout: Recording | None = None,
    log: Log | None = None,
) -> tuple[Diagnosis, Ladder]:
    """The sim-to-real gap diagnosis of `recording`, scored on `holdout` (else k-fold).

    Returns
    -------
    diagnosis : Diagnosis
        The DIAGNOSIS.json document (as `robot_calib.diagnose.diagnosis.diagnose`).
    ladder : Ladder
        The rungs behind it, each with its calibration and held-out scores.
    """
    from robot_calib.diagnose.diagnosis import diagnose

    return diagnose(recording, robot, holdout, log=log)


def diagnose_bags(
    bags: Sequence[str | Path],
    robot: RobotDescription,
    holdout: Sequence[str | Path] = (),
    pair_tolerance: float = PAIR_TOLERANCE_S,
    log: Log | None = None,
) -> tuple[Diagnosis, Ladder, Recording]:
    """The diagnosis of `bags` scored on the `holdout` bags (none: k-fold CV over poses).

    Returns
    -------
    diagnosis, ladder : Diagnosis, Ladder
        As `diagnose_recordings`.
    recording : Recording
        The paired measurements of `bags` (as `read_bags`); the hold-out's are not kept.
    """
    recording = read_bags(bags, robot, pair_tolerance, log)
    held = read_bags(holdout, robot, pair_tolerance, log) if holdout else None
    diagnosis, ladder = diagnose_recordings(recording, robot, held, log)
    return diagnosis, ladder, recording


def write_diagnosis(
    diagnosis: Diagnosis, ladder: Ladder, recording: Recording, output: str | Path
) -> Path:
    """Write DIAGNOSIS.json at `output` and the Markdown report (+ plots) beside it.

    Returns
    -------
    report : Path
        The report: `output` with the suffix '.md'.
    """
    from robot_calib.diagnose.report import write_report
    from robot_calib.identify.params_file import write_json_atomic

    output = Path(output)
    write_json_atomic(diagnosis.to_dict(), output)
    report = output.with_suffix(".md")
    write_report(diagnosis, ladder, recording, report)
    return report


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
    """
    from robot_calib.accuracy import accuracy
    from robot_calib.effects import MAIN_JOB_EFFECTS
    from robot_calib.identify.params_file import write_json_atomic
    from robot_calib.kinematics.description import load_robot
    from robot_calib.sim.plans import PLAN_NAMES

    description = load_robot(robot)  # every input checked before anything is written
    if plan not in PLAN_NAMES:
        raise InputError(f"--plan {plan}: unknown plan (known: {', '.join(PLAN_NAMES)})")
    if n_holdout < 1 or seed < 0:
        raise InputError(f"--holdout {n_holdout}, --seed {seed}: need >= 1 poses, seed >= 0")
    effects = MAIN_JOB_EFFECTS if effects is None else effects
    world = simulation_world(None, robot, effects, seed)
    if Path(output_dir).exists() and not Path(output_dir).is_dir():
        raise InputError(f"{output_dir}: exists and is not a folder")
    folder = Path(output_dir) / time.strftime("run-%Y%m%d-%H%M%S")
    folder.mkdir(parents=True, exist_ok=False)
    bag, holdout = folder / "calibration.mcap", folder / "holdout.mcap"
    steps = 4
    say(f"[1/{steps}] simulate + record: {plan} in the default world -> {bag}")
    first = simulate(bag, plan, world, seed, n_holdout, progress)
    say(f"[2/{steps}] simulate + record: {n_holdout} random hold-out poses -> {holdout}")
    truth = simulation_world(first.world_file, robot, (), seed + 1)
    second = simulate(holdout, "random", truth, seed + 1, n_holdout, progress)
    recording = read_bags([bag], description, log=log)
    held = read_bags([holdout], description, log=log)
    say(f"[3/{steps}] calibrate: {', '.join(RUN_MODELS)}")
    models = {}
    for name in RUN_MODELS:
        cal = calibrate_recording(recording, description, name, log=log)
        write_json_atomic(cal.to_dict(recording), folder / f"params_{name}.json")
        models[name] = ModelScore(cal, accuracy(held.points, cal.predict(held.poses)))
    say(f"[4/{steps}] diagnose the sim-to-real gap (hold-out: {holdout.name})")
    diagnosis, ladder = diagnose_recordings(recording, description, held, log)
    report = write_diagnosis(diagnosis, ladder, recording, folder / "diagnosis.json")
    return RunResult(folder, first, second, recording, models, diagnosis, report)
