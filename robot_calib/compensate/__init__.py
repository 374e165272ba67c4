"""Compensation: joint commands that make the calibrated robot reach what the nominal
model promised (issue 15)."""

from robot_calib.compensate.solve import Compensation, compensate_commands

__all__ = ["Compensation", "compensate_commands"]
