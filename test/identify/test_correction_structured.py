"""The hybrid model's load-driven geometry (effects outside the vocabulary).
Known answers on the simulated UR10 (700 calibration / 300 hold-out poses): a gravity-side
backlash of joint 2 and link 3 twisting out of the arm plane, which the physical rungs
leave at 65 x and 20 x the noise floor and the Gaussian process alone at 27 x and 9 x, come
to about 1.1 x held out, and the strongest load-driven motion names the joint; where the
physical rung already reaches the floor the correction does no harm; the correction
survives PARAMS.json, and a file of the process alone (format 1) still loads."""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from robot_calib.errors import InputError
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import Calibration
from robot_calib.identify.correction_structured import StructuredCorrection, correction_from_dict
from robot_calib.identify.correction_structured_fit import fit_structured
from robot_calib.kinematics.frames import Array
from robot_calib.sim.blind import ur10_out_of_vocabulary
from robot_calib.sim.scenarios import Scenario, noise_rms_mm, ur10_random

HARMONICS = "geometric+joint_harmonics:2:orders=11,27+joint_harmonics:1:orders=17"


def rms_mm(residuals: Array) -> float:
    return float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))) * 1e3)


def hybrid_ratio(scenario: Scenario, model: str) -> tuple[float, float, StructuredCorrection]:
    """Held-out rms / noise floor of the physical model and of the hybrid."""
    cal = calibrate(scenario.calibration, scenario.world.model.robot, model)
    correction = fit_structured(
        cal.model, cal.parameters, scenario.calibration.poses, cal.residuals
    )
    floor = noise_rms_mm(scenario.world, scenario.holdout)
    held = cal.predict(scenario.holdout.poses) - scenario.holdout.points
    after = held - correction.predict(scenario.holdout.poses)
    return rms_mm(held) / floor, rms_mm(after) / floor, correction


@pytest.mark.parametrize(
    ("kind", "joint", "motion"),
    [
        ("gravity_backlash", 2, "rz"),  # joint 2's angle steps with its gravity torque's sign
        ("link_bending", 4, "rx"),  # joint 4's housing tilts about link 3's axis
    ],
)
def test_out_of_vocabulary_effects_come_to_the_floor(kind: str, joint: int, motion: str) -> None:
    scenario = ur10_out_of_vocabulary(kind, seed=0, n=1000)
    physical, hybrid, correction = hybrid_ratio(scenario, "geometric")
    assert physical > 15, physical  # measured: 65 x, 20.5 x
    assert hybrid < 1.5, (physical, hybrid)  # measured: 1.08 x, 1.05 x (goal: 3 x)
    first, *others = correction.strongest(scenario.calibration.poses)
    assert (first.joint, first.motion) == (joint, motion), first
    # the first explains the structure, what the others add is of the noise's size
    assert first.rms_um > 100 * max(m.rms_um for m in others), (first, others)
    # columns of rounding noise (loads zero by the geometry) are left out: coefficients of
    # a physical size, and the correction a smooth function of the readings
    assert np.abs(correction.coefficients).max() < 0.1
    poses = scenario.holdout.poses
    again = correction.predict(replace(poses, q=poses.q * (1 + 1e-15)))
    assert np.abs(again - correction.predict(poses)).max() < 1e-12


def test_no_harm_where_the_physical_rung_reaches_the_floor() -> None:
    scenario = ur10_random(seed=0, n=1000)
    physical, hybrid, correction = hybrid_ratio(scenario, HARMONICS)
    assert physical < 1.1 and hybrid <= physical * 1.01, (physical, hybrid)
    assert correction.dof == 0 and not np.any(correction.gp.dual), correction.line()


def load(doc: dict[str, Any]) -> StructuredCorrection:
    """The structured correction of a PARAMS.json document `doc` ('bad.json'), checked
    against the file's own parameters."""
    cal = Calibration.from_dict(doc, "bad.json")  # the file's model and parameters
    out = correction_from_dict(
        doc["correction"], cal.model, "bad.json: correction", cal.parameters
    )
    assert isinstance(out, StructuredCorrection)
    return out


