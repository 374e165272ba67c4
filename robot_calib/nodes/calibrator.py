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
`~/markers` (RViz / Foxglove); a plausible result also as a calibrated URDF on
`robot_description` (latched, as robot_state_publisher publishes it), and the node's health
and accuracy on `/diagnostics` (nodes/ros_outputs.py, msgs_doc/ros_topics.md). Topics,
layouts and parameters: msgs_doc/calibrator.md.

The node is this adapter alone: its parameters are read in `calibrator_parameters.py`, live
mode's subscriptions and pairing live in `calibrator_live.py`, the result messages are built
in `calibrator_messages.py` and `ros_outputs.py`.

Bad input (RobotCalibError) is logged as one error line. A live node keeps running;
standalone in bag mode the node then exits with status 2.

Standalone: `ros2 run robot_calib calibrator --ros-args -p bags:="['run.mcap']"`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from diagnostic_msgs.srv import SelfTest
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.client import Client
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterUninitializedException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.timer import Timer
from std_msgs.msg import Empty, Float64MultiArray, String
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from robot_calib.diagnosis.diagnosis import Diagnosis
from robot_calib.diagnosis.ladder import Ladder
from robot_calib.errors import InputError, RobotCalibError
from robot_calib.flows.bags import read_bags
from robot_calib.flows.calibrate import calibrate_recording
from robot_calib.flows.diagnose import diagnose_recordings
from robot_calib.identify.calibration import Calibration, summary
from robot_calib.identify.params_file import write_json_atomic
from robot_calib.measurements import Recording
from robot_calib.messages import JOINT_STATES_TOPIC, TRACKER_FRAME
from robot_calib.nodes._common import declare, in_ros_terms, overrides, run_node
from robot_calib.nodes.calibrator_live import LiveInputs
from robot_calib.nodes.calibrator_messages import calibration_markers, residuals_message
from robot_calib.nodes.calibrator_parameters import (
    PARAMETER_NAMES,
    checked_parameters,
    declare_parameters,
)
from robot_calib.nodes.ros_outputs import (
    DIAGNOSTIC_PERIOD_S,
    DIAGNOSTICS_QOS,
    DIAGNOSTICS_TOPIC,
    ROBOT_DESCRIPTION_QOS,
    ROBOT_DESCRIPTION_TOPIC,
    HeldOut,
    calibrated_urdf,
    calibration_status,
    diagnostic_array,
    score_held_out,
    status_name,
    tracker_in_base,
)

# late joiners (RViz, a test, `ros2 topic echo`) get the last result: KEEP_LAST 1, RELIABLE,
# TRANSIENT_LOCAL, the profile robot_state_publisher gives /robot_description
LATCHED = ROBOT_DESCRIPTION_QOS
STEADY = ClockType.STEADY_TIME  # timers run on wall time also when /clock stands still
IDLE_CHECK_S = 0.1  # live mode: how often the idle solve (solve_after_idle_s) is checked


