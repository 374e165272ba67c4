"""An honest floor and the learnable bound: without repeat poses, circle sweeps
or a stated accuracy the noise floor is unknown and every output says so; the verdict is
never null merely because geometric fits itself: a residual model (a Gaussian process on
the readings, its hyperparameters from the calibration poses only) scored held out decides
whether structure is left. Known answers: simulated worlds with random poses only."""

from __future__ import annotations

import numpy as np
import pytest

from robot_calib.diagnosis.diagnosis import UNKNOWN, diagnose
from robot_calib.effects import parse_effect, registered
from robot_calib.effects.base import JointOffsetEffect
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import plan_times, random_plan
from robot_calib.sim.world import World, load_world, with_effect

WORLD = load_world()
ROBOT = WORLD.model.robot


def random_poses(world: World, n: int, seed: int) -> Recording:
    """n random general poses (no sweep, no repeat): a UR10-style campaign."""
    rng = np.random.default_rng(seed)
    plan = random_plan(ROBOT, n, rng)
    time = plan_times(plan, world.timing)
    points = physical_points(world, Poses.from_readings(plan.q, time=time), rng)
    return recording_from_arrays(plan.q, points, time, robot=ROBOT)


class Coupled(JointOffsetEffect):
    """theta_j += c_j cos(q_{j+1}): an undeclared coupling, outside the vocabulary."""

    name = "test_coupling"
    in_vocabulary = False
    unit = "rad"
    default_magnitude = 5e-4
    draw_range = (4e-4, 6e-4)

    def signal(self, robot: RobotDescription, poses: Poses) -> Array:
        return np.cos(np.roll(poses.q, -1, axis=1))


def test_without_independent_evidence_the_floor_is_unknown_and_said_so() -> None:
    cal, held = random_poses(WORLD, 150, 1), random_poses(WORLD, 100, 2)
    diagnosis, _ = diagnose(cal, ROBOT, held)
    noise = diagnosis.noise
    assert not noise.floor_known and noise.floor_abs_rms_mm is None and noise.sigma_mm is None
    assert diagnosis.unexplained.ratio_to_noise_floor is None
    assert "noise floor unknown" in diagnosis.unexplained.note
    assert "Noise floor unknown" in diagnosis.summary()
    bound = diagnosis.learnable
    assert bound is not None and not bound.structure_left  # nothing but noise to learn
    assert "Gaussian process" in bound.method and len(bound.length_scales_deg) == 6
    assert bound.noise_mm is not None and bound.fitted_poses == 150
    assert diagnosis.dominant_effect is None
    assert "noise floor unknown" in diagnosis.verdict
    # a stated tracker accuracy is a floor: geometric is then at it
    stated, _ = diagnose(cal, ROBOT, held, tracker_sigma_m=4.8e-6)
    assert stated.noise.floor_known and stated.noise.source.startswith("stated")
    ratio = stated.unexplained.ratio_to_noise_floor
    assert ratio is not None and 0.8 < ratio < 1.4
    assert stated.verdict.startswith("null (geometric reaches the noise level; that floor rests")
    assert "stated tracker accuracy (given by the user) alone" in stated.verdict


def test_structure_no_effect_explains_is_unknown_not_null_without_a_floor() -> None:
    """An undeclared coupling of joint 2 to joint 3's reading: no effect of the vocabulary
    removes it, the floor is unknown, yet the residual model learns it held out: the
    verdict is 'unknown', never null."""
    with registered(Coupled):
        world = with_effect(WORLD, Coupled(joints=(2,)), {"test_coupling2": 5e-4})
        cal, held = random_poses(world, 150, 3), random_poses(world, 100, 4)
    diagnosis, _ = diagnose(cal, ROBOT, held)
    bound = diagnosis.learnable
    assert bound is not None and bound.structure_left, bound
    assert bound.holdout_abs_rms_mm < 0.8 * bound.geometric_abs_rms_mm
    assert diagnosis.dominant_effect is not None
    if len(diagnosis.ladder) == 1:  # no rung helped: the structure is named unknown
        assert diagnosis.dominant_effect.effect == UNKNOWN


def test_each_rung_reports_its_share_of_the_learnable_gap() -> None:
    """A harmonic-drive ripple (2nd harmonic of joint 2, 200 urad): a joint-angle harmonic
    of joint 2 (transmission_error, or joint_harmonics at order 2: the same term) is found
    and closes the whole gap to within 1 % (the bound: that rung plus a learned correction,
    which finds nothing left)."""
    effect = parse_effect("transmission_error:2:order=2", ROBOT.n_joints)
    world = with_effect(WORLD, effect, {"te2_s2": 2e-4})
    cal, held = random_poses(world, 150, 5), random_poses(world, 100, 6)
    diagnosis, _ = diagnose(cal, ROBOT, held, tracker_sigma_m=4.8e-6)
    dom = diagnosis.dominant_effect
    assert dom is not None and dom.joints == [2]
    assert dom.effect in ("transmission_error", "joint_harmonics")
    shares = [r.learnable_gap_share for r in diagnosis.ladder]
    assert shares[0] == pytest.approx(0.0, abs=1e-12)
    assert shares[-1] == pytest.approx(1.0, abs=0.01)
    effects = dict(diagnosis.effect_shares())  # each effect's own share: here the one
    added = diagnosis.ladder[1].model.removeprefix("geometric+")
    assert effects == pytest.approx({added: 1.0}, abs=0.01)
    ratio = diagnosis.unexplained.ratio_to_noise_floor
    assert ratio is not None and ratio < 1.5


def test_a_share_never_prints_as_minus_zero() -> None:
    """Geometric's own share of -1.3e-16 prints as '0 %', never '-0 %'."""
    from robot_calib.diagnosis.diagnosis import percent

    assert percent(-1.33e-16) == "0 %"
    assert percent(-0.004) == "0 %"
    assert percent(0.996) == "100 %"
    assert percent(-0.25) == "-25 %"


def test_a_residual_model_worse_than_geometric_bounds_nothing() -> None:
    """A residual model that does worse held out than geometric alone did not fit: its
    figure is no bound (a '10.0150 mm bound' was printed beside a 0.155 mm geometric
    error), neither in the line nor in the ladder's picture."""
    from robot_calib.diagnosis.learnable import LearnableBound

    worse = LearnableBound("method", "hold-out bags", 0.155, 0.14, 10.015, 9.0, -63.6)
    assert not worse.bounds
    line = worse.line()
    assert line.startswith("learnable bound: none: the residual model did not fit")
    assert "10.0150 mm with it" in line and "learnable" not in line.split(":", 2)[2]
    better = LearnableBound("method", "hold-out bags", 0.155, 0.14, 0.010, 0.009, 0.93)
    assert better.bounds and "93 % of geometric's error is learnable" in better.line()
