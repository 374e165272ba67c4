"""`robot-calib` command line: parse, call the core, print, map errors to exit codes.

Every bad input ends in one line on stderr naming the file/value and exit status 2; a
calibration that ran to its end with a nonsense result (PARAMS.json `plausible: false`,
written for inspection) in "fitted, implausible: REASON" and exit status 3.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np

from robot_calib.errors import ImplausibleError, InputError, RobotCalibError
from robot_calib.identify import DEFAULT_ECC_ORDER, DEFAULT_MODEL
from robot_calib.kinematics.description import (
    RobotDescription,
    available_robots,
    with_joint_names,
    with_payload,
)
from robot_calib.kinematics.loader import load_robot
from robot_calib.measurements import PAIR_TOLERANCE_S
from robot_calib.pipeline import (
    DEFAULT_PLAN,
    DEFAULT_ROBOT,
    N_RANDOM_POSES,
    RUN_HOLDOUT_POSES,
    RUN_PLAN,
    output_path,
)

if TYPE_CHECKING:
    from robot_calib.bag.csv_import import OrientationColumns, SigmaColumns
    from robot_calib.diagnose.diagnosis import Diagnosis
    from robot_calib.identify.correction_structured import LearnedCorrection
    from robot_calib.kinematics.parameters import ParameterVector
    from robot_calib.model import KinematicModel


def _robot_table(robot: RobotDescription) -> str:
    """The nominal DH/Hayati table in mm and deg (human units, labelled)."""
    lines = [
        f"{robot.name}: nominal DH/Hayati table ({robot.source})",
        "joint  theta[deg]    d[mm]    a[mm]  alpha[deg]  beta[deg]  limits[deg]",
    ]
    for j in range(robot.n_joints):
        beta = f"{np.degrees(robot.beta[j]):9.3f}" if robot.hayati[j] else "        -"
        lo, hi = np.degrees(robot.limits[j])
        lines.append(
            f"{robot.joint_names[j]:>8} {np.degrees(robot.theta[j]):8.3f} "
            f"{robot.d[j] * 1e3:8.2f} {robot.a[j] * 1e3:8.2f} {np.degrees(robot.alpha[j]):10.3f}"
            f"  {beta}  [{lo:.0f}, {hi:.0f}]"
        )
    return "\n".join(lines)


def _robot(args: argparse.Namespace, name: str | None = None) -> RobotDescription:
    """--robot (or `name`) loaded, its joints renamed by --joint-names where given."""
    robot = load_robot(args.robot if name is None else name)
    if getattr(args, "payload", None) is not None:
        robot = with_payload(robot, *_payload(args.payload))
    return robot if args.joint_names is None else with_joint_names(robot, args.joint_names)


def _payload(text: str) -> tuple[float, tuple[float, float, float]]:
    """--payload KG[:X,Y,Z] -> (mass [kg], centre of mass in the flange frame [m])."""
    mass, _, centre = text.partition(":")
    try:
        values = [float(v) for v in centre.split(",")] if centre else [0.0, 0.0, 0.0]
        kg = float(mass)
    except ValueError:
        raise InputError(
            f"--payload {text}: expected KG or KG:X,Y,Z (kg; m, flange frame)"
        ) from None
    if len(values) != 3:
        raise InputError(f"--payload {text}: the centre of mass takes three values X,Y,Z [m]")
    if not (math.isfinite(kg) and 0 <= kg <= MAX_PAYLOAD_KG) or not all(
        math.isfinite(v) and abs(v) <= MAX_PAYLOAD_COM_M for v in values
    ):
        raise InputError(
            f"--payload {text}: a mass 0 to {MAX_PAYLOAD_KG:g} kg and a centre of mass within "
            f"+-{MAX_PAYLOAD_COM_M:g} m of the flange (msgs_doc/units.md)"
        )
    return kg, (values[0], values[1], values[2])


def _print_diagnosis(diagnosis: Diagnosis, output: Path, report: Path, seconds: float) -> None:
    """The diagnosis for people: the ladder (mm), the floor, the verdict, what remains,
    the measurements left out as tracker blunders."""
    from robot_calib.diagnose.diagnosis import percent
    from robot_calib.identify.params_file import outlier_lines

    print(f"{'model':<40}{'held-out mean/max [mm]':>24}{'abs rms [mm]':>14}")
    for rung in diagnosis.ladder:
        print(f"{rung.model:<40}{rung.holdout_mean_mm:>11.4f} / {rung.holdout_max_mm:<9.4f}"
              f"{rung.holdout_abs_rms_mm:>14.4f}")  # fmt: skip
    floor = diagnosis.noise.floor_abs_rms_mm
    unknown = "unknown (no repeat poses, circle sweeps or stated accuracy; --tracker-accuracy)"
    known = f"{floor:.4f} mm ({diagnosis.noise.source})" if floor is not None else ""
    print(f"noise floor (abs rms): {known or ('unknown' if diagnosis.noise.warning else unknown)}")
    if diagnosis.noise.warning:  # a stated accuracy the evidence contradicts (issue 24)
        print(diagnosis.noise.warning)
    geometric = diagnosis.unexplained.geometric_ratio_to_noise_floor
    if geometric is not None:
        print(f"geometric held-out: {geometric:.2f} x the noise floor")
    if diagnosis.learnable is not None:
        print(diagnosis.learnable.line())
        note = diagnosis.bound_note()
        if note is not None:
            print(note)
        shares = [f"{effect} {percent(share)}" for effect, share in diagnosis.effect_shares()]
        if shares:
            print("share of the learnable gap each effect closed: " + ", ".join(shares))
    for figures in diagnosis.iso9283:
        print(figures.line())
    print(f"dominant effect: {diagnosis.verdict}")
    if diagnosis.outside_vocabulary is not None:
        print(diagnosis.outside_vocabulary.line())
    for spectrum in diagnosis.unexplained.where.harmonic_orders:  # what the model leaves
        if spectrum.dominant_orders:
            print(f"joint-angle harmonics left by {diagnosis.physical_model}: "
                  f"{spectrum.line()}")  # fmt: skip
    print(f"unexplained: {diagnosis.unexplained.note}")
    for line in outlier_lines(diagnosis.outliers):
        print(line)
    print(f"{output}, {report} in {seconds:.1f} s")
    from robot_calib.pipeline import html_report_path

    print(f"HTML report (self-contained, open in a browser): {html_report_path(output)}")


def cmd_run(args: argparse.Namespace) -> int:
    """The main job on built-in defaults: simulate + record a calibration bag and a hold-out
    bag, calibrate the models of the ladder, score them on the hold-out poses, diagnose.
    Every run writes a new folder under --output."""
    from robot_calib import pipeline
    from robot_calib.identify.calibration import summary
    from robot_calib.sim.plans import check_plan

    robot = load_robot(args.robot)
    check_plan(args.plan, robot)  # a bad plan: its error before any output
    _run_folder(Path(args.output))
    print(_robot_table(robot))
    started = time.perf_counter()
    result = pipeline.run(
        args.output, args.robot, args.plan, args.effects, args.seed, args.holdout,
        say=print, log=_log, progress=_progress(),
    )  # fmt: skip
    geometric = result.models["geometric"].calibration
    print(summary(geometric, result.recording))
    print("accuracy (seed criterion: pairwise distance errors; absolute: tracker frame)")
    print(f"{'model':<12}{'in-sample mean/max [mm]':>26}{'hold-out mean/max [mm]':>26}"
          f"{'hold-out abs mean [mm]':>25}")  # fmt: skip
    for name, score in result.models.items():
        fit, test = score.calibration.accuracy, score.holdout
        print(
            f"{name:<12}{fit.pairwise_mean_mm:>15.4f} / {fit.pairwise_max_mm:<8.4f}"
            f"{test.pairwise_mean_mm:>15.4f} / {test.pairwise_max_mm:<8.4f}"
            f"{test.absolute_mean_mm:>17.4f}"
        )
    for warning in result.warnings:
        print(warning)
    seconds = time.perf_counter() - started
    _print_diagnosis(result.diagnosis, result.folder / "diagnosis.json", result.report, seconds)
    print(f"best model (lowest held-out error): {result.best} -> "
          f"{result.folder / 'params_best.json'}")  # fmt: skip
    print(f"done: {result.folder} (report: {result.report})")
    return 0


def _run_folder(folder: Path) -> None:
    """`run -o FOLDER` checked before any work, nothing created (the run creates it when it
    writes, so a bad argument found later leaves no empty folder): InputError (exit 2, one
    line) when a part of it is a file, or the deepest part that exists cannot be written
    (read-only, permissions)."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"{folder}: {existing} exists and is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        what = "folder not writable" if existing == folder else f"{existing} not writable"
        raise InputError(f"{folder}: {what}; cannot write a run there")


