"""ROS 2 nodes: thin rclpy adapters over the ROS-free core.

Each node is a program (`ros2 run robot_calib NODE`, `robot_calib.NODE_PROGRAMS`): its
start-up (one BLAS thread) is done by `robot_calib/__init__.py` before numpy loads, as the
command line's; importing this package (the public API's simulation does) tunes nothing.
"""