class CalibratorNode(LifecycleNode):
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
            self.settings = declare_parameters(self)
            autostart: bool = declare(
                self,
                "autostart",
                True,
                "configure and activate at once (false: stay unconfigured for a lifecycle "
                "manager: ros2 lifecycle set NODE configure, then activate)",
            )
        except RobotCalibError:
            super().destroy_node()
            raise
        self.calibration: Calibration | None = None
        self.diagnosis: Diagnosis | None = None  # the last diagnosis (parameter `diagnose`)
        self.recording: Recording | None = None
        self.error: RobotCalibError | None = None
        self.solves = 0
        self.held_out: HeldOut | None = None  # the last result scored on `holdout_bags`
        # what the diagnosis says of the published model ('' when nothing: `left_by_published`)
        self.diagnosis_note = ""
        self._description_note = ""  # what became of /robot_description (for /diagnostics)
        self.active = False  # lifecycle state active: solves and live topics taken
        self._rsp_client: Client | None = None  # robot_state_publisher's SetParameters
        self._static_tf: Any = None  # tf2_ros StaticTransformBroadcaster, where installed
        self._said_no_tf = False
        self._said_no_rsp = False
        self._live: LiveInputs | None = None  # live mode's buffers, from configure to cleanup
        self._once: Timer | None = None  # bag mode's solve at activation
        self._idle_timer: Timer | None = None  # live mode's idle solve check
        self._result_publishers = {
            "parameters": self.create_publisher(String, "~/parameters", LATCHED),
            "summary": self.create_publisher(String, "~/summary", LATCHED),
            "residuals": self.create_publisher(Float64MultiArray, "~/residuals", LATCHED),
            "markers": self.create_publisher(MarkerArray, "~/markers", LATCHED),
            "diagnosis": self.create_publisher(String, "~/diagnosis", LATCHED),
            "diagnosis_summary": self.create_publisher(String, "~/diagnosis_summary", LATCHED),
        }
        self._description = self.create_publisher(
            String, ROBOT_DESCRIPTION_TOPIC, ROBOT_DESCRIPTION_QOS
        )
        self._diagnostics = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS
        )
        self._status = self._health(waiting="unconfigured (lifecycle): waiting for configure")
        self._steady = Clock(clock_type=STEADY)
        self.create_timer(DIAGNOSTIC_PERIOD_S, self._publish_status, clock=self._steady)
        # Solving takes seconds: its callbacks share one mutually exclusive group (one solve
        # at a time), apart from the default group of the parameter and lifecycle services,
        # so under a MultiThreadedExecutor the node keeps answering while it solves
        # (ros2/examples callback_group.py).
        self._solver_group = MutuallyExclusiveCallbackGroup()
        self.busy = False  # a solve is running
        self.stopping = False  # destroy_node was called: a running solve publishes nothing
        self._warned_calibrate = False  # the deprecated ~/calibrate warns once
        group = self._solver_group
        self.create_service(Trigger, "~/solve", self._on_solve_service, callback_group=group)
        # deprecated: SelfTest on ~/calibrate, kept for one release beside ~/solve
        self.create_service(SelfTest, "~/calibrate", self._on_calibrate, callback_group=group)
        self.create_service(Trigger, "~/reset", self._on_reset, callback_group=group)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        if autostart:
            for name, transition in (
                ("configure", self.trigger_configure),
                ("activate", self.trigger_activate),
            ):
                if transition() != TransitionCallbackReturn.SUCCESS:
                    super().destroy_node()
                    raise InputError(
                        f"{node_name}: the lifecycle transition {name} failed at start (autostart)"
                    )
        else:
            self.get_logger().info(
                "unconfigured: waiting for the lifecycle transitions configure and activate"
            )

    # --- lifecycle (rclpy.lifecycle: configure / activate / deactivate / cleanup) ------------

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Bag mode: nothing to set up; live mode: subscribe and start buffering."""
        del state
        if self.settings.bags:
            self.get_logger().info(
                f"calibrating {self.settings.model_spec} from {', '.join(self.settings.bags)}"
            )
            self._status = self._health(
                waiting="configured: calibrating from the bags once active"
            )
            return TransitionCallbackReturn.SUCCESS
        group = self._solver_group
        self._live = LiveInputs(
            self, self.settings.robot, self.settings.targets, self.settings.qos_depth, group
        )
        self._solve_topic = self.create_subscription(
            Empty, "~/solve", self._on_solve, 10, callback_group=group
        )
        self._start_idle_timer()
        topics = [JOINT_STATES_TOPIC, *self.settings.targets.topics]
        self.get_logger().info(
            f"collecting {', '.join(topics[:-1])} and {topics[-1]}; solving "
            f"{self.settings.model_spec} "
            f"on {self.resolve_topic_name('~/solve')} (topic std_msgs/msg/Empty or service "
            f"std_srvs/srv/Trigger){self._idle_text()}"
        )
        self._status = self._health(waiting="collecting live topics")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Take live topics and solves; bag mode solves its bags now (once)."""
        self.active = True
        if self._live is not None:
            self._live.drain()  # delivered while inactive: dropped, not taken now
            self._live.enabled = True
        if self.settings.bags and self.calibration is None and self._once is None:
            self._once = self.create_timer(
                0.0, self._solve_bags, clock=self._steady, callback_group=self._solver_group
            )
        return super().on_activate(state)

    def _refuse_while_solving(self, transition: str) -> bool:
        """True (and said) when a solve is running: a transition waits for its end."""
        if self.busy:
            self.get_logger().warning(
                f"{transition} refused: a solve is running; try again when it has ended"
            )
        return self.busy

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Keep the buffers and results; take no message and answer no solve (refused
        while a solve runs)."""
        if self._refuse_while_solving("deactivate"):
            return TransitionCallbackReturn.FAILURE
        self.active = False
        if self._live is not None:
            self._live.enabled = False
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Drop the live set (its subscriptions and buffers) and the results (refused while
        a solve runs)."""
        del state
        if self._refuse_while_solving("cleanup"):
            return TransitionCallbackReturn.FAILURE
        if self._once is not None:
            self.destroy_timer(self._once)
        if self._live is not None:
            self._live.close()
            self.destroy_subscription(self._solve_topic)
            if self._idle_timer is not None:
                self.destroy_timer(self._idle_timer)
                self._idle_timer = None
        self._live, self._once = None, None
        self._clear_results("unconfigured (lifecycle): waiting for configure")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        del state
        self.active = False
        return TransitionCallbackReturn.SUCCESS

    def _start_idle_timer(self) -> None:
        """Live mode with solve_after_idle_s > 0: the timer that checks for the idle solve
        (none otherwise: no callback every tick for nothing)."""
        if (
            self._idle_timer is None
            and self._live is not None
            and (self.settings.solve_after_idle_s > 0)
        ):
            self._idle_timer = self.create_timer(
                IDLE_CHECK_S,
                self._check_idle,
                clock=self._steady,
                callback_group=self._solver_group,
            )

    def _idle_text(self) -> str:
        idle = self.settings.solve_after_idle_s
        return f", or {idle} s after the last point" if idle > 0 else ""

    def _clear_results(self, waiting: str) -> None:
        """Forget the last result and error (the latched topics keep their last message)."""
        self.calibration = self.diagnosis = self.recording = self.error = None
        self.held_out, self.diagnosis_note, self._description_note = None, "", ""
        self._publish_status(self._health(waiting=waiting))

    def _on_reset(self, _request: Trigger.Request, response: Trigger.Response) -> Any:
        """Service ~/reset (std_srvs/srv/Trigger): begin a new set: live mode forgets every
        message received, both modes the last result (bag mode then solves its bags again
        when active)."""
        counts = {} if self._live is None else self._live.clear()
        self._clear_results("reset: collecting live topics" if self._live is not None else "reset")
        if self.settings.bags and self.active:
            self._once = self.create_timer(
                0.0, self._solve_bags, clock=self._steady, callback_group=self._solver_group
            )
        dropped = ", ".join(f"{t}={n}" for t, n in counts.items()) or "no live messages"
        response.success = True
        response.message = f"reset: dropped {dropped} and the last result"
        self.get_logger().info(response.message)
        return response

    def _value(self, name: str) -> Any:  # noqa: ANN401 - a parameter's value
        """Parameter `name`'s value ([] for an empty list never set: uninitialised)."""
        try:
            return self.get_parameter(name).value
        except ParameterUninitializedException:
            return []

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """Run-time parameters (calibrator_parameters.RUN_TIME) checked as at start and
        taking effect from the next solve; a bad value is refused with its reason."""
        values = {name: self._value(name) for name in PARAMETER_NAMES}
        values.update({p.name: p.value for p in parameters if p.name in values})
        try:
            self.settings = checked_parameters(self.get_name(), values, self.settings.robot)
        except RobotCalibError as exc:
            return SetParametersResult(successful=False, reason=in_ros_terms(exc))
        except (TypeError, ValueError) as exc:  # a value of another type than declared
            return SetParametersResult(successful=False, reason=f"{type(exc).__name__}: {exc}")
        self._start_idle_timer()  # solve_after_idle_s set > 0 at run time
        changed = ", ".join(f"{p.name}={p.value}" for p in parameters)
        self.get_logger().info(f"parameters changed: {changed} (from the next solve)")
        return SetParametersResult(successful=True)

    def _solve_on_request(self) -> tuple[Calibration | None, bool, str]:
        """A service's solve: live mode solves now, bag mode answers with the bags' result.
        Returns the calibration (None on failure), whether it is a result to use (False:
        none, or an implausible one: `solve_verdict`) and one line saying why or what."""
        if not self.active:
            state = "unconfigured" if self._live is None and not self.settings.bags else "inactive"
            todo = "configure and activate it first" if state == "unconfigured" else "activate it"
            return None, False, f"{self.get_name()} is {state} (lifecycle): {todo}"
        cal = self.calibration if self.settings.bags else self.solve()
        return (cal, *solve_verdict(cal, self.error, self.diagnosis_note))

    def _on_solve_service(self, _request: Trigger.Request, response: Trigger.Response) -> Any:
        """Service ~/solve (std_srvs/srv/Trigger): solve now; `success` (False without a
        result to use) and one line."""
        _, response.success, response.message = self._solve_on_request()
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
        cal, usable, message = self._solve_on_request()
        status = DiagnosticStatus(name=self.get_fully_qualified_name(), hardware_id="")
        if cal is None or not usable:
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
        response.passed = bytes([cal is not None and usable])
        response.status = [status]
        return response

    # --- public ---------------------------------------------------------------------------

    def destroy_node(self) -> None:
        """Destroy the node; a solve still running in another thread then publishes nothing
        (its thread ends with the solve)."""
        self.stopping = True
        super().destroy_node()

    @property
    def failed(self) -> bool:
        """Bag mode could not calibrate (standalone: exit status 2)."""
        return bool(self.settings.bags) and self.error is not None

    @property
    def received(self) -> dict[str, int]:
        """Live mode: messages buffered per topic (joint states refused are not counted)."""
        if self.settings.bags or self._live is None:
            return {}
        return self._live.counts

    def solve(self) -> Calibration | None:
        """Live mode: pair everything received so far, calibrate and publish. Bad input is
        logged (one line) and kept in `error`; returns None then."""
        if self.settings.bags:
            self.get_logger().warning("~/solve ignored: the node calibrates from its bags")
            return None
        live = self._live  # one reference: a cleanup cannot pull it away mid-solve
        if live is None or not self.active:
            self.get_logger().warning("~/solve ignored: the node is not active (lifecycle)")
            return None
        try:
            recording = live.recording(self.settings.pair_tolerance)
            for warning in recording.warnings:
                self._log(warning)
            return self._calibrate(recording)
        except RobotCalibError as exc:
            self._fail(exc)
            return None

    # --- internals ------------------------------------------------------------------------

    def _solve_bags(self) -> None:
        if self._once is not None:
            self._once.cancel()
            self.destroy_timer(self._once)
            self._once = None
        try:
            recording = read_bags(
                self.settings.bags, self.settings.robot, self.settings.pair_tolerance, self._log
            )
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
        settings = self.settings
        self.get_logger().info(recording.summary())
        cal = calibrate_recording(
            recording, settings.robot, settings.model_spec, settings.ecc_order, log=self._log
        )
        if settings.learned_correction:  # the hybrid model (`Calibration.with_learned_correction`)
            cal = cal.with_learned_correction(recording)
            correction = cal.correction
            for line in [] if correction is None else [correction.line(), *correction.warnings]:
                self._log(line)
        holdout = None
        if settings.holdout_bags:  # a bad hold-out bag is bad input, as for the diagnosis
            holdout = read_bags(
                settings.holdout_bags, settings.robot, settings.pair_tolerance, self._log
            )
        published, fitted_on = cal, recording
        note = ""
        if settings.diagnose:
            diagnosis, ladder = self._diagnose(recording, holdout)
            if diagnosis is not None and ladder is not None:
                best = ladder.rungs[-1].calibration
                if settings.publish == "best" and ladder.recording is not None:
                    published, fitted_on = best, ladder.recording
                    self.get_logger().info(
                        f"publishing the diagnosis's model {best.name} (parameter publish: best)"
                    )
                note = left_by_published(published.name, diagnosis)
                if note:
                    self.get_logger().warning(note)
        doc = published.to_dict(fitted_on)
        if self.stopping:  # destroyed while solving (Ctrl-C): nothing to publish to
            return published
        if settings.output:
            try:
                write_json_atomic(doc, Path(settings.output))
            except OSError as exc:
                raise InputError(f"{settings.output}: cannot write ({exc.strerror})") from None
        self._result_publishers["parameters"].publish(String(data=json.dumps(doc)))
        # residuals and markers of the points fitted (tracker blunders are left out)
        points = fitted_on.points
        fitted_points = points if published.inliers is None else points[published.inliers]
        self._result_publishers["summary"].publish(String(data=summary(published, fitted_on)))
        self._result_publishers["residuals"].publish(
            residuals_message(fitted_points, published.residuals)
        )
        self._result_publishers["markers"].publish(
            calibration_markers(published, fitted_points, settings.residual_scale)
        )
        self._description_note = self._publish_description(published)
        if published.plausible:
            self._publish_tracker_frame(published)
        held_out = None if holdout is None else score_held_out(published, fitted_on, holdout)
        for warning in held_out.warnings if held_out is not None else ():
            self._log(warning)
        self.calibration, self.recording, self.error = published, fitted_on, None
        self.held_out, self.diagnosis_note = held_out, note
        self.solves += 1
        self._publish_status(self._health())
        written = f", written to {settings.output}" if settings.output else ""
        self.get_logger().info(
            f"{published.name}: {published.accuracy.line()}; published{written}"
        )
        return published

    def _diagnose(
        self, recording: Recording, holdout: Recording | None
    ) -> tuple[Diagnosis | None, Ladder | None]:
        """Run the diagnosis on `recording` (scored on `holdout`, the `holdout_bags`, or
        k-fold) and publish the DIAGNOSIS.json document and its one-paragraph summary; the
        diagnosis and its ladder (None when the node is being destroyed)."""
        # on this process alone: the executor's threads run (a fork would copy their locks)
        diagnosis, ladder = diagnose_recordings(recording, self.settings.robot, holdout)
        if self.stopping:
            return None, None
        self.diagnosis = diagnosis
        self._result_publishers["diagnosis"].publish(String(data=json.dumps(diagnosis.to_dict())))
        self._result_publishers["diagnosis_summary"].publish(String(data=diagnosis.summary()))
        self.get_logger().info(diagnosis.summary())
        return diagnosis, ladder

    def _fail(self, exc: RobotCalibError) -> None:
        self.error = exc
        self.get_logger().error(in_ros_terms(exc))
        self._publish_status(self._health())

    # --- robot_description and /diagnostics (nodes/ros_outputs.py) ----------------------------

    def _publish_description(self, cal: Calibration) -> str:
        """Publish `cal` as a calibrated URDF on robot_description (a plausible one only: a
        reader has no means to tell); returns what became of it, for /diagnostics."""
        if not self.settings.publish_robot_description:
            return "off (parameter publish_robot_description)"
        if not cal.plausible:
            return "not published: the calibration is implausible"
        source = self.settings.output or self.resolve_topic_name("~/parameters")
        try:
            text, into = calibrated_urdf(cal, source, self.settings.nominal_urdf)
        except RobotCalibError as exc:
            self.get_logger().warning(f"{self._description.topic_name} not published: {exc}")
            return f"not published: {exc}"
        self._description.publish(String(data=text))
        self._update_state_publisher(text)
        return f"published to {self._description.topic_name}, written into {into}"

    def _update_state_publisher(self, urdf: str) -> None:
        """Set the robot_description parameter of the robot_state_publisher node named by
        the parameter of that name (its SetParameters service; the answer is logged), so
        TF and RViz follow the calibration."""
        target = self.settings.robot_state_publisher
        if not target:
            return
        name = f"{target.rstrip('/')}/set_parameters"
        if self._rsp_client is None or self._rsp_client.srv_name != name:
            self._rsp_client = self.create_client(SetParameters, name)
        if not self._rsp_client.service_is_ready():
            if not self._said_no_rsp:  # once: a launch without urdf:= starts none
                self._said_no_rsp = True
                hint = "start robot_state_publisher on the URDF: calibrator.launch.py urdf:=FILE"
                self.get_logger().warning(
                    f"{name}: not available: TF does not follow the calibration ({hint})"
                )
            return
        request = SetParameters.Request(
            parameters=[Parameter("robot_description", value=urdf).to_parameter_msg()]
        )
        future = self._rsp_client.call_async(request)

        def said(done: Any) -> None:  # noqa: ANN401 - an rclpy Future
            results = getattr(done.result(), "results", None) or []
            if results and results[0].successful:
                self.get_logger().info(f"{target}: robot_description set: TF follows")
            else:
                reason = results[0].reason if results else "no answer"
                self.get_logger().warning(f"{target}: robot_description not set ({reason})")

        future.add_done_callback(said)

    def _publish_tracker_frame(self, cal: Calibration) -> None:
        """The tracker frame's place in the robot's base frame as a static transform
        (tf2_ros, where installed): markers in laser_tracker then show in base_link."""
        if self._static_tf is None:
            try:
                from tf2_ros.static_transform_broadcaster import StaticTransformBroadcaster
            except ImportError:
                if not self._said_no_tf:
                    self._said_no_tf = True
                    self.get_logger().info(
                        "tf2_ros is not installed: the tracker frame is not on /tf_static "
                        "(its place is in ~/parameters, base2tracker)"
                    )
                return
            self._static_tf = StaticTransformBroadcaster(self)
        from geometry_msgs.msg import TransformStamped

        translation, quaternion = tracker_in_base(cal)
        stamped = TransformStamped()
        stamped.header.stamp = self.get_clock().now().to_msg()
        stamped.header.frame_id = self.settings.base_frame
        stamped.child_frame_id = TRACKER_FRAME
        t, q = stamped.transform.translation, stamped.transform.rotation
        t.x, t.y, t.z = (float(v) for v in translation)
        q.x, q.y, q.z, q.w = (float(v) for v in quaternion)
        self._static_tf.sendTransform(stamped)

    def _health(self, waiting: str = "") -> DiagnosticStatus:
        """The node's status on /diagnostics from its last result or error."""
        return calibration_status(
            status_name(self.get_name()),
            self.settings.robot.name,
            self.calibration,
            self.error,
            held_out=self.held_out,
            params_path=self.settings.output,
            description=self._description_note,
            waiting=waiting,
            diagnosis=self.diagnosis_note,
        )

    def _publish_status(self, status: DiagnosticStatus | None = None) -> None:
        """Publish `status` (kept as the last one), or the last one again (the timer)."""
        if status is not None:
            self._status = status
        if not self.stopping:
            stamp = self.get_clock().now().to_msg()
            self._diagnostics.publish(diagnostic_array(self._status, stamp))

    def _log(self, message: str) -> None:
        """The core's progress lines as info, its 'warning: ...' lines as warnings and its
        'implausible: ...' lines as errors (a result not to use)."""
        if message.startswith("warning: "):
            self.get_logger().warning(message.removeprefix("warning: "))
        elif message.startswith("implausible: "):
            self.get_logger().error(in_ros_terms(message.strip()))
        else:
            self.get_logger().info(message.strip())

    def _on_solve(self, _msg: Empty) -> None:
        self.solve()

    def _check_idle(self) -> None:
        """Solve once the points have stopped for solve_after_idle_s (the plan ended)."""
        if self._live is None or not self.active or self.settings.solve_after_idle_s <= 0:
            return
        what = self._live.idle(self.settings.solve_after_idle_s)
        if what is not None:
            self.get_logger().info(
                f"no new point for {self.settings.solve_after_idle_s} s: solving {what}"
            )
            self.solve()


