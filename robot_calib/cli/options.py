"""The options several verbs share, each defined once: the robot and its URDF chain,
-o/--output and --force (the overwrite policy), pairing (--pair-tolerance, --stream),
--joint-names, --payload; the argparse types that range unit-bearing values (seconds, Hz,
counts; msgs_doc/units.md) and the parser classes (one-line usage errors, required options
said so in --help).

Light on purpose: `robot-calib --help` builds every verb's parser from these and loads no
solver, file format or ROS (test_import_layers).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import NoReturn

from robot_calib.flows import DEFAULT_ROBOT
from robot_calib.kinematics.description import available_robots
from robot_calib.measurements import PAIR_TOLERANCE_S

OVERWRITE_POLICY = (
    "Files: an existing output is never overwritten unless --force (then it is replaced "
    "whole: written under a temporary name and renamed); an input is never overwritten, "
    "even with --force; a failed or interrupted command leaves nothing behind."
)

# --robot's default, said in --help: verbs reading a PARAMS.json take its robot (--robot,
# when given, must name it); simulate and plan the world file's
CALIBRATION_ROBOT = "PARAMS.json's robot; when given, it must be that robot"
WORLD_ROBOT = f"the world's; {DEFAULT_ROBOT} in the built-in world"

MAX_TOLERANCE_S = 10.0  # --pair-tolerance, --max-gap: beyond, any two messages pair
MAX_LATENCY_S = 1.0  # --latency: a clock offset above 1 s is no latency
MAX_RATE_HZ = 100_000.0  # --joint-rate, --point-rate: no tracker or controller streams faster
MAX_PAYLOAD_KG, MAX_PAYLOAD_COM_M = 2500.0, 2.0  # --payload: the largest robots' ratings


class OneLineParser(argparse.ArgumentParser):
    """Usage errors as one line and exit status 2 (the contract's rule for bad input)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class RequiredHelpFormatter(argparse.HelpFormatter):
    """Every required option says so in --help (the others state their default)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if action.required and action.option_strings and "required" not in text:
            text += " (required)"
        return text


# -- argparse types: a bad value is a one-line usage error, exit 2 ---------------------------


def at_least(low: int) -> Callable[[str], int]:
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


count, positive = at_least(0), at_least(1)


def bounded_count(most: int) -> Callable[[str], int]:
    """An argparse type: an integer in 1..most."""

    def parse(text: str) -> int:
        value = positive(text)
        if value > most:
            raise argparse.ArgumentTypeError(f"{value} > {most} (the most this accepts)")
        return value

    return parse


def tolerance(text: str) -> float:
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


def signed_seconds(text: str) -> float:
    """An argparse type: a latency [s] within +-MAX_LATENCY_S."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not (math.isfinite(value) and abs(value) <= MAX_LATENCY_S):
        raise argparse.ArgumentTypeError(f"{text} s: need a number within +-{MAX_LATENCY_S:g} s")
    return value


def latency(text: str) -> str:
    """An argparse type: 'auto' or a finite number of seconds (else a usage error)."""
    if text == "auto":
        return text
    try:
        signed_seconds(text)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"'auto' or {exc}") from None
    return text


