"""link_bending (simulator only, NOT in the contract's vocabulary): a link twisting about
its own axis under the weight of what hangs beside the arm plane, tilting the next joint's
housing and the wrist out of the arm plane.

Link j (the link joint j moves, from joint j's axis to joint j+1's housing, DH frame j)
carries the links beyond joint j+1. Their weight hangs off the arm plane (a UR's wrist
sits d4 = 0.16 m beside it), so besides joint j+1's own gravity torque the link carries a
moment across it:

    M = R_j^T sum_{i > j} (c_i - o_j) x m_i g           (frame j, [N m])

on the nominal kinematics and the robot's mass model (a payload included), c_i the centre
of mass of link i, o_j and R_j frame j's origin and orientation, g = -9.81 m/s^2 z of the
base. Its component about the link's own axis t (the link o_j - o_{j-1}, projected normal
to joint j+1's axis z_j and normalised) twists the link, so joint j+1's housing turns
about t:

    phi = c_j (M . t) t        (ex, ey of joint j+1's housing, frame j, [rad]; phi . z_j = 0)

entering the chain as housing error motions of joint j+1 (`E = Rx(ex) Ry(ey)` before its
rotation, the channel `eccentricity` uses; the small-angle rotation vector phi read as
ex, ey). On a UR forearm (j = 3, t along x_3, z_3 horizontal and normal to the arm plane)
M . t is the wrist's weight times its offset d4 from the arm plane, times the cosine of the
forearm's elevation: the forearm twists, joint 4's axis tilts out of the normal of the arm
plane and the flange, a lever of d5 + d6 beyond it, swings out of the arm plane by an
amount that follows the forearm's elevation (q_2 + q_3) and the wrist's configuration
(q_4, q_5, which set the lever and the wrist's centre of mass). Parameter `link_bendingJ`
[rad/(N m)] = c_j, the compliance of the link and of its joints' bearings about its axis;
the effect's joint J names the link. Simulator defaults and blind draws size c_j by its
effect at the flange: 150 um rms (draws: 50-300 um) over poses spread over the joint
limits; for a UR10 forearm 150 um is c_3 = 1.5e-4 rad/(N m) (twist stiffness 7 kN m/rad).

Why the form is the twist only: a link's bending under the same moment, about the
horizontal in-plane axis, turns the wrist about an axis fixed in the base and mostly drops
it by a constant amount, which the tracker frame and the DH angles absorb (on the
UR10 random-pose campaign a forearm bent and twisted as a tube keeps 40 % of its
deflection after a geometric fit, twisted only 80 %: `sim.blind.ur10_out_of_vocabulary`
leaves geometric at 22 x the noise floor, `test/sim/test_effects_outside_vocabulary.py`).

Why no effect of the vocabulary expresses it: the deflection is a turn about the link's
own axis, perpendicular to joint j+1's (no joint turns about it: `compliance`,
`gravity_compliance`, `backlash`, `transmission_error`, `joint_harmonics` and
`encoder_scale` are all rotations about joint axes), driven by the whole pose as a product
of functions of several joints; `eccentricity`, the vocabulary's only housing effect, is a
function of joint j+1's own reading.
"""

from __future__ import annotations

import numpy as np

from robot_calib.effects.base import Contribution, Effect, register_effect
from robot_calib.effects.compliance import GRAVITY
from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import Parameter, ParameterVector
from robot_calib.poses import Poses

#: simulator default: rms deflection of the flange over the workspace [m]
DEFAULT_FLANGE_M = 150e-6
#: blind tests: rms deflection of the flange [m], and the links drawn (upper arm, forearm)
DRAW_FLANGE_M = (50e-6, 300e-6)
DRAW_LINKS = (2, 3)
#: a link whose twisting moment stays below this rms [N m] over the workspace would need an
#: unphysical compliance to deflect the flange visibly: not drawn
SIGNIFICANT_MOMENT_NM = 2.0
#: a link shorter than this normal to the next joint's axis [m] has no axis to twist about
MIN_SPAN_M = 1e-6
#: poses spread over the joint limits where the flange deflection is sized (fixed, not drawn)
SPREAD_POSES = 500


def carried_moment(robot: RobotDescription, q: Array, link: int) -> Array:
    """M (n, 3) [N m] in frame `link`: the gravity moment about frame `link`'s origin of
    the links beyond joint link + 1 (1-based `link`), for readings q (n, J) [rad]."""
    frames = robot.nominal_frames(q)
    com = np.einsum("njab,jb->nja", frames[:, 1:, :3, :3], robot.link_com) + frames[:, 1:, :3, 3]
    force = robot.link_mass[:, None] * GRAVITY  # (J, 3) base frame
    origin = frames[:, link, :3, 3]
    moment = np.cross(com[:, link:] - origin[:, None, :], force[link:]).sum(axis=1)
    return np.einsum("nab,na->nb", frames[:, link, :3, :3], moment)


def twist_axis(robot: RobotDescription, link: int) -> Array:
    """The link's axis t (3,) in frame `link` (1-based): o_link - o_{link-1} normal to joint
    link+1's axis, normalised; zeros for a link along that axis (it cannot twist)."""
    frames = robot.nominal_frames(np.zeros((1, robot.n_joints)))[0]  # the span is fixed in frame j
    span = frames[link, :3, :3].T @ (frames[link, :3, 3] - frames[link - 1, :3, 3])
    span[2] = 0.0
    norm = float(np.linalg.norm(span))
    return span / norm if norm > MIN_SPAN_M else np.zeros(3)


