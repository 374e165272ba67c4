"""The blind harness: worlds with one withheld effect (random joint, realistic random
magnitude), calibrated on the seed's Test 2 sweeps and scored on random general poses; the
diagnosis, told nothing, must name the effect and its joints and bring the held-out error
to within 1.5 x the noise floor. Shared by the test suite and scripts/blind_harness.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from robot_calib.diagnose.diagnosis import Diagnosis, diagnose
from robot_calib.effects import EFFECTS, Effect, effect_class
from robot_calib.kinematics.description import RobotDescription
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import Plan, paper_test_plan, plan_times, random_plan
from robot_calib.sim.world import World, load_world, with_effect

NONE = "none"  # the class of cases with no withheld effect (geometric only)
FLOOR_FACTOR = 1.5


def classes() -> tuple[str, ...]:
    """The case classes: none, then every registered effect (vocabulary or not)."""
    return (NONE, *EFFECTS)


@dataclass(frozen=True)
class Case:
    """One blind case: the withheld effect (class, joints, true values) and its recordings."""

    effect: str
    joints: tuple[int, ...]
    values: dict[str, float]
    calibration: Recording
    holdout: Recording


def random_effect(
    effect: str, robot: RobotDescription, rng: np.random.Generator
) -> tuple[Effect | None, dict[str, float]]:
    """A random instance of the class `effect` (random joint) and realistic random true
    values (SI), `Effect.draw`; (None, {}) for the class `none`."""
    joint = int(rng.integers(1, robot.n_joints + 1))  # drawn for every class: same streams
    if effect == NONE:
        return None, {}
    return effect_class(effect).draw(robot, rng, joint)


def _record(world: World, plan: Plan, rng: np.random.Generator) -> Recording:
    time = plan_times(plan, world.timing)
    poses = Poses.from_readings(plan.q, time=time)
    return recording_from_arrays(
        plan.q, physical_points(world, poses, rng), time, robot=world.model.robot
    )


def make_case(effect: str, seed: int, n_holdout: int = 200) -> Case:
    """A world with `effect` withheld (random joint and magnitude from `seed`) and its
    calibration (Test 2 sweeps) and hold-out (random general poses) recordings."""
    rng = np.random.default_rng(seed)
    world = load_world()
    withheld, values = random_effect(effect, world.model.robot, rng)
    if withheld is not None:
        world = with_effect(world, withheld, values)
    holdout_plan = random_plan(world.model.robot, n_holdout, rng)
    joints = () if withheld is None else withheld.joints
    return Case(effect, joints, values, _record(world, paper_test_plan(2), rng),
                _record(world, holdout_plan, rng))  # fmt: skip


def judge(case: Case, diagnosis: Diagnosis) -> dict[str, Any]:
    """Did the diagnosis name the withheld effect and its joints, and reach the floor?"""
    dom = diagnosis.dominant_effect
    ratio = diagnosis.unexplained.ratio_to_noise_floor
    outside = case.effect != NONE and not effect_class(case.effect).in_vocabulary
    if case.effect == NONE:
        named = dom is None
    elif outside:  # no model can name it: the right joints are the answer
        named = dom is not None and list(case.joints) == dom.joints
    else:
        named = dom is not None and dom.effect == case.effect and (dom.joints == list(case.joints))
    at_floor = ratio is not None and ratio <= FLOOR_FACTOR
    return {
        "effect": case.effect,
        "joints": list(case.joints),
        "answer": None if dom is None else dom.to_dict(),
        "named": bool(named),
        "ratio_to_floor": ratio,
        "at_floor": bool(at_floor),
        "hit": bool(named and (at_floor or outside)),
        "outliers": len(diagnosis.outliers),  # the harness injects no blunder: must be 0
    }


def run_case(effect: str, seed: int) -> dict[str, Any]:
    """Make, diagnose and judge one blind case."""
    case = make_case(effect, seed)
    diagnosis, _ = diagnose(case.calibration, load_world().model.robot, case.holdout)
    return judge(case, diagnosis)
