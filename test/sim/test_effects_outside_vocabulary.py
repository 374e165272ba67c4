"""The simulator's effects outside the vocabulary: gravity_backlash and
link_bending, known answers of their physics, that no vocabulary model absorbs them on
the UR10 random-pose campaign, and the blind harness's cases for them and for high-order joint
harmonics (built and judged here; diagnosing them is the harness's and test_diagnose's).

The checks every effect gets (Jacobian against finite differences, text and file forms,
PARAMS.json round trip, realistic simulator defaults) run for both in test_effects.py,
which is parametrized over the registry.
"""

from __future__ import annotations

import json
from types import SimpleNamespace
from typing import Any, cast

import numpy as np
import pytest

from robot_calib.accuracy import accuracy
from robot_calib.diagnosis.diagnosis import Diagnosis, DominantEffect, diagnose
from robot_calib.effects import EFFECTS, make_effect, vocabulary
from robot_calib.effects.compliance import gravity_torques
from robot_calib.effects.gravity_backlash import TAU0_NM, GravityBacklash
from robot_calib.effects.joint_harmonics import JointHarmonics
from robot_calib.effects.link_bending import (
    DEFAULT_FLANGE_M,
    LinkBending,
    _spread,
    carried_moment,
    housing_per_unit,
    twist_axis,
)
from robot_calib.errors import InputError
from robot_calib.flows.blind import run_case
from robot_calib.identify.calibrate import calibrate
from robot_calib.kinematics.loader import load_robot
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses
from robot_calib.sim.blind import (
    GENERAL_POSES,
    OOV_UR10,
    Case,
    classes,
    judge,
    make_case,
    ur10_out_of_vocabulary,
)
from robot_calib.sim.plans import paper_test_plan
from robot_calib.sim.scenarios import noise_rms_mm

UR10 = load_robot("ur10")
PLAY = 2.0e-3  # rad
DEG = np.pi / 180.0
# UR10 wrist (links 4-6, UR's published masses and centres) at q5 = 0: its first moment
# out of the arm plane, sum m_i (offset of c_i along joint 4's axis) [kg m]
WRIST_OUT_OF_PLANE_KG_M = (
    2.0 * (0.163941 + 0.007)  # link 4: d4, its centre 7 mm along y_4 = z_3
    + 2.0 * (0.163941 + 0.018)  # link 5: d4, its centre 18 mm along z_5 = z_3
    + 0.365 * (0.163941 + 0.0922 - 0.026)  # link 6: d4 + d6, its centre -26 mm along z_6
)


def ur10_poses(rows_deg: list[list[float]], direction: float = 1.0) -> Poses:
    q = np.radians(np.array(rows_deg, dtype=float))
    return Poses.from_readings(q, direction=np.full(q.shape, direction))


def model_and_truth(effect: Any, values: dict[str, float]) -> tuple[KinematicModel, Any]:
    model = KinematicModel(UR10, (effect,))
    return model, model.parameters().with_values(values)


# -- gravity_backlash ---------------------------------------------------------------------


def test_gravity_backlash_takes_the_side_of_the_gravity_torque() -> None:
    """Over a sweep of joint 2 through the vertical the offset is (b/2) tanh(tau / tau0):
    +-b/2 where |tau| >> tau0, its sign flips exactly where the gravity torque's does, on
    joint 2 only, and the approach direction changes nothing (backlash's does)."""
    effect = GravityBacklash(joints=(2,))
    model, params = model_and_truth(effect, {"gravity_backlash2": PLAY})
    rows = [[0.0, q2, 30.0, -90.0, 90.0, 0.0] for q2 in np.linspace(-170.0, -10.0, 161)]
    forth, back = ur10_poses(rows, 1.0), ur10_poses(rows, -1.0)
    offset = effect.contribution(UR10, params, forth).joint_offset
    assert offset is not None
    np.testing.assert_array_equal(offset, effect.contribution(UR10, params, back).joint_offset)
    assert not np.any(np.delete(offset, 1, axis=1))
    tau = gravity_torques(UR10, forth.q)[:, 1]
    assert tau.min() < -100.0 and tau.max() > 100.0  # the sweep crosses the vertical
    far = np.abs(tau) > 10.0 * TAU0_NM
    np.testing.assert_allclose(offset[far, 1], 0.5 * PLAY * np.sign(tau[far]), rtol=1e-8)
    flips = np.flatnonzero(np.diff(np.sign(offset[:, 1])))
    assert flips.tolist() == np.flatnonzero(np.diff(np.sign(tau))).tolist() and len(flips) == 1