def twist_alignment(robot: RobotDescription, link: int) -> float:
    """|cos| of the angle between link `link`'s twist axis (`twist_axis`) and its own joint's
    axis (joint `link`'s, z of frame link - 1): near 1, a twist turns the housing the way
    the joint turns (a joint-angle error, no twist); 0 for a link that cannot twist."""
    frames = robot.nominal_frames(np.zeros((1, robot.n_joints)))[0]
    own = frames[link, :3, :3].T @ frames[link - 1, :3, 2]
    return abs(float(twist_axis(robot, link) @ own))


def housing_per_unit(robot: RobotDescription, q: Array, link: int) -> Array:
    """Housing error motions (n, 5) [m, m, m, rad, rad per rad/(N m)] of joint link + 1 per
    unit compliance of link `link` (1-based): 0, 0, 0 and the twist's ex, ey."""
    axis = twist_axis(robot, link)
    twist = carried_moment(robot, q, link) @ axis  # (n,) [N m]
    out = np.zeros((len(q), 5))
    out[:, 3:] = twist[:, None] * axis[:2]
    return out


def flange_per_unit(robot: RobotDescription, q: Array, link: int) -> Array:
    """Flange-origin displacement (n,) [m per rad/(N m)] of link `link`'s twist, to first
    order: (R phi) x (flange - o_link)."""
    frames = robot.nominal_frames(q)
    ex_ey = housing_per_unit(robot, q, link)[:, 3:]
    tilt = np.einsum("nab,nb->na", frames[:, link, :3, :2], ex_ey)  # base frame
    lever = frames[:, -1, :3, 3] - frames[:, link, :3, 3]
    return np.linalg.norm(np.cross(tilt, lever), axis=1)


def _spread(robot: RobotDescription) -> Array:
    """SPREAD_POSES readings (n, J) [rad] spread over the joint limits (a fixed spread of
    poses, not a random draw)."""
    rng = np.random.default_rng(0)
    return rng.uniform(robot.limits[:, 0], robot.limits[:, 1], (SPREAD_POSES, robot.n_joints))


def bending_links(robot: RobotDescription) -> tuple[int, ...]:
    """Links (1-based, 1..J-1) whose twisting moment M . t exceeds SIGNIFICANT_MOMENT_NM
    rms over the poses spread over the joint limits."""
    q = _spread(robot)
    return tuple(
        j
        for j in range(1, robot.n_joints)
        if np.sqrt(np.mean((carried_moment(robot, q, j) @ twist_axis(robot, j)) ** 2))
        > SIGNIFICANT_MOMENT_NM
    )


def compliance_for(robot: RobotDescription, link: int, flange_rms_m: float) -> float:
    """The compliance [rad/(N m)] of link `link` that deflects the flange by `flange_rms_m`
    [m] rms over SPREAD_POSES poses spread over the joint limits."""
    rms = float(np.sqrt(np.mean(flange_per_unit(robot, _spread(robot), link) ** 2)))
    if rms < 1e-12:
        raise InputError(
            f"link_bending: link {link} of {robot.name} carries no moment to twist it "
            "(a link along the next joint's axis, or nothing beside the arm plane)"
        )
    return flange_rms_m / rms


@register_effect
class LinkBending(Effect):
    name = "link_bending"
    in_vocabulary = False

    def _check(self, robot: RobotDescription) -> None:
        bad = [j for j in self.joints if j >= robot.n_joints]
        if bad:
            raise InputError(
                f"link_bending: links {bad} carry no further joint (1..{robot.n_joints - 1})"
            )

    def parameters(self, robot: RobotDescription) -> list[Parameter]:
        self._check(robot)
        return [
            Parameter(f"{self.name}{j}", "rad/(N m)", 0.0, group=self.name) for j in self.joints
        ]

    def contribution(
        self, robot: RobotDescription, params: ParameterVector, poses: Poses
    ) -> Contribution:
        self._check(robot)
        n, n_joints = poses.q.shape
        jac = np.zeros((n, n_joints, 5, len(self.joints)))
        for k, j in enumerate(self.joints):
            jac[:, j, :, k] = housing_per_unit(robot, poses.q, j)  # joint j+1's housing
        return Contribution(housing=jac @ self.values(robot, params), housing_jac=jac)

    def diagnosed_joints(self) -> tuple[int, ...]:
        """The link's two joints: J and J + 1, whose housing turns."""
        return tuple(sorted({k for j in self.joints for k in (j, j + 1)}))

    def default_values(self, robot: RobotDescription) -> dict[str, float]:
        """Compliances that deflect the flange by DEFAULT_FLANGE_M rms each."""
        return {f"{self.name}{j}": compliance_for(robot, j, DEFAULT_FLANGE_M) for j in self.joints}

    @classmethod
    def draw(
        cls, robot: RobotDescription, rng: np.random.Generator, joint: int
    ) -> tuple[Effect, dict[str, float]]:
        """Link 2 or 3 with a significant twisting moment (`bending_links`; `joint` if it is
        one of them, else one at random), deflecting the flange by DRAW_FLANGE_M rms."""
        links = [j for j in DRAW_LINKS if j in bending_links(robot)] or list(DRAW_LINKS)
        link = joint if joint in links else int(rng.choice(links))
        effect = cls(joints=(link,))
        value = compliance_for(robot, link, float(rng.uniform(*DRAW_FLANGE_M)))
        return effect, {f"{cls.name}{link}": value}

    @classmethod
    def ladder_candidates(cls, robot: RobotDescription, poses: Poses) -> list[Effect]:
        """Every link that carries a further joint (the ladder never tries it: out of the
        vocabulary)."""
        return [cls(joints=(j,)) for j in range(1, robot.n_joints)]