def _progress() -> Callable[[str, int, int], None]:
    """A progress printer for simulations: 'plan: k/N poses' at most once a second."""
    last = [0.0]

    def progress(plan: str, done: int, total: int) -> None:
        if time.monotonic() - last[0] > 1.0 or done == total:
            last[0] = time.monotonic()
            print(f"  {plan}: {done}/{total} poses", file=sys.stderr)

    return progress


def cmd_simulate(args: argparse.Namespace) -> int:
    """Simulate a plan in a world and record the bag (+ the world's truth beside it)."""
    from robot_calib import pipeline

    world = pipeline.simulation_world(args.world, args.robot, args.effects or (), args.seed)
    plan = args.plan
    if args.stream:
        from robot_calib.sim.stream import StreamOptions

        options = StreamOptions(args.joint_rate, args.point_rate, args.sim_latency)
        plan = "random" if plan == DEFAULT_PLAN else plan
        sim = pipeline.simulate_stream(
            args.output, plan, world, args.seed, args.n_random, options, args.force
        )
    else:
        sim = pipeline.simulate(
            args.output, args.plan, world, args.seed, args.n_random, _progress(), args.force
        )
    print(
        f"{sim.bag}: {', '.join(f'{t}={n}' for t, n in sim.counts.items())} messages "
        f"({plan}{', stream' if args.stream else ''}, effects: "
        f"{', '.join(sim.effects) or 'none'}) in {sim.seconds:.1f} s; "
        f"truth in {sim.world_file}"
    )
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    """Plan N measurement poses for a model (D-optimal), print what they promise against
    random poses at equal N, write PLAN.yaml."""
    from robot_calib import pipeline
    from robot_calib.atomic import write_text_atomic
    from robot_calib.plan.campaign import campaign_yaml, plan_campaign
    from robot_calib.plan.evaluate import human

    noise = args.noise_mm
    if noise is not None and not (math.isfinite(noise) and 0 < noise < 10):
        raise InputError(f"--noise-mm {noise}: a 1-sigma per coordinate in mm, > 0 and < 10")
    floor = args.floor_z
    if math.isnan(floor) or (math.isfinite(floor) and abs(floor) > MAX_FLOOR_Z_M):
        raise InputError(
            f"--floor-z {floor:g}: a height in m of the robot base frame within "
            f"+-{MAX_FLOOR_Z_M:g} m (or -inf: no floor); mm given as m? ({floor:g} mm = "
            f"{floor * 1e-3:g} m)"
        )
    world = pipeline.simulation_world(args.world, args.robot, (), args.seed)
    output = output_path(args.output, "PLAN.yaml", pipeline.simulation_inputs(world), args.force)
    if output.suffix.lower() not in (".yaml", ".yml"):  # after the input check: never an input
        raise InputError(f"{output}: a plan is written as YAML: give a .yaml or .yml name")
    c = plan_campaign(world, args.model, args.poses, args.candidates, args.seed, args.floor_z,
                      None if noise is None else noise * 1e-3, args.ecc_order, args.trials,
                      args.holdout, _log)  # fmt: skip
    planned, rand = c.planned.prediction, c.random.prediction
    print(f"{args.model} on {world.model.robot.name}: {args.poses} poses of "
          f"{len(c.problem.candidates)} candidates in {c.design_seconds:.2f} s; noise "
          f"{planned.noise_m * 1e3:.4f} mm per coordinate; predicted 1-sigma:")  # fmt: skip
    print(f"{'parameter':<22}{'planned':>34}{'random (same N)':>34}")
    for k, name in enumerate(planned.names):
        unit = planned.units[k]
        print(f"{name:<22}{human(float(planned.std[k]), unit):>34}"
              f"{human(float(rand.std[k]), unit):>34}")  # fmt: skip
    for name, reason in c.problem.fixed:
        print(f"{name:<22} fixed: {reason}")
    for label, fig in (("planned", c.planned), ("random", c.random)):
        pred = fig.prediction
        held = "not simulated" if fig.holdout is None else (
            f"{fig.holdout.abs_rms_mm:.4f} mm abs rms, seed criterion mean "
            f"{fig.holdout.pairwise_mean_mm:.4f} mm, model error (vs the true points) "
            f"{fig.holdout.model_rms_mm:.4f} mm rms ({fig.holdout.trials} random true "
            f"robot(s), {fig.holdout.n_poses} held-out poses)")  # fmt: skip
        print(f"{label}: worst {pred.line(pred.worst)}; held-out {held}; campaign "
              f"{fig.hours * 60:.1f} min")  # fmt: skip
    ratio = rand.rms_m.max() / planned.rms_m.max()
    print(f"worst predicted 1-sigma: {ratio:.2f} x smaller than random poses at equal N")
    write_text_atomic(output, campaign_yaml(c, args.floor_z))
    print(f"{output}: {args.poses} poses (msgs_doc/plan.md)")
    return 0


