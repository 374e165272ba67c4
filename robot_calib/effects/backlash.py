"""backlash: a joint-angle offset whose sign follows the approach direction.

theta_j += 0.5 * play_j * direction_j, so poses reached forth and back differ by the play.
Parameter `backlashJ` [rad] = the total play of joint J.
"""

from __future__ import annotations

from robot_calib.effects.base import JointOffsetEffect, register_effect
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.poses import Poses


@register_effect
class Backlash(JointOffsetEffect):
    name = "backlash"
    signature_family = "direction"
    unit = "rad"
    # A joint-4 play of 2 mrad moves the target ~0.25 mm between approach directions (the
    # seed reports 250 um).
    default_magnitude = 2.0e-3
    draw_range = (1e-3, 4e-3)

    def signal(self, robot: RobotDescription, poses: Poses) -> Array:
        return 0.5 * poses.direction
