"""`robot-calib run`: the main job on built-in defaults (flows/run.py): simulate + record a
calibration bag and a hold-out bag, calibrate the models of the ladder, score them on the
hold-out poses, diagnose; every run writes a new folder under --output."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from robot_calib.cli.common import header_fields, log, print_diagnosis, progress
from robot_calib.cli.options import add_report_header, count, positive
from robot_calib.errors import ImplausibleError, InputError
from robot_calib.flows import RUN_HOLDOUT_POSES, RUN_PLAN
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.loader import load_robot

NAME = "run"
HELP = "the main job on built-in defaults"
# what it writes: a new folder each time, never an existing one (no --force to replace)
FILES = (
    "Files: each run writes a new folder run-<date>-<time> under --output (-o) and never "
    "replaces one; a failed or interrupted run leaves nothing behind."
)
ROBOT = None  # --robot's default: DEFAULT_ROBOT


def add_arguments(run: argparse.ArgumentParser) -> None:
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
    run.add_argument("--seed", type=count, default=0, help="random seed (>= 0; default 0)")
    run.add_argument(
        "--holdout",
        type=positive,
        default=RUN_HOLDOUT_POSES,
        help=f"random hold-out poses ({RUN_HOLDOUT_POSES})",
    )
    add_report_header(run)


def main(args: argparse.Namespace) -> int:
    """The main job on built-in defaults: simulate + record a calibration bag and a hold-out
    bag, calibrate the models of the ladder, score them on the hold-out poses, diagnose.
    Every run writes a new folder under --output."""
    from robot_calib.flows.run import run
    from robot_calib.forked import FORKED
    from robot_calib.identify.calibration import summary
    from robot_calib.nodes.simulate import simulate_bag
    from robot_calib.parallel import using
    from robot_calib.sim.plans import check_plan

    robot = load_robot(args.robot)
    check_plan(args.plan, robot)  # a bad plan: its error before any output
    check_run_folder(Path(args.output))
    if args.pdf:
        from robot_calib.diagnosis.pdf import browser

        browser()  # no Chromium: said before any work
    print(robot_table(robot))
    started = time.perf_counter()
    with using(FORKED):  # the diagnosis's independent work on the other core
        result = run(
            args.output,
            args.robot,
            args.plan,
            args.effects,
            args.seed,
            args.holdout,
            say=print,
            log=log,
            progress=progress(),
            record=simulate_bag,  # the simulated graph in-process
            header=header_fields(args),
            pdf=args.pdf,
        )
    geometric = result.models["geometric"].calibration
    text = summary(geometric, result.recording)
    for source in result.recording.sources:  # read while staged: named where it now lies
        text = text.replace(str(Path(source).parent), str(result.folder))
    print(text)
    print("accuracy (seed criterion: pairwise distance errors; absolute: tracker frame)")
    print(
        f"{'model':<12}{'in-sample mean/max [mm]':>26}{'hold-out mean/max [mm]':>26}"
        f"{'hold-out abs mean [mm]':>25}"
    )
    for name, score in result.models.items():
        fit, test = score.calibration.accuracy, score.holdout
        print(
            f"{name:<12}{fit.pairwise_mean_mm:>15.4f} / {fit.pairwise_max_mm:<8.4f}"
            f"{test.pairwise_text(8):>26}"
            f"{test.absolute_mean_mm:>17.4f}"
        )
    for warning in result.warnings:
        print(warning)
    seconds = time.perf_counter() - started
    print_diagnosis(result.diagnosis, result.folder / "diagnosis.json", result.report, seconds)
    print(
        f"best model (lowest held-out error): {result.best} -> "
        f"{result.folder / 'params_best.json'}"
    )
    print(f"done: {result.folder} (report: {result.report})")
    if result.diagnosis.implausible:  # written (to be read), but no exit 0 with nonsense
        raise ImplausibleError(
            f"{'; '.join(result.diagnosis.implausible)} ({result.folder}: "
            "implausible, written to be read)"
        )
    return 0


def check_run_folder(folder: Path) -> None:
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


def robot_table(robot: RobotDescription) -> str:
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
