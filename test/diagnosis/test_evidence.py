"""The per-joint evidence (diagnosis/evidence.py) on blind worlds whose truth is known: the
joints without an effect show no term at >= 5 x its uncertainty, the joint with the effect
does, and the strongest structure is on it (or on time for a drift). Tested one term at a
time against the tracker's noise, a backlash on joint 4 showed on joints 1 and 6 at over
100 x and a compliance on joint 3 on joints 2 and 5."""

from __future__ import annotations

import numpy as np
import pytest

from robot_calib.diagnosis.evidence import joint_evidence, normal_z, paired_z
from robot_calib.diagnosis.signatures import where_it_lies
from robot_calib.identify.calibrate import calibrate
from robot_calib.poses import reading_groups
from robot_calib.sim.blind import EVIDENCE_Z, judge_evidence, make_case
from robot_calib.sim.world import load_world


@pytest.mark.parametrize(
    ("effect", "seed"),
    [
        ("backlash", 1002),  # joint 4, as the README's run
        ("compliance", 1000),  # joint 3: seen on a short arc as its gravity, reading, 1st harmonic
        ("thermal_drift", 1000),  # time, no joint
        ("none", 1000),
        ("link_bending", 1000),  # link 2 twisting under an unknown tool: joint 3's housing turns
    ],
)
def test_structure_only_where_the_world_has_it(effect: str, seed: int) -> None:
    case = make_case(effect, seed)
    geo = calibrate(case.calibration, load_world().model.robot, "geometric", screen_outliers=False)
    where = where_it_lies(geo.model, geo.parameters, case.calibration, geo.residuals, 5e-6)
    verdict = judge_evidence(case, where)
    assert verdict.false_rows == [], (verdict, where.strongest_signature)
    assert verdict.missed == [], verdict
    assert verdict.strongest_ok, where.strongest_signature
    sig = where.strongest_signature
    if effect == "thermal_drift":
        assert sig is not None and sig.joint == 0 and "time" in sig.text
        assert where.time.drift_significance >= EVIDENCE_Z
    if effect == "link_bending":  # once read as joint 5's gravity term (no twist term then)
        assert sig is not None and sig.family == "twist" and sig.joint == 3, sig
        assert [t.joint for t in where.twists()] == [3], where.twists()
    else:
        assert where.twists() == [], where.twists()
    # one number per term: the arc table's harmonics are the joint fit's
    for arc, terms in zip(where.joints, where.joints_from_all_poses):
        assert arc.harmonics_significance == terms.harmonics_significance


def test_a_term_the_poses_cannot_resolve_has_no_value() -> None:
    """On the seed's sweeps joint 2 turns through a short arc only: its low harmonics and
    its reading's slope are collinear there; they get no amplitude (an arc 4035.8 urad
    'harmonic' beside an rms of 12.6 urad was printed before) and no significance."""
    case = make_case("none", 1000)
    geo = calibrate(case.calibration, load_world().model.robot, "geometric", screen_outliers=False)
    evidence = joint_evidence(geo.model, geo.parameters, case.calibration, geo.residuals)
    unresolved = [t for t in evidence.terms if not t.resolvable]
    assert unresolved, "some terms of a short arc must be unresolvable"
    assert all(t.value is None and t.significance == 0.0 for t in unresolved)
    # the scatter the joint fit leaves is the tracker's noise here (5 um per axis)
    assert 4e-6 < evidence.scatter_m < 6.5e-6, evidence.scatter_m
    for t in evidence.terms:
        if t.value is not None and t.family == "harmonics":
            assert abs(t.value) < 200.0, t  # urad: no made-up amplitude in a world without any


def test_normal_z_and_the_paired_test() -> None:
    assert normal_z(25.0, 1) == pytest.approx(5.0)
    assert 4.0 < normal_z(25.0, 2) < 5.0  # the same chi^2 on two degrees is less surprising
    assert normal_z(1e6, 6) == pytest.approx(np.sqrt(1e6 - 5), rel=1e-6)
    rng = np.random.default_rng(0)
    null = [paired_z(rng.normal(0.0, 1.0, 200)) for _ in range(400)]
    assert np.mean(np.abs(null) >= 2.0) < 0.1  # ~5 % of pure noise reaches 2
    assert paired_z(rng.normal(1.0, 1.0, 200)) > 10


def test_reads_of_one_pose_share_a_group() -> None:
    q = np.array([[0.1, 0.2], [0.1, 0.2], [0.3, 0.2], [0.1 + 1e-9, 0.2], [0.3, 0.2]])
    assert reading_groups(q).tolist() == [0, 0, 1, 0, 1]
