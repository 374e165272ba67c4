"""The simulated graph: sim_robot -> sim_tracker -> recorder, in-process and as processes.

Real rclpy and Fast DDS on this process's private ROS_DOMAIN_ID (conftest.py); bags are
read back with our reader, with mcap_ros2 and independently with rosbags.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from robot_calib.bag import BagReader
from robot_calib.messages import JOINT_STATES_TOPIC, POINT_TOPIC, joint_positions, stamp_to_ns
from robot_calib.nodes.simulate import simulate_bag
from robot_calib.sim.plans import paper_test_plan
from robot_calib.sim.world import load_world

BIN = Path(sys.executable).parent


def test_in_process_graph_records_every_message(tmp_path: Path) -> None:
    bag = tmp_path / "test1.mcap"
    counts = simulate_bag(bag, "paper-test1")
    plan = paper_test_plan(1)
    assert counts == {JOINT_STATES_TOPIC: len(plan), POINT_TOPIC: len(plan)}

    with BagReader(bag) as reader:
        assert reader.counts == counts
        states = [m.decode() for m in reader.messages([JOINT_STATES_TOPIC])]
        points = [m.decode() for m in reader.messages([POINT_TOPIC])]
    q = np.array([joint_positions(m, tuple(f"joint_a{j}" for j in range(1, 7))) for m in states])
    np.testing.assert_allclose(q, plan.q)  # every pose, in order, exact readings
    assert all(p.header.frame_id == "laser_tracker" for p in points)
    # Stamps: points precede their joint state by 0..2 ms; poses are seconds apart.
    lag = np.array(
        [stamp_to_ns(s.header.stamp) - stamp_to_ns(p.header.stamp) for s, p in zip(states, points)]
    )
    assert np.all((lag >= 0) & (lag <= 2_000_000))
    assert np.all(np.diff([stamp_to_ns(s.header.stamp) for s in states]) > 900_000_000)

    # mcap_ros2 decodes every message; rosbags reads the bare .mcap independently.
    with bag.open("rb") as f:
        decoded = list(
            make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
        )
    assert len(decoded) == 2 * len(plan)
    with AnyReader([bag]) as reader:
        by_topic = {c.topic: c.msgcount for c in reader.connections}
        assert by_topic == counts
        conn = next(c for c in reader.connections if c.topic == POINT_TOPIC)
        first = next(reader.messages(connections=[conn]))
        msg = reader.deserialize(first[2], conn.msgtype)
        assert msg.point.x == pytest.approx(points[0].point.x)


def test_dropouts_are_recorded_as_missing_points(tmp_path: Path) -> None:
    world_file = tmp_path / "world.yaml"
    world_file.write_text(yaml.safe_dump({"seed": 3, "tracker": {"dropout_probability": 0.2}}))
    counts = simulate_bag(tmp_path / "drop.mcap", "paper-test1", world_file)
    assert counts[JOINT_STATES_TOPIC] == 120
    assert 60 < counts[POINT_TOPIC] < 115  # about 20 % of the points lost


def test_simulated_points_match_the_world(tmp_path: Path) -> None:
    """The bag's points are the world's true points within noise (a few um)."""
    from robot_calib.poses import Poses
    from robot_calib.sim.measure import physical_points

    bag = tmp_path / "t1.mcap"
    simulate_bag(bag, "paper-test1")
    with BagReader(bag) as reader:
        points = np.array(
            [
                [m.point.x, m.point.y, m.point.z]
                for m in (b.decode() for b in reader.messages([POINT_TOPIC]))
            ]
        )
    world = load_world()
    exact = physical_points(world, Poses.from_readings(paper_test_plan(1).q), None, noisy=False)
    error = np.linalg.norm(points - exact, axis=1)
    assert 1e-6 < error.mean() < 20e-6


@pytest.mark.slow
def test_nodes_run_alone_as_processes(tmp_path: Path) -> None:
    """The three console scripts as separate processes (as `ros2 run` starts them)."""
    bag = tmp_path / "procs.mcap"
    env = dict(os.environ)
    recorder = subprocess.Popen(
        [str(BIN / "recorder"), "--ros-args", "-p", f"output:={bag}"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    tracker = subprocess.Popen(
        [str(BIN / "sim_tracker"), "--ros-args", "-p", "wait_for_subscribers:=1"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        robot = subprocess.run(
            [
                str(BIN / "sim_robot"),
                "--ros-args",
                "-p",
                "plan:=paper-test1",
                "-p",
                "rate:=400.0",
                "-p",
                "wait_for_subscribers:=2",
            ],
            env=env,
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert robot.returncode == 0, robot.stderr[-2000:]
        time.sleep(1.0)
    finally:
        tracker.send_signal(signal.SIGINT)
        recorder.send_signal(signal.SIGINT)
        tracker.wait(timeout=20)
        out, _ = recorder.communicate(timeout=20)
    assert recorder.returncode == 0, out
    with BagReader(bag) as reader:
        assert reader.counts == {JOINT_STATES_TOPIC: 120, POINT_TOPIC: 120}
    assert "/joint_states=120" in out


def test_committed_sample_bag_matches_its_world() -> None:
    """bags/paper_test3.mcap (see bags/README.md) against its ground-truth world file."""
    from robot_calib.poses import Poses
    from robot_calib.sim.measure import physical_points

    bag = Path(__file__).resolve().parents[2] / "bags" / "paper_test3.mcap"
    world = load_world(bag.with_suffix(".world.yaml"))
    with BagReader(bag) as reader:
        assert reader.counts == {JOINT_STATES_TOPIC: 290, POINT_TOPIC: 290}
        names = world.model.robot.joint_names
        q = np.array(
            [joint_positions(m.decode(), names) for m in reader.messages([JOINT_STATES_TOPIC])]
        )
        points = np.array(
            [
                [p.point.x, p.point.y, p.point.z]
                for p in (m.decode() for m in reader.messages([POINT_TOPIC]))
            ]
        )
    np.testing.assert_allclose(q, paper_test_plan(3).q)
    exact = physical_points(world, Poses.from_readings(q), None, noisy=False)
    assert np.linalg.norm(points - exact, axis=1).max() < 50e-6
    with AnyReader([bag]) as reader:
        assert sum(c.msgcount for c in reader.connections) == 580
