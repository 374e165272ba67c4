"""What several verbs do with their parsed arguments: the robot of --robot/--joint-names/
--payload, a PARAMS.json checked for --robot and plausibility, the log and progress lines
on stderr, the diagnosis printed for people (`diagnose`, `run`)."""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from robot_calib.cli.flags import in_flags
from robot_calib.cli.options import MAX_PAYLOAD_COM_M, MAX_PAYLOAD_KG
from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription, with_joint_names, with_payload
from robot_calib.kinematics.loader import load_robot

if TYPE_CHECKING:
    from robot_calib.diagnosis.diagnosis import Diagnosis
    from robot_calib.diagnosis.header import HeaderFields
    from robot_calib.identify.calibration import Calibration


def log(message: str) -> None:
    """A line for people on stderr (warnings, progress), apart from the results on stdout;
    the core's keywords in it as the verb's flags."""
    print(in_flags(message), file=sys.stderr)


def progress() -> Callable[[str, int, int], None]:
    """A progress printer for simulations: 'plan: k/N poses' at most once a second."""
    last = [0.0]

    def show(plan: str, done: int, total: int) -> None:
        if time.monotonic() - last[0] > 1.0 or done == total:
            last[0] = time.monotonic()
            print(f"  {plan}: {done}/{total} poses", file=sys.stderr)

    return show


def robot_files(args: argparse.Namespace) -> list[str]:
    """The robot description file --robot names (a YAML, or a URDF without its #links), an
    input of the command that no output may overwrite; none for a built-in robot."""
    text = str(getattr(args, "robot", None) or "").partition("#")[0]
    return [text] if text and Path(text).is_file() else []


def robot_of(args: argparse.Namespace, name: str | None = None) -> RobotDescription:
    """--robot (or `name`) loaded, its joints renamed by --joint-names where given."""
    robot = load_robot(args.robot if name is None else name)
    if getattr(args, "payload", None) is not None:
        robot = with_payload(robot, *payload(args.payload))
    return robot if args.joint_names is None else with_joint_names(robot, args.joint_names)


def payload(text: str) -> tuple[float, tuple[float, float, float]]:
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


def calibration_of(args: argparse.Namespace) -> Calibration:
    """The calibration of args.params (PARAMS.json, `Calibration.load`: checked, finite SI
    values, the robot unchanged), for the robot --robot names, if it names one (its default
    is None: the calibration's robot, so that an explicit --robot of the default robot is
    checked too)."""
    from robot_calib.identify.calibration import Calibration as Loaded

    cal = Loaded.load(args.params)
    robot = cal.model.robot
    if args.robot is not None and load_robot(args.robot).name != robot.name:
        raise InputError(
            f"{args.params}: identified for robot {robot.name}, not --robot {args.robot}"
        )
    return cal


def plausible_or_forced(reasons: tuple[str, ...], args: argparse.Namespace) -> None:
    """Exit 2 naming args.params and its `reasons` when it is marked implausible
    (`Calibration.implausible`), unless --force: then a warning."""
    from robot_calib.identify.params_file import check_plausible

    warning = check_plausible(reasons, args.params, args.force)
    if warning is not None:
        log(warning)


def print_diagnosis(diagnosis: Diagnosis, output: Path, report: Path, seconds: float) -> None:
    """The diagnosis for people: the ladder (mm), the floor, the verdict, what remains,
    the measurements left out as tracker blunders."""
    from robot_calib.diagnosis.diagnosis import percent
    from robot_calib.flows.diagnose import html_report_path
    from robot_calib.identify.params_file import outlier_lines

    print(f"{'model':<40}{'held-out mean/max [mm]':>24}{'abs rms [mm]':>14}")
    for rung in diagnosis.ladder:
        print(f"{rung.model:<40}{rung.holdout_seed_text():>22} {rung.holdout_abs_rms_mm:>14.4f}")
    floor = diagnosis.noise.floor_abs_rms_mm
    unknown = "unknown (no repeat poses, circle sweeps or stated accuracy; --tracker-accuracy)"
    known = f"{floor:.4f} mm ({diagnosis.noise.source})" if floor is not None else ""
    print(f"noise floor (abs rms): {known or ('unknown' if diagnosis.noise.warning else unknown)}")
    if diagnosis.noise.warning:  # a stated accuracy the evidence contradicts
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
            print(f"joint-angle harmonics left by {diagnosis.physical_model}: {spectrum.line()}")
    print(f"unexplained: {diagnosis.unexplained.note}")
    for line in outlier_lines(diagnosis.outliers):
        print(line)
    if diagnosis.poses and diagnosis.measurements > diagnosis.poses:  # re-reads, targets
        print(f"calibration data: {diagnosis.reads_line()}")
    for drift in diagnosis.tracker_drift:
        print(f"tracker drift: {drift.line()}")
    if "not the description's" in diagnosis.mass_model:  # not what was given
        print(f"mass model of the gravity effects: {diagnosis.mass_model}")
    for place in diagnosis.concentration_lines():
        print(f"where the residual concentrates: {place}")
    for warning in diagnosis.warnings:  # as the reports list them (the floor's: above)
        if warning != diagnosis.noise.warning:
            print(warning if warning.startswith(("warning", "note")) else f"warning: {warning}")
    print(f"{output}, {report} in {seconds:.1f} s")
    print(f"HTML report (self-contained, open in a browser): {html_report_path(output)}")


def header_fields(args: argparse.Namespace) -> HeaderFields:
    """The report header's fields of a verb's args (--serial, --operator, --instrument) and
    the exact command (as a shell would take it back)."""
    import shlex

    from robot_calib.diagnosis.header import HeaderFields

    command = shlex.join(["robot-calib", *getattr(args, "argv", sys.argv[1:])])
    return HeaderFields(args.serial, args.operator, args.instrument, command)