def _log(message: str) -> None:
    print(message, file=sys.stderr)


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Identify a model from bags; write PARAMS.json; print a summary in mm/deg."""
    from robot_calib import pipeline
    from robot_calib.identify.calibration import summary
    from robot_calib.identify.params_file import write_json_atomic

    robot = _robot(args)
    output = pipeline.output_path(args.output, "PARAMS.json", args.bags, args.force)
    _check_model_terms(args.model, robot, args.ecc_order)
    started = time.perf_counter()
    if args.stream:
        if args.objective != "absolute":
            raise InputError("--stream: only --objective absolute")
        fit = pipeline.calibrate_stream_bag(
            args.bags, robot, args.model, args.ecc_order,
            None if args.latency == "auto" else float(args.latency),
            args.stream_max_points, args.max_gap, _log,
        )  # fmt: skip
        cal, recording = fit.calibration, fit.recording
        print(fit.line())
        print(summary(cal, recording))
        write_json_atomic(fit.document(), output)
    else:
        if args.latency != "auto":
            raise InputError("--latency applies with --stream only")
        cal, recording = pipeline.calibrate_bags(
            args.bags, robot, args.model, args.ecc_order, args.objective, args.pair_tolerance,
            _log,
        )  # fmt: skip
        print(summary(cal, recording))
        write_json_atomic(cal.to_dict(recording), output)
    print(f"{output}: {cal.name} in {time.perf_counter() - started:.2f} s")
    if not cal.plausible:  # written for inspection; predict, compensate, export refuse it
        raise ImplausibleError(f"{'; '.join(cal.implausible)} ({output}: plausible false)")
    return 0


def _check_model_terms(spec: str, robot: RobotDescription, ecc_order: int) -> None:
    """Before any fit: InputError naming --model and the terms when two terms give the same
    parameters (`joint_harmonics:2:orders=11,27+joint_harmonics:2:orders=11`), and a log
    line for each joint_harmonics term that leaves its defaults to be guessed (no
    `orders=`: order 2 alone; no joints: every joint; msgs_doc/effects.md)."""
    from robot_calib.identify.calibrate import parse_model

    _, effects = parse_model(spec, robot, ecc_order)
    terms = spec.split("+")[1:]
    owner: dict[str, str] = {}
    for text, effect in zip(terms, effects):
        for name in effect.parameter_names(robot):
            if name in owner:
                raise InputError(f"--model {spec}: terms {owner[name]!r} and {text!r} both "
                                 f"give parameter {name}: give each joint (and order) "
                                 "once")  # fmt: skip
            owner[name] = text
        if effect.name != "joint_harmonics":
            continue
        options = text.split(":")[1:]
        guessed = [what for what, given in (
            ("the default order 2 alone", any(o.startswith("orders=") for o in options)),
            ("every joint", any(not o.startswith("orders=") for o in options)),
        ) if not given]  # fmt: skip
        if guessed:
            _log(f"--model: {text} is {effect.spec} ({' and '.join(guessed)}: "
                 "msgs_doc/effects.md)")  # fmt: skip


def cmd_diagnose(args: argparse.Namespace) -> int:
    """The sim-to-real gap diagnosis -> DIAGNOSIS.json + a Markdown report with plots + a
    self-contained HTML report."""
    from robot_calib import pipeline

    robot = _robot(args)
    inputs = [*args.bags, *(args.holdout or ())]
    output = pipeline.output_path(args.output, "DIAGNOSIS.json", inputs, args.force)
    pipeline.output_path(pipeline.report_path(output), "the report", inputs, args.force)
    pipeline.output_path(pipeline.html_report_path(output), "the HTML report", inputs, args.force)
    best = pipeline.output_path(pipeline.best_params_path(output), "the best model's PARAMS.json",
                                inputs, args.force)  # fmt: skip
    started = time.perf_counter()
    accuracy = args.tracker_accuracy
    if accuracy is not None and not (math.isfinite(accuracy) and 1e-4 <= accuracy < 10):
        raise InputError(f"--tracker-accuracy {accuracy}: a 1-sigma in mm, 0.0001 (0.1 um) "
                         "to 10")  # fmt: skip
    diagnosis, ladder, recording = pipeline.diagnose_bags(
        args.bags, robot, args.holdout or (), args.pair_tolerance, _log,
        None if accuracy is None else accuracy * 1e-3,
    )  # fmt: skip
    compared, warnings = pipeline.compare_before_after(ladder)
    diagnosis = dataclasses.replace(diagnosis, warnings=[*diagnosis.warnings, *warnings])
    report = pipeline.write_diagnosis(diagnosis, ladder, recording, output, args.force,
                                      warnings=warnings, compared=compared)  # fmt: skip
    _print_diagnosis(diagnosis, output, report, time.perf_counter() - started)
    for warning in warnings:
        print(warning)
    print(f"best model (the ladder's chosen rung): {diagnosis.ladder[-1].model} -> {best}")
    if diagnosis.implausible:  # written (to be read), but no exit 0 with nonsense
        raise ImplausibleError(f"{'; '.join(diagnosis.implausible)} ({output}: implausible, "
                               "written to be read)")  # fmt: skip
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    """Measurement CSV(s) -> a contract bag (rows in order, bad rows reported by line)."""
    from robot_calib.bag.csv_import import (
        PRESETS,
        CsvFormat,
        check_no_copies,
        counted,
        joined_times,
        read_measurement_csv,
        target_label,
        with_overrides,
        write_measurement_bag,
    )

    preset = PRESETS.get(args.preset or "")
    robot_name = args.robot  # else the preset's robot, else the default robot
    if robot_name is None:
        robot_name = preset.robot if preset is not None and preset.robot else DEFAULT_ROBOT
    robot = _robot(args, robot_name)
    output = output_path(args.output, "the bag", args.csv, args.force)
    if args.preset:
        if args.preset not in PRESETS:
            raise InputError(f"--preset {args.preset}: known presets: {', '.join(PRESETS)}")
        fmt = PRESETS[args.preset]
    else:
        if not args.joints or not args.point:
            raise InputError("give --preset, or --joints and --point (column names or indices)")
        fmt = CsvFormat(joints=tuple(args.joints.split(",")), point=tuple(args.point.split(",")))
    split = lambda text: None if text is None else tuple(text.split(","))  # noqa: E731
    fmt = with_overrides(
        fmt,
        joints=split(args.joints),
        point=split(args.point),
        dif=split(args.dif),
        dif_sign=args.dif_sign,
        time=args.time,
        temperature=args.temperature,
        separator=args.sep,
        decimal_comma=True if args.decimal_comma else None,
        angle_unit=args.angle_unit,
        length_unit=args.length_unit,
        header=False if args.no_header else None,
        targets=_target_columns(args.target) if args.target else None,
        orientations=_orientation_columns(args.orientation, args.orientation_rpy),
        sigmas=_sigma_columns(args.sigma),
        orientation_unit=args.orientation_unit,
        sigma_unit=args.sigma_unit,
        sigma_angle_unit=args.sigma_angle_unit,
    )
    if len(fmt.point) != 3 or (fmt.dif is not None and len(fmt.dif) != 3):
        raise InputError("--point and --dif take three columns: x,y,z")
    tables = []
    check_no_copies(args.csv, [])  # a CSV given twice, before any is read
    for csv_path in args.csv:
        table = read_measurement_csv(csv_path, fmt, robot.limits)
        for warning in table.warnings:
            _log(warning)
        for line, why in table.bad_rows:
            _log(f"warning: {csv_path}:{line}: {why}: row skipped")
        print(f"{csv_path}: {counted(len(table.q), 'row')} imported, "
              f"{counted(len(table.bad_rows), 'bad row')} skipped")  # fmt: skip
        for name, (rotation, sigma) in table.six_dof.items():
            print(f"  {target_label(name)}: {np.isfinite(rotation).all(axis=(1, 2)).sum()} "
                  f"orientations, {np.isfinite(sigma).any(axis=1).sum()} rows with stated "
                  "standard deviations")  # fmt: skip
        tables.append(table)
    check_no_copies(args.csv, tables)
    q = np.concatenate([t.q for t in tables])
    points = np.concatenate([t.points for t in tables])
    times = joined_times([t.time for t in tables])  # absolute Unix times kept as they are
    temperature = None
    if all(t.temperature is not None for t in tables):
        temperature = np.concatenate([t.temperature for t in tables if t.temperature is not None])
    extra = {
        name: np.concatenate([t.extra_points[name] for t in tables]) for name, _ in fmt.targets
    }
    for name, xyz in extra.items():
        if not np.isfinite(xyz).all(axis=1).any():
            _log(f"warning: {', '.join(args.csv)}: target {name} has no measured point: no "
                 "topic written for it")  # fmt: skip
    six_dof = {
        name: (np.concatenate([t.six_dof[name][0] for t in tables]),
               np.concatenate([t.six_dof[name][1] for t in tables]))
        for name in tables[0].six_dof
    }  # fmt: skip
    for o in fmt.orientations:
        if not np.isfinite(six_dof[o.target][0]).any():
            _log(f"warning: {', '.join(args.csv)}: {o.option}: every cell is empty: "
                 f"{target_label(o.target)} has no orientation")  # fmt: skip
    counts = write_measurement_bag(
        output, q, points, robot.joint_names, times, args.force, temperature=temperature,
        extra_points=extra, six_dof=six_dof,
    )  # fmt: skip
    print(f"{output}: {', '.join(f'{k}={v}' for k, v in counts.items())} messages "
          f"({robot.name}, {fmt.angle_unit}/{fmt.length_unit} -> rad/m)")  # fmt: skip
    return 0


def _target_columns(specs: list[str]) -> tuple[tuple[str, tuple[str, str, str]], ...]:
    """--target NAME:X,Y,Z (repeated) -> ((NAME, (X, Y, Z)), ...); InputError on a bad one."""
    from robot_calib.poses import TARGET_NAME

    out: list[tuple[str, tuple[str, str, str]]] = []
    for spec in specs:
        name, _, columns = spec.partition(":")
        cols = tuple(columns.split(","))
        if not TARGET_NAME.fullmatch(name) or len(cols) != 3 or not all(cols):
            raise InputError(
                f"--target {spec}: expected NAME:X,Y,Z (NAME letters, digits, underscores, "
                "starting with a letter; three columns)"
            )
        if name in (n for n, _ in out):
            raise InputError(f"--target {spec}: target {name} given twice")
        out.append((name, (cols[0], cols[1], cols[2])))
    return tuple(out)


def _named_columns(option: str, spec: str, n_columns: tuple[int, ...]) -> tuple[str, list[str]]:
    """'[NAME:]C,C,...' of `option` -> (NAME or '' for the first target, the columns);
    InputError unless the columns are non-empty and their number is one of `n_columns`."""
    name, colon, columns = spec.partition(":")
    if not colon:
        name, columns = "", spec
    cols = columns.split(",")
    if (colon and not name) or len(cols) not in n_columns or not all(cols):
        counts = " or ".join(map(str, n_columns))
        raise InputError(f"{option} {spec}: expected [NAME:] and {counts} columns, comma-"
                         "separated (without NAME: the first target)")  # fmt: skip
    return name, cols


def _orientation_columns(
    quaternions: list[str] | None, rpys: list[str] | None
) -> tuple[OrientationColumns, ...] | None:
    """--orientation [NAME:]QX,QY,QZ,QW and --orientation-rpy [NAME:]R,P,Y (each repeated)
    -> the format's orientation columns (None when neither is given)."""
    from robot_calib.bag.csv_import import OrientationColumns

    if not quaternions and not rpys:
        return None
    out = []
    for kind, option, specs, n in (("quaternion", "--orientation", quaternions, 4),
                                   ("rpy", "--orientation-rpy", rpys, 3)):  # fmt: skip
        for spec in specs or ():
            name, cols = _named_columns(option, spec, (n,))
            out.append(OrientationColumns(name, kind, tuple(cols)))
    return tuple(out)


