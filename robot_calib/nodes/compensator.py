"""compensator: joint trajectories planned on the nominal model, corrected for the calibrated
robot (msgs_doc/compensator.md).

Subscribes a trajectory_msgs/JointTrajectory (parameter `input_topic`), maps its
joint_names to the calibration's joints by name (any order; parameter `joint_names` renames
the model's joints to the controller's), compensates every point's positions with
`compensation.compensate_commands` (approach directions from the motion between consecutive
points, the first point's from where the robot stands and how it got there, as
/joint_states last showed it; time from time_from_start), and republishes the trajectory
(parameter `output_topic`) with the same header, joint_names, times, velocities,
accelerations and efforts, only the positions corrected (a hybrid calibration's learned
correction, PARAMS.json `correction`, included). A message with unknown, missing or
repeated joints, positions that are not finite, in degrees or beyond the joint limits (before
or after the correction: `RobotDescription.check_joints`, the check `compensate` applies) is
logged as one error line and dropped: nothing leaves the node that the CLI would refuse.

Standalone: `ros2 run robot_calib compensator --ros-args -p params:=params_best.json`.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from robot_calib.compensation import Compensation, compensate_commands
from robot_calib.compensation.write import LARGE_CHANGE_DEG
from robot_calib.errors import InputError, RobotCalibError
from robot_calib.identify.calibration import Calibration
from robot_calib.identify.params_file import check_plausible
from robot_calib.kinematics.description import with_joint_names
from robot_calib.kinematics.frames import Array
from robot_calib.messages import JOINT_STATES_TOPIC, joint_positions, velocity_signs
from robot_calib.nodes._common import declare, in_ros_terms, run_node
from robot_calib.poses import DirectionTracker, Poses, approach_directions

INPUT_TOPIC = "~/joint_trajectory_in"
OUTPUT_TOPIC = "/joint_trajectory_controller/joint_trajectory"  # ros2_control's JTC listens here


def trajectory_readings(msg: Any, joint_names: tuple[str, ...], where: str) -> tuple[Array, Array]:
    """The positions of a JointTrajectory as readings (n, J) [rad] in the model's joint order
    (matched by name) and time_from_start (n,) [s]; InputError naming `where` for unknown,
    missing or repeated names, points of the wrong length, non-finite positions, no points."""
    names = list(msg.joint_names)
    unknown = [n for n in names if n not in joint_names]
    missing = [n for n in joint_names if n not in names]
    if unknown or missing or len(set(names)) != len(names):
        raise InputError(
            f"{where}: joint_names {names} are not the calibration's joints "
            f"{list(joint_names)} (unknown {unknown}, missing {missing}); map them with the "
            "parameter joint_names"
        )
    if not msg.points:
        raise InputError(f"{where}: a trajectory without points")
    order = [names.index(n) for n in joint_names]
    rows, times = [], []
    for k, point in enumerate(msg.points):
        if len(point.positions) != len(names):
            raise InputError(
                f"{where}: point {k} has {len(point.positions)} positions for "
                f"{len(names)} joint_names"
            )
        rows.append([point.positions[i] for i in order])
        times.append(point.time_from_start.sec + 1e-9 * point.time_from_start.nanosec)
    q = np.array(rows, dtype=float)
    if not np.all(np.isfinite(q)):
        raise InputError(f"{where}: positions not finite")
    return q, np.array(times)


def corrected_trajectory(msg: Any, q: Array, joint_names: tuple[str, ...]) -> JointTrajectory:
    """A copy of JointTrajectory `msg` with every point's positions replaced by readings
    q (n, J) [rad] (model joint order; written back in the message's order)."""
    column = [joint_names.index(n) for n in msg.joint_names]
    out = JointTrajectory(header=msg.header, joint_names=list(msg.joint_names))
    for point, row in zip(msg.points, q):
        out.points.append(
            JointTrajectoryPoint(
                positions=[float(row[j]) for j in column],
                velocities=list(point.velocities),
                accelerations=list(point.accelerations),
                effort=list(point.effort),
                time_from_start=point.time_from_start,
            )
        )
    return out


class CompensatorNode(Node):
    """JointTrajectory in, compensated JointTrajectory out (module docstring); counts in
    `received`, `published`, `dropped`; `last` is the last Compensation."""

    def __init__(self, **kwargs: Any) -> None:  # rclpy.node.Node's keyword arguments
        super().__init__("compensator", **kwargs)
        params_file: str = declare(self, "params", "", "PARAMS.json of the calibration (required)")
        input_topic: str = declare(
            self, "input_topic", INPUT_TOPIC, "JointTrajectory to correct (nominal model's)"
        )
        output_topic: str = declare(
            self, "output_topic", OUTPUT_TOPIC, "corrected JointTrajectory (to the controller)"
        )
        joint_names: list[str] = declare(
            self,
            "joint_names",
            [],
            "the trajectory's names of the calibration's joints 1..J, in order (default: the "
            "robot description's names)",
        )
        temperature: float = declare(
            self,
            "temperature_c",
            float("nan"),
            "the robot's temperature [deg C], for a model that follows it (default: none)",
        )
        depth: int = declare(self, "qos_depth", 10, "queue depth of both topics")
        self.max_correction = declare(
            self,
            "max_correction",
            LARGE_CHANGE_DEG,
            "a trajectory with a point corrected by more than this [deg] (near a singularity) "
            "or not reached is dropped, not sent",
        )
        use_anyway: bool = declare(
            self,
            "force",
            False,
            "use a PARAMS.json marked plausible: false (a fit that ended in nonsense) anyway",
        )
        states_topic: str = declare(
            self,
            "joint_states_topic",
            JOINT_STATES_TOPIC,
            "the robot's joint states: where a trajectory starts and each joint's last "
            "approach direction (backlash); '' = not read, the first point's directions +1",
        )
        action_controller: str = declare(
            self,
            "action_controller",
            "",
            "the controller's control_msgs/FollowJointTrajectory action (e.g. "
            "/joint_trajectory_controller/follow_joint_trajectory): serve "
            "~/follow_joint_trajectory in front of it, goals compensated ('' = none)",
        )
        if not params_file:
            raise InputError(f"{self.get_name()}: parameter 'params' (PARAMS.json) is required")
        # the one loader of PARAMS.json (a hybrid calibration's learned correction included,
        # applied by the compensation)
        self.calibration = Calibration.load(params_file)
        # a calibration marked implausible never steers a robot unless asked for (`force`),
        # as compensate, predict and export refuse it
        reasons = self.calibration.implausible
        warning = check_plausible(reasons, params_file, use_anyway)
        if warning is not None:
            self.get_logger().warning(warning)
        if joint_names:
            robot = with_joint_names(self.calibration.model.robot, joint_names)
            model = replace(self.calibration.model, robot=robot)
            self.calibration = replace(self.calibration, model=model)
        self.model = self.calibration.model
        self.temperature = temperature
        # reliable and volatile, as ros2_control's joint_trajectory_controller subscribes
        qos = QoSProfile(
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
            history=HistoryPolicy.KEEP_LAST,
            depth=depth,
        )
        self.publisher = self.create_publisher(JointTrajectory, output_topic, qos)
        # each trajectory's outcome for its sender: corrected (OK) or dropped and why (ERROR)
        self.status = self.create_publisher(DiagnosticStatus, "~/status", qos)
        self.subscription = self.create_subscription(
            JointTrajectory, input_topic, self.on_trajectory, qos
        )
        self.robot_state: tuple[Array, Array] | None = None  # readings, directions (J,)
        self._directions = DirectionTracker()
        if states_topic:
            self.create_subscription(JointState, states_topic, self.on_joint_state, 100)
        self._warned_no_state = False
        self.received = self.published = self.dropped = 0
        self.last_error: str | None = None  # the last dropped trajectory's error line
        self.last: Compensation | None = None
        self.adapter = None
        if action_controller:
            try:
                from robot_calib.nodes.compensator_action import FollowJointTrajectoryAdapter

                self.adapter = FollowJointTrajectoryAdapter(self, action_controller)
            except ImportError as exc:
                raise InputError(
                    f"{self.get_name()}: parameter 'action_controller': "
                    f"control_msgs is not installed ({exc.name}): install "
                    "ros-jazzy-control-msgs, or leave it ''"
                ) from None
        self.get_logger().info(
            f"compensating {self.subscription.topic_name} -> {self.publisher.topic_name} "
            f"with {params_file} ({self.model.robot.name}, joints "
            f"{list(self.model.robot.joint_names)})"
        )

    def on_joint_state(self, msg: JointState) -> None:
        """Track where the robot stands and each joint's last approach direction (the
        velocity's sign where it has one, else its last motion beyond the tolerance:
        `poses.DirectionTracker`)."""
        try:
            q = joint_positions(msg, self.model.robot.joint_names)
        except InputError as exc:
            self.get_logger().error(in_ros_terms(exc), throttle_duration_sec=10.0)
            return
        self._directions.add(q, velocity_signs(msg, self.model.robot.joint_names))
        assert self._directions.direction is not None
        self.robot_state = (q, self._directions.direction.copy())

    def commands(self, q: Array, time: Array) -> Poses:
        """The trajectory's points as commands: readings (n, J) [rad], directions from the
        motion since the robot's last joint state and between consecutive points, times
        (n,) [s], the temperature parameter."""
        if self.robot_state is None and not self._warned_no_state:
            self._warned_no_state = True
            self.get_logger().warning(
                "no joint state yet: the first point's approach directions are assumed +1 "
                "(backlash compensation may be off for joints that keep still)"
            )
        direction = approach_directions(q, start=self.robot_state)
        poses = Poses.from_readings(q, direction, time)
        if np.isfinite(self.temperature):
            poses = replace(poses, temperature=np.full(len(poses), self.temperature))
        return poses

    def _drop(self, error: str, msg: JointTrajectory) -> None:
        self.dropped += 1
        self.last_error = error
        self.get_logger().error(error)
        said = error.replace("dropped a trajectory, not sent: ", "dropped, not sent: ")
        self._report(DiagnosticStatus.ERROR, said, msg)

    def _report(
        self,
        level: bytes,
        message: str,
        msg: JointTrajectory,
        values: Sequence[tuple[str, str]] = (),
    ) -> None:
        """One trajectory's outcome on ~/status: level, one line, the trajectory's stamp
        and points (which trajectory it was), and `values`."""
        stamp = f"{msg.header.stamp.sec}.{msg.header.stamp.nanosec:09d}"
        status = DiagnosticStatus(
            level=level,
            name=f"{self.get_name()}: trajectory",
            message=message,
            hardware_id=self.model.robot.name,
        )
        every = (("stamp", stamp), ("points", str(len(msg.points))), *values)
        status.values = [KeyValue(key=k, value=v) for k, v in every]
        self.status.publish(status)

    def on_trajectory(self, msg: JointTrajectory) -> None:
        """A trajectory on the input topic: compensated and sent on (`compensated`)."""
        corrected = self.compensated(msg, self.subscription.topic_name)
        if corrected is not None:
            self.publisher.publish(corrected)

    def compensated(self, msg: JointTrajectory, where: str) -> JointTrajectory | None:
        """Trajectory `msg` (received on `where`) with every point compensated, its outcome
        reported on ~/status and logged; None when it is dropped (`last_error` says why):
        what the topic and the FollowJointTrajectory adapter (compensator_action.py) send."""
        self.received += 1
        names = self.model.robot.joint_names
        try:
            q, time = trajectory_readings(msg, names, where)
            # the one check of limits and units, as `compensate` and sim_robot apply it:
            # degrees or a point beyond the limits never reach the controller
            self.model.robot.check_joints(q, where, what="point")
            result = compensate_commands(self.calibration, self.commands(q, time))
            if result.converged.all():
                self.model.robot.check_joints(result.q, f"{where}: compensated", what="point")
        except RobotCalibError as exc:
            self._drop(f"dropped a trajectory, not sent: {in_ros_terms(exc)}", msg)
            return None
        change = np.abs(result.q - q)
        k, j = np.unravel_index(int(np.argmax(change)), change.shape)
        if not result.converged.all() or np.degrees(change[k, j]) > self.max_correction:
            bad = np.flatnonzero(~result.converged).tolist()
            self._drop(
                f"dropped a trajectory, not sent: points {bad[:10]} not reached by the "
                f"calibrated model (singularity or out of reach)"
                if bad
                else f"dropped a trajectory, not sent: point {k} {names[j]} would be corrected by "
                f"{np.degrees(change[k, j]):.3f} deg > max_correction {self.max_correction:g} "
                "deg (near a singularity?)",
                msg,
            )
            return None
        self.published += 1
        self.last = result
        line = (
            f"{len(q)} points compensated; largest correction {change[k, j] * 1e3:.3f} "
            f"mrad ({names[j]}, point {k}); model error max "
            f"{result.error_m.max() * 1e6:.3f} um"
        )
        self.get_logger().info(line)
        self._report(
            DiagnosticStatus.OK,
            f"corrected: {line}",
            msg,
            (
                ("largest_correction_mrad", f"{change[k, j] * 1e3:.6f}"),
                ("model_error_max_um", f"{result.error_m.max() * 1e6:.6f}"),
            ),
        )
        return corrected_trajectory(msg, result.q, names)


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node(CompensatorNode, args, name="compensator"))


if __name__ == "__main__":
    main()
