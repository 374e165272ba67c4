"""`robot-calib diagnose`: the sim-to-real gap diagnosis of bags -> DIAGNOSIS.json, a
Markdown report with plots, a self-contained HTML report and the best model's PARAMS.json
(flows/diagnose.py). An implausible diagnosis is written to be read and exits 3."""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from typing import TYPE_CHECKING

from robot_calib.cli.common import header_fields, log, print_diagnosis, robot_files, robot_of
from robot_calib.cli.options import (
    add_force,
    add_joint_names,
    add_output,
    add_pair_tolerance,
    add_payload,
    add_report_header,
)
from robot_calib.errors import ImplausibleError, InputError

if TYPE_CHECKING:
    from robot_calib.flows.diagnose import ReadAside
    from robot_calib.kinematics.description import RobotDescription

NAME = "diagnose"
HELP = "sim-to-real gap diagnosis -> DIAGNOSIS.json + report"
ROBOT = None  # --robot's default: DEFAULT_ROBOT


def add_arguments(diag: argparse.ArgumentParser) -> None:
    diag.add_argument("bags", nargs="+", metavar="BAG", help="calibration bag(s) (.mcap)")
    diag.add_argument(
        "--holdout",
        nargs="+",
        metavar="BAG",
        help="hold-out bag(s): scored only (default: none; the calibration bags' k-fold)",
    )
    add_pair_tolerance(diag)
    add_joint_names(diag)
    add_payload(diag)
    diag.add_argument(
        "--tracker-accuracy",
        type=float,
        metavar="MM",
        help="the tracker's stated 1-sigma per axis of a point [mm], e.g. 0.005: the noise floor "
        "when the data have no repeat poses or circle sweeps (default: none; then the floor "
        "is unknown and said so)",
    )
    add_report_header(diag)
    add_output(
        diag,
        "DIAGNOSIS.json to write; the reports go beside it as <name>.md (+ "
        "<name>_*.png), <name>.html (self-contained) and with --pdf <name>.pdf, so -o may "
        "not end in .md, .html or .pdf",
    )
    add_force(diag)


def main(args: argparse.Namespace) -> int:
    """The sim-to-real gap diagnosis -> DIAGNOSIS.json + a Markdown report with plots + a
    self-contained HTML report."""
    from robot_calib.flows.diagnose import ReadAside
    from robot_calib.forked import FORKED
    from robot_calib.parallel import using

    robot = robot_of(args)
    # the bags read by a child while this process loads the diagnosis' modules; the
    # diagnosis's independent work (folds, joints' scans) on the other core
    with (
        ReadAside(args.bags, args.holdout or (), robot, args.pair_tolerance, log) as reading,
        using(FORKED),
    ):
        return _diagnose(args, robot, reading)


def _diagnose(args: argparse.Namespace, robot: RobotDescription, reading: ReadAside) -> int:
    from robot_calib.atomic import output_path, refuse_input
    from robot_calib.diagnosis.header import report_header
    from robot_calib.diagnosis.report import plot_paths
    from robot_calib.flows.diagnose import (
        FiguresWhenClimbed,
        best_params_path,
        diagnose_read,
        html_report_path,
        pdf_report_path,
        report_path,
        started_figures,
        write_diagnosis,
    )

    inputs = [*args.bags, *(args.holdout or ()), *robot_files(args)]
    output = output_path(args.output, "DIAGNOSIS.json", inputs, args.force)
    report = output_path(report_path(output), "the report", inputs, args.force)
    output_path(html_report_path(output), "the HTML report", inputs, args.force)
    if args.pdf:
        from robot_calib.diagnosis.pdf import browser

        browser()  # no Chromium: said before any work
        output_path(pdf_report_path(output), "the PDF report", inputs, args.force)
    for figure in plot_paths(report.with_suffix("")):  # written with --force: never an input
        refuse_input(figure, inputs)
    best = output_path(
        best_params_path(output), "the best model's PARAMS.json", inputs, args.force
    )
    started = time.perf_counter()
    accuracy = args.tracker_accuracy
    if accuracy is not None and not (math.isfinite(accuracy) and 1e-4 <= accuracy < 10):
        raise InputError(f"--tracker-accuracy {accuracy}: a 1-sigma in mm, 0.0001 (0.1 um) to 10")
    read = reading.read()
    with started_figures() as figures:  # its helper gets ready while the diagnosis runs
        # drawn while the diagnosis is written up; the reference models from `reading`
        early = FiguresWhenClimbed(figures, references=reading.references)
        diagnosis, ladder, recording = diagnose_read(
            read, robot, log, None if accuracy is None else accuracy * 1e-3, on_ladder=early
        )
        compared, warnings = early.before_after(ladder)
        header = report_header(
            robot.name,
            [recording, *([ladder.holdout] if ladder.holdout is not None else [])],
            header_fields(args),
            None if accuracy is None else accuracy * 1e-3,
        )
        diagnosis = dataclasses.replace(
            diagnosis, warnings=[*diagnosis.warnings, *warnings], header=header
        )
        report = write_diagnosis(
            diagnosis,
            ladder,
            recording,
            output,
            args.force,
            warnings=warnings,
            compared=compared,
            figures=figures,
            pdf=args.pdf,
        )
    print_diagnosis(diagnosis, output, report, time.perf_counter() - started)
    for warning in warnings:
        print(warning)
    print(f"best model (the ladder's chosen rung): {diagnosis.ladder[-1].model} -> {best}")
    if diagnosis.implausible:  # written (to be read), but no exit 0 with nonsense
        raise ImplausibleError(
            f"{'; '.join(diagnosis.implausible)} ({output}: implausible, written to be read)"
        )
    return 0