def _sigma_columns(specs: list[str] | None) -> tuple[SigmaColumns, ...] | None:
    """--sigma [NAME:]SP[,SR] (repeated) -> the format's standard deviation columns."""
    from robot_calib.bag.csv_import import SigmaColumns

    if not specs:
        return None
    out = []
    for spec in specs:
        name, cols = _named_columns("--sigma", spec, (1, 2))
        out.append(SigmaColumns(name, cols[0], cols[1] if len(cols) == 2 else None))
    return tuple(out)


def _calibration(
    args: argparse.Namespace,
) -> tuple[KinematicModel, ParameterVector, dict[str, Any]]:
    """The model, parameters and document of args.params (PARAMS.json), checked (finite SI
    values) and for the robot --robot names, if it names one (its default is None: the
    calibration's robot, so that an explicit --robot of the default robot is checked too)."""
    from robot_calib.identify.params_file import load_params

    model, params, doc = load_params(args.params)  # checked: finite SI values, robot unchanged
    if args.robot is not None and load_robot(args.robot).name != model.robot.name:
        raise InputError(
            f"{args.params}: identified for robot {model.robot.name}, not --robot {args.robot}"
        )
    return model, params, doc


def _plausible_or_forced(
    doc: Mapping[str, Any] | tuple[str, ...], args: argparse.Namespace
) -> None:
    """Exit 2 naming args.params and its reasons when it is marked `plausible: false`
    (`doc`: the PARAMS.json document, or its reasons), unless --force: then a warning."""
    from robot_calib.identify.params_file import check_plausible, implausible_of

    reasons = doc if isinstance(doc, tuple) else implausible_of(doc, args.params)
    warning = check_plausible(reasons, args.params, args.force)
    if warning is not None:
        _log(warning)


def _correction(
    doc: Mapping[str, Any], model: KinematicModel, params: ParameterVector,
    args: argparse.Namespace,
) -> LearnedCorrection | None:  # fmt: skip
    """The learned correction of args.params (PARAMS.json `correction`, the hybrid model,
    fitted at the file's `params`), None when it has none."""
    from robot_calib.identify.params_file import correction_of

    return correction_of(doc, model, params, args.params)


def cmd_predict(args: argparse.Namespace) -> int:
    """Target positions (tracker frame, m) for the joint angles of JOINTS.csv."""
    from robot_calib.messages import target_topic
    from robot_calib.predict import read_joints_csv, write_points_csv

    model, params, doc = _calibration(args)
    _plausible_or_forced(doc, args)
    correction = _correction(doc, model, params, args)
    args.target = model.targets[0] if args.target is None else args.target
    if args.target not in model.targets:
        known = ", ".join(repr(t) for t in model.targets)
        raise InputError(f"{args.params}: no target {args.target!r} (its targets: {known})")
    poses = read_joints_csv(args.joints, model.robot.n_joints, model.robot.limits)
    index = np.full(len(poses), model.targets.index(args.target))
    poses = dataclasses.replace(poses, target=index)
    output = output_path(args.output, "POINTS.csv", [args.params, args.joints], args.force)
    quaternions = None
    if args.target in model.oriented:  # a 6-DoF probe: its frame too (msgs_doc/six_dof.md)
        from scipy.spatial.transform import Rotation

        frames = model.probe_orientations(params, poses)
        quaternions = Rotation.from_matrix(frames).as_quat()
    points = model.target_points(params, poses)
    if correction is not None:  # the hybrid model: minus the learned residual
        points = points - correction.predict(poses)
    write_points_csv(points, output, quaternions)
    which = "" if len(model.targets) == 1 else f", target {target_topic(args.target)}"
    frames_too = "" if quaternions is None else " with the probe frame as qx,qy,qz,qw"
    learned = "" if correction is None else "; the learned correction applied"
    print(f"{output}: {len(poses)} points (m, laser_tracker frame{which}){frames_too}{learned}")
    return 0


def cmd_compensate(args: argparse.Namespace) -> int:
    """Nominal joint commands, or targets, -> compensated commands (msgs_doc/compensate.md)."""
    from robot_calib.compensate import compensate_commands, compensate_targets
    from robot_calib.compensate.solve import nominal_counterpart, within_limits
    from robot_calib.compensate.targets import check_reach, goals_in_base, read_targets_csv
    from robot_calib.compensate.write import LARGE_CHANGE_DEG, row_status, write_compensated_csv
    from robot_calib.predict import read_joints_csv

    model, params, doc = _calibration(args)
    _plausible_or_forced(doc, args)
    correction = _correction(doc, model, params, args)
    n_joints, limits = model.robot.n_joints, model.robot.limits
    source = args.joints or args.targets
    inputs = [args.params, source] + ([args.seed_joints] if args.seed_joints else [])
    nominal, nominal_params = nominal_counterpart(model, params)
    if args.joints:
        for option in ("seed_joints", "frame", "unit"):
            if getattr(args, option) is not None:
                raise InputError(f"--{option.replace('_', '-')} goes with --targets, not --joints")
        poses = read_joints_csv(args.joints, n_joints, limits)
        output = output_path(args.output, "JOINTS.csv", inputs, args.force)
        result = compensate_commands(model, params, nominal, nominal_params, poses, correction)
        # a command or its correction beyond the limits: `beyond_limits` (the one check)
        inside = within_limits(model.robot, result.q) & within_limits(model.robot, poses.q)
        status = row_status(result, poses.q, inside)
        write_compensated_csv(output, result, poses.direction, status)
        change = np.degrees(np.abs(result.q - poses.q)).max()
        what = f"compensated commands (rad); largest change {change:.4f} deg"
    else:
        targets = read_targets_csv(args.targets, n_joints, limits, args.unit or "m")
        if args.seed_joints:
            if targets.seed is not None:
                raise InputError(f"{args.targets}: has seed columns q1..q{n_joints}; give "
                                 "them or --seed-joints, not both")  # fmt: skip
            seeds = read_joints_csv(args.seed_joints, n_joints, limits).q
            if len(seeds) != len(targets):
                raise InputError(f"{args.seed_joints}: {len(seeds)} seed rows for "
                                 f"{len(targets)} targets in {args.targets}")  # fmt: skip
            targets = dataclasses.replace(targets, seed=seeds)
        goals = goals_in_base(targets, args.frame or "base", model, params)
        check_reach(goals, model, args.targets)
        output = output_path(args.output, "JOINTS.csv", inputs, args.force)
        found = compensate_targets(model, params, nominal, nominal_params, targets, goals,
                                   correction)  # fmt: skip
        result = found.compensated
        status = row_status(result, found.nominal.q, found.within_limits)
        write_compensated_csv(output, result, found.direction, status)
        kind = "poses" if targets.rotation is not None else "positions"
        seeded = "seed readings" if targets.seed is not None else "the home pose"
        frame = args.frame or "base"
        what = f"commands (rad) for target {kind} ({frame} frame; nominal IK from {seeded})"
    flags = np.array(status)
    n, reached = len(result.q), int(np.isin(flags, ("ok", "large_change", "position_only")).sum())
    print(f"{output}: {n} {what}; model error max {result.error_m.max() * 1e3:.6f} mm / "
          f"{result.error_rad.max() * 1e6:.3f} urad, {int(result.iterations.max())} iterations "
          f"at most; {reached}/{n} reached"
          + ("; the learned correction applied" if correction is not None else ""))  # fmt: skip
    for flag, text in (
        ("not_reached", "not reached by the calibrated model (near a singularity or out of "
                        "reach; their q are nan)"),
        ("beyond_limits", "reached only beyond the joint limits"),
        ("large_change", f"moved by more than {LARGE_CHANGE_DEG:g} deg (near a singularity?): "
                         "check them before sending"),
        ("position_only", f"near a singularity (the exact pose would swing a joint by more "
                          f"than {LARGE_CHANGE_DEG:g} deg): solved for the tool position alone, "
                          "orientation off by their error_urad"),
    ):  # fmt: skip
        if (flags == flag).any():
            print(f"warning: {source}: {int((flags == flag).sum())} row(s) {text}: "
                  f"{_data_rows(flags == flag)[0]} (column status)", file=sys.stderr)  # fmt: skip
    if n and not reached:  # written for inspection, but no exit 0 when nothing is usable
        raise NothingReached(f"{source}: none of its {n} rows reached by the calibration "
                             f"{args.params} ({output} written, every row flagged in column "
                             "status): a calibration far from the robot, or targets out of "
                             "its reach?")  # fmt: skip
    return 0


class NothingReached(RobotCalibError):
    """`compensate` ran to its end but reached no row (msgs_doc/compensate.md): exit 3, the
    output written for inspection."""

    exit_status = 3
    kind = "nothing reached"


