"""calibrator: identify a model from bags or from live topics and publish it, latched.

Bag mode (parameter `bags` set): once at start, read and pair the bags (msgs_doc/specification.md
section 1), calibrate, publish. Live mode (`bags` empty): buffer /joint_states and
/laser_tracker/point (with parameter `targets` also further targets' /laser_tracker/NAME/point,
with `six_dof_targets` 6-DoF probes' /laser_tracker/(NAME/)pose); on a call of the service
`~/solve` (std_srvs/srv/Trigger: the outcome as success + one line), a std_msgs/Empty on
the topic `~/solve`, or after `solve_after_idle_s` without a new point ("the plan has
ended"), pair everything received so far exactly as a bag is paired and calibrate. The
service `~/calibrate` (diagnostic_msgs/srv/SelfTest) does the same for a release more,
deprecated: its first call logs a warning naming `~/solve`. Results go out on latched (transient
local) topics: `~/parameters` (the PARAMS.json document), `~/summary`, `~/residuals` and
`~/markers` (RViz / Foxglove). Topics, layouts and parameters: msgs_doc/calibrator.md.

Bad input (RobotCalibError) is logged as one error line. A live node keeps running;
standalone in bag mode the node then exits with status 2.

Standalone: `ros2 run robot_calib calibrator --ros-args -p bags:="['run.mcap']"`.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from diagnostic_msgs.srv import SelfTest
from geometry_msgs.msg import Point, PointStamped, PoseStamped, PoseWithCovarianceStamped
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import QoSRequestedIncompatibleQoSInfo, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Empty, Float64MultiArray, MultiArrayDimension, String
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from robot_calib.diagnose.diagnosis import Diagnosis
from robot_calib.errors import InputError, RobotCalibError
from robot_calib.flows import DEFAULT_ROBOT
from robot_calib.flows.bags import read_bags
from robot_calib.flows.calibrate import calibrate_recording
from robot_calib.flows.diagnose import diagnose_recordings
from robot_calib.identify import DEFAULT_ECC_ORDER, DEFAULT_MODEL
from robot_calib.identify.calibrate import parse_model
from robot_calib.identify.calibration import Calibration, summary
from robot_calib.identify.params_file import write_json_atomic
from robot_calib.kinematics.description import with_joint_names
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.loader import load_robot
from robot_calib.measurements import PAIR_TOLERANCE_S, Recording, recording_from_stream
from robot_calib.measurements.six_dof import PoseReading, join_poses
from robot_calib.messages import (
    JOINT_STATES_TOPIC,
    POSE_COV_TYPE,
    POSE_TYPE,
    TRACKER_FRAME,
    joint_positions,
    pose_measurement,
    pose_topic,
    stamp_to_ns,
    target_topic,
    velocity_signs,
)
from robot_calib.nodes._common import declare, overrides, run_node
from robot_calib.poses import PRIMARY_TARGET, TARGET_NAME

LATCHED = QoSProfile(  # late joiners (RViz, a test, `ros2 topic echo`) get the last result
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
DEFAULT_QOS_DEPTH = 10000
AXIS_LENGTH_M = 0.3  # drawn length of an identified joint axis, centred on its circles
CIRCLE_SEGMENTS = 72
RESIDUAL_FIELDS = "x,y,z,residual"  # the columns of ~/residuals (msgs_doc/calibrator.md)
STEADY = ClockType.STEADY_TIME  # timers run on wall time also when /clock stands still
FIRST_TARGET = "first"  # the first target's name in `six_dof_targets` (as in a world file)
POSE_CLASSES = {POSE_TYPE: PoseStamped, POSE_COV_TYPE: PoseWithCovarianceStamped}
DISCOVERY_PERIOD_S = 0.1  # how often the graph is asked for the type of a pose topic


class CalibratorNode(Node):
    """Calibrates from `bags`, or from live topics when `bags` is empty.

    In-process: `CalibratorNode(bags=[...], context=...)`; keyword values become parameter
    overrides (as do `parameter_overrides=[Parameter(...)]`; keywords win). `solve()` pairs
    and calibrates what live mode received so far. `calibration` is the last result,
    `error` the last bad-input error (logged), `failed` tells that bag mode failed.
    Raises RobotCalibError on bad parameters (unknown robot or model, missing output folder).
    """

    def __init__(
        self,
        bags: Sequence[str | os.PathLike[str]] | None = None,
        *,
        model: str | None = None,
        robot: str | None = None,
        output: str | os.PathLike[str] | None = None,
        solve_after_idle_s: float | None = None,
        node_name: str = "calibrator",
        parameter_overrides: Sequence[Parameter] | None = None,
        **node_kwargs: Any,
    ) -> None:
        values = {
            "bags": None if bags is None else [os.fspath(b) for b in bags],
            "model": model,
            "robot": robot,
            "output": None if output is None else os.fspath(output),
            "solve_after_idle_s": solve_after_idle_s,
        }
        super().__init__(
            node_name, parameter_overrides=overrides(values, parameter_overrides), **node_kwargs
        )
        try:
            self._declare_parameters()
        except RobotCalibError:
            super().destroy_node()
            raise
        self.calibration: Calibration | None = None
        self.diagnosis: Diagnosis | None = None  # the last diagnosis (parameter `diagnose`)
        self.recording: Recording | None = None
        self.error: RobotCalibError | None = None
        self.solves = 0
        self._result_publishers = {
            "parameters": self.create_publisher(String, "~/parameters", LATCHED),
            "summary": self.create_publisher(String, "~/summary", LATCHED),
            "residuals": self.create_publisher(Float64MultiArray, "~/residuals", LATCHED),
            "markers": self.create_publisher(MarkerArray, "~/markers", LATCHED),
        }
        if self.diagnose:
            self._result_publishers["diagnosis"] = self.create_publisher(
                String, "~/diagnosis", LATCHED
            )
            self._result_publishers["diagnosis_summary"] = self.create_publisher(
                String, "~/diagnosis_summary", LATCHED
            )
        steady = Clock(clock_type=STEADY)
        # Solving takes seconds: its callbacks share one mutually exclusive group (one solve
        # at a time), apart from the default group of the subscriptions and the parameter
        # services, so under a MultiThreadedExecutor the node keeps answering while it
        # solves (ros2/examples callback_group.py).
        self._solver_group = MutuallyExclusiveCallbackGroup()
        self._lock = threading.Lock()  # the live buffers, shared with the solving thread
        self.busy = False  # a solve is running
        self.stopping = False  # destroy_node was called: a running solve publishes nothing
        self._warned_calibrate = False  # the deprecated ~/calibrate warns once
        group = self._solver_group
        self.create_service(Trigger, "~/solve", self._on_solve_service, callback_group=group)
        # deprecated (issue 16): SelfTest on ~/calibrate, kept for one release beside ~/solve
        self.create_service(SelfTest, "~/calibrate", self._on_calibrate, callback_group=group)
        if self.bags:
            self._once = self.create_timer(
                0.0, self._solve_bags, clock=steady, callback_group=self._solver_group
            )
            self.get_logger().info(f"calibrating {self.model_spec} from {', '.join(self.bags)}")
            return
        self._js_ns: list[int] = []
        self._js_q: list[Array] = []
        self._js_v: list[Array] = []
        self._pt_ns: list[int] = []
        self._pt_xyz: list[Array] = []
        self._pt_target: list[int] = []  # index into target_names
        self._poses: list[dict[int, PoseReading]] = [{} for _ in self.target_names]
        self._counts = dict.fromkeys([JOINT_STATES_TOPIC, *self.live_topics], 0)
        self.rejected = 0
        self._last_point_s: float | None = None
        self._unsolved = False
        live_qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=self.qos_depth,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
        )
        self._live_qos = live_qos
        self._subscribe(JointState, JOINT_STATES_TOPIC, self._on_joint_state)
        for k, name in enumerate(self.target_names):
            if name in self.point_targets:
                self._subscribe(PointStamped, target_topic(name), partial(self._on_point, k))
        # a pose topic's type (PoseStamped or PoseWithCovarianceStamped) comes from the graph
        self._pending_poses = {pose_topic(t): k for k, t in enumerate(self.target_names)
                               if t in self.six_dof_targets}  # fmt: skip
        if self._pending_poses:
            self._discovery_timer = self.create_timer(
                DISCOVERY_PERIOD_S, self._discover_poses, clock=steady
            )
            self._discover_poses()
        self.create_subscription(Empty, "~/solve", self._on_solve, 10, callback_group=group)
        if self.solve_after_idle_s > 0:
            period = min(self.solve_after_idle_s / 4, 0.5)
            self._idle_timer = self.create_timer(
                period, self._check_idle, clock=steady, callback_group=group
            )
        idle = (
            f", or {self.solve_after_idle_s} s after the last point"
            if self.solve_after_idle_s > 0
            else ""
        )
        topics = [JOINT_STATES_TOPIC, *self.live_topics]
        self.get_logger().info(
            f"collecting {', '.join(topics[:-1])} and {topics[-1]}; solving {self.model_spec} "
            f"on {self.resolve_topic_name('~/solve')} (topic std_msgs/msg/Empty or service "
            f"std_srvs/srv/Trigger){idle}"
        )

    def _solve_on_request(self) -> tuple[Calibration | None, str]:
        """A service's solve: live mode solves now, bag mode answers with the bags' result.
        Returns the calibration (None on failure) and one line: the model and its in-sample
        accuracy (seed criterion and absolute, mm, points fitted), or the error."""
        cal = self.calibration if self.bags else self.solve()
        if cal is None:
            return None, str(self.error) if self.error else "no calibration"
        return cal, f"{cal.name}: in-sample {cal.accuracy.line()}"

    def _on_solve_service(self, _request: Trigger.Request, response: Trigger.Response) -> Any:
        """Service ~/solve (std_srvs/srv/Trigger): solve now; `success` and one line."""
        cal, response.message = self._solve_on_request()
        response.success = cal is not None
        return response

    def _on_calibrate(self, _request: SelfTest.Request, response: SelfTest.Response) -> Any:
        """Deprecated service ~/calibrate (diagnostic_msgs/srv/SelfTest: empty request): as
        ~/solve, the outcome as one DiagnosticStatus (message = accuracy or the error). The
        first call logs a deprecation warning naming ~/solve."""
        if not self._warned_calibrate:
            self._warned_calibrate = True
            self.get_logger().warning(
                f"service {self.resolve_service_name('~/calibrate')} "
                "(diagnostic_msgs/srv/SelfTest) is deprecated and goes in the next release: "
                f"call {self.resolve_service_name('~/solve')} (std_srvs/srv/Trigger) instead"
            )
        cal, message = self._solve_on_request()
        status = DiagnosticStatus(name=self.get_fully_qualified_name(), hardware_id="")
        if cal is None:
            status.level = DiagnosticStatus.ERROR
            status.message = message
        else:
            status.level = DiagnosticStatus.OK
            status.message = cal.accuracy.line()
            acc = cal.accuracy
            status.values = [
                KeyValue(key=k, value=v)
                for k, v in (
                    ("model", cal.name),
                    ("points", str(acc.n_points)),
                    ("absolute_mean_mm", f"{acc.absolute_mean_mm:.6f}"),
                    ("absolute_max_mm", f"{acc.absolute_max_mm:.6f}"),
                    ("pairwise_mean_mm", f"{acc.pairwise_mean_mm:.6f}"),
                    ("pairwise_max_mm", f"{acc.pairwise_max_mm:.6f}"),
                )
            ]
        response.id = cal.name if cal is not None else ""
        response.passed = bytes([cal is not None])
        response.status = [status]
        return response

    def _declare_parameters(self) -> None:
        self.bags: list[str] = declare(
            self, "bags", [], "calibration bags (.mcap) to solve at start; empty: live topics"
        )
        self.model_spec: str = declare(
            self,
            "model",
            DEFAULT_MODEL,
            "model to identify, e.g. geometric, geometric+eccentricity",
        )
        self.ecc_order: int = declare(
            self, "ecc_order", DEFAULT_ECC_ORDER, "Fourier order of the eccentricity effect [1]"
        )
        robot_name: str = declare(
            self, "robot", DEFAULT_ROBOT, "built-in robot name or robot YAML file"
        )
        joint_names: list[str] = declare(
            self,
            "joint_names",
            [],
            "JointState names of joints 1..J in order, if not the robot's own; empty: the robot's",
        )
        self.pair_tolerance: float = declare(
            self,
            "pair_tolerance",
            PAIR_TOLERANCE_S,
            "a point pairs with the joint state nearest in header.stamp within this [s]",
        )
        self.output: str = declare(
            self, "output", "", "also write each result to this PARAMS.json path ('' = no file)"
        )
        self.solve_after_idle_s: float = declare(
            self,
            "solve_after_idle_s",
            0.0,
            "live mode: solve when no new point arrived for this long after the last one "
            "[s, wall time]; 0 = only on ~/solve",
        )
        self.residual_scale: float = declare(
            self,
            "residual_scale",
            100.0,
            "residual lines in ~/markers are drawn this many times their length [1]",
        )
        self.learned_correction: bool = declare(
            self,
            "learned_correction",
            False,
            "also learn a correction of the model's residuals (a Gaussian process: the hybrid "
            "model, PARAMS.json correction), which predict, score and compensate apply",
        )
        self.diagnose: bool = declare(
            self,
            "diagnose",
            False,
            "also run the sim-to-real gap diagnosis and publish ~/diagnosis (+ _summary)",
        )
        self.holdout_bags: list[str] = declare(
            self, "holdout_bags", [], "hold-out bags for the diagnosis (empty: k-fold CV)"
        )
        self.qos_depth: int = declare(
            self,
            "qos_depth",
            DEFAULT_QOS_DEPTH,
            "live mode: history depth of the topic subscriptions [messages]",
        )
        further: list[str] = declare(
            self,
            "targets",
            [],
            "live mode: further targets NAME whose /laser_tracker/NAME/point to take too",
        )
        six_dof: list[str] = declare(
            self,
            "six_dof_targets",
            [],
            f"live mode: targets with a 6-DoF probe whose /laser_tracker/(NAME/)pose to take "
            f"('{FIRST_TARGET}' = the first target, /laser_tracker/pose)",
        )
        self.robot = load_robot(robot_name)
        if joint_names:
            self.robot = with_joint_names(self.robot, joint_names)
        parse_model(self.model_spec, self.robot, self.ecc_order)  # a bad model fails now
        name = self.get_name()
        if self.ecc_order < 1:
            raise InputError(f"{name}: parameter 'ecc_order' must be >= 1")
        if self.pair_tolerance <= 0:
            raise InputError(f"{name}: parameter 'pair_tolerance' must be > 0 [s]")
        if self.solve_after_idle_s < 0:
            raise InputError(f"{name}: parameter 'solve_after_idle_s' must be >= 0 [s]")
        if self.residual_scale <= 0:
            raise InputError(f"{name}: parameter 'residual_scale' must be > 0")
        if self.qos_depth < 1:
            raise InputError(f"{name}: parameter 'qos_depth' must be >= 1")
        if self.output and not Path(self.output).parent.is_dir():
            raise InputError(f"{self.output}: no such folder for the parameter file")
        self._live_targets(further, six_dof)

    def _live_targets(self, further: list[str], six_dof: list[str]) -> None:
        """The targets of live mode from the parameters `targets` and `six_dof_targets`:
        `target_names` ('' first, then by name, as a bag's topics are read), `point_targets`
        (point topics taken), `six_dof_targets` (pose topics taken) and `live_topics`."""
        name = self.get_name()
        for param, values in (("targets", further), ("six_dof_targets", six_dof)):
            bad = [v for v in values if v != FIRST_TARGET and not TARGET_NAME.fullmatch(v)]
            if param == "targets" and FIRST_TARGET in values:
                bad.append(FIRST_TARGET)  # names the first target in six_dof_targets
            if bad or len(set(values)) != len(values):
                raise InputError(
                    f"{name}: parameter {param!r}: {values}: want distinct target names "
                    f"(letters, digits, underscores, starting with a letter; '{FIRST_TARGET}' "
                    "in six_dof_targets only, for the first target)"
                )
        probes = {PRIMARY_TARGET if t == FIRST_TARGET else t for t in six_dof}
        self.point_targets: tuple[str, ...] = (PRIMARY_TARGET, *further)
        self.six_dof_targets: tuple[str, ...] = tuple(sorted(probes))
        self.target_names: tuple[str, ...] = (
            PRIMARY_TARGET, *sorted((set(further) | probes) - {PRIMARY_TARGET}),
        )  # fmt: skip
        self.live_topics: list[str] = [
            *(target_topic(t) for t in self.target_names if t in self.point_targets),
            *(pose_topic(t) for t in self.six_dof_targets),
        ]

    # --- public ---------------------------------------------------------------------------

    def destroy_node(self) -> None:
        """Destroy the node; a solve still running in another thread then publishes nothing
        (its thread ends with the solve)."""
        self.stopping = True
        super().destroy_node()

    @property
    def failed(self) -> bool:
        """Bag mode could not calibrate (standalone: exit status 2)."""
        return bool(self.bags) and self.error is not None

    @property
    def received(self) -> dict[str, int]:
        """Live mode: messages buffered per topic (joint states refused are not counted)."""
        if self.bags:
            return {}
        with self._lock:
            return dict(self._counts)

    def solve(self) -> Calibration | None:
        """Live mode: pair everything received so far, calibrate and publish. Bad input is
        logged (one line) and kept in `error`; returns None then."""
        if self.bags:
            self.get_logger().warning("~/solve ignored: the node calibrates from its bags")
            return None
        names = self.robot.joint_names
        with self._lock:  # a consistent snapshot while the subscriptions keep appending
            self._unsolved = False
            js_ns = np.array(self._js_ns, dtype=np.int64)
            js_q = np.array(self._js_q).reshape(-1, len(names))
            js_v = np.array(self._js_v).reshape(-1, len(names))
            pt_ns, pt_xyz, pt_target = list(self._pt_ns), list(self._pt_xyz), list(self._pt_target)
            poses = [dict(by_stamp) for by_stamp in self._poses]
        source = "live " + " + ".join([JOINT_STATES_TOPIC, *self.live_topics])
        targets = self.target_names
        try:
            # a pose joins the point of its target and stamp, as in a bag (msgs_doc/six_dof.md)
            stamped = join_poses(source, targets, pt_ns, pt_xyz, pt_target, poses, set(pt_target))
            recording = recording_from_stream(
                js_ns, js_q, js_v, stamped.point_ns, stamped.points, self.pair_tolerance,
                source=source, robot=self.robot,
                point_target=stamped.point_target if len(targets) > 1 else None,
                target_names=targets, rotation=stamped.rotation, sigma=stamped.sigma,
            )  # fmt: skip
            for warning in recording.warnings:
                self._log(warning)
            return self._calibrate(recording)
        except RobotCalibError as exc:
            self._fail(exc)
            return None

    # --- internals ------------------------------------------------------------------------

    def _solve_bags(self) -> None:
        self._once.cancel()
        try:
            recording = read_bags(self.bags, self.robot, self.pair_tolerance, self._log)
            self._calibrate(recording)
        except RobotCalibError as exc:
            self._fail(exc)

    def _calibrate(self, recording: Recording) -> Calibration:
        """Calibrate `recording`, write `output` if set, publish every result topic."""
        self.busy = True
        try:
            return self._calibrate_and_publish(recording)
        finally:
            self.busy = False

    def _calibrate_and_publish(self, recording: Recording) -> Calibration:
        self.get_logger().info(recording.summary())
        cal = calibrate_recording(
            recording, self.robot, self.model_spec, self.ecc_order, log=self._log
        )
        if self.learned_correction:  # the hybrid model (`Calibration.with_learned_correction`)
            cal = cal.with_learned_correction(recording)
            correction = cal.correction
            for line in [] if correction is None else [correction.line(), *correction.warnings]:
                self._log(line)
        doc = cal.to_dict(recording)
        if self.stopping:  # destroyed while solving (Ctrl-C): nothing to publish to
            return cal
        if self.output:
            try:
                write_json_atomic(doc, Path(self.output))
            except OSError as exc:
                raise InputError(f"{self.output}: cannot write ({exc.strerror})") from None
        self._result_publishers["parameters"].publish(String(data=json.dumps(doc)))
        # residuals and markers of the points fitted (tracker blunders are left out)
        fitted_points = recording.points if cal.inliers is None else recording.points[cal.inliers]
        self._result_publishers["summary"].publish(String(data=summary(cal, recording)))
        self._result_publishers["residuals"].publish(
            residuals_message(fitted_points, cal.residuals)
        )
        self._result_publishers["markers"].publish(
            calibration_markers(cal, fitted_points, self.residual_scale)
        )
        if self.diagnose:
            self._diagnose(recording)
        self.calibration, self.recording, self.error = cal, recording, None
        self.solves += 1
        written = f", written to {self.output}" if self.output else ""
        self.get_logger().info(f"{cal.name}: {cal.accuracy.line()}; published{written}")
        return cal

    def _diagnose(self, recording: Recording) -> None:
        """Run the diagnosis on `recording` (scored on `holdout_bags` or k-fold) and publish
        the DIAGNOSIS.json document and its one-paragraph summary."""
        holdout = None
        if self.holdout_bags:
            holdout = read_bags(self.holdout_bags, self.robot, self.pair_tolerance, self._log)
        diagnosis, _ = diagnose_recordings(recording, self.robot, holdout)
        if self.stopping:
            return
        self.diagnosis = diagnosis
        self._result_publishers["diagnosis"].publish(String(data=json.dumps(diagnosis.to_dict())))
        self._result_publishers["diagnosis_summary"].publish(String(data=diagnosis.summary()))
        self.get_logger().info(diagnosis.summary())

    def _fail(self, exc: RobotCalibError) -> None:
        self.error = exc
        self.get_logger().error(str(exc))

    def _log(self, message: str) -> None:
        """The core's progress lines as info, its 'warning: ...' lines as warnings."""
        if message.startswith("warning: "):
            self.get_logger().warning(message.removeprefix("warning: "))
        else:
            self.get_logger().info(message.strip())

    def _on_incompatible_qos(self, topic: str, event: QoSRequestedIncompatibleQoSInfo) -> None:
        self.get_logger().warning(
            f"{topic}: a publisher's QoS is incompatible with RELIABLE "
            f"(policy {event.last_policy_kind}); its messages are not received"
        )

    def _on_solve(self, _msg: Empty) -> None:
        self.solve()

    def _on_joint_state(self, msg: JointState) -> None:
        names = self.robot.joint_names
        try:
            q = joint_positions(msg, names)
        except InputError as exc:
            self.rejected += 1
            self.get_logger().warning(
                f"{exc} ({self.rejected} refused so far)", throttle_duration_sec=10.0
            )
            return
        with self._lock:
            self._js_ns.append(stamp_to_ns(msg.header.stamp))
            self._js_q.append(q)
            self._js_v.append(velocity_signs(msg, names))
            self._counts[JOINT_STATES_TOPIC] += 1

    def _subscribe(self, msg_type: type, topic: str, callback: Any) -> None:
        """A live subscription (RELIABLE, VOLATILE, qos_depth) warning of incompatible QoS."""
        self.create_subscription(
            msg_type,
            topic,
            callback,
            self._live_qos,
            event_callbacks=SubscriptionEventCallbacks(
                incompatible_qos=partial(self._on_incompatible_qos, topic)
            ),
        )

    def _discover_poses(self) -> None:
        """Subscribe to each pose topic once the graph shows its type (a publisher exists)."""
        graph = dict(self.get_topic_names_and_types())
        for topic, k in list(self._pending_poses.items()):
            types = [t for t in graph.get(topic, []) if t in POSE_CLASSES]
            if not types:
                if graph.get(topic):
                    self.get_logger().warning(
                        f"{topic}: type {graph[topic]} is none of {list(POSE_CLASSES)}: "
                        "waiting for a publisher of one of them",
                        throttle_duration_sec=10.0,
                    )
                continue
            del self._pending_poses[topic]
            self._subscribe(POSE_CLASSES[types[0]], topic, partial(self._on_pose, k, topic))
            self.get_logger().info(f"{topic}: subscribed as {types[0]}")
        if not self._pending_poses:
            self._discovery_timer.cancel()

    def _check_frame(self, topic: str, frame_id: str) -> None:
        if frame_id != TRACKER_FRAME:
            self.get_logger().warning(
                f"{topic}: frame_id {frame_id!r} is not '{TRACKER_FRAME}' "
                "(used as the tracker frame anyway)",
                once=True,
            )

    def _on_point(self, target: int, msg: PointStamped) -> None:
        topic = target_topic(self.target_names[target])
        xyz = np.array([msg.point.x, msg.point.y, msg.point.z])
        if not np.all(np.isfinite(xyz)):
            self.get_logger().warning(f"{topic}: point not finite {xyz}: ignored")
            return
        self._check_frame(topic, msg.header.frame_id)
        with self._lock:
            self._pt_ns.append(stamp_to_ns(msg.header.stamp))
            self._pt_xyz.append(xyz)
            self._pt_target.append(target)
            self._counts[topic] += 1
            self._last_point_s = time.monotonic()
            self._unsolved = True

    def _on_pose(
        self, target: int, topic: str, msg: PoseStamped | PoseWithCovarianceStamped
    ) -> None:
        try:
            where = f"{topic} message {self._counts[topic] + 1}"
            reading = pose_measurement(msg, where)
        except InputError as exc:
            self.get_logger().warning(f"{exc}: ignored", throttle_duration_sec=10.0)
            return
        self._check_frame(topic, msg.header.frame_id)
        with self._lock:
            self._poses[target][stamp_to_ns(msg.header.stamp)] = reading
            self._counts[topic] += 1
            self._last_point_s = time.monotonic()
            self._unsolved = True

    def _check_idle(self) -> None:
        """Solve once the points have stopped for solve_after_idle_s (the plan ended)."""
        with self._lock:
            due = (
                self._unsolved
                and self._last_point_s is not None
                and time.monotonic() - self._last_point_s >= self.solve_after_idle_s
            )
            n_poses = sum(len(by_stamp) for by_stamp in self._poses)
            what = f"{len(self._pt_ns)} points" + (f" and {n_poses} poses" if n_poses else "")
        if due:
            self.get_logger().info(f"no new point for {self.solve_after_idle_s} s: solving {what}")
            self.solve()


# --- messages of a result (no ROS graph needed) ---------------------------------------------


def residuals_message(measured: Array, residuals: Array) -> Float64MultiArray:
    """~/residuals: rows [x, y, z, |r|] of the measured points (n, 3) [m, tracker frame] and
    the norms of the residuals (n, 3) predicted - measured [m], row-major, dims [n, 4]."""
    table = np.column_stack([measured, np.linalg.norm(residuals, axis=1)])
    msg = Float64MultiArray()
    msg.layout.dim = [
        MultiArrayDimension(label="measurement", size=table.shape[0], stride=table.size),
        MultiArrayDimension(label=RESIDUAL_FIELDS, size=4, stride=4),
    ]
    msg.layout.data_offset = 0
    msg.data = table.ravel().tolist()
    return msg


def _points(xyz: Array | Sequence[Array]) -> list[Point]:
    return [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in xyz]


def _marker(ns: str, marker_id: int, kind: int, rgba: tuple[float, ...]) -> Marker:
    marker = Marker(ns=ns, id=marker_id, type=kind, action=Marker.ADD)
    marker.header.frame_id = TRACKER_FRAME  # stamp 0: RViz uses the latest transform
    marker.pose.orientation.w = 1.0
    marker.color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
    return marker


def circle_polyline(centre: Array, normal: Array, radius: float, n: int) -> Array:
    """Closed polyline (n + 1, 3) of the circle of `centre` (3,) [m], unit `normal` (3,),
    `radius` [m]: first point repeated last."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    angle = np.linspace(0.0, 2 * np.pi, n + 1)
    return centre + radius * (np.cos(angle)[:, None] * u + np.sin(angle)[:, None] * v)


def calibration_markers(cal: Calibration, measured: Array, residual_scale: float) -> MarkerArray:
    """~/markers in the tracker frame: a DELETEALL (clears an earlier result), then namespace
    "axes" (one ARROW per identified joint axis, id = joint), "circles" (one LINE_STRIP per
    fitted sweep circle), "measured" (SPHERE_LIST of the points) and "residuals" (LINE_LIST
    from each measured point towards its prediction, `residual_scale` times the residual)."""
    markers = [Marker(action=Marker.DELETEALL)]
    markers[0].header.frame_id = TRACKER_FRAME
    if cal.cpa is not None:
        for j, axis in enumerate(cal.cpa.axes, start=1):
            arrow = _marker("axes", j, Marker.ARROW, (0.1, 0.4, 1.0, 1.0))
            half = 0.5 * AXIS_LENGTH_M * axis.direction
            arrow.points = _points([axis.point - half, axis.point + half])
            arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.004, 0.010, 0.020  # shaft, head [m]
            markers.append(arrow)
        for k, sweep in enumerate(cal.cpa.sweeps):
            strip = _marker("circles", k, Marker.LINE_STRIP, (0.2, 0.8, 0.2, 1.0))
            c = sweep.circle
            strip.points = _points(circle_polyline(c.centre, c.normal, c.radius, CIRCLE_SEGMENTS))
            strip.scale.x = 0.001  # line width [m]
            markers.append(strip)
    dots = _marker("measured", 0, Marker.SPHERE_LIST, (1.0, 1.0, 1.0, 1.0))
    dots.points = _points(measured)
    dots.scale.x = dots.scale.y = dots.scale.z = 0.003  # sphere diameter [m]
    lines = _marker("residuals", 0, Marker.LINE_LIST, (1.0, 0.2, 0.1, 1.0))
    ends = measured + residual_scale * cal.residuals
    lines.points = _points(np.stack([measured, ends], axis=1).reshape(-1, 3))
    lines.scale.x = 0.0005  # line width [m]
    markers += [dots, lines]
    return MarkerArray(markers=markers)


def main(args: Sequence[str] | None = None) -> int:
    """`ros2 run robot_calib calibrator [--ros-args -p bags:="['A.mcap']" ...]`."""
    started: list[CalibratorNode] = []

    def start() -> CalibratorNode:
        started.append(CalibratorNode())
        return started[-1]

    status = run_node(
        start, args, done=lambda node: node.failed, name="calibrator", multithreaded=True
    )
    if status == 0 and started and started[0].failed:
        assert started[0].error is not None
        return started[0].error.exit_status
    return status


if __name__ == "__main__":
    raise SystemExit(main())
