"""ROS 2 nodes: thin rclpy adapters over the ROS-free core.

Each node is a program (`ros2 run robot_calib NODE`): loading this package, before any node
module imports numpy, is its entry's start-up (one BLAS thread, `robot_calib.one_blas_thread`).
"""

from robot_calib import one_blas_thread

one_blas_thread()
