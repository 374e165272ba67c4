"""The topics ROS users look for, through real rclpy on this process's private
domain: the calibrator's calibrated URDF on /robot_description reaches a TRANSIENT_LOCAL
subscriber that joins after it was published, parses and carries the calibrated joint
origins; its /diagnostics status is OK for a calibration at the noise on held-out poses, WARN
for one far above it, ERROR for an implausible calibration and a failed one. (capture's
progress on /diagnostics: test_capture.py.)"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from robot_calib.bag.write import write_measurement_bag
from robot_calib.export.urdf_nominal import render_on_nominal
from robot_calib.kinematics.frames import rot_x, rot_y, rot_z
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.kinematics.urdf import parse_urdf
from robot_calib.nodes.calibrator import CalibratorNode
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import paper_test_plan, random_plan
from robot_calib.sim.world import load_world

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "bags" / "paper_test3.mcap"
WORLD = load_world(SAMPLE.with_suffix(".world.yaml"))
ROBOT = WORLD.model.robot
TIMEOUT_S = 30.0
STATUS = "robot_calib: calibrator"
# what a reader of robot_state_publisher's robot_description asks for (RViz's RobotModel,
# the controller manager): written out here, not imported, so a change on our side shows
LATE_READER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


def spin_until(executor: SingleThreadedExecutor, condition: Callable[[], bool]) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        executor.spin_once(timeout_sec=0.01)


class Listener(Node):
    """/diagnostics statuses named `name` (RELIABLE, VOLATILE, as diagnostic_aggregator
    reads them) and, once `read_description()`, /robot_description (TRANSIENT_LOCAL)."""

    def __init__(self, context: Context, name: str = STATUS) -> None:
        super().__init__("listener", context=context)
        self.statuses: list[DiagnosticStatus] = []
        self.descriptions: list[str] = []
        self.create_subscription(
            DiagnosticArray,
            "/diagnostics",
            lambda msg: self.statuses.extend(s for s in msg.status if s.name == name),
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE),
        )

    def read_description(self) -> None:
        self.create_subscription(
            String,
            "/robot_description",
            lambda msg: self.descriptions.append(msg.data),
            LATE_READER_QOS,
        )

    def result(self) -> DiagnosticStatus | None:
        """The last status about a result (it names the model) or a failure."""
        done = [s for s in self.statuses if s.level == DiagnosticStatus.ERROR or values(s)]
        return done[-1] if done else None


def values(status: DiagnosticStatus) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values if kv.key != "robot"}


def run_calibrator(
    context: Context, bags: list[Path], overrides: list[Parameter], read_description: bool
) -> tuple[CalibratorNode, Listener]:
    """A bag-mode calibrator and a listener of /diagnostics spun until the result's status
    arrived; with `read_description` the listener then subscribes to /robot_description (a
    late joiner) and spins until it arrives. Both nodes destroyed after."""
    calibrator = CalibratorNode(bags=bags, context=context, parameter_overrides=overrides)
    listener = Listener(context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(calibrator)
    executor.add_node(listener)
    try:
        spin_until(executor, lambda: listener.result() is not None)
        assert calibrator.calibration is not None or calibrator.error is not None
        if read_description:
            listener.read_description()  # joins after the description went out
            spin_until(executor, lambda: bool(listener.descriptions))
        else:  # give a description that should not exist the time to arrive
            listener.read_description()
            deadline = time.monotonic() + 0.5
            while time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.01)
    finally:
        executor.shutdown()
        calibrator.destroy_node()
        listener.destroy_node()
    return calibrator, listener


def holdout_bag(path: Path, shift_m: float = 0.0) -> Path:
    """100 random poses of the sample's world measured with its noise (seeded), the points
    moved by `shift_m` along x (a tracker bumped since the calibration)."""
    rng = np.random.default_rng(11)
    q = random_plan(ROBOT, 100, rng).q
    points = physical_points(WORLD, Poses.from_readings(q), rng)
    write_measurement_bag(path, q, points + [shift_m, 0.0, 0.0], ROBOT.joint_names)
    return path


def dh_row(params: ParameterVector, j: int) -> np.ndarray:
    """Rz(theta_j) Tz(d_j) Tx(a_j) Rx(alpha_j) Ry(beta_j) of the calibrated parameters (beta 0
    where the joint has none): joint j+1's origin in a URDF of the chain."""
    rz, rx, ry = (
        f([params.get(f"{n}{j}", 0.0)])[0]
        for f, n in ((rot_z, "theta"), (rot_x, "alpha"), (rot_y, "beta"))
    )
    row = np.eye(4)
    row[:3, :3] = rz @ rx @ ry
    row[:3, 3] = rz @ [params[f"a{j}"], 0.0, 0.0] + [0.0, 0.0, params[f"d{j}"]]
    return row