def _data_rows(*masks: np.ndarray) -> list[str]:
    """'rows 1, 5, ...' (data rows, 1 = the first after the header) of each boolean mask,
    at most 10 named."""
    out = []
    for mask in masks:
        rows = [str(k + 1) for k in np.flatnonzero(mask)]
        more = f" and {len(rows) - 10} more" if len(rows) > 10 else ""
        out.append(f"data rows {', '.join(rows[:10])}{more}")
    return out


def cmd_split(args: argparse.Namespace) -> int:
    """One bag -> a calibration bag and a hold-out bag (random share, or the last share),
    both in one folder, written together (a failure leaves neither)."""
    from robot_calib import pipeline
    from robot_calib.atomic import staged_outputs
    from robot_calib.bag.csv_import import START_NS, write_measurements
    from robot_calib.bag.read import other_topics
    from robot_calib.measurements.split import holdout_mask

    robot = _robot(args)
    source = Path(args.bag)
    stem = source.with_suffix("")
    outputs = [Path(args.calibration_out or f"{stem}.cal.mcap"),
               Path(args.holdout_out or f"{stem}.holdout.mcap")]  # fmt: skip
    for out in outputs:
        output_path(out, "the split bag", [source], args.force)
    if outputs[0].resolve() == outputs[1].resolve():
        raise InputError(f"{outputs[1]}: --calibration-out and --holdout-out name one file")
    if outputs[0].resolve().parent != outputs[1].resolve().parent:
        raise InputError(f"{outputs[1]}: write both bags into one folder (they are written "
                         "together)")  # fmt: skip
    recording = pipeline.read_bags([args.bag], robot, args.pair_tolerance, _log)
    first, points = recording.points_by_target()  # per pose: every target measured there
    poses = recording.subset(np.isin(np.arange(len(recording)), first))
    held = holdout_mask(poses, args.holdout, args.by, args.seed)
    n = len(recording)
    rotation = recording.by_target(
        np.full((n, 3, 3), np.nan) if recording.poses.rotation is None
        else recording.poses.rotation
    )[1]  # fmt: skip
    sigma = recording.by_target(
        np.full((n, 2), np.nan) if recording.poses.sigma is None else recording.poses.sigma
    )[1]
    stamps = (poses.stamp_ns if poses.stamp_ns is not None
              else START_NS + np.round(poses.poses.time * 1e9).astype(np.int64))  # fmt: skip
    temperature = poses.poses.temperature  # the side topic at each pose (as read_bag reads it)
    others = other_topics(source)
    if others:
        _log(f"warning: {source}: topics {others} are not measurements: not copied")
    with staged_outputs(outputs[0].resolve().parent, args.force) as stage:
        counts = [
            write_measurements(
                stage / out.name,
                poses.poses.q[rows],
                points[0][rows],
                robot.joint_names,
                stamps[rows],
                poses.poses.direction[rows],
                extra_points={
                    name: points[k][rows] for k, name in enumerate(recording.target_names) if k
                },
                six_dof={
                    name: (rotation[k][rows], sigma[k][rows])
                    for k, name in enumerate(recording.target_names)
                },
                temperature=None if temperature is None else temperature[rows],
            )  # fmt: skip
            for out, rows in zip(outputs, (~held, held))
        ]
    for out, role, count in zip(outputs, ("calibration", "hold-out"), counts):
        print(f"{out}: {count[next(iter(count))]} poses ({role}, split {args.by}; the "
              "original stamps and approach directions)")  # fmt: skip
    return 0


def cmd_score(args: argparse.Namespace) -> int:
    """A calibration scored on bags it was not fitted on (absolute and seed criterion)."""
    from robot_calib import pipeline
    from robot_calib.identify.params_file import implausible_of, in_sample_accuracy
    from robot_calib.score import score, write_points_table

    model, params, doc = _calibration(args)
    reasons = implausible_of(doc, args.params, model, params)
    if reasons:  # scored all the same: that is inspecting it
        _log(f"warning: {args.params}: fitted, implausible ({'; '.join(reasons)}); scored to "
             "inspect it")  # fmt: skip
    in_sample = in_sample_accuracy(doc, args.params)
    fitted = doc.get("recordings", [])
    if not isinstance(fitted, list) or not all(isinstance(f, str) for f in fitted):
        raise InputError(f"{args.params}: 'recordings' must be a list of bag paths")
    robot = model.robot
    if args.joint_names is not None:
        robot = with_joint_names(robot, args.joint_names)
    table = None
    if args.points_csv:
        table = output_path(args.points_csv, "the per-point table",
                            [args.params, *args.bags], args.force)  # fmt: skip
    recording = pipeline.read_bags(args.bags, robot, args.pair_tolerance, _log)
    correction = _correction(doc, model, params, args)
    judged_by = "the calibration's in-sample rms"
    if correction is not None:  # the model applied: physical + learned correction
        hybrid = in_sample_accuracy(doc, args.params, "hybrid_residuals")
        if hybrid is not None:
            in_sample, judged_by = hybrid, "the hybrid model's in-sample rms"
        else:
            judged_by = ("the physical model's in-sample rms (the file has no "
                         "hybrid_residuals: written before them)")  # fmt: skip
    result = score(model, params, recording, in_sample, fitted, correction, judged_by)
    for warning in result.warnings:  # also in stdout and the per-point table
        _log(warning)
    for line in result.lines(", ".join(args.bags)):
        print(line)
    if correction is not None:
        print(f"the learned correction applied ({correction.line()})")
    if table is not None:
        write_points_table(result, recording, table)
        print(f"{table}: {len(recording)} points (bag, index, x/y/z, dx/dy/dz, error in m)")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    """A calibration (PARAMS.json) in a format robots and their software read."""
    from robot_calib.atomic import write_text_atomic
    from robot_calib.export import FORMATS
    from robot_calib.export.base import correction_lines
    from robot_calib.identify.calibration import load_calibration

    cal = load_calibration(args.params)
    _plausible_or_forced(cal.implausible, args)
    robot = cal.model.robot
    if args.robot is not None and load_robot(args.robot).name != robot.name:
        raise InputError(
            f"{args.params}: identified for robot {robot.name}, not --robot {args.robot}"
        )
    exporter = FORMATS[args.format]
    inputs = [args.params] + ([args.nominal_urdf] if args.nominal_urdf else [])
    output = output_path(args.output, f"the {args.format} export", inputs, args.force)
    if args.nominal_urdf is not None:
        from robot_calib.export.urdf_nominal import render_on_nominal

        if args.format != "urdf":
            raise InputError(f"--nominal-urdf is for --format urdf, not {args.format}")
        text = render_on_nominal(cal, str(args.params), args.nominal_urdf)
    else:
        text = exporter.render(cal, str(args.params))
    write_text_atomic(output, text)
    effects = len(cal.model.effects) if args.format in ("urdf", "ur") else 0
    left = f"; {effects} effect(s) it cannot hold, listed in its header" if effects else ""
    print(f"{output}: {exporter.description}, robot {robot.name}, model {cal.name}{left}")
    for line in correction_lines(cal):  # also in the file's header where it has one
        _log(f"warning: {output}: {line}")
    return 0


def cmd_repair(args: argparse.Namespace) -> int:
    """Copy every complete message of a crashed (or intact) bag into a new, indexed bag."""
    from robot_calib.bag.repair import repair_bag

    print(repair_bag(Path(args.bag), Path(args.output), args.force).summary())
    return 0


class _OneLineParser(argparse.ArgumentParser):
    """Usage errors as one line and exit status 2 (the contract's rule for bad input)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _at_least(low: int) -> Callable[[str], int]:
    """An argparse type: an integer >= `low` (else a one-line usage error, exit 2)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"{value} < {low}")
        return value

    return parse


_count, _positive = _at_least(0), _at_least(1)


MAX_TOLERANCE_S = 10.0  # --pair-tolerance, --max-gap: beyond, any two messages pair
MAX_LATENCY_S = 1.0  # --latency: a clock offset above 1 s is no latency
MAX_RATE_HZ = 100_000.0  # --joint-rate, --point-rate: no tracker or controller streams faster
MAX_PAYLOAD_KG, MAX_PAYLOAD_COM_M = 2500.0, 2.0  # --payload: the largest robots' ratings


def _tolerance(text: str) -> float:
    """An argparse type: a finite number 0..MAX_TOLERANCE_S [s] (else a one-line usage
    error, exit 2)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and 0 <= value <= MAX_TOLERANCE_S):
        raise argparse.ArgumentTypeError(
            f"{text} s: need a finite number >= 0 and <= {MAX_TOLERANCE_S:g}"
        )
    return value


def _signed_seconds(text: str) -> float:
    """An argparse type: a latency [s] within +-MAX_LATENCY_S."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not (math.isfinite(value) and abs(value) <= MAX_LATENCY_S):
        raise argparse.ArgumentTypeError(f"{text} s: need a number within +-{MAX_LATENCY_S:g} s")
    return value


