"""encoder_scale: a joint-angle scale (gear-ratio) error.

The real angle is (1 + s_j) times the reading: theta_j += s_j * q_j.
Parameter `encoder_scaleJ` [1] = s_j.
"""

from __future__ import annotations

from robot_calib.effects.base import JointOffsetEffect, register_effect
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.poses import Poses


@register_effect
class EncoderScale(JointOffsetEffect):
    name = "encoder_scale"
    signature_family = "scale"
    unit = "1"
    default_magnitude = 3e-4  # tenths of a mm over the workspace
    draw_range = (2e-4, 8e-4)
    draw_signed = True

    def signal(self, robot: RobotDescription, poses: Poses) -> Array:
        return poses.q
