"""The blind harness: worlds with withheld effects (random joints, realistic random
magnitudes), calibrated on the seed's Test 2 sweeps and scored on random general poses; the
diagnosis, told nothing, must name the effects and their joints and bring the held-out
error to within 1.5 x the noise floor. Shared by the test suite and scripts/blind_harness.py.

Case classes (`classes()`):
- `none`, and every registered effect alone (`Effect.draw`: the vocabulary and the
  simulator-only `joint_ripple`, `gravity_backlash` and `link_bending`);
- COMBINATIONS: two or three effects at once ('backlash+thermal_warmup', ...);
- FORMS: effects in forms other than the vocabulary's: `compliance_payload` (gravity
  compliance of the robot with an unknown 2-5 kg payload: the vocabulary's `compliance`
  assumes the robot's own masses), `drift_exponential` (a first-order warm-up, where
  `thermal_drift` is linear in time), `ripple_order5` (a 5th-harmonic joint-angle ripple,
  the simulator's joint_ripple: no single order of the ladder's transmission_error, 1, 2,
  3, 4, 6, is it, order 6 holds it; judged by its joint, as effects outside the vocabulary),
  `harmonics_high` (high-order gear harmonics: joint_harmonics of orders 11 and 27 on
  joint 2 and 17 on joint 1, 50-300 urad each, random phases), `harmonics_aliased` (orders
  17 on joint 1, 23 on joint 2 and 11 on joint 3, calibrated on the sweeps alone: the
  sweeps' regular steps alias 23 with 43 and 44, 11 with 57; the hold-out's general poses
  tell them apart).
Calibration poses: the Test 2 sweeps; the classes of GENERAL_POSE_CLASSES add
GENERAL_POSES random general poses, because the sweeps alone do not show their effects:
the sweeps step by 5.3-6.2 deg, so a joint harmonic above order ~30 (joint_harmonics draws
7-60) is aliased on them and a frequency scan of the sweeps finds the alias; link_bending
follows the whole pose (the wrist's weight beside the arm plane), which single-joint sweeps
from one home pose barely vary (its right model fitted on the sweeps alone stays at 20-40 x
the floor); gravity_backlash's sign follows the gravity torque of the whole pose, and what
no vocabulary effect expresses is left to a learned correction, which learns from general
poses, not from sweeps. `link_bending` cases carry an unknown tool beside the joint-6
axis (CARRIED_TOOL_KG, CARRIED_TOOL_OFFSET_M): the KR5's wrist is in line with its arm, so
without a load beside the arm plane no link of it twists.
Judging (`judge`): effects of the vocabulary by name and joints (the dominant effect, or
each among the chosen rung's terms); effects whose options come from the residuals
(`Effect.candidates_from_residuals`: joint_harmonics' orders) also by those options (the
chosen rung holds every withheld parameter); effects outside the vocabulary by their joints
only (`Effect.diagnosed_joints`: link_bending's link J may be named J or J + 1), whatever
the effect named (`unknown` included), without the floor.
Every case also gets the right model's held-out error (the withheld effects, fitted as the
diagnosis would fit them, scored on the same hold-out poses): the diagnosis's chosen rung
over that is the `ratio_to_right` of the README.
`ur10_out_of_vocabulary` builds the out-of-vocabulary UR10 campaigns
(`sim.scenarios.ur10_random` with OOV_UR10 effects) for the hybrid model's tests.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from robot_calib.accuracy import accuracy
from robot_calib.diagnosis.diagnosis import Diagnosis
from robot_calib.diagnosis.evidence import STRUCTURE_Z
from robot_calib.diagnosis.signatures import WhereItLies
from robot_calib.effects import EFFECTS, Effect, effect_class, parse_effect
from robot_calib.effects.base import signed_uniform
from robot_calib.effects.compliance import Compliance
from robot_calib.effects.joint_harmonics import DRAW_RANGE as HARMONICS_RANGE
from robot_calib.effects.joint_harmonics import JointHarmonics
from robot_calib.effects.link_bending import compliance_for
from robot_calib.effects.ripple import DRAW_RANGE as RIPPLE_RANGE
from robot_calib.effects.ripple import JointRipple
from robot_calib.effects.thermal_temperature import ThermalTemperature
from robot_calib.effects.thermal_warmup import ThermalWarmup
from robot_calib.errors import InputError
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.fit import fit_model
from robot_calib.identify.model_spec import ModelSpec
from robot_calib.kinematics.description import RobotDescription, with_payload
from robot_calib.kinematics.loader import load_robot
from robot_calib.measurements import Recording
from robot_calib.model import KinematicModel
from robot_calib.records import Record
from robot_calib.sim.measure import record_plan
from robot_calib.sim.plans import Plan, paper_test_plan, random_plan
from robot_calib.sim.scenarios import UR10_HARMONICS, UR10_ROBOT, Scenario, ur10_random
from robot_calib.sim.world import TemperatureProfile, World, load_world, with_effect

NONE = "none"  # the class of cases with no withheld effect (geometric only)
FLOOR_FACTOR = 1.5
COMBINATIONS = (
    "backlash+thermal_warmup",
    "transmission_error+gravity_compliance",
    "backlash+eccentricity+thermal_warmup",
)
FORMS = (
    "compliance_payload",
    "drift_exponential",
    "ripple_order5",
    "harmonics_high",
    "harmonics_aliased",
)
#: the joint-angle harmonics of harmonics_high and harmonics_aliased: joint -> orders
HIGH_HARMONICS: dict[str, dict[int, tuple[int, ...]]] = {
    "harmonics_high": {2: (11, 27), 1: (17,)},
    "harmonics_aliased": {1: (17,), 2: (23,), 3: (11,)},
}
#: classes calibrated on the sweeps plus GENERAL_POSES random general poses (docstring)
GENERAL_POSE_CLASSES = ("joint_harmonics", "harmonics_high", "gravity_backlash", "link_bending")
GENERAL_POSES = 300
#: classes whose robot carries an unknown tool: mass [kg] and its centre's distance from
#: the joint-6 axis [m] (0.1 m out from the flange), each uniform in the range
CARRIED_TOOL_CLASSES = ("link_bending",)
CARRIED_TOOL_KG = (3.0, 5.0)
CARRIED_TOOL_OFFSET_M = (0.10, 0.15)
#: the out-of-vocabulary UR10 cases: kind -> (effect name, joint, magnitude): the
#: play [rad] of gravity_backlash, the flange deflection [m rms] of link_bending (whose
#: compliance is sized for it); geometric alone leaves about 60 x and 20 x the noise floor
OOV_UR10 = {
    "gravity_backlash": ("gravity_backlash", 2, 2.0e-3),
    "link_bending": ("link_bending", 3, 200e-6),
}
#: what a diagnosis may answer for each form (effect names it may name on the joints)
FORM_ANSWERS = {
    "compliance_payload": ("compliance", "gravity_compliance"),
    "drift_exponential": ("thermal_warmup",),
}


#: effects another vocabulary effect expresses term for term: a transmission error's k-th
#: harmonic is joint_harmonics at order k (the ladder, scanning orders, may name either)
SAME_TERMS = {"transmission_error": ("transmission_error", "joint_harmonics")}


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
        elif name in HIGH_HARMONICS:
            return _high_harmonics(world, HIGH_HARMONICS[name], rng)
        else:
            effect = JointRipple(joints=(joint,), order=5)
            values = {f"ripple_sin{joint}": float(rng.uniform(*RIPPLE_RANGE))}
        return with_effect(world, effect, values), [effect], values
    if name in CARRIED_TOOL_CLASSES:
        world = _carrying_tool(world, rng)
        robot = world.model.robot
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


def _high_harmonics(
    world: World, harmonics: dict[int, tuple[int, ...]], rng: np.random.Generator
) -> Withheld:
    """The world with joint harmonics (`harmonics`: joint -> orders), each of a random
    amplitude in joint_harmonics' DRAW_RANGE (50-300 urad) and a random phase."""
    effects: list[Effect] = []
    values: dict[str, float] = {}
    for joint, orders in harmonics.items():
        effect = JointHarmonics(joints=(joint,), orders=orders)
        mine = {}
        for k in orders:
            amplitude = signed_uniform(rng, *HARMONICS_RANGE)
            phase = rng.uniform(0.0, 2.0 * np.pi)
            mine[JointHarmonics.term(joint, "c", k)] = float(amplitude * np.sin(phase))
            mine[JointHarmonics.term(joint, "s", k)] = float(amplitude * np.cos(phase))
        world = with_effect(world, effect, mine)
        effects.append(effect)
        values.update(mine)
    return world, effects, values