def _separator(text: str) -> str:
    """An argparse type: a CSV field separator, one character; 'tab' or '\\t' for a tab."""
    if text in ("tab", "\\t"):
        return "\t"
    if len(text) != 1:
        raise argparse.ArgumentTypeError(f"{text!r}: one character (tab: a tab)")
    return text


OVERWRITE_POLICY = (
    "Files: an existing output is never overwritten unless --force (then it is replaced "
    "whole: written under a temporary name and renamed); an input is never overwritten, "
    "even with --force; a failed or interrupted command leaves nothing behind."
)


def _add_force(p: argparse.ArgumentParser, implausible: bool = False) -> None:
    """--force; `implausible`: it also lets a PARAMS.json marked plausible false be used."""
    also = (
        "; use a PARAMS.json marked plausible: false (a fit `calibrate` ended with exit 3)"
        if implausible
        else ""
    )
    p.add_argument(
        "--force",
        action="store_true",
        help=f"replace existing outputs (never an input of the command){also}",
    )


def _add_pair_tolerance(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--pair-tolerance",
        type=_tolerance,
        default=PAIR_TOLERANCE_S,
        help=f"point/joint-state pairing [s] (default {PAIR_TOLERANCE_S})",
    )


def _rate(text: str) -> float:
    """An argparse type: a finite rate > 0 [Hz]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and 0 < value <= MAX_RATE_HZ):
        raise argparse.ArgumentTypeError(f"{text} Hz: need a number > 0 and <= {MAX_RATE_HZ:g}")
    return value


def _latency(text: str) -> str:
    """An argparse type: 'auto' or a finite number of seconds (else a usage error)."""
    if text == "auto":
        return text
    try:
        _signed_seconds(text)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"'auto' or {exc}") from None
    return text


def _add_stream(p: argparse.ArgumentParser) -> None:
    from robot_calib.measurements.stream import STREAM_MAX_GAP_S, STREAM_MAX_POINTS

    p.add_argument(
        "--stream",
        action="store_true",
        help="continuous tracking (msgs_doc/stream.md): one bag of points streamed while the "
        "robot moves; joint readings interpolated (cubic spline) to each point's stamp + latency "
        "instead of the nearest-stamp pairing (default: off, the contract's pairing)",
    )
    p.add_argument(
        "--latency",
        type=_latency,
        default="auto",
        metavar="auto|SECONDS",
        help="with --stream: the controller's stamps minus the tracker's for one instant [s], "
        "or auto: identified (default auto)",
    )
    p.add_argument(
        "--stream-max-points",
        type=_positive,
        default=STREAM_MAX_POINTS,
        metavar="N",
        help=f"with --stream: fit every k-th point, k chosen so that at most N remain "
        f"(default {STREAM_MAX_POINTS})",
    )
    p.add_argument(
        "--max-gap",
        type=_tolerance,
        default=STREAM_MAX_GAP_S,
        metavar="SECONDS",
        help="with --stream: points between two joint states further apart than this are "
        f"dropped and counted [s] (default {STREAM_MAX_GAP_S})",
    )


def _add_payload(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--payload",
        metavar="KG[:X,Y,Z]",
        help="a payload on the flange during the measurements: mass [kg] and centre of mass "
        "in the flange frame [m] (default: none), e.g. 3:0,0,0.08; gravity compliance then "
        "includes it; PARAMS.json keeps it",
    )


MAX_FLOOR_Z_M = 10.0  # plan --floor-z: no robot reaches a floor 10 m from its base (mm as m?)
MAX_CANDIDATES = 100_000  # plan --candidates: ~1.5 GB of Jacobian rows for geometric


def _bounded_count(most: int) -> Callable[[str], int]:
    """An argparse type: an integer in 1..most."""

    def parse(text: str) -> int:
        value = _positive(text)
        if value > most:
            raise argparse.ArgumentTypeError(f"{value} > {most} (the most this accepts)")
        return value

    return parse


def _add_joint_names(
    p: argparse.ArgumentParser, what: str = "the bags' JointState names of joints 1..J"
) -> None:
    p.add_argument(
        "--joint-names",
        metavar="NAME1,...,NAMEJ",
        help=f"{what}, in joint order, where they are not the robot's own "
        "(e.g. j1,j2,j3,j4,j5,j6; default: the robot's names)",
    )


# predict and score: the robot is PARAMS.json's; --robot, when given, must name it
CALIBRATION_ROBOT = "PARAMS.json's robot; when given, it must be that robot"


class _RequiredHelpFormatter(argparse.HelpFormatter):
    """Every required option says so in --help (the others state their default)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if action.required and action.option_strings and "required" not in text:
            text += " (required)"
        return text