def test_gravity_backlash_turns_the_joint_by_half_its_play() -> None:
    """Far from the sign change the target moves exactly as theta2 turned by +-b/2: the
    arm reaching forward (gravity torque one way) and back over the top (the other)."""
    model, params = model_and_truth(GravityBacklash(joints=(2,)), {"gravity_backlash2": PLAY})
    poses = ur10_poses(
        [[10.0, -20.0, -30.0, 0.0, 60.0, 0.0], [10.0, -160.0, 30.0, 0.0, 60.0, 0.0]]
    )
    sign = np.sign(gravity_torques(UR10, poses.q)[:, 1])
    assert sign.tolist() in ([1.0, -1.0], [-1.0, 1.0])
    geometric = KinematicModel(UR10)
    for k in range(2):
        turned = geometric.parameters().with_values({"theta2": 0.5 * PLAY * sign[k]})
        np.testing.assert_allclose(
            model.target_points(params, poses.subset(np.array([k]))),
            geometric.target_points(turned, poses.subset(np.array([k]))),
            atol=1e-13,
        )


# -- link_bending -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "q1, q2, q3, q4, q6", [(0, 0, 0, 0, 0), (40, 30, -30, 70, -120), (-90, -150, 150, 200, 30)]
)
def test_link_bending_twisting_moment_is_the_wrist_weight_beside_the_arm_plane(
    q1: float, q2: float, q3: float, q4: float, q6: float
) -> None:
    """Known answer: the UR10 forearm (link 3) twists under g x the wrist's first moment
    out of the arm plane (0.790 kg m at q5 = 0) x cos(forearm elevation q2 + q3), whatever
    q1, q4 and q6; the twist turns joint 4's housing about the forearm only (ex, ey; no
    shift)."""
    elevations = np.array([0.0, 60.0, 90.0, 135.0])
    rows = [[q1, q2, q3 + e, q4, 0.0, q6] for e in elevations]
    q = np.radians(np.array(rows, dtype=float))
    twist = carried_moment(UR10, q, 3) @ twist_axis(UR10, 3)
    expected = 9.81 * WRIST_OUT_OF_PLANE_KG_M * np.cos(np.radians(q2 + q3 + elevations))
    np.testing.assert_allclose(np.abs(twist), np.abs(expected), atol=1e-9)
    assert abs(9.81 * WRIST_OUT_OF_PLANE_KG_M - 7.7476) < 1e-3
    unit = housing_per_unit(UR10, q, 3)
    assert not np.any(unit[:, :3])
    np.testing.assert_allclose(unit[:, 3:], twist[:, None] * twist_axis(UR10, 3)[:2])
    np.testing.assert_allclose(np.abs(twist_axis(UR10, 3)), [1.0, 0.0, 0.0])  # along x_3


