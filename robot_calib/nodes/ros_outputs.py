"""The topics ROS users look for (msgs_doc/ros_topics.md): the calibrated URDF on
`robot_description` and each node's health on `/diagnostics`.

Builders only: what goes into the messages, from the typed results (`Calibration`, `Score`,
the capture's counts); no node, no publisher. The nodes own the publishers with the QoS
below and call one builder per result.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.urdf import is_urdf_reference
from robot_calib.nodes._common import in_ros_terms

if TYPE_CHECKING:
    from robot_calib.errors import RobotCalibError
    from robot_calib.identify.calibration import Calibration
    from robot_calib.identify.score import Score
    from robot_calib.measurements import Recording

# robot_state_publisher (Jazzy, 3.3.x: src/robot_state_publisher.cpp) publishes the relative
# name `robot_description` with rclcpp::QoS(1).transient_local() (KEEP_LAST 1, RELIABLE by
# default); its later releases subscribe to it (`use_robot_description_topic`) with
# QoS(1).transient_local().reliable(). The same profile here, so every reader of robot_state_
# publisher's topic (RViz's RobotModel, the controller manager, MoveIt) reads this one, and a
# reader that joins later still gets the last description.
ROBOT_DESCRIPTION_TOPIC = "robot_description"  # relative: /robot_description at the root
ROBOT_DESCRIPTION_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
# diagnostic_updater publishes the absolute `/diagnostics` RELIABLE, VOLATILE, depth 1 and
# again every second (an aggregator marks a silent status stale); depth 10 here, so that a
# capture's pose-by-pose progress reaches a reader that is a little slow.
DIAGNOSTICS_TOPIC = "/diagnostics"
DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
DIAGNOSTIC_PERIOD_S = 1.0  # the last status is published again this often [s, wall time]
OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


def status_name(node_name: str) -> str:
    """The DiagnosticStatus name of a node: 'robot_calib: calibrator' (diagnostic_updater's
    'node: task' form; a renamed node keeps its statuses apart)."""
    return f"robot_calib: {node_name}"


def diagnostic_array(status: DiagnosticStatus, stamp: Time) -> DiagnosticArray:
    """One status as the /diagnostics message, stamped `stamp`."""
    array = DiagnosticArray(status=[status])
    array.header.stamp = stamp
    return array


def _status(
    name: str, hardware_id: str, level: bytes, message: str, values: Sequence[tuple[str, str]]
) -> DiagnosticStatus:
    return DiagnosticStatus(
        level=level,
        name=name,
        hardware_id=hardware_id,
        message=message,
        values=[KeyValue(key=k, value=v) for k, v in values],
    )


def _unlabelled(warning: str) -> str:
    return warning.removeprefix("warning: ")


# --- the calibrator ------------------------------------------------------------------------


def robot_urdf(robot: RobotDescription) -> str:
    """The URDF file the robot was loaded from (`robot:=FILE.urdf[#...]`), '' for a built-in
    robot or a robot YAML."""
    reference = robot.reference()
    return reference.partition("#")[0] if is_urdf_reference(reference) else ""


XML_DECLARATION = re.compile(r"\A\s*<\?xml\s[^>]*\?>")


def as_text(urdf: str) -> str:
    """A URDF file's text as a topic's string: its XML declaration without `encoding` (the
    message is text, not bytes; lxml and urdf_parser_py refuse a str that declares one)."""
    return XML_DECLARATION.sub('<?xml version="1.0"?>', urdf, count=1)


def calibrated_urdf(cal: Calibration, source: str, nominal_urdf: str = "") -> tuple[str, str]:
    """The calibrated URDF of `cal` (`source`: the PARAMS.json it is, for the file's header)
    and what it was written into: the user's URDF `nominal_urdf`, else the robot's own URDF
    when it was loaded from one (both as `export --nominal-urdf`), else the calibrated
    chain alone (`export --format urdf`). ExportError / RobotDescriptionError (one line)
    when the description cannot take the calibration."""
    nominal = nominal_urdf or robot_urdf(cal.model.robot)
    if nominal:
        from robot_calib.export.urdf_nominal import render_on_nominal

        return as_text(render_on_nominal(cal, source, nominal)), nominal
    from robot_calib.export import FORMATS

    return FORMATS["urdf"].render(cal, source), "the calibrated chain (export --format urdf)"


@dataclass(frozen=True)
class HeldOut:
    """The calibration scored on measurements it was not fitted on: `score` of the bags
    `sources`, and the warnings that judge it against the tracker's noise."""

    score: Score
    sources: tuple[str, ...]
    warnings: tuple[str, ...]


def score_held_out(cal: Calibration, recording: Recording, holdout: Recording) -> HeldOut:
    """`cal` (fitted on `recording`) scored on `holdout` as `robot-calib score` scores it
    (`Calibration.score`: its warnings included)."""
    result = cal.score(holdout, fitted=recording.sources)
    return HeldOut(result, tuple(holdout.sources), result.warnings)


def calibration_status(
    name: str,
    robot: str,
    cal: Calibration | None,
    error: RobotCalibError | None,
    *,
    held_out: HeldOut | None = None,
    params_path: str = "",
    description: str = "",
    waiting: str = "",
    diagnosis: str = "",
) -> DiagnosticStatus:
    """The calibrator's health: ERROR when the last solve failed (`error`) or its result is
    implausible (`cal.implausible`); WARN with the calibration's warnings, those of its
    held-out score (`held_out`: far above the noise, or not held out) and a description
    that could not be published (`description` starting 'not published'); else OK.
    `diagnosis`: what the diagnosis says the published model leaves (a WARN when given).
    Before any result: OK with `waiting` (what the node is doing). Values: model, held-out
    and in-sample rms / mean / max [mm], measurements used, PARAMS path, robot_description."""
    values: list[tuple[str, str]] = [("robot", robot)]
    if error is not None:
        return _status(name, robot, ERROR, f"failed: {error}", values)
    if cal is None:
        return _status(name, robot, OK, waiting or "no calibration yet", values)
    acc = cal.accuracy
    values += [
        ("model", cal.label),
        ("plausible", str(cal.plausible).lower()),
        ("poses_used", str(acc.n_points)),
        ("outliers_left_out", str(len(cal.outliers))),
    ]
    if held_out is not None:
        figures = held_out.score.accuracy
        values += [
            ("held_out_rms_mm", f"{figures.absolute_rms_mm:.6f}"),
            ("held_out_mean_mm", f"{figures.absolute_mean_mm:.6f}"),
            ("held_out_max_mm", f"{figures.absolute_max_mm:.6f}"),
            ("held_out_points", str(figures.n_points)),
            ("held_out_bags", ", ".join(held_out.sources)),
        ]
    else:
        values.append(("held_out", "none (parameter holdout_bags empty)"))
    values += [
        ("in_sample_rms_mm", f"{acc.absolute_rms_mm:.6f}"),
        ("in_sample_mean_mm", f"{acc.absolute_mean_mm:.6f}"),
        ("in_sample_max_mm", f"{acc.absolute_max_mm:.6f}"),
        ("params", params_path or "not written (parameter output empty)"),
        ("robot_description", description),
    ]
    if not cal.plausible:
        return _status(
            name, robot, ERROR, in_ros_terms("implausible: " + "; ".join(cal.implausible)), values
        )
    warnings = [*cal.warnings, *(held_out.warnings if held_out is not None else ())]
    if description.startswith("not published"):
        warnings.append(f"/robot_description {description}")
    if diagnosis:
        warnings.append(diagnosis)
    if warnings:
        return _status(name, robot, WARN, "; ".join(map(_unlabelled, warnings)), values)
    figures = held_out.score.accuracy if held_out is not None else acc
    said = "held-out" if held_out is not None else "in-sample (no hold-out)"
    message = (
        f"{cal.label}: {said} rms {figures.absolute_rms_mm:.4f} mm, "
        f"max {figures.absolute_max_mm:.4f} mm ({figures.n_points} points)"
    )
    return _status(name, robot, OK, message, values)


# --- capture -------------------------------------------------------------------------------


@dataclass(frozen=True)
class CaptureProgress:
    """Where a capture campaign stands: poses measured of those to measure (`total`,
    besides `earlier` ones already in the bag), the plan pose at hand (None when none),
    the state machine's step ('finished' at the end, also when stopped with poses to go),
    the skipped poses' reasons (refused or failed), and `error` once aborted."""

    measured: int
    total: int
    earlier: int
    current_pose: int | None
    step: str
    skipped: tuple[str, ...]
    bag: str
    eta_s: float | None = None
    error: str | None = None


def capture_status(name: str, robot: str, progress: CaptureProgress) -> DiagnosticStatus:
    """The capture's progress: ERROR once aborted (`progress.error`), WARN once any pose
    was skipped (refused up front or failed) and when stopped with poses to go, else OK.
    Values: poses done / total, the current plan pose, the step, failures and the last
    reason, the bag, time left."""
    p = progress
    values = [
        ("poses_done", str(p.measured)),
        ("poses_total", str(p.total)),
        ("poses_earlier", str(p.earlier)),
        ("current_pose", "none" if p.current_pose is None else str(p.current_pose)),
        ("step", p.step),
        ("failures", str(len(p.skipped))),
        ("last_failure", p.skipped[-1] if p.skipped else ""),
        ("bag", p.bag),
    ]
    if p.eta_s is not None:
        values.append(("time_left_s", f"{p.eta_s:.0f}"))
    done = f"{p.measured} of {p.total} poses measured"
    if p.error is not None:
        return _status(name, robot, ERROR, f"aborted: {p.error} ({done})", values)
    skipped = f", {len(p.skipped)} skipped" if p.skipped else ""
    if p.step == "finished" and p.current_pose is not None:  # stopped (Ctrl-C) mid-campaign
        message = f"stopped at plan pose {p.current_pose}: {done}{skipped}; run again to resume"
        return _status(name, robot, WARN, message, values)
    at = "" if p.current_pose is None else f"; at plan pose {p.current_pose} ({p.step})"
    return _status(name, robot, WARN if p.skipped else OK, done + skipped + at, values)


def tracker_in_base(cal: Calibration) -> tuple[Array, Array]:
    """Where the tracker frame sits in the robot's base frame by the calibration (its
    fitted base2tracker inverted): translation (3,) [m] and rotation as a quaternion
    (x, y, z, w): the static transform base -> laser_tracker that TF wants (a point p
    measured in the tracker frame is R p + t in the base frame)."""
    from scipy.spatial.transform import Rotation

    base2tracker = cal.model.base2tracker(cal.parameters)  # p_tracker = B p_base
    rotation = base2tracker[:3, :3].T
    translation = -rotation @ base2tracker[:3, 3]
    return translation, Rotation.from_matrix(rotation).as_quat()