def rate(text: str) -> float:
    """An argparse type: a finite rate > 0 [Hz]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and 0 < value <= MAX_RATE_HZ):
        raise argparse.ArgumentTypeError(f"{text} Hz: need a number > 0 and <= {MAX_RATE_HZ:g}")
    return value


def separator(text: str) -> str:
    """An argparse type: a CSV field separator, one character; 'tab' or '\\t' for a tab."""
    if text in ("tab", "\\t"):
        return "\t"
    if len(text) != 1:
        raise argparse.ArgumentTypeError(f"{text!r}: one character (tab: a tab)")
    return text


# -- option groups ----------------------------------------------------------------------------


def add_robot(p: argparse.ArgumentParser, default: str | None = None) -> None:
    """--robot (a built-in name, a robot YAML or a URDF), --base-link and --tip-link (the
    URDF chain); every verb has them. `default`: what --robot defaults to, in words, when
    the verb takes the robot from its input (then the option's default is None); None:
    DEFAULT_ROBOT."""
    p.add_argument(
        "--robot",
        default=DEFAULT_ROBOT if default is None else None,
        help=f"built-in robot name ({', '.join(available_robots())}), robot YAML file, "
        "DH table as CSV (.csv, standard or modified DH, units in the header) or URDF file "
        f"(.urdf) (default {default or DEFAULT_ROBOT})",
    )
    p.add_argument(
        "--base-link", help="URDF robots: the chain's base link (default: the root link)"
    )
    p.add_argument(
        "--tip-link",
        help="URDF robots: the chain's tip link, the flange (default: tool0, else flange, "
        "else the end of the longest chain)",
    )


def add_output(p: argparse.ArgumentParser, what: str) -> None:
    """-o/--output, required: `what` says which file it is."""
    p.add_argument("-o", "--output", required=True, help=what)


def add_force(p: argparse.ArgumentParser, implausible: bool = False) -> None:
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


def add_pair_tolerance(p: argparse.ArgumentParser) -> None:
    """--pair-tolerance [s]: how far apart a point and a joint state may be to pair."""
    p.add_argument(
        "--pair-tolerance",
        type=tolerance,
        default=PAIR_TOLERANCE_S,
        help=f"point/joint-state pairing [s] (default {PAIR_TOLERANCE_S})",
    )


def add_stream(p: argparse.ArgumentParser) -> None:
    """--stream and its pairing options (--latency, --stream-max-points, --max-gap)."""
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
        type=latency,
        default="auto",
        metavar="auto|SECONDS",
        help="with --stream: the controller's stamps minus the tracker's for one instant [s], "
        "or auto: identified (default auto)",
    )
    p.add_argument(
        "--stream-max-points",
        type=positive,
        default=None,  # STREAM_MAX_POINTS with --stream; given without it: refused
        metavar="N",
        help=f"with --stream: fit every k-th point, k chosen so that at most N remain "
        f"(default {STREAM_MAX_POINTS})",
    )
    p.add_argument(
        "--max-gap",
        type=tolerance,
        default=None,  # STREAM_MAX_GAP_S with --stream; given without it: refused
        metavar="SECONDS",
        help="with --stream: points between two joint states further apart than this are "
        f"dropped and counted [s] (default {STREAM_MAX_GAP_S})",
    )


def add_joint_names(
    p: argparse.ArgumentParser, what: str = "the bags' JointState names of joints 1..J"
) -> None:
    """--joint-names: the names the input uses for joints 1..J, where not the robot's."""
    p.add_argument(
        "--joint-names",
        metavar="NAME1,...,NAMEJ",
        help=f"{what}, in joint order, where they are not the robot's own "
        "(e.g. j1,j2,j3,j4,j5,j6; default: the robot's names)",
    )


def add_payload(p: argparse.ArgumentParser) -> None:
    """--payload KG[:X,Y,Z] (read by `common.robot_of`)."""
    p.add_argument(
        "--payload",
        metavar="KG[:X,Y,Z]",
        help="a payload on the flange during the measurements: mass [kg] and centre of mass "
        "in the flange frame [m] (default: none), e.g. 3:0,0,0.08; gravity compliance then "
        "includes it; PARAMS.json keeps it",
    )


def add_report_header(p: argparse.ArgumentParser) -> None:
    """The report's header (`diagnosis.header.ReportHeader`) and its PDF."""
    p.add_argument(
        "--serial", help="the robot's serial number, for the report's header (default: not given)"
    )
    p.add_argument(
        "--operator", help="who ran the campaign, for the report's header (default: not given)"
    )
    p.add_argument(
        "--instrument",
        help="the measuring instrument, e.g. 'Leica AT960-MR #123', for the report's header "
        "(default: not given)",
    )
    p.add_argument(
        "--pdf",
        action="store_true",
        help="also print the HTML report to <name>.pdf with a headless Chromium (Debian: "
        "apt-get install chromium; default: no PDF)",
    )
