"""robot_calib: laser-tracker calibration of 6-axis robots and sim-to-real gap diagnosis.

Flow (one package per step): sim -> bag -> identify (CPA, geometric, effects) -> diagnose.
The core imports numpy/scipy only; ROS lives in `robot_calib.nodes`.
"""

__version__ = "0.1.0"