def left_by_published(published: str, diagnosis: Diagnosis) -> str:
    """'' when the diagnosis chose the published model `published` (or nothing beyond it);
    else one line naming the model it chose and the held-out figures of both, and how to
    publish it (parameter publish: best)."""
    scores = {r.model: r.holdout_abs_rms_mm for r in diagnosis.ladder}
    chosen = diagnosis.ladder[-1].model if diagnosis.ladder else published
    if chosen == published:
        return ""
    mine = (
        f"{scores[published]:.4f} mm" if published in scores else "not on the diagnosis's ladder"
    )
    floor = diagnosis.noise.floor_abs_rms_mm
    against = "" if floor is None else f", noise floor {floor:.4f} mm"
    return (
        f"the diagnosis chose {chosen} (held-out rms {scores[chosen]:.4f} mm{against}) "
        f"over the published {published} ({mine}): the published model leaves what it "
        "found; parameter publish: best publishes the diagnosis's model"
    )


def solve_verdict(
    cal: Calibration | None, error: RobotCalibError | None, note: str = ""
) -> tuple[bool, str]:
    """What a service answers for a solve's result: (usable, one line). None (nothing could
    be fitted, the data are not enough): False and the error; an implausible calibration
    (readings in degrees, a residual 1000 x the noise, parameters beyond physics): False and
    its reasons; else True, the model and its in-sample accuracy, and `note` (what the
    diagnosis says of it) when given."""
    if cal is None:
        return False, str(error) if error else "no calibration"
    if not cal.plausible:
        return False, in_ros_terms(f"{cal.name}: implausible: {'; '.join(cal.implausible)}")
    line = f"{cal.name}: in-sample {cal.accuracy.line()}"
    return True, f"{line}; {note}" if note else line


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
        return started[0].error.exit_status  # its one line: the node's [ERROR] log line
    return status


if __name__ == "__main__":
    raise SystemExit(main())
