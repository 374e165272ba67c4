"""The offline simulation sees no other ROS 2 graph (issue 24, found again at the end of
issue 22): a foreign node publishing /joint_states and /clock on this process's domain (as
a real robot or a user's sim_robot would on the default domain) made `simulate` and `run`
stall. Their in-process graph runs on a private domain (`nodes.private_domain`)."""

from __future__ import annotations

import threading
from pathlib import Path

import rclpy
from builtin_interfaces.msg import Time
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from robot_calib.nodes.private_domain import claim, private_domain
from robot_calib.nodes.simulate import simulate_bag


def test_two_claims_never_share_a_domain() -> None:
    with private_domain() as first:
        second, handle = claim()
        handle.close()
        assert second != first and first != 0


def test_simulation_ignores_a_foreign_graph_on_the_same_domain(tmp_path: Path) -> None:
    context = Context()
    rclpy.init(context=context)  # this process's domain (conftest): the 'default' one here
    node = rclpy.create_node("foreign_robot", context=context)
    states = node.create_publisher(JointState, "/joint_states", 10)
    clock = node.create_publisher(Clock, "/clock", 10)

    def publish() -> None:
        msg = JointState(name=[f"joint_{j}" for j in range(1, 7)], position=[0.3] * 6)
        states.publish(msg)
        clock.publish(Clock(clock=Time(sec=12345)))

    node.create_timer(0.005, publish)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        counts = simulate_bag(tmp_path / "sim.mcap", plan="random", n_random=15, seed=1)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        spinner.join(timeout=5)
    assert counts == {"/joint_states": 15, "/laser_tracker/point": 15}, counts