def _carrying_tool(world: World, rng: np.random.Generator) -> World:
    """The world's robot carrying an unknown tool (CARRIED_TOOL_KG, its centre
    CARRIED_TOOL_OFFSET_M off the joint-6 axis at a random angle, 0.1 m out)."""
    mass, offset = rng.uniform(*CARRIED_TOOL_KG), rng.uniform(*CARRIED_TOOL_OFFSET_M)
    angle = rng.uniform(0.0, 2.0 * np.pi)
    centre = [offset * np.cos(angle), offset * np.sin(angle), 0.1]
    carrying = with_payload(world.model.robot, float(mass), centre)
    return replace(world, model=replace(world.model, robot=carrying))


def make_case(effect: str, seed: int, n_holdout: int = 200) -> Case:
    """A world with the class `effect` withheld (random joints and magnitudes from `seed`)
    and its calibration (Test 2 sweeps, plus GENERAL_POSES random general poses for the
    GENERAL_POSE_CLASSES) and hold-out (random general poses) recordings."""
    rng = np.random.default_rng(seed)
    world, withheld, values = _withheld(effect, load_world(), rng)
    robot = world.model.robot
    holdout_plan = random_plan(robot, n_holdout, rng)
    plan = paper_test_plan(2)
    if effect in GENERAL_POSE_CLASSES:
        general = random_plan(robot, GENERAL_POSES, rng)
        plan = Plan(
            f"{plan.name}+random",
            np.concatenate([plan.q, general.q]),
            np.concatenate([plan.sweep, general.sweep]),
            plan.speed_fraction,
        )
    return Case(
        effect,
        tuple(withheld),
        values,
        record_plan(world, plan, rng),
        record_plan(world, holdout_plan, rng),
        world,
    )


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
            fit_model(
                model,
                start.with_values({k: v for part in starts for k, v in part.items()}),
                case.calibration.poses,
                case.calibration.points,
            )
            for starts in itertools.product(*(e.fit_starts(robot) for e in case.withheld))
        ]
        best = min(fits, key=lambda f: f.solver.cost_m2 or 0.0)
        predicted = model.target_points(best.parameters, case.holdout.poses)
    return accuracy(case.holdout.points, predicted).absolute_rms_mm


