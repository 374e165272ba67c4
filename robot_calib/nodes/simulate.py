"""`robot-calib simulate`: sim_robot + sim_tracker + recorder in one process, on simulated time.

The three real nodes share one process and one ROS 2 context; every message goes through
rclpy and the middleware from node to node. sim_robot drives /clock (every node has
use_sim_time). The driver steps the graph in bursts (`_Stepper.burst`): sim_robot publishes
the joint states of BURST poses at once, sim_tracker takes them all and measures them in
one batch, then for each pose k in turn sim_robot advances /clock to pose k and the
recorder takes pose k's joint state and the tracker's answer on each of its topics (each
target's point, each 6-DoF probe's pose): so the recorder writes what the former lockstep
wrote (pose by pose: /clock, the joint state, the tracker's topics) with the same receive
times (the recorder's clock at pose k). The driver takes the messages from the nodes'
subscriptions itself and calls their callbacks (an executor's spin rebuilds its wait set
every time: ~0.4 ms, 9 spins per pose); the executor still runs discovery, timers and
events between bursts. Nothing waits on the wall clock: 100k poses take about 20 s.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from functools import partial
from pathlib import Path

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from robot_calib.errors import RobotCalibError
from robot_calib.messages import JOINT_STATES_TOPIC
from robot_calib.nodes.private_domain import discovery_off, private_domain
from robot_calib.nodes.recorder import RecorderNode
from robot_calib.nodes.sim_robot import QOS, SimRobotNode
from robot_calib.nodes.sim_tracker import SimTrackerNode

STEP_TIMEOUT_S = 10.0
BURST = 500
"""Poses the robot publishes at once: within every reader's and writer's queue depth
(sim_robot's QOS 1000, the recorder's qos_depth 10000), so a burst is never cut short."""


class SimulationStalled(RobotCalibError):
    """The in-process graph did not deliver a message within STEP_TIMEOUT_S."""


SIMULATION_TOPICS = (JOINT_STATES_TOPIC, "/clock")


def stall_cause(node: Node, own: Sequence[str]) -> str:
    """What most likely stalled a graph of nodes named `own` that `node` belongs to: the
    nodes of other graphs publishing on /joint_states or /clock on its domain (named, from
    `get_publishers_info_by_topic`), other nodes on the domain, or neither (then a machine
    too loaded to answer within STEP_TIMEOUT_S)."""
    domain = f"ROS domain {node.context.get_domain_id()}"
    foreign: dict[str, set[str]] = {}
    for topic in SIMULATION_TOPICS:
        for info in node.get_publishers_info_by_topic(topic):
            if info.node_name not in own:
                name = f"{info.node_namespace.rstrip('/')}/{info.node_name}"
                if "_UNKNOWN_" in name:  # its process has not yet said its nodes' names
                    name = "a node of another process"
                foreign.setdefault(topic, set()).add(name)
    if foreign:
        listed = "; ".join(f"{t} by {', '.join(sorted(n))}" for t, n in foreign.items())
        return (
            f"another ROS 2 graph on {domain} publishes the simulation's topics ({listed}): "
            "stop it, or simulate on a free domain (robot-calib simulate alone, not inside "
            "a running ROS 2 graph)"
        )
    others = sorted(set(node.get_node_names()) - set(own))
    if others:
        return f"other nodes on {domain} ({', '.join(others[:5])}): another ROS 2 graph?"
    return (
        f"no other publisher of {' or '.join(SIMULATION_TOPICS)} on {domain}: a machine "
        f"too loaded to deliver a message within {STEP_TIMEOUT_S:g} s?"
    )


def _spin_until(
    executor: SingleThreadedExecutor,
    condition: Callable[[], bool],
    what: str,
    received: Sequence[int] = (),
) -> None:
    """Spin until `condition`; KeyboardInterrupt once a signal is in `received` (a safe
    point: between callbacks, never inside one)."""
    deadline = time.monotonic() + STEP_TIMEOUT_S
    while not condition():
        if received:
            raise KeyboardInterrupt
        if time.monotonic() > deadline:
            raise SimulationStalled(f"simulation stalled waiting for {what}")
        executor.spin_once(timeout_sec=0.01)


@contextlib.contextmanager
def _deferred_signals() -> Iterator[list[int]]:
    """While the graph runs, SIGINT, SIGTERM and SIGHUP (where Python handles them: Ctrl-C,
    the CLI's SIGTERM and SIGHUP) only record the signal; the driver raises
    KeyboardInterrupt at its next step, so an interruption never lands inside an rclpy
    callback. Handlers restored after.

    Yields
    ------
    received : list of int
        The signals received so far.
    """
    received: list[int] = []
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            handler = signal.getsignal(sig)
            if callable(handler):  # not SIG_DFL / SIG_IGN: those stay as they are
                previous[sig] = handler
                signal.signal(sig, lambda signum, _frame: received.append(signum))
    try:
        yield received
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


class _Stepper:
    """Steps the graph of `_simulate_bag` one burst of poses at a time (module docstring)."""

    def __init__(
        self,
        executor: SingleThreadedExecutor,
        robot: SimRobotNode,
        tracker: SimTrackerNode,
        recorder: RecorderNode,
        received: Sequence[int],
    ) -> None:
        self.executor, self.robot, self.tracker, self.recorder = executor, robot, tracker, recorder
        self.received = received
        self.clocks = {n: _clock_subscription(n) for n in (robot, tracker, recorder)}
        self.answers = [t for t in recorder.subscribed if t in tracker.topics]
        if len(self.answers) != len(tracker.topics):
            missing = sorted(set(tracker.topics) - set(self.answers))
            raise SimulationStalled(f"the recorder has not subscribed to {missing}")

    def burst(self, size: int) -> None:
        """The next `size` poses (fewer at the plan's end) from publication to the bag."""
        robot, tracker, recorder = self.robot, self.tracker, self.recorder
        first = robot.next_pose
        if robot.start_ns is None:
            robot.publish_clock(first)  # sets the plan's start: the wall clock now
            self._take_clocks()
        stamps = robot.publish_poses(size)
        measured: list[bool] = []

        def answered() -> bool:
            measured.extend(tracker.take_joint_states())
            if len(measured) > len(stamps):  # joint states the robot did not publish
                raise SimulationStalled(
                    f"sim_tracker received {len(measured)} joint states for the "
                    f"{len(stamps)} poses {first}..{first + len(stamps) - 1} published"
                )
            return len(measured) >= len(stamps)

        self._wait(answered, f"sim_tracker at poses {first}..{first + len(stamps) - 1}")
        recorder_clock = self.clocks[recorder]
        for k, answer in enumerate(measured, start=first):
            robot.publish_clock(k)
            self._wait(partial(_take, recorder_clock), f"/clock at pose {k}")
            self._wait(partial(recorder.take, JOINT_STATES_TOPIC), f"pose {k}")
            if answer:
                for topic in self.answers:
                    for _ in range(tracker.messages_per_pose(topic)):
                        self._wait(partial(recorder.take, topic), f"{topic} of pose {k}")
        self._take_clocks()
        self.executor.spin_once(timeout_sec=0)  # timers (the recorder's flush), events
        if self.received:
            raise KeyboardInterrupt

    def _take_clocks(self) -> None:
        """Every node's clock at the last /clock published (the latest message counts)."""
        for subscription in self.clocks.values():
            while _take(subscription):
                pass

    def _wait(self, done: Callable[[], bool], what: str) -> None:
        """Call `done` until it is true (a message has arrived): at once in-process, else
        polled; SimulationStalled after STEP_TIMEOUT_S, KeyboardInterrupt on a signal."""
        if done():
            return
        deadline = time.monotonic() + STEP_TIMEOUT_S
        while not done():
            if self.received:
                raise KeyboardInterrupt
            if time.monotonic() > deadline:
                raise SimulationStalled(f"simulation stalled waiting for {what}")
            time.sleep(0.0005)


def _clock_subscription(node: Node) -> Subscription:
    """The node's /clock subscription (its time source's, with use_sim_time)."""
    for subscription in node.subscriptions:
        if subscription.topic_name == "/clock":
            return subscription
    raise SimulationStalled(f"{node.get_name()}: no /clock subscription (use_sim_time)")


def _take(subscription: Subscription) -> bool:
    """Take one message of `subscription` and run its callback; False if none waits."""
    with subscription.handle:
        taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
    if taken is None:
        return False
    subscription.callback(taken[0])
    return True


def simulate_bag(
    output: Path,
    plan: str = "paper-test3",
    world: str | Path | None = None,
    seed: int = -1,
    n_random: int = 200,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, int]:
    """Simulate `plan` in `world` and record it to the MCAP file `output` (must not exist).

    Returns the recorder's message counts per topic. The graph always runs in a ROS 2
    context of its own, on a private domain (`nodes.private_domain`) with discovery off,
    even when the caller's process runs a graph of its own (an initialised default
    context): no other ROS 2 graph on this machine (a robot, another simulation, the
    caller's nodes) reaches the offline one, and it reaches none of them. It installs no
    signal handlers of rclpy's: Ctrl-C (and SIGTERM where the caller maps it so) raises
    KeyboardInterrupt at the next step, the bag is closed and the caller discards it.
    """
    with _deferred_signals() as received, private_domain() as domain:
        return _simulate_bag(output, plan, world, seed, n_random, progress, received, domain)


def _simulate_bag(
    output: Path,
    plan: str,
    world: str | Path | None,
    seed: int,
    n_random: int,
    progress: Callable[[int, int], None] | None,
    received: Sequence[int],
    domain_id: int,
) -> dict[str, int]:
    context = Context()
    with discovery_off():  # its own nodes only, whoever else is on the domain
        rclpy.init(
            context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO
        )
    sim_time = Parameter("use_sim_time", value=True)
    world_param = Parameter("world", value=str(world) if world else "")
    nodes: list[Node] = []
    try:
        with warnings.catch_warnings():  # the world's description warned when it was built
            warnings.simplefilter("ignore", UserWarning)
            robot = SimRobotNode(
                context=context,
                parameter_overrides=[
                    sim_time,
                    world_param,
                    Parameter("plan", value=plan),
                    Parameter("seed", value=seed),
                    Parameter("n_random", value=n_random),
                    Parameter("publish_clock", value=True),
                    Parameter("wait_for_subscribers", value=2),
                    Parameter("autostart", value=False),
                ],
            )
            nodes.append(robot)
            tracker = SimTrackerNode(context=context, parameter_overrides=[sim_time, world_param])
            nodes.append(tracker)
        recorder = RecorderNode(
            context=context,
            parameter_overrides=[
                sim_time,
                Parameter("output", value=str(output)),
                Parameter("topics", value=[JOINT_STATES_TOPIC, *tracker.topics]),
            ],
        )
        nodes.append(recorder)
        executor = SingleThreadedExecutor(context=context)
        for node in nodes:
            executor.add_node(node)
        _spin_until(
            executor,
            lambda: (
                robot.ready()
                and all(p.get_subscription_count() >= 1 for p in tracker.all_publishers)
            ),
            "discovery",
            received,
        )

        total = len(robot.plan)
        step = _Stepper(executor, robot, tracker, recorder, received)
        while not robot.done:
            reads = tracker.world.tracker.reads_per_pose  # messages per pose on a point topic
            step.burst(min(BURST, QOS.depth // reads, recorder.qos_depth // reads))
            if progress is not None:
                progress(robot.next_pose, total)
        recorder.close()
        return dict(recorder.counts)
    except SimulationStalled as exc:  # say why, while the graph is still up
        cause = stall_cause(nodes[0], [n.get_name() for n in nodes])
        raise SimulationStalled(f"{exc}: {cause}") from None
    finally:
        for node in reversed(nodes):
            if isinstance(node, RecorderNode):
                node.close()
            node.destroy_node()
        rclpy.try_shutdown(context=context)