def test_a_late_subscriber_gets_the_calibrated_urdf_and_the_status_is_ok(
    context: Context, tmp_path: Path
) -> None:
    params_path = tmp_path / "params.json"
    calibrator, listener = run_calibrator(
        context,
        [SAMPLE],
        [
            Parameter("output", value=str(params_path)),
            Parameter("holdout_bags", value=[str(holdout_bag(tmp_path / "held.mcap"))]),
        ],
        read_description=True,
    )
    cal = calibrator.calibration
    assert cal is not None and cal.plausible
    (text,) = listener.descriptions  # one description, latched
    urdf = parse_urdf(text, "/robot_description")
    assert urdf.name == ROBOT.name
    joints = {j.name: j for j in urdf.joints}
    params, nominal = cal.parameters, cal.model.parameters()
    np.testing.assert_allclose(joints[ROBOT.joint_names[0]].origin, np.eye(4), atol=1e-12)
    moved = 0.0  # how far the calibrated origins lie from the nominal ones [m]
    for j in range(1, ROBOT.n_joints):  # joint j+1 sits where calibrated row j puts it
        origin = joints[ROBOT.joint_names[j]].origin
        np.testing.assert_allclose(origin, dh_row(params, j), rtol=0, atol=1e-9)
        moved = max(moved, np.abs(origin[:3, 3] - dh_row(nominal, j)[:3, 3]).max())
    assert moved > 1e-4  # the sample world's geometry is not the nominal one
    assert f"from {params_path} (model geometric)" in text  # the header names the file

    status = listener.result()
    assert status is not None and status.level == DiagnosticStatus.OK, status.message
    assert status.hardware_id == ROBOT.name
    got = values(status)
    assert got["model"] == "geometric" and got["plausible"] == "true"
    assert got["poses_used"] == "290" and got["params"] == str(params_path)
    assert got["held_out_points"] == "100"
    assert calibrator.held_out is not None
    figures = calibrator.held_out.score.accuracy
    assert float(got["held_out_rms_mm"]) == pytest.approx(figures.absolute_rms_mm, abs=1e-6)
    assert float(got["held_out_max_mm"]) >= float(got["held_out_mean_mm"]) > 0.0
    assert float(got["held_out_rms_mm"]) < 0.05  # the sample's noise: a few um per axis
    assert got["robot_description"].startswith("published to /robot_description")
    assert status.message.startswith("geometric: held-out rms ")


def test_held_out_far_above_the_noise_warns(context: Context, tmp_path: Path) -> None:
    held = holdout_bag(tmp_path / "bumped.mcap", shift_m=1e-3)  # the tracker moved 1 mm
    _, listener = run_calibrator(
        context, [SAMPLE], [Parameter("holdout_bags", value=[str(held)])], read_description=True
    )
    status = listener.result()
    assert status is not None and status.level == DiagnosticStatus.WARN
    assert f"{held}: held-out residual" in status.message and "x the noise" in status.message
    assert float(values(status)["held_out_rms_mm"]) > 0.9
    assert values(status)["params"] == "not written (parameter output empty)"
    assert len(listener.descriptions) == 1  # plausible: the description is published


def test_implausible_or_failed_is_an_error_and_publishes_no_description(
    context: Context, tmp_path: Path
) -> None:
    degrees = tmp_path / "deg.mcap"  # readings in degrees: fitted, implausible
    q = np.degrees(paper_test_plan(3).q)
    points = physical_points(WORLD, Poses.from_readings(np.radians(q)), np.random.default_rng(5))
    write_measurement_bag(degrees, q, points, ROBOT.joint_names)
    calibrator, listener = run_calibrator(context, [degrees], [], read_description=False)
    assert calibrator.calibration is not None and not calibrator.calibration.plausible
    status = listener.result()
    assert status is not None and status.level == DiagnosticStatus.ERROR
    assert status.message.startswith("implausible: readings of joint(s) 1 (")
    assert values(status)["plausible"] == "false"
    assert values(status)["robot_description"] == "not published: the calibration is implausible"
    assert listener.descriptions == []

    missing = tmp_path / "missing.mcap"
    calibrator, listener = run_calibrator(context, [missing], [], read_description=False)
    status = listener.result()
    assert calibrator.failed and status is not None and status.level == DiagnosticStatus.ERROR
    assert status.message.startswith("failed: ") and str(missing) in status.message
    assert listener.descriptions == []


def test_a_urdf_robot_gets_the_calibration_written_into_its_own_urdf(
    context: Context,
) -> None:
    """robot:=FILE.urdf: robot_description is that file with the calibrated origins (its
    links kept), exactly what `export --nominal-urdf FILE.urdf` writes."""
    urdf_file = ROOT / "test" / "data" / "kr5_sixx_r650.urdf"
    calibrator, listener = run_calibrator(
        context, [SAMPLE], [Parameter("robot", value=str(urdf_file))], read_description=True
    )
    cal = calibrator.calibration
    assert cal is not None and cal.plausible
    (text,) = listener.descriptions
    exported = render_on_nominal(cal, "/calibrator/parameters", urdf_file)
    assert text.splitlines()[1:] == exported.splitlines()[1:]  # the same but the first line:
    assert text.startswith('<?xml version="1.0"?>\n')  # text: no encoding declared
    assert "tool0" in parse_urdf(text, "/robot_description").links  # the user's links kept
    status = listener.result()
    assert status is not None and status.level == DiagnosticStatus.OK, status.message
    assert values(status)["robot_description"].endswith(f"written into {urdf_file}")
