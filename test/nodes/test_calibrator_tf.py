"""TF the ROS way: the calibrator sets robot_state_publisher's robot_description to each
plausible calibrated URDF (its SetParameters service, through real rclpy: a node standing in
for robot_state_publisher's parameter interface answers it), and the tracker frame's place
in the base frame follows the fitted base2tracker (known answer: the simulated world's)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from scipy.spatial.transform import Rotation

from robot_calib.nodes.calibrator import CalibratorNode
from robot_calib.nodes.ros_outputs import tracker_in_base
from robot_calib.sim.world import load_world

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "paper_test3.mcap"


def test_robot_state_publisher_follows_each_calibration(context: Context) -> None:
    """A node named robot_state_publisher with its robot_description parameter (what the
    real one declares): after the bag's solve it holds the calibrated URDF, as published."""
    state_publisher = Node("robot_state_publisher", context=context)
    state_publisher.declare_parameter("robot_description", "<robot name='nominal'/>")
    calibrator = CalibratorNode(
        bags=[SAMPLE],
        context=context,
        parameter_overrides=[Parameter("robot_state_publisher", value="/robot_state_publisher")],
    )
    executor = SingleThreadedExecutor(context=context)
    for node in (state_publisher, calibrator):
        executor.add_node(node)
    deadline = time.monotonic() + 30.0
    try:
        while "calibrated" not in state_publisher.get_parameter("robot_description").value:
            assert time.monotonic() < deadline, "robot_description never set"
            assert calibrator.error is None, calibrator.error
            executor.spin_once(timeout_sec=0.01)
        urdf = state_publisher.get_parameter("robot_description").value
    finally:
        executor.shutdown()
        for node in (state_publisher, calibrator):
            node.destroy_node()
    assert urdf.lstrip().startswith("<?xml") and "<robot" in urdf
    assert calibrator._description_note.startswith("published to /robot_description")


def test_the_tracker_frame_in_the_base_frame_is_the_worlds() -> None:
    """The sample bag's world puts the robot base at (2.2, 1.0, -0.3) m, turned 200 deg
    about z, in the tracker frame (joint 1's zero offset and d1 taken into the base pose,
    as the calibration's canonical form does): the calibration's tracker frame in the base
    frame is its inverse, to the fit's accuracy (0.05 mm, 0.005 deg)."""
    from robot_calib.bag.read import read_recording
    from robot_calib.identify.calibrate import calibrate
    from robot_calib.model import absorb_base_offsets

    world = load_world()
    robot = world.model.robot
    cal = calibrate(read_recording([SAMPLE], robot), robot, "geometric", log=None)
    translation, quaternion = tracker_in_base(cal)
    truth = world.model.base2tracker(absorb_base_offsets(robot, world.truth))
    expected = Rotation.from_matrix(truth[:3, :3].T)
    found = Rotation.from_quat(quaternion)
    assert np.degrees((found * expected.inv()).magnitude()) < 0.005
    assert np.linalg.norm(translation - (-truth[:3, :3].T @ truth[:3, 3])) < 5e-5
    yaw = np.degrees(Rotation.from_matrix(truth[:3, :3]).as_euler("xyz")[2]) % 360.0
    assert abs(yaw - 200.0) < 0.2  # the world's 200 deg (plus joint 1's 0.08 deg offset)
