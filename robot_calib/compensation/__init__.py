"""Compensation: joint commands that make the calibrated robot reach what the nominal
model promised, or given targets."""

from robot_calib.compensation.solve import (
    Compensation,
    TargetCompensation,
    compensate_commands,
    compensate_targets,
)

__all__ = ["Compensation", "TargetCompensation", "compensate_commands", "compensate_targets"]