def test_the_structured_correction_round_trips_through_params_json() -> None:
    scenario = ur10_out_of_vocabulary("link_bending", seed=0, n=400)
    recording, held = scenario.calibration, scenario.holdout
    geo = calibrate(recording, scenario.world.model.robot, "geometric")
    hybrid = geo.with_learned_correction(recording)
    assert isinstance(hybrid.correction, StructuredCorrection)
    doc = json.loads(json.dumps(hybrid.to_dict(recording)))
    assert doc["correction"]["format"] == "robot_calib.correction/2"
    back = Calibration.from_dict(doc, "hybrid.json")
    assert np.allclose(back.predict(held.poses), hybrid.predict(held.poses), rtol=0, atol=1e-12)
    assert rms_mm(back.predict(held.poses) - held.points) < 0.5 * rms_mm(
        geo.predict(held.poses) - held.points
    )
    # the format-1 section (the process alone) still loads, as written before
    old = {**doc, "correction": hybrid.correction.gp.to_dict()}
    assert old["correction"]["format"] == "robot_calib.correction/1"
    loaded = Calibration.from_dict(old, "old.json").correction
    assert loaded is not None and not isinstance(loaded, StructuredCorrection)
    assert np.allclose(
        loaded.predict(held.poses), hybrid.correction.gp.predict(held.poses), rtol=0, atol=1e-12
    )
    structured = doc["correction"]["structured"]
    parameters = structured["parameters"]
    changed = dict(parameters, **{k: v + 1e-9 for k, v in list(parameters.items())[:1]})
    for change, said in (
        ({"coefficients": [1.0]}, "coefficients must have"),
        ({"parameters": {"bogus": 0.0}}, "do not match"),
        ({"rms_m": 1.0}, "beyond"),
        # beyond physics: what it predicts at its own poses, against its stored size
        (
            {"coefficients": [1e4 * c for c in structured["coefficients"]]},
            "predicts .* mm at its own poses",
        ),
        (
            {"coefficients": [1.5 * c for c in structured["coefficients"]]},
            "structured.rms_m .* it predicts",
        ),
        ({"rms_m": 0.5 * structured["rms_m"]}, "structured.rms_m .* it predicts"),
        ({"ridge": -5.0}, "ridge must be >= 0"),
        ({"degrees_of_freedom": -1.0}, "degrees_of_freedom must be >= 0"),
        ({"ridge": None}, "coefficients must be zero with ridge null"),
        # its own parameters: those of the file
        ({"parameters": changed}, "differ from the file's parameters"),
    ):
        bad = json.loads(json.dumps(doc))
        bad["correction"]["structured"].update(change)
        with pytest.raises(InputError, match=f"^bad.json: correction: .*{said}"):
            load(bad)
    for change, said in (
        ({"rms_m": 2.0 * doc["correction"]["rms_m"]}, "rms_m .* it predicts"),
        ({"fitted_poses": -3}, "fitted_poses must be >= 1"),
    ):
        bad = json.loads(json.dumps(doc))
        bad["correction"].update(change)
        with pytest.raises(InputError, match=f"^bad.json: correction: .*{said}"):
            load(bad)


def test_a_correction_measures_its_stored_rms_as_its_loader_does() -> None:
    """The stored rms (structured.rms_m, rms_m) are what the loader measures at the
    readings as stored (rounded to 1e-12 rad), not at the fitted readings: a structured
    part whose coefficients cancel (a ridge of 1e-12 lets them) would otherwise carry the
    rounding into its rms and be refused by predict and score (params_best.json of a real
    ABB arm: 'structured.rms_m 0.2738 mm, it predicts 0.2738 mm rms')."""
    from robot_calib.identify.load_features import structured_design
    from robot_calib.poses import Poses

    scenario = ur10_out_of_vocabulary("link_bending", seed=0, n=300)
    recording = scenario.calibration
    geo = calibrate(recording, scenario.world.model.robot, "geometric")
    fitted = geo.with_learned_correction(recording).correction
    assert isinstance(fitted, StructuredCorrection)
    gp = fitted.gp
    assert len(gp.inducing_q) == fitted.n_fitted  # every fitted pose is an inducing pose
    # readings off the 1e-12 rad grid the file stores them on: held as stored
    off_grid = replace(gp, inducing_q=gp.inducing_q + 4.3e-13)
    assert np.array_equal(off_grid.inducing_q, np.round(gp.inducing_q + 4.3e-13, 12))
    poses = replace(Poses.from_readings(off_grid.inducing_q), target=gp.inducing_target)
    design = structured_design(
        fitted.model, fitted.parameters, fitted.columns, fitted.step_tau, poses
    ).reshape(-1, len(fitted.coefficients))
    _, singular, directions = np.linalg.svd(design, full_matrices=False)
    weak = int(np.flatnonzero(singular > 1e-10 * singular[0])[-1])  # weakest, not null
    # coefficients along it that predict 0.1 mm rms: huge, cancelling one another
    size = 1e-4 * np.sqrt(len(poses)) / singular[weak]
    cancelling = replace(
        fitted,
        gp=off_grid,
        ridge=1e-12,
        coefficients=fitted.coefficients + size * directions[weak],
    )
    own = cancelling.with_own_rms()
    stored = own.structured(replace(poses, q=np.round(poses.q, 12)))
    measured = float(np.sqrt(np.mean(np.sum(stored**2, axis=1))))
    assert abs(own.structured_rms_m - measured) <= 1e-12 * measured
    assert 0.05e-3 < own.structured_rms_m < 0.2e-3  # the 0.1 mm it was given
    cal = replace(geo, correction=own)
    doc = json.loads(json.dumps(cal.to_dict(recording)))
    back = Calibration.from_dict(doc, "cancelling.json")  # no InputError
    assert back.correction is not None
    held = scenario.holdout.poses
    assert np.allclose(back.predict(held), cal.predict(held), rtol=0, atol=1e-9)