def _answers(case: Case) -> list[tuple[tuple[str, ...], tuple[int, ...]]]:
    """What naming each withheld effect means: (acceptable effect names, its joints)."""
    if case.effect in FORM_ANSWERS:
        return [(FORM_ANSWERS[case.effect], case.joints)]
    return [(SAME_TERMS.get(e.name, (e.name,)), e.joints) for e in case.withheld]


def judge(case: Case, diagnosis: Diagnosis, right_rms_mm: float | None = None) -> dict[str, Any]:
    """Did the diagnosis name the withheld effects and their joints, and reach the floor?
    One effect: the dominant effect; several: each among the ladder's rungs; effects whose
    options come from the residuals (joint_harmonics): also their options, held by the
    chosen rung; outside the vocabulary: the dominant effect's joints are the right ones
    (`_joints_named`), whatever effect it names."""
    dom = diagnosis.dominant_effect
    ratio = diagnosis.unexplained.ratio_to_noise_floor
    outside = (
        bool(case.withheld)
        and case.effect not in FORM_ANSWERS
        and not all(effect_class(e.name).in_vocabulary for e in case.withheld)
    )
    robot = case.world.model.robot
    terms = _rung_terms(diagnosis, robot.n_joints)
    added = [(e.name, e.joints) for e in terms]
    if not case.withheld:
        named = dom is None
    elif outside:  # no model can name it: the right joints are the answer
        named = dom is not None and _joints_named(case.withheld, dom.joints)
    elif len(case.withheld) == 1:
        names, joints = _answers(case)[0]
        named = dom is not None and dom.effect in names and dom.joints == list(joints)
    else:
        named = all(
            any(n in names and set(joints) <= set(j) for n, j in added)
            for names, joints in _answers(case)
        )
    if case.withheld and not outside:
        named = named and _options_found(case.withheld, terms, robot)
    at_floor = ratio is not None and ratio <= FLOOR_FACTOR
    chosen = diagnosis.ladder[-1].holdout_abs_rms_mm
    evidence = judge_evidence(case, diagnosis.where)
    return {
        **evidence.to_dict(),
        "effect": case.effect,
        "joints": list(case.joints),
        "answer": None if dom is None else dom.to_dict(),
        "named": bool(named),
        "ratio_to_floor": ratio,
        "at_floor": bool(at_floor),
        "hit": bool(named and (at_floor or outside)),
        "outliers": len(diagnosis.outliers),  # the harness injects no blunder: must be 0
        "chosen_model": diagnosis.ladder[-1].model,
        "chosen_rms_mm": chosen,
        "right_rms_mm": right_rms_mm,
        "ratio_to_right": None if right_rms_mm is None else chosen / right_rms_mm,
    }


@dataclass(frozen=True)
class EvidenceVerdict(Record):
    """How true the per-joint evidence of a case's geometric residuals is (`where`):
    false_rows: the effect-free joints (not in any withheld effect's `diagnosed_joints`)
    with a term at >= EVIDENCE_Z, of free_rows; missed: the withheld effects' joints
    without one (an effect diagnosed on other joints, `Effect.diagnosed_joints`: without one
    on any of them); strongest_ok: the strongest structure is on a withheld effect's joint, or
    on time for a thermal effect, or there is none (>= EVIDENCE_Z) without effects."""

    false_rows: list[int]
    free_rows: int
    missed: list[int]
    strongest_ok: bool