def test_link_bending_tilts_the_wrist_plane_out_of_the_arm_plane() -> None:
    """Joints 3 and 4 of a UR10 are parallel (both normal to the arm plane); a twisted
    forearm turns everything beyond it, joint 4's axis and the wrist, about the forearm by
    c |M . t|, so the wrist's plane of motion leaves the arm plane's; and the flange
    deflection over the workspace is the documented size (DEFAULT_FLANGE_M rms: the exact
    chain against the sizing's first order)."""
    effect = LinkBending(joints=(3,))
    values = effect.default_values(UR10)
    model, params = model_and_truth(effect, values)
    nominal = KinematicModel(UR10)
    plain = nominal.parameters()  # the tracker frame is the base frame
    poses = ur10_poses(
        [[20.0, -30.0, 10.0, 50.0, 0.0, 0.0], [0.0, -120.0, 60.0, -40.0, 0.0, 90.0]]
    )
    origins, axes = nominal.joint_axes(plain, poses)
    np.testing.assert_allclose(axes[:, 3], axes[:, 2], atol=1e-12)  # joints 3, 4 parallel
    forearm = origins[:, 3] - origins[:, 2]  # frame 2 to frame 3
    forearm /= np.linalg.norm(forearm, axis=1, keepdims=True)
    turn = model.flange_rotations(params, poses) @ np.swapaxes(
        nominal.flange_rotations(plain, poses), 1, 2
    )  # the wrist's extra rotation, base frame
    angle = np.arccos(np.clip((np.trace(turn, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0))
    twist = carried_moment(UR10, poses.q, 3) @ twist_axis(UR10, 3)
    np.testing.assert_allclose(angle, values["link_bending3"] * np.abs(twist), rtol=1e-6)
    about = np.stack(
        [
            turn[:, 2, 1] - turn[:, 1, 2],
            turn[:, 0, 2] - turn[:, 2, 0],
            turn[:, 1, 0] - turn[:, 0, 1],
        ],
        axis=1,
    )
    about /= np.linalg.norm(about, axis=1, keepdims=True)
    np.testing.assert_allclose(np.abs(np.einsum("na,na->n", about, forearm)), 1.0, atol=1e-9)
    spread = Poses.from_readings(_spread(UR10))
    moved = model.target_points(params, spread) - nominal.target_points(plain, spread)
    rms = float(np.sqrt(np.mean(np.sum(moved**2, axis=1))))
    assert abs(rms / DEFAULT_FLANGE_M - 1.0) < 0.01


def test_link_bending_names_a_link_and_its_two_joints() -> None:
    effect = make_effect("link_bending", [3])
    assert effect.diagnosed_joints() == (3, 4)
    assert GravityBacklash(joints=(2,)).diagnosed_joints() == (2,)
    with pytest.raises(InputError, match="carry no further joint"):
        LinkBending(joints=(6,)).parameters(UR10)


# -- outside the vocabulary on the UR10 random-pose campaign ------------------------------


def test_both_are_registered_outside_the_vocabulary() -> None:
    for name in ("gravity_backlash", "link_bending"):
        assert name in EFFECTS and name not in vocabulary()
        assert not EFFECTS[name].in_vocabulary


@pytest.mark.parametrize(
    "kind, vocabulary_models",
    [
        ("gravity_backlash", ("compliance:2,3", "gravity_compliance:2,3", "backlash:2,3")),
        (
            "link_bending",
            ("compliance:3,4,5", "gravity_compliance:3,4,5", "eccentricity:4,5:order=2"),
        ),
    ],
)
def test_no_vocabulary_model_absorbs_it(kind: str, vocabulary_models: tuple[str, ...]) -> None:
    """On 400 random UR10 poses (280 calibrate, 120 held out) geometric leaves >= 15 x the
    noise floor held out, and so does each vocabulary model of the joints it acts on
    (measured: gravity_backlash 65 x geometric, 45 x compliance; link_bending 22 x, 19 x)."""
    scenario = ur10_out_of_vocabulary(kind, seed=0, n=400)
    floor = noise_rms_mm(scenario.world, scenario.holdout)
    robot = scenario.world.model.robot

    def held_out(cal: Any) -> float:
        predicted = cal.predict(scenario.holdout.poses)
        return accuracy(scenario.holdout.points, predicted).absolute_rms_mm / floor

    geo = calibrate(scenario.calibration, robot, "geometric", log=None, screen_outliers=False)
    assert held_out(geo) >= 15.0
    for spec in vocabulary_models:
        cal = calibrate(
            scenario.calibration,
            robot,
            f"geometric+{spec}",
            log=None,
            start=geo,
            screen_outliers=False,
        )
        assert held_out(cal) >= 15.0, spec


def test_ur10_out_of_vocabulary_cases() -> None:
    both = ur10_out_of_vocabulary("gravity_backlash+link_bending", n=20, harmonics=True)
    assert [e.spec for e in both.world.effects] == [
        "joint_harmonics:1:orders=17",
        "joint_harmonics:2:orders=11,27",
        "gravity_backlash:2",
        "link_bending:3",
    ]
    assert both.world.truth["gravity_backlash2"] == OOV_UR10["gravity_backlash"][2]
    assert len(both.calibration) == 14 and len(both.holdout) == 6
    with pytest.raises(InputError, match="no out-of-vocabulary UR10 case"):
        ur10_out_of_vocabulary("thermal_drift")


# -- the blind harness's cases ------------------------------------------------------------

NEW_CLASSES = ("joint_harmonics", "harmonics_high", "gravity_backlash", "link_bending")


def true_motion_mm(case: Case) -> float:
    """rms [mm] the withheld effects move the hold-out targets (exact, noise-free)."""
    world = case.world
    bare = KinematicModel(world.model.robot)
    truth = bare.parameters().with_values(
        {k: v for k, v in zip(world.truth.names, world.truth.values) if k in bare.parameters()}
    )
    moved = world.model.target_points(world.truth, case.holdout.poses) - bare.target_points(
        truth, case.holdout.poses
    )
    return float(np.sqrt(np.mean(np.sum(moved**2, axis=1))) * 1e3)


def test_the_new_classes_are_blind_classes() -> None:
    assert set(NEW_CLASSES) <= set(classes())


@pytest.mark.parametrize("effect", NEW_CLASSES)
def test_make_case_builds_the_new_classes(effect: str) -> None:
    """The Test 2 sweeps plus GENERAL_POSES random poses to calibrate on, 200 hold-out
    poses, the withheld effects switched on in the world, moving the targets by more than
    the noise (~9 um; a joint-6 harmonic moves a target 0.06 m off the axis by ~13 um)."""
    case = make_case(effect, 0)
    sweeps = len(paper_test_plan(2).q)
    assert len(case.calibration) == sweeps + GENERAL_POSES and len(case.holdout) == 200
    assert set(case.withheld) <= set(case.world.effects) and case.withheld
    assert 0.01 < true_motion_mm(case) < 2.0
    names = {e.name for e in case.withheld}
    if effect == "harmonics_high":
        assert set(case.withheld) == {
            JointHarmonics(joints=(2,), orders=(11, 27)),
            JointHarmonics(joints=(1,), orders=(17,)),
        }
        amplitudes = [
            np.hypot(case.values[f"jh{j}_c{k}"], case.values[f"jh{j}_s{k}"])
            for j, k in ((2, 11), (2, 27), (1, 17))
        ]
        assert all(50e-6 <= a <= 300e-6 for a in amplitudes)
    else:
        assert names == {effect}
    if effect == "gravity_backlash":
        assert case.joints in ((2,), (3,))
        assert 1e-3 <= case.values[f"gravity_backlash{case.joints[0]}"] <= 4e-3
    if effect == "link_bending":
        assert case.joints in ((2,), (3,))
        nominal = load_robot("kr5_sixx_r650")
        assert case.world.model.robot.link_mass[-1] - nominal.link_mass[-1] >= 3.0  # a tool


def diagnosis(joints: list[int] | None, model: str, effect: str = "unknown") -> Diagnosis:
    """A stand-in with what `judge` reads: the dominant effect, the chosen rung, the ratio."""
    dominant = None if joints is None else DominantEffect(effect, joints)
    rung = SimpleNamespace(model=model, holdout_abs_rms_mm=0.01, learned=False)
    return cast(
        Diagnosis,
        SimpleNamespace(
            dominant_effect=dominant,
            ladder=[rung],
            outliers=[],
            physical_model=model,
            unexplained=SimpleNamespace(ratio_to_noise_floor=1.2),
            where=SimpleNamespace(evidence=[], strongest_signature=None),
        ),
    )


def test_judge_names_harmonics_by_joints_and_orders() -> None:
    case = make_case("harmonics_high", 0)
    right = "geometric+joint_harmonics:2:orders=11,27+joint_harmonics:1:orders=17"
    assert judge(case, diagnosis([1, 2], right, "joint_harmonics"))["hit"]
    split = "geometric+joint_harmonics:2:orders=11+joint_harmonics:1,2:orders=17,27"
    assert judge(case, diagnosis([1, 2], split, "joint_harmonics"))["hit"]
    for wrong in (
        "geometric+joint_harmonics:2:orders=11,26+joint_harmonics:1:orders=17",  # an order
        "geometric+joint_harmonics:2:orders=11,27",  # joint 1 missing
        "geometric+transmission_error:2:order=6+joint_harmonics:1:orders=17",
    ):
        assert not judge(case, diagnosis([1, 2], wrong, "joint_harmonics"))["named"], wrong


def test_judge_names_effects_outside_the_vocabulary_by_their_joints() -> None:
    """Any effect name ('unknown' included) on the right joints, no floor needed;
    link_bending of link J may be named J, J + 1 or both, nothing else."""
    bending = make_case("link_bending", 0)
    link = bending.joints[0]
    for joints in ([link], [link + 1], [link, link + 1]):
        verdict = judge(bending, diagnosis(joints, "geometric"))
        assert verdict["named"] and verdict["hit"], joints
    for joints in ([link - 1], [link, link + 2], []):
        assert not judge(bending, diagnosis(joints, "geometric"))["named"], joints
    assert not judge(bending, diagnosis(None, "geometric"))["named"]
    backlash = make_case("gravity_backlash", 0)
    joint = backlash.joints[0]
    assert judge(backlash, diagnosis([joint], "geometric+compliance:2", "compliance"))["hit"]
    assert not judge(backlash, diagnosis([joint, 5], "geometric"))["named"]


def test_params_of_a_case_world_name_its_effects() -> None:
    """The world's truth holds every withheld value (the right model starts from them)."""
    case = make_case("link_bending", 1)
    truth = cast(ParameterVector, case.world.truth)
    for name, value in case.values.items():
        assert truth[name] == value


def test_judge_a_real_diagnosis_whose_hybrid_rung_won() -> None:
    """A link twisting out of the arm plane: the diagnosis ends with the hybrid rung (a
    learned correction on the best physical rung); the judge reads the physical rung's
    effects (it once parsed '+learned' as an effect and crashed) and scores the hybrid."""
    case = make_case("link_bending", 0)
    diagnosis, _ = diagnose(case.calibration, case.world.model.robot, case.holdout)
    hybrid, physical = diagnosis.ladder[-1], diagnosis.ladder[-2]
    assert hybrid.learned and not physical.learned, [r.model for r in diagnosis.ladder]
    assert hybrid.holdout_abs_rms_mm <= 0.95 * physical.holdout_abs_rms_mm  # it won
    verdict = judge(case, diagnosis)
    assert verdict["chosen_model"] == hybrid.model and verdict["chosen_rms_mm"] > 0


@pytest.mark.parametrize(("kind", "joint"), [("gravity_backlash", 2), ("link_bending", 4)])
def test_the_diagnosis_says_what_lies_outside_the_vocabulary(kind: str, joint: int) -> None:
    """On the UR10 campaign the physical rungs stay far above the floor, the
    hybrid rung comes to it, and the diagnosis says that most of what remains lies outside
    the vocabulary, naming the joint whose load-driven motion it is (gravity backlash:
    joint 2's angle; link 3 twisting: joint 4's axis) in the verdict and DIAGNOSIS.json."""
    scenario = ur10_out_of_vocabulary(kind, seed=0, n=1000)
    diagnosis, _ = diagnose(scenario.calibration, UR10, holdout=scenario.holdout)
    outside = diagnosis.outside_vocabulary
    assert outside is not None, diagnosis.verdict
    floor = noise_rms_mm(scenario.world, scenario.holdout)
    assert outside.hybrid_abs_rms_mm < 1.5 * floor < outside.physical_abs_rms_mm / 5, outside
    assert outside.joints[0] == joint, outside.line()
    assert "outside the vocabulary" in diagnosis.verdict and f"[{joint}" in diagnosis.verdict
    again = Diagnosis.from_dict(json.loads(json.dumps(diagnosis.to_dict())))
    assert again.outside_vocabulary == outside


def test_a_link_twisting_under_an_unknown_tool_is_named_by_its_load_driven_motion() -> None:
    """The blind harness's hardest case outside the vocabulary: a KR5 carrying an unknown
    3-5 kg tool 0.1-0.15 m off the joint-6 axis (the diagnosis knows no payload), one link
    twisting under it; geometric leaves ~20 x the floor. The learned correction's load
    features of an unknown payload bring the hybrid rung to the floor, and its strongest
    motion names the twisting link (link J: joint J or J + 1), which no signature of the
    physical residuals did (they pointed at joint 5)."""
    verdict = run_case("link_bending", 1000)
    assert verdict["named"] and verdict["hit"], verdict
    assert verdict["chosen_model"].endswith("+learned"), verdict
    assert verdict["ratio_to_floor"] < 1.5 and verdict["ratio_to_right"] < 1.4, verdict