def build_parser() -> argparse.ArgumentParser:
    parser = _OneLineParser(
        prog="robot-calib",
        description="Calibrate 6-axis robots from laser-tracker measurements and diagnose "
        "why the real robot still differs from the model. Start with `robot-calib run`; "
        "units on disk are SI (m, rad), reports add mm/deg. Bad input: one line, exit 2.",
        epilog=OVERWRITE_POLICY,
    )
    from robot_calib import __version__

    parser.add_argument("--version", action="version", version=f"robot-calib {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    def add(
        name: str, func: Callable[[argparse.Namespace], int], help_: str, robot: str | None = None
    ) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help_, description=help_, epilog=OVERWRITE_POLICY,
                           formatter_class=_RequiredHelpFormatter)  # fmt: skip
        p.add_argument(
            "--robot",
            default=DEFAULT_ROBOT if robot is None else None,
            help=f"built-in robot name ({', '.join(available_robots())}), robot YAML file "
            f"or URDF file (.urdf) (default {robot or DEFAULT_ROBOT})",
        )
        p.add_argument(
            "--base-link", help="URDF robots: the chain's base link (default: the root link)"
        )
        p.add_argument(
            "--tip-link",
            help="URDF robots: the chain's tip link, the flange (default: tool0, else flange, "
            "else the end of the longest chain)",
        )
        p.set_defaults(func=func)
        return p

    sim = add(
        "simulate",
        cmd_simulate,
        "simulate a measurement plan and record an MCAP bag",
        robot=f"the world's; {DEFAULT_ROBOT} in the built-in world",
    )
    sim.add_argument(
        "--plan",
        default=DEFAULT_PLAN,
        help=f"paper-test1..6 (seed Table 2), random, iso9283, or a PLAN.yaml file "
        f"(robot-calib plan) (default {DEFAULT_PLAN})",
    )
    sim.add_argument("--world", help="world YAML file (default: the built-in default world)")
    sim.add_argument(
        "--effects",
        nargs="*",
        metavar="EFFECT",
        help="effects to switch on, e.g. backlash:4 eccentricity:1,2 "
        "thermal_drift compliance:2=2e-5 (default magnitudes unless =VALUE)",
    )
    sim.add_argument(
        "--seed", type=_count, help="random seed of noise and plan (>= 0; default: the world's)"
    )
    sim.add_argument(
        "--n-random",
        type=_positive,
        default=N_RANDOM_POSES,
        help=f"poses of the random plan (default {N_RANDOM_POSES})",
    )
    sim.add_argument(
        "--stream",
        action="store_true",
        help="continuous tracking (msgs_doc/stream.md): move smoothly through the plan's poses "
        "(default plan then: random) while joint states and points stream at their rates, "
        "no ROS graph (default: off, stop-and-go through the simulated graph)",
    )
    for flag, what, default in (("--joint-rate", "joint states", 200.0),
                                ("--point-rate", "tracker points", 1000.0)):  # fmt: skip
        sim.add_argument(
            flag, type=_rate, default=default,
            help=f"with --stream: {what} per second [Hz] (default {default:g})",
        )  # fmt: skip
    sim.add_argument(
        "--latency", dest="sim_latency", type=_signed_seconds, default=0.002, metavar="SECONDS",
        help="with --stream: the controller's stamps minus the tracker's for one instant [s] "
        "(default 0.002)",
    )  # fmt: skip
    sim.add_argument(
        "-o", "--output", required=True, help="bag to write (BAG.mcap; + BAG.world.yaml)"
    )
    _add_force(sim)

    pla = add("plan", cmd_plan, "choose measurement poses for a model (D-optimal) -> PLAN.yaml",
              robot=f"the world's; {DEFAULT_ROBOT} in the built-in world")  # fmt: skip
    pla.add_argument(
        "--model",
        default=DEFAULT_MODEL,
        help=f"geometric[+EFFECT[:joints]...] to plan for (default {DEFAULT_MODEL})",
    )
    pla.add_argument("--poses", type=_positive, required=True, help="N: poses to plan")
    pla.add_argument(
        "--candidates",
        type=_bounded_count(MAX_CANDIDATES),
        default=2000,
        help=f"M: random candidate poses to choose from (default 2000, at most {MAX_CANDIDATES})",
    )
    pla.add_argument(
        "--floor-z",
        type=float,
        default=0.0,
        metavar="M",
        help="flange and target stay at or above z = M [m] of the robot base frame "
        f"(default 0.0: the base's mounting plane; -inf: no floor; within +-{MAX_FLOOR_Z_M:g})",
    )
    pla.add_argument(
        "--noise-mm",
        type=float,
        metavar="MM",
        help="tracker noise, 1-sigma per coordinate [mm] (default: the world's "
        "tracker, target and repeatability noise)",
    )
    pla.add_argument(
        "--world",
        help="world YAML file: robot, tracker pose, target, noise "
        "(default: the built-in default world)",
    )
    pla.add_argument(
        "--seed",
        type=_count,
        default=0,
        help="random seed of candidates and simulations (default 0)",
    )
    pla.add_argument(
        "--trials",
        type=_count,
        default=1,
        help="simulated calibrations (random true robots) per plan for the "
        "held-out error (default 1; 0: none)",
    )
    pla.add_argument(
        "--holdout",
        type=_positive,
        default=200,
        help="random held-out poses per simulated calibration (default 200)",
    )
    pla.add_argument(
        "--ecc-order",
        type=_positive,
        default=DEFAULT_ECC_ORDER,
        help=f"eccentricity Fourier order (default {DEFAULT_ECC_ORDER})",
    )
    pla.add_argument("-o", "--output", required=True, help="PLAN.yaml to write")
    _add_force(pla)

    cal = add("calibrate", cmd_calibrate, "identify a model from bags -> PARAMS.json")
    cal.add_argument("bags", nargs="+", metavar="BAG", help="calibration bag(s) (.mcap)")
    cal.add_argument(
        "--model",
        default=DEFAULT_MODEL,
        help="nominal | cpa | geometric | geometric+eccentricity | geometric+EFFECT[:joints]"
        " (default geometric)",
    )
    cal.add_argument(
        "--ecc-order",
        type=_positive,
        default=DEFAULT_ECC_ORDER,
        help=f"eccentricity Fourier order (default {DEFAULT_ECC_ORDER})",
    )
    cal.add_argument(
        "--objective",
        default="absolute",
        choices=("absolute", "seed"),
        help="absolute tracker-frame residuals (O(N), default) or the seed's pairwise "
        "distances anchored on the CPA centres of circles 1, 3, 5 (O(N^2))",
    )
    _add_pair_tolerance(cal)
    _add_stream(cal)
    _add_joint_names(cal)
    _add_payload(cal)
    cal.add_argument("-o", "--output", required=True, help="PARAMS.json to write")
    _add_force(cal)

    diag = add("diagnose", cmd_diagnose, "sim-to-real gap diagnosis -> DIAGNOSIS.json + report")
    diag.add_argument("bags", nargs="+", metavar="BAG", help="calibration bag(s) (.mcap)")
    diag.add_argument(
        "--holdout", nargs="*", metavar="BAG",
        help="hold-out bag(s): scored only (default: none; the calibration bags' k-fold)",
    )  # fmt: skip
    _add_pair_tolerance(diag)
    _add_joint_names(diag)
    _add_payload(diag)
    diag.add_argument(
        "--tracker-accuracy",
        type=float,
        metavar="MM",
        help="the tracker's stated 1-sigma per axis of a point [mm], e.g. 0.005: the noise floor "
        "when the data have no repeat poses or circle sweeps (default: none; then the floor "
        "is unknown and said so)",
    )
    diag.add_argument(
        "-o",
        "--output",
        required=True,
        help="DIAGNOSIS.json to write; the reports go beside it as <name>.md (+ "
        "<name>_*.png) and <name>.html (self-contained), so -o may not end in .md or .html",
    )
    _add_force(diag)

    imp = add("import", cmd_import, "measurement CSV(s) -> a bag of the contract",
              robot=f"{DEFAULT_ROBOT}; with --preset, the preset's robot")  # fmt: skip
    imp.add_argument("csv", nargs="+", metavar="CSV", help="CSV file(s), rows in visiting order")
    imp.add_argument(
        "--preset",
        help="a known export format: ur5_jacobi2025 (its columns, units and robot; options "
        "given override them) (default: none; then --joints and --point)",
    )
    imp.add_argument(
        "--joints",
        help="joint columns, names or 0-based indices: q1,q2,... (default: the preset's)",
    )
    imp.add_argument("--point", help="measured point columns x,y,z (default: the preset's)")
    imp.add_argument(
        "--dif",
        help="difference columns dx,dy,dz: point = point + sign * dif (default: none, or the "
        "preset's)",
    )
    imp.add_argument(
        "--dif-sign", type=float, choices=(-1.0, 1.0),
        help="sign of --dif (+1/-1) (default +1; ur5_jacobi2025: -1)",
    )  # fmt: skip
    imp.add_argument("--time", help="time column [s] (default: none; poses 1 s apart)")
    imp.add_argument(
        "--target", action="append", metavar="NAME:X,Y,Z",
        help="a further target (SMR) measured at each pose: its name and x,y,z columns, onto "
        "/laser_tracker/NAME/point (repeat per target; an empty cell: not measured there) "
        "(default: none)",
    )  # fmt: skip
    imp.add_argument(
        "--temperature",
        help="a temperature column [deg C]: written to /temperature (sensor_msgs/Temperature) "
        "(default: none)",
    )
    imp.add_argument(
        "--orientation", action="append", metavar="[NAME:]QX,QY,QZ,QW",
        help="a 6-DoF probe's orientation as unit quaternion columns in x, y, z, w order, onto "
        "/laser_tracker/(NAME/)pose; without NAME the first target, else the --target NAME "
        "(repeat per target; empty cells: orientation not measured at that pose) (default: none)",
    )  # fmt: skip
    imp.add_argument(
        "--orientation-rpy", action="append", metavar="[NAME:]R,P,Y",
        help="as --orientation, as roll, pitch, yaw columns: R = Rz(yaw) Ry(pitch) Rx(roll), "
        "in --orientation-unit (default: none)",
    )  # fmt: skip
    imp.add_argument(
        "--orientation-unit", choices=("deg", "rad"),
        help="unit of --orientation-rpy columns (default: --angle-unit)",
    )  # fmt: skip
    imp.add_argument(
        "--sigma", action="append", metavar="[NAME:]SP[,SR]",
        help="the tracker's stated standard deviations: position column (per coordinate, "
        "--sigma-unit) and optionally orientation column (per axis, --sigma-angle-unit) of "
        "the first target, or of target NAME (repeat per target; an empty cell: not stated) "
        "(default: none)",
    )  # fmt: skip
    imp.add_argument(
        "--sigma-unit", choices=("mm", "m", "um"),
        help="unit of the position standard deviations (default: --length-unit)",
    )  # fmt: skip
    imp.add_argument(
        "--sigma-angle-unit", choices=("deg", "rad", "mdeg", "urad"),
        help="unit of the orientation standard deviations (default: --orientation-unit, "
        "else --angle-unit)",
    )  # fmt: skip
    imp.add_argument(
        "--sep", type=_separator,
        help="field separator, one character; tab: a tab (default ',')",
    )  # fmt: skip
    imp.add_argument(
        "--decimal-comma", action="store_true",
        help="numbers written 1,5 (default: off, numbers written 1.5)",
    )  # fmt: skip
    imp.add_argument(
        "--angle-unit", choices=("deg", "rad"),
        help="joint angle unit (default rad; ur5_jacobi2025: deg)",
    )  # fmt: skip
    imp.add_argument(
        "--length-unit", choices=("mm", "m"),
        help="unit of the point, --dif and --target columns (default m; ur5_jacobi2025: mm)",
    )  # fmt: skip
    imp.add_argument(
        "--no-header", action="store_true",
        help="the CSV has no header row (default: the first row is the header)",
    )  # fmt: skip
    _add_joint_names(imp, "JointState names to write for joints 1..J")
    imp.add_argument("-o", "--output", required=True, help="bag to write (BAG.mcap)")
    _add_force(imp)

    pred = add("predict", cmd_predict, "target positions for joint angles (JOINTS.csv)",
               robot=CALIBRATION_ROBOT)  # fmt: skip
    pred.add_argument("params", metavar="PARAMS.json")
    pred.add_argument(
        "--joints", required=True,
        help="JOINTS.csv, header q1..qJ [rad]: the readings of the robot's J joints, in rad "
        "(optional columns t [s] and dir1..dirJ: approach directions +1/-1); a reading beyond "
        "any reading of its joint in rad (degrees?) is refused",
    )  # fmt: skip
    pred.add_argument("-o", "--output", required=True, help="POINTS.csv to write (x,y,z m)")
    pred.add_argument(
        "--target", metavar="NAME",
        help="which target of a several-target calibration (msgs_doc/targets.md; default: "
        "the first, /laser_tracker/point)",
    )  # fmt: skip
    _add_force(pred, implausible=True)

    comp = add("compensate", cmd_compensate, "nominal joint commands (JOINTS.csv) or targets "
               "(TARGETS.csv) -> compensated commands", robot=CALIBRATION_ROBOT)  # fmt: skip
    comp.add_argument("params", metavar="PARAMS.json")
    given = comp.add_mutually_exclusive_group(required=True)
    given.add_argument(
        "--joints",
        help="JOINTS.csv of the nominal program, header q1..qJ [rad] (optional t [s], "
        "dir1..dirJ approach directions, temp_c): where the nominal model puts the tool is "
        "where the compensated commands make the calibrated robot go (this or --targets is "
        "required)",
    )  # fmt: skip
    given.add_argument(
        "--targets",
        help="TARGETS.csv: header x,y,z (the tool point, --unit), optional qx,qy,qz,qw (the "
        "tool frame's orientation; without: positions only), optional q1..qJ [rad] seeds, t "
        "[s], dir1..dirJ, temp_c (msgs_doc/compensate.md; this or --joints is required)",
    )  # fmt: skip
    comp.add_argument(
        "--frame", choices=("base", "tracker"),
        help="with --targets: the frame of the targets, the robot base or the laser tracker "
        "(through the calibration's base2tracker) (default base)",
    )  # fmt: skip
    comp.add_argument(
        "--unit", choices=("m", "mm"),
        help="with --targets: unit of x,y,z (default m)",
    )  # fmt: skip
    comp.add_argument(
        "--seed-joints", metavar="JOINTS.csv",
        help="with --targets: readings q1..qJ [rad], one row per target, where the nominal "
        "inverse kinematics starts (default: seed columns of TARGETS.csv, else the home pose)",
    )  # fmt: skip
    comp.add_argument(
        "-o", "--output", required=True,
        help="JOINTS.csv to write: q1..qJ [rad] compensated, dir1..dirJ (the approach "
        "directions assumed), error_mm and error_urad (the calibrated model's remaining "
        "error), iterations",
    )  # fmt: skip
    _add_force(comp, implausible=True)

    spl = add("split", cmd_split, "one bag -> a calibration bag and a hold-out bag")
    spl.add_argument("bag", metavar="BAG", help="the bag to split (.mcap)")
    _add_joint_names(spl)
    spl.add_argument("--holdout", type=float, default=0.3, help="share held out (0.3)")
    spl.add_argument(
        "--by",
        default="random",
        choices=("random", "order", "time"),
        help="random share (default), or the last share in order or time",
    )
    spl.add_argument("--seed", type=_count, default=0, help="seed of the random split (0)")
    spl.add_argument("--calibration-out", help="calibration bag (default BAG.cal.mcap)")
    spl.add_argument("--holdout-out", help="hold-out bag (default BAG.holdout.mcap)")
    _add_pair_tolerance(spl)
    _add_force(spl)

    sco = add("score", cmd_score, "score a calibration on bags it was not fitted on",
              robot=CALIBRATION_ROBOT)  # fmt: skip
    sco.add_argument("params", metavar="PARAMS.json")
    sco.add_argument("bags", nargs="+", metavar="BAG", help="bag(s) to score on (.mcap)")
    sco.add_argument(
        "--points-csv", help="also write a per-point table (CSV, m; default: not written)"
    )
    _add_joint_names(sco)
    _add_pair_tolerance(sco)
    _add_force(sco)

    from robot_calib.export import FORMATS

    exp = add("export", cmd_export, "a calibration as a URDF, DH table, UR calibration or JSON",
              robot=CALIBRATION_ROBOT)  # fmt: skip
    exp.add_argument("params", metavar="PARAMS.json")
    exp.add_argument(
        "--format", required=True, choices=sorted(FORMATS),
        help="; ".join(f"{k}: {v.description}" for k, v in sorted(FORMATS.items()))
        + " (msgs_doc/export.md; no default)",
    )  # fmt: skip
    exp.add_argument("-o", "--output", required=True, help="file to write (e.g. robot.urdf)")
    exp.add_argument(
        "--nominal-urdf", metavar="NOMINAL.urdf",
        help="--format urdf: write the calibrated joint origins into this nominal URDF of the "
        "robot, keeping its link names, limits, meshes and other tags (default: a bare chain)",
    )  # fmt: skip
    _add_force(exp, implausible=True)

    rep = add("repair", cmd_repair, "recover the messages of a crashed recording -> a new bag")
    rep.add_argument("bag", metavar="BAG", help="bag whose writer was killed (.mcap)")
    rep.add_argument("-o", "--output", required=True, help="new bag to write (FIXED.mcap)")
    rep.add_argument("--force", action="store_true", help="replace an existing output")

    run = add("run", cmd_run, "the main job on built-in defaults")
    run.add_argument(
        "-o",
        "--output",
        default="out",
        help="output folder (default out/); every run writes a new run-<time> folder in it",
    )
    run.add_argument(
        "--plan", default=RUN_PLAN, help=f"calibration plan, as for simulate (default {RUN_PLAN})"
    )
    run.add_argument(
        "--effects",
        nargs="*",
        help="effects of the simulated robot, as for simulate (default: joint-4 backlash)",
    )
    run.add_argument("--seed", type=_count, default=0, help="random seed (>= 0; default 0)")
    run.add_argument(
        "--holdout",
        type=_positive,
        default=RUN_HOLDOUT_POSES,
        help=f"random hold-out poses ({RUN_HOLDOUT_POSES})",
    )
    return parser


