"""The offline simulation sees no other ROS 2 graph: a foreign node publishing
/joint_states and /clock on this process's domain (as a real robot or a user's sim_robot
would on the default domain) made `simulate` and `run` stall. Their in-process
graph runs on a private domain (`nodes.private_domain`)."""

from __future__ import annotations

import fcntl
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Time
from cli_runner import robot_calib
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from robot_calib.bag.read import read_recording
from robot_calib.kinematics.loader import load_robot
from robot_calib.nodes.private_domain import DOMAINS, LOCK_DIR, claim, private_domain
from robot_calib.nodes.simulate import simulate_bag, stall_cause


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


FOREIGN = """
import sys, threading, time, rclpy
from builtin_interfaces.msg import Time
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
for domain in map(int, sys.argv[1:]):
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("foreign_robot", context=context)
    states = node.create_publisher(JointState, "/joint_states", 10)
    clock = node.create_publisher(Clock, "/clock", 10)
    def publish(states=states, clock=clock):
        names = [f"joint_a{j}" for j in range(1, 7)]
        states.publish(JointState(name=names, position=[0.3] * 6))
        clock.publish(Clock(clock=Time(sec=12345)))
    node.create_timer(0.001, publish)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
print("publishing", flush=True)
while True:
    time.sleep(1)
"""


def foreign_graph(*domains: int) -> subprocess.Popen[str]:
    """Another process (a robot, a user's sim_robot) publishing /joint_states and /clock at
    1 kHz on each of `domains`, with ROS 2's default discovery; up on return."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("ROS_AUTOMATIC")}
    foreign = subprocess.Popen(
        [sys.executable, "-c", FOREIGN, *map(str, domains)],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert foreign.stdout is not None and foreign.stdout.readline() == "publishing\n"
    time.sleep(1.0)  # discovery: the foreign graph is up before a simulation starts
    return foreign


def free_domains(count: int) -> list[int]:
    """The first `count` domains nobody holds now: those the next simulations will claim."""
    free = []
    for domain in DOMAINS:
        handle = open(LOCK_DIR / f"{domain}.lock", "w")  # noqa: SIM115 - closed below
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            free.append(domain)
        except OSError:
            pass
        finally:
            handle.close()
        if len(free) == count:
            return free
    raise AssertionError("no free domain")


@pytest.mark.slow
def test_two_simulations_beside_foreign_publishers_on_every_domain(tmp_path: Path) -> None:
    """Two `robot-calib simulate` at once, while another process publishes /joint_states
    and /clock (1 kHz) on domain 0 and on the domains the simulations will claim (a
    foreign graph holds no lock): both bags hold the plan's poses and nothing else, the
    same measurements as a simulation run alone (known answer: the same seed)."""
    args = ["simulate", "--plan", "random", "--n-random", "3000", "--seed", "5"]
    foreign = foreign_graph(0, *free_domains(4))
    try:
        runs = [
            subprocess.Popen(
                [sys.executable, "-m", "robot_calib", *args, "-o", f"s{k}.mcap"],
                cwd=tmp_path,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            for k in (1, 2)
        ]
        results = [run.communicate(timeout=120) for run in runs]
    finally:
        foreign.terminate()
        foreign.wait(timeout=10)
    for run, (_, err) in zip(runs, results):
        assert run.returncode == 0, err
    alone = robot_calib(*args, "-o", "alone.mcap", cwd=tmp_path)
    assert alone.returncode == 0, alone.stderr
    robot = load_robot("kr5_sixx_r650")
    reference = read_recording([tmp_path / "alone.mcap"], robot)
    assert len(reference.points) == 3000 and not np.any(reference.poses.q == 0.3)
    for name in ("s1.mcap", "s2.mcap"):
        recording = read_recording([tmp_path / name], robot)
        np.testing.assert_array_equal(recording.poses.q, reference.poses.q)
        np.testing.assert_array_equal(recording.points, reference.points)


def test_the_callers_graph_never_reaches_the_simulation(tmp_path: Path) -> None:
    """Inside a running graph (the caller's default context on this process's domain, a
    foreign process publishing /joint_states and /clock there that the caller hears) the
    simulation runs in a context of its own: it ends with the lone run's measurements, and
    a stall in the caller's graph would be named by the foreign publishers (`stall_cause`
    on the caller's node)."""
    foreign = foreign_graph(int(os.environ["ROS_DOMAIN_ID"]))  # this process's (conftest)
    rclpy.init()  # the default context: the caller's graph
    try:
        # the caller's graph hears the foreign publisher before the simulation starts (a
        # loaded machine takes longer than foreign_graph's second)
        probe = rclpy.create_node("probe")
        heard: list[JointState] = []
        probe.create_subscription(JointState, "/joint_states", heard.append, 10)
        deadline = time.monotonic() + 60.0
        while not heard:
            assert time.monotonic() < deadline, "no foreign /joint_states ever arrived"
            rclpy.spin_once(probe, timeout_sec=0.1)
        counts = simulate_bag(tmp_path / "sim.mcap", plan="random", n_random=3000, seed=1)
        message = stall_cause(probe, ["probe"])
        probe.destroy_node()
    finally:
        rclpy.try_shutdown()
        foreign.terminate()
        foreign.wait(timeout=10)
    assert counts == {"/joint_states": 3000, "/laser_tracker/point": 3000}, counts
    recording = read_recording([tmp_path / "sim.mcap"], load_robot("kr5_sixx_r650"))
    assert not np.any(recording.poses.q == 0.3)  # no foreign joint state recorded
    assert "another ROS 2 graph on ROS domain" in message, message
    # the publisher named by node once the graph has its name, else by its process
    assert re.search(r"/joint_states by (/foreign_robot|a node of another process)", message), (
        message
    )
