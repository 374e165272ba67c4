"""`robot-calib calibrate`: a model identified from bags, written as PARAMS.json with a
summary in mm/deg (flows/calibrate.py). A fit that ran to its end with a nonsense result is
written for inspection and exits 3."""

from __future__ import annotations

import argparse
import time

from robot_calib.cli.common import log, robot_files, robot_of
from robot_calib.cli.options import (
    add_force,
    add_joint_names,
    add_output,
    add_pair_tolerance,
    add_payload,
    add_stream,
    positive,
)
from robot_calib.errors import ImplausibleError, InputError
from robot_calib.identify import DEFAULT_ECC_ORDER, DEFAULT_MODEL

NAME = "calibrate"
HELP = "identify a model from bags -> PARAMS.json"
ROBOT = None  # --robot's default: DEFAULT_ROBOT


def add_arguments(cal: argparse.ArgumentParser) -> None:
    cal.add_argument("bags", nargs="+", metavar="BAG", help="calibration bag(s) (.mcap)")
    cal.add_argument(
        "--model",
        default=DEFAULT_MODEL,
        help="nominal | cpa | geometric | geometric+eccentricity | geometric+EFFECT[:joints]"
        " (default geometric)",
    )
    cal.add_argument(
        "--ecc-order",
        type=positive,
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
    add_pair_tolerance(cal)
    add_stream(cal)
    add_joint_names(cal)
    add_payload(cal)
    add_output(cal, "PARAMS.json to write")
    add_force(cal)


def main(args: argparse.Namespace) -> int:
    """Identify a model from bags; write PARAMS.json; print a summary in mm/deg."""
    from robot_calib.atomic import output_path
    from robot_calib.flows.calibrate import calibrate_bags, calibrate_stream_bag
    from robot_calib.identify.calibrate import parse_model
    from robot_calib.identify.calibration import summary
    from robot_calib.identify.params_file import write_json_atomic

    robot = robot_of(args)
    output = output_path(args.output, "PARAMS.json", [*args.bags, *robot_files(args)], args.force)
    parse_model(args.model, robot, args.ecc_order)  # a bad model: its error before any work
    started = time.perf_counter()
    if args.stream:
        if args.objective != "absolute":
            raise InputError("--stream: only --objective absolute")
        fit = calibrate_stream_bag(
            args.bags,
            robot,
            args.model,
            args.ecc_order,
            None if args.latency == "auto" else float(args.latency),
            args.stream_max_points,
            args.max_gap,
            log,
        )
        cal, recording = fit.calibration, fit.recording
        print(fit.line())
        print(summary(cal, recording))
        write_json_atomic(fit.document(), output)
    else:
        given = [
            flag
            for flag, set_ in (
                ("--latency", args.latency != "auto"),
                ("--stream-max-points", args.stream_max_points is not None),
                ("--max-gap", args.max_gap is not None),
            )
            if set_
        ]
        if given:  # a stream's option on poses at rest would be ignored without a word
            raise InputError(f"{', '.join(given)} applies with --stream only")
        cal, recording = calibrate_bags(
            args.bags,
            robot,
            args.model,
            args.ecc_order,
            args.objective,
            args.pair_tolerance,
            log,
        )
        print(summary(cal, recording))
        write_json_atomic(cal.to_dict(recording), output)
    print(f"{output}: {cal.name} in {time.perf_counter() - started:.2f} s")
    if not cal.plausible:  # written for inspection; predict, compensate, export refuse it
        raise ImplausibleError(f"{'; '.join(cal.implausible)} ({output}: plausible false)")
    return 0