#: the significance at which a term counts as structure in `judge_evidence`
EVIDENCE_Z = STRUCTURE_Z
#: effects whose structure is time, not a joint
TIME_EFFECTS = ("thermal_drift", "thermal_warmup", "thermal_temperature")


def judge_evidence(case: Case, where: WhereItLies) -> EvidenceVerdict:
    """`EvidenceVerdict` of `where` (a diagnosis's, of the geometric model's residuals) on
    `case`: every term a joint shows anywhere (both per-joint tables and the frequency
    scan's orders carry the joint fit's numbers, `where.evidence`)."""
    allowed = {j for e in case.withheld for j in e.diagnosed_joints()}
    shown: dict[int, float] = {}
    for term in where.evidence:
        shown[term.joint] = max(shown.get(term.joint, 0.0), term.significance)
    n_joints = case.world.model.robot.n_joints
    free = [j for j in range(1, n_joints + 1) if j not in allowed]
    false = [j for j in free if shown.get(j, 0.0) >= EVIDENCE_Z]
    missed = []  # an effect diagnosed on other joints than its own (a link's twist shows
    for e in case.withheld:  # on the housing it turns): found on any of them
        if tuple(e.diagnosed_joints()) == tuple(e.joints):
            missed += [j for j in e.joints if shown.get(j, 0.0) < EVIDENCE_Z]
        elif all(shown.get(j, 0.0) < EVIDENCE_Z for j in e.diagnosed_joints()):
            missed += list(e.joints)
    missed = sorted(set(missed))
    timed = case.effect == "drift_exponential" or any(
        e.name in TIME_EFFECTS for e in case.withheld
    )
    sig = where.strongest_signature
    if sig is None or sig.significance < EVIDENCE_Z:
        ok = not case.withheld or (not case.joints and not timed)
    else:
        ok = sig.joint in allowed or (sig.joint == 0 and timed)
    return EvidenceVerdict(false, len(free), missed, ok)


def _rung_terms(diagnosis: Diagnosis, n_joints: int) -> list[Effect]:
    """The effects of the chosen physical rung's model name (its terms after the geometry;
    the hybrid rung, a learned correction on top of it, adds none)."""
    return [parse_effect(t, n_joints) for t in ModelSpec.parse(diagnosis.physical_model).terms]


def _joints_named(withheld: tuple[Effect, ...], joints: list[int]) -> bool:
    """True when `joints` (a diagnosis's answer) are joints of the withheld effects
    (`Effect.diagnosed_joints`) and name at least one of each."""
    allowed = [set(e.diagnosed_joints()) for e in withheld]
    return (
        bool(joints)
        and set(joints) <= set().union(*allowed)
        and all(set(joints) & a for a in allowed)
    )


def _options_found(
    withheld: tuple[Effect, ...], terms: list[Effect], robot: RobotDescription
) -> bool:
    """True when the chosen rung's `terms` hold every parameter of each withheld effect
    whose options come from the residuals (joint_harmonics: its joints and orders)."""
    for effect in withheld:
        if not effect_class(effect.name).candidates_from_residuals:
            continue
        held = {n for t in terms if t.name == effect.name for n in t.parameter_names(robot)}
        if not set(effect.parameter_names(robot)) <= held:
            return False
    return True


def ur10_out_of_vocabulary(
    kind: str, seed: int = 0, n: int = 1000, holdout_share: float = 0.3, harmonics: bool = False
) -> Scenario:
    """The UR10 random-pose campaign (`sim.scenarios.ur10_random`: `n` poses,
    `holdout_share` held out) with effects outside the vocabulary: `kind` a key of OOV_UR10
    or several joined by '+' ('gravity_backlash+link_bending'); `harmonics` adds the UR10's
    gear harmonics (UR10_HARMONICS). The answer: the world's effects and their
    `diagnosed_joints` (gravity_backlash: joint 2; link_bending of link 3: joints 3-4)."""
    robot = load_robot(UR10_ROBOT)
    entries = []
    for part in kind.split("+"):
        if part not in OOV_UR10:
            raise InputError(f"{part!r}: no out-of-vocabulary UR10 case (known: {list(OOV_UR10)})")
        name, joint, size = OOV_UR10[part]
        value = compliance_for(robot, joint, size) if name == "link_bending" else size
        entries.append({"name": name, "joints": [joint], "values": {f"{name}{joint}": value}})
    return ur10_random(seed, n, holdout_share, (*(UR10_HARMONICS if harmonics else ()), *entries))
