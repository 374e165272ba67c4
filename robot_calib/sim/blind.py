"""The blind harness: worlds with withheld effects (random joints, realistic random
magnitudes), calibrated on the seed's Test 2 sweeps and scored on random general poses; the
diagnosis, told nothing, must name the effects and their joints and bring the held-out
error to within 1.5 x the noise floor. Shared by the test suite and scripts/blind_harness.py.

Case classes (`classes()`):
- `none`, and every registered effect alone (`Effect.draw`: the vocabulary and the
  simulator-only `joint_ripple`);
- COMBINATIONS: two or three effects at once ('backlash+thermal_warmup', ...);
- FORMS: effects in forms other than the vocabulary's: `compliance_payload` (gravity
  compliance of the robot with an unknown 2-5 kg payload: the vocabulary's `compliance`
  assumes the robot's own masses), `drift_exponential` (a first-order warm-up, where
  `thermal_drift` is linear in time), `ripple_order5` (a 5th-harmonic joint-angle ripple,
  the simulator's joint_ripple: no single order of the ladder's transmission_error, 1, 2,
  3, 4, 6, is it, order 6 holds it; judged by its joint, as effects outside the vocabulary).
Every case also gets the right model's held-out error (the withheld effects, fitted as the
diagnosis would fit them, scored on the same hold-out poses): the diagnosis's chosen rung
over that is the `ratio_to_right` of the README.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from robot_calib.accuracy import accuracy
from robot_calib.diagnose.diagnosis import Diagnosis, diagnose
from robot_calib.effects import EFFECTS, Effect, effect_class, parse_effect
from robot_calib.effects.compliance import Compliance
from robot_calib.effects.ripple import DRAW_RANGE as RIPPLE_RANGE
from robot_calib.effects.ripple import JointRipple
from robot_calib.effects.thermal_temperature import ThermalTemperature
from robot_calib.effects.thermal_warmup import ThermalWarmup
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.fit import fit_model
from robot_calib.kinematics.description import RobotDescription, with_payload
from robot_calib.measurements import Recording
from robot_calib.model import KinematicModel
from robot_calib.sim.measure import record_plan
from robot_calib.sim.plans import paper_test_plan, random_plan
from robot_calib.sim.world import TemperatureProfile, World, load_world, with_effect

NONE = "none"  # the class of cases with no withheld effect (geometric only)
FLOOR_FACTOR = 1.5
COMBINATIONS = (
    "backlash+thermal_warmup",
    "transmission_error+gravity_compliance",
    "backlash+eccentricity+thermal_warmup",
)
FORMS = ("compliance_payload", "drift_exponential", "ripple_order5")
#: what a diagnosis may answer for each form (effect names it may name on the joints)
FORM_ANSWERS = {
    "compliance_payload": ("compliance", "gravity_compliance"),
    "drift_exponential": ("thermal_warmup",),
}


def classes() -> tuple[str, ...]:
    """The case classes: none, every registered effect, the combinations and the forms."""
    return (NONE, *EFFECTS, *COMBINATIONS, *FORMS)


@dataclass(frozen=True)
class Case:
    """One blind case: its class, the withheld effects (their joints and true values) and
    its recordings; `world` the true world (the right model's robot: a payload included)."""

    effect: str
    withheld: tuple[Effect, ...]
    values: dict[str, float]
    calibration: Recording
    holdout: Recording
    world: World

    @property
    def joints(self) -> tuple[int, ...]:
        """Every joint of the withheld effects, sorted."""
        return tuple(sorted({j for e in self.withheld for j in e.joints}))


def random_effect(
    effect: str, robot: RobotDescription, rng: np.random.Generator
) -> tuple[Effect | None, dict[str, float]]:
    """A random instance of the class `effect` (random joint) and realistic random true
    values (SI), `Effect.draw`; (None, {}) for the class `none`."""
    joint = int(rng.integers(1, robot.n_joints + 1))  # drawn for every class: same streams
    if effect == NONE:
        return None, {}
    return effect_class(effect).draw(robot, rng, joint)


Withheld = tuple[World, list[Effect], dict[str, float]]


def _withheld(name: str, world: World, rng: np.random.Generator) -> Withheld:
    """The world with the effects of class `name` switched on, and those effects."""
    robot = world.model.robot
    if name in FORMS:
        joint = int(rng.integers(1, robot.n_joints + 1))
        if name == "compliance_payload":
            centre = [*rng.uniform(-0.05, 0.05, 2), 0.1]
            carrying = with_payload(robot, float(rng.uniform(2.0, 5.0)), centre)
            world = replace(world, model=replace(world.model, robot=carrying))
            effect, values = Compliance.draw(robot, rng, joint)
        elif name == "drift_exponential":
            effect, values = ThermalWarmup.draw(robot, rng, joint)
        else:
            effect = JointRipple(joints=(joint,), order=5)
            values = {f"ripple_sin{joint}": float(rng.uniform(*RIPPLE_RANGE))}
        return with_effect(world, effect, values), [effect], values
    effects: list[Effect] = []
    values = {}
    for part in name.split("+") if name != NONE else []:
        drawn_effect, drawn = random_effect(part, robot, rng)
        assert drawn_effect is not None
        effects.append(drawn_effect)
        values.update(drawn)
        world = with_effect(world, drawn_effect, drawn)
    if name == NONE:
        random_effect(NONE, robot, rng)  # the same random streams as before
    if any(isinstance(e, ThermalTemperature) for e in effects):
        world = replace(world, temperature=TemperatureProfile())  # a recorded temperature
    return world, effects, values


def make_case(effect: str, seed: int, n_holdout: int = 200) -> Case:
    """A world with the class `effect` withheld (random joints and magnitudes from `seed`)
    and its calibration (Test 2 sweeps) and hold-out (random general poses) recordings."""
    rng = np.random.default_rng(seed)
    world, withheld, values = _withheld(effect, load_world(), rng)
    holdout_plan = random_plan(world.model.robot, n_holdout, rng)
    return Case(effect, tuple(withheld), values, record_plan(world, paper_test_plan(2), rng),
                record_plan(world, holdout_plan, rng), world)  # fmt: skip


def right_model_rms_mm(case: Case) -> float:
    """Held-out rms [mm] of the right model: the withheld effects (on the true world's
    robot, a payload included) fitted from the geometric calibration, as the ladder fits."""
    robot = load_world().model.robot
    geo = calibrate(case.calibration, robot, "geometric", screen_outliers=False)
    if not case.withheld:
        predicted = geo.predict(case.holdout.poses)
    else:
        model = KinematicModel(case.world.model.robot, case.withheld)
        start = model.parameters().with_values(
            dict(zip(geo.parameters.names, geo.parameters.values))
        )
        fits = [
            fit_model(model, start.with_values({k: v for part in starts for k, v in part.items()}),
                      case.calibration.poses, case.calibration.points)
            for starts in itertools.product(*(e.fit_starts(robot) for e in case.withheld))
        ]  # fmt: skip
        best = min(fits, key=lambda f: f.solver.cost_m2 or 0.0)
        predicted = model.target_points(best.parameters, case.holdout.poses)
    return accuracy(case.holdout.points, predicted).absolute_rms_mm


def _answers(case: Case) -> list[tuple[tuple[str, ...], tuple[int, ...]]]:
    """What naming each withheld effect means: (acceptable effect names, its joints)."""
    if case.effect in FORM_ANSWERS:
        return [(FORM_ANSWERS[case.effect], case.joints)]
    return [((e.name,), e.joints) for e in case.withheld]


def judge(case: Case, diagnosis: Diagnosis, right_rms_mm: float | None = None) -> dict[str, Any]:
    """Did the diagnosis name the withheld effects and their joints, and reach the floor?
    One effect: the dominant effect; several: each among the ladder's rungs; outside the
    vocabulary: the dominant effect's joints are the right ones."""
    dom = diagnosis.dominant_effect
    ratio = diagnosis.unexplained.ratio_to_noise_floor
    outside = (
        bool(case.withheld)
        and case.effect not in FORM_ANSWERS
        and not all(effect_class(e.name).in_vocabulary for e in case.withheld)
    )
    added = _rung_effects(diagnosis, case.world.model.robot.n_joints)
    if not case.withheld:
        named = dom is None
    elif outside:  # no model can name it: the right joints are the answer
        named = dom is not None and list(case.joints) == dom.joints
    elif len(case.withheld) == 1:
        names, joints = _answers(case)[0]
        named = dom is not None and dom.effect in names and dom.joints == list(joints)
    else:
        named = all(
            any(n in names and set(joints) <= set(j) for n, j in added)
            for names, joints in _answers(case)
        )
    at_floor = ratio is not None and ratio <= FLOOR_FACTOR
    chosen = diagnosis.ladder[-1].holdout_abs_rms_mm
    return {
        "effect": case.effect,
        "joints": list(case.joints),
        "answer": None if dom is None else dom.to_dict(),
        "named": bool(named),
        "ratio_to_floor": ratio,
        "at_floor": bool(at_floor),
        "hit": bool(named and (at_floor or outside)),
        "outliers": len(diagnosis.outliers),  # the harness injects no blunder: must be 0
        "chosen_rms_mm": chosen,
        "right_rms_mm": right_rms_mm,
        "ratio_to_right": None if right_rms_mm is None else chosen / right_rms_mm,
    }


def _rung_effects(diagnosis: Diagnosis, n_joints: int) -> list[tuple[str, tuple[int, ...]]]:
    """(effect name, joints) of every term of the chosen rung's model name."""
    terms = diagnosis.ladder[-1].model.split("+")[1:]
    return [(e.name, e.joints) for e in (parse_effect(t, n_joints) for t in terms)]


def run_case(effect: str, seed: int) -> dict[str, Any]:
    """Make, diagnose and judge one blind case (with its right model's held-out error)."""
    case = make_case(effect, seed)
    diagnosis, _ = diagnose(case.calibration, load_world().model.robot, case.holdout)
    return judge(case, diagnosis, right_model_rms_mm(case))
