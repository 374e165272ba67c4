"""Capture on a real robot: a plan's poses as safe moves (`moves`), when a joint is settled
(`settle`), which poses a campaign already has (`resume`). The ROS node that drives a
joint_trajectory_controller with them is `robot_calib.nodes.capture`."""
