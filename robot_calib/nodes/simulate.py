"""`robot-calib simulate`: sim_robot + sim_tracker + recorder in one process, on simulated time.

The three real nodes share one SingleThreadedExecutor. sim_robot drives /clock (every node
has use_sim_time), and the driver steps the graph in lockstep: advance the clock to pose k,
publish its joint state, spin until the tracker has answered and the recorder holds the
joint state and every topic of the tracker (each target's point, each 6-DoF probe's pose).
Nothing waits on the wall clock, so a 580-pose bag takes about a second.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from functools import partial
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from robot_calib.errors import RobotCalibError
from robot_calib.messages import JOINT_STATES_TOPIC
from robot_calib.nodes.private_domain import private_domain
from robot_calib.nodes.recorder import RecorderNode
from robot_calib.nodes.sim_robot import SimRobotNode
from robot_calib.nodes.sim_tracker import SimTrackerNode

STEP_TIMEOUT_S = 10.0


class SimulationStalled(RobotCalibError):
    """The in-process graph did not deliver a message within STEP_TIMEOUT_S."""


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


def simulate_bag(
    output: Path,
    plan: str = "paper-test3",
    world: str | Path | None = None,
    seed: int = -1,
    n_random: int = 200,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, int]:
    """Simulate `plan` in `world` and record it to the MCAP file `output` (must not exist).

    Returns the recorder's message counts per topic. Owns rclpy init/shutdown unless a
    context is already initialised (then it uses the default context and leaves it up);
    an owned context runs on a private domain (`nodes.private_domain`), so that no other
    ROS 2 graph on this machine (a robot, another simulation) reaches the offline one.
    An owned context installs no signal handlers of rclpy's: Ctrl-C (and SIGTERM where
    the caller maps it so) raises KeyboardInterrupt at the next step, the bag is closed
    and the caller discards it.
    """
    with _deferred_signals() as received:
        if rclpy.ok():  # the caller's graph: its domain
            return _simulate_bag(output, plan, world, seed, n_random, progress, received)
        with private_domain() as domain:  # an offline graph sees nobody else's topics
            return _simulate_bag(output, plan, world, seed, n_random, progress, received,
                                 domain)  # fmt: skip


def _simulate_bag(
    output: Path,
    plan: str,
    world: str | Path | None,
    seed: int,
    n_random: int,
    progress: Callable[[int, int], None] | None,
    received: Sequence[int],
    domain_id: int | None = None,
) -> dict[str, int]:
    owns_context = not rclpy.ok()
    if owns_context:
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO, domain_id=domain_id)
    sim_time = Parameter("use_sim_time", value=True)
    world_param = Parameter("world", value=str(world) if world else "")
    nodes: list[Node] = []
    try:
        robot = SimRobotNode(
            parameter_overrides=[
                sim_time,
                world_param,
                Parameter("plan", value=plan),
                Parameter("seed", value=seed),
                Parameter("n_random", value=n_random),
                Parameter("publish_clock", value=True),
                Parameter("wait_for_subscribers", value=2),
                Parameter("autostart", value=False),
            ]
        )
        nodes.append(robot)
        tracker = SimTrackerNode(parameter_overrides=[sim_time, world_param])
        nodes.append(tracker)
        recorder = RecorderNode(
            parameter_overrides=[
                sim_time,
                Parameter("output", value=str(output)),
                Parameter("topics", value=[JOINT_STATES_TOPIC, *tracker.topics]),
            ]
        )
        nodes.append(recorder)
        executor = SingleThreadedExecutor()
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

        def clocks_at(stamp: int) -> bool:
            return all(n.get_clock().now().nanoseconds == stamp for n in nodes)

        def recorded(sent: int) -> bool:
            return (
                tracker.received == sent
                and recorder.counts.get(JOINT_STATES_TOPIC, 0) == sent
                and all(recorder.counts.get(t, 0) == tracker.published for t in tracker.topics)
            )

        total = len(robot.plan)
        while not robot.done:
            k = robot.next_pose
            robot.publish_clock(k)
            _spin_until(executor, partial(clocks_at, robot.stamp_ns(k)), "/clock", received)
            robot.publish_pose()
            _spin_until(executor, partial(recorded, k + 1), f"pose {k}", received)
            if progress is not None:
                progress(k + 1, total)
        recorder.close()
        return dict(recorder.counts)
    finally:
        for node in reversed(nodes):
            if isinstance(node, RecorderNode):
                node.close()
            node.destroy_node()
        if owns_context:
            rclpy.try_shutdown()
