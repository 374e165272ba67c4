"""The calibrator as a managed lifecycle node, through real rclpy and the lifecycle_msgs
services a lifecycle manager calls: unconfigured it answers no solve; configured and active
it takes the topics and solves; inactive it takes nothing; cleanup drops the live set;
~/reset begins a new set; a run-time parameter changed by `set_parameters` takes effect at
the next solve, a bad value or a read-only parameter is refused with its reason."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_spin import spin_until
from std_srvs.srv import Trigger

from robot_calib.messages import JOINT_STATES_TOPIC, POINT_TOPIC
from robot_calib.nodes.calibrator import CalibratorNode
from robot_calib.nodes.replay import ReplayNode

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "paper_test3.mcap"
TIMEOUT_S = 30.0
ALL = {JOINT_STATES_TOPIC: 290, POINT_TOPIC: 290}


class Graph:
    """A calibrator (not autostarted), a manager node calling its services, one executor."""

    def __init__(self, context: Context, **parameters: Any) -> None:  # noqa: ANN401
        self.context = context
        overrides = [
            Parameter("autostart", value=False),
            *(Parameter(k, value=v) for k, v in parameters.items()),
        ]
        self.calibrator = CalibratorNode(context=context, parameter_overrides=overrides)
        self.manager = Node("manager", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        for node in (self.calibrator, self.manager):
            self.executor.add_node(node)

    def spin_until(self, condition: Callable[[], bool]) -> None:
        spin_until(self.executor, condition, TIMEOUT_S)

    def call(self, srv: Any, name: str, request: Any) -> Any:  # noqa: ANN401 - srv types
        client = self.manager.create_client(srv, f"/calibrator/{name}")
        self.spin_until(client.service_is_ready)
        future = client.call_async(request)
        self.spin_until(future.done)
        self.manager.destroy_client(client)
        return future.result()

    def transition(self, transition_id: int) -> bool:
        return bool(
            self.call(
                ChangeState,
                "change_state",
                ChangeState.Request(transition=Transition(id=transition_id)),
            ).success
        )

    def state(self) -> int:
        return int(self.call(GetState, "get_state", GetState.Request()).current_state.id)

    def replay(self, taken: dict[str, int] | None = None) -> None:
        """The sample bag (290 poses) replayed into the calibrator, delivered (and `taken`:
        spun until the calibrator counts that)."""
        replay = ReplayNode(bag=SAMPLE, rate=0.0, wait_for_subscribers=1, context=self.context)
        self.executor.add_node(replay)
        self.spin_until(lambda: replay.done)
        assert replay.wait_for_acks(5.0)
        self.executor.remove_node(replay)
        replay.destroy_node()
        if taken is not None:
            self.spin_until(lambda: self.calibrator.received == taken)

    def close(self) -> None:
        self.executor.shutdown()
        for node in (self.calibrator, self.manager):
            node.destroy_node()


def test_lifecycle_transitions_and_reset(context: Context) -> None:
    graph = Graph(context)
    calibrator = graph.calibrator
    try:
        assert graph.state() == State.PRIMARY_STATE_UNCONFIGURED
        answer = graph.call(Trigger, "solve", Trigger.Request())
        assert not answer.success and "unconfigured (lifecycle)" in answer.message
        assert graph.transition(Transition.TRANSITION_CONFIGURE)
        assert graph.transition(Transition.TRANSITION_ACTIVATE)
        assert graph.state() == State.PRIMARY_STATE_ACTIVE
        graph.replay()
        answer = graph.call(Trigger, "solve", Trigger.Request())
        assert answer.success and answer.message.startswith("geometric: in-sample"), answer
        assert calibrator.received == ALL
        # inactive: nothing taken, no solve; the buffers and the result stay
        assert graph.transition(Transition.TRANSITION_DEACTIVATE)
        graph.replay()
        for _ in range(50):  # whatever the executor hands over while inactive is dropped
            graph.executor.spin_once(timeout_sec=0.01)
        assert calibrator.received == ALL
        answer = graph.call(Trigger, "solve", Trigger.Request())
        assert not answer.success and "inactive (lifecycle)" in answer.message
        assert calibrator.calibration is not None
        # active again, then reset: a new set begins
        assert graph.transition(Transition.TRANSITION_ACTIVATE)
        answer = graph.call(Trigger, "reset", Trigger.Request())
        assert answer.success and "/joint_states=290" in answer.message, answer
        assert calibrator.received == dict.fromkeys(ALL, 0) and calibrator.calibration is None
        graph.replay(taken=ALL)
        # cleanup drops the live set; configured again, it starts empty
        assert graph.transition(Transition.TRANSITION_DEACTIVATE)
        assert graph.transition(Transition.TRANSITION_CLEANUP)
        assert graph.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert calibrator.received == {} and calibrator.calibration is None
        assert graph.transition(Transition.TRANSITION_CONFIGURE)
        assert calibrator.received == dict.fromkeys(ALL, 0)
    finally:
        graph.close()


def test_a_run_time_parameter_takes_effect_at_the_next_solve(context: Context) -> None:
    graph = Graph(context)
    calibrator = graph.calibrator
    try:
        assert graph.transition(Transition.TRANSITION_CONFIGURE)
        assert graph.transition(Transition.TRANSITION_ACTIVATE)
        graph.replay()
        first = calibrator.solve()
        assert first is not None and first.name == "geometric"
        (result,) = calibrator.set_parameters([Parameter("model", value="geometric+backlash:4")])
        assert result.successful, result.reason
        second = calibrator.solve()
        assert second is not None and second.name == "geometric+backlash:4"
        (bad,) = calibrator.set_parameters([Parameter("model", value="geometrc")])
        assert not bad.successful and "parameter 'model' geometrc" in bad.reason, bad.reason
        (fixed,) = calibrator.set_parameters([Parameter("robot", value="ur10")])
        assert not fixed.successful  # read-only: the node's configuration
        for name, value in (
            ("residual_scale", "abc"),
            ("pair_tolerance", float("nan")),
            ("pair_tolerance", True),
        ):
            (odd,) = calibrator.set_parameters([Parameter(name, value=value)])
            assert not odd.successful, (name, value)  # refused, the node alive
        assert calibrator.settings.model_spec == "geometric+backlash:4"
        assert calibrator.settings.pair_tolerance == 0.05
    finally:
        graph.close()


def test_a_transition_waits_for_a_running_solve(context: Context) -> None:
    """Deactivate and cleanup are refused while a solve runs (its result would land in an
    unconfigured node), and succeed once it has ended."""
    graph = Graph(context)
    calibrator = graph.calibrator
    try:
        assert graph.transition(Transition.TRANSITION_CONFIGURE)
        assert graph.transition(Transition.TRANSITION_ACTIVATE)
        calibrator.busy = True  # as while `_calibrate` runs in the solver's thread
        assert not graph.transition(Transition.TRANSITION_DEACTIVATE)
        assert graph.state() == State.PRIMARY_STATE_ACTIVE
        calibrator.busy = False
        assert graph.transition(Transition.TRANSITION_DEACTIVATE)
        calibrator.busy = True
        assert not graph.transition(Transition.TRANSITION_CLEANUP)
        calibrator.busy = False
        assert graph.transition(Transition.TRANSITION_CLEANUP)
    finally:
        graph.close()
