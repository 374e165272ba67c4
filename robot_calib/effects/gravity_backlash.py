"""gravity_backlash (simulator only, NOT in the contract's vocabulary): backlash whose side is
chosen by gravity, not by the approach direction.

A joint with play b_j whose link is loaded by gravity rests against the side of its play
the gravity torque pushes it to, whichever way the joint arrived; the side flips where the
gravity torque tau_j changes sign (the arm's centre of mass crosses the vertical through
the joint), which on joints 2-3 happens inside the workspace:

    theta_j += (b_j / 2) * tanh(tau_j(q) / TAU0_NM)

tau_j [N m] the gravity torque about joint j on the nominal kinematics and the robot's
mass model (`effects.compliance.gravity_torques`, a payload included), TAU0_NM the torque
over which the joint crosses its play (friction holds it in between): a smooth sign, so
that the signal and the Jacobian stay smooth. Far from the sign change the offset is
+-b_j / 2. Parameter `gravity_backlashJ` [rad] = b_j, the total play.

Why no effect of the vocabulary expresses it: `backlash` takes its side from the approach
direction (the readings' history), `compliance` and `gravity_compliance` are linear in the
gravity torque (a tanh of it is a step: a line fitted to a step leaves half its rms), and
`transmission_error`/`joint_harmonics` are functions of the joint's own reading, whereas
tau_j depends on every joint from j on (and on joint 1 nowhere: its axis is vertical).
"""

from __future__ import annotations

import numpy as np

from robot_calib.effects.base import Effect, JointOffsetEffect, register_effect
from robot_calib.effects.compliance import gravity_joints, gravity_torques
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.poses import Poses

#: the gravity torque over which the joint crosses its play [N m] (tanh's scale)
TAU0_NM = 2.0
#: the joints a blind case draws on: where the gravity torque changes sign in the workspace
DRAW_JOINTS = (2, 3)


@register_effect
class GravityBacklash(JointOffsetEffect):
    name = "gravity_backlash"
    in_vocabulary = False
    unit = "rad"
    # 2 mrad of play, as `backlash`'s default: about 0.5 mm at the KR5's target (joint 2)
    default_magnitude = 2.0e-3
    draw_range = (1e-3, 4e-3)

    def signal(self, robot: RobotDescription, poses: Poses) -> Array:
        """0.5 tanh(tau / TAU0_NM) of every joint, shape (n, J): offset = b * signal."""
        return 0.5 * np.tanh(gravity_torques(robot, poses.q) / TAU0_NM)

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        """1-4 mrad on joint 2 or 3 (`joint` if it is one of them, else one at random)
        among the joints with a significant gravity torque."""
        choices = [j for j in DRAW_JOINTS if j in gravity_joints(robot)] or list(DRAW_JOINTS)
        chosen = joint if joint in choices else int(rng.choice(choices))
        return super().draw(robot, rng, chosen)