_SIGNALLED: list[int] = []  # signals received (SIGINT, SIGTERM, SIGHUP) while a verb runs


def _interrupt(signum: int, _frame: object) -> NoReturn:
    """Ctrl-C, SIGTERM and SIGHUP (the terminal closed): unwind (staged outputs are
    removed), 'interrupted', exit 130."""
    _SIGNALLED.append(signum)
    raise KeyboardInterrupt


def _ignore_interrupt_in_callback(unraisable: Any) -> None:
    """A KeyboardInterrupt raised by `_interrupt` inside a callback Python cannot raise from
    (a weakref or __del__: 'Exception ignored in ... WeakSet') is not printed: the signal
    is recorded and `main` exits 130 after all (was: the program went on to exit 0)."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt) and _SIGNALLED:
        return
    sys.__unraisablehook__(unraisable)


def main(argv: Sequence[str] | None = None) -> int:
    from robot_calib import _interrupted_while_starting

    args = build_parser().parse_args(argv)
    signal.signal(signal.SIGTERM, _interrupt)
    if signal.getsignal(signal.SIGHUP) is signal.SIG_DFL:  # not under nohup (ignored)
        signal.signal(signal.SIGHUP, _interrupt)
    if signal.getsignal(signal.SIGINT) in (  # not when ignored
        signal.default_int_handler,
        _interrupted_while_starting,  # robot_calib/__init__.py's, while the modules loaded
    ):
        signal.signal(signal.SIGINT, _interrupt)
    sys.unraisablehook = _ignore_interrupt_in_callback
    try:
        if args.base_link or args.tip_link:  # carried in the robot reference (PARAMS.json)
            from robot_calib.kinematics.urdf import urdf_reference

            args.robot = urdf_reference(args.robot or "", args.base_link, args.tip_link)
        status = int(args.func(args))
        if _SIGNALLED:  # the interrupt fell in a callback that swallowed it
            raise KeyboardInterrupt
        return status
    except BaseException as exc:
        # A signal can surface as another exception when it lands in a C extension's call
        # back into Python (e.g. an rclpy callback): it is still an interruption.
        if isinstance(exc, KeyboardInterrupt) or _SIGNALLED:
            print(f"robot-calib {args.command}: interrupted", file=sys.stderr)
            return 130
        if isinstance(exc, RobotCalibError):
            print(f"robot-calib {args.command}: {exc.kind}: {exc}", file=sys.stderr)
            return exc.exit_status
        raise


if __name__ == "__main__":
    sys.exit(main())
