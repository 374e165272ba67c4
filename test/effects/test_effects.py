"""Every registered effect, checked through the one Effect interface: a new effect module is
covered here without editing this file (test_effect_plugin.py proves it with an effect that
exists only in the test suite).

For each effect: its analytic Jacobian against finite differences at realistic random
values (`Effect.draw`), its text and file forms and a PARAMS.json round trip of a fitted
model, and its simulator defaults (they move the target by a realistic amount).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from robot_calib.effects import (
    EFFECTS,
    Effect,
    effect_from_dict,
    ladder_candidates,
    make_effect,
    parse_effect,
    vocabulary,
)
from robot_calib.identify.calibrate import calibrate, parse_model
from robot_calib.identify.calibration import Calibration, load_calibration
from robot_calib.identify.params_file import write_json_atomic
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import recording_from_arrays
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import paper_test_plan, random_plan
from robot_calib.sim.world import load_world, with_effect

WORLD = load_world()
ROBOT = WORLD.model.robot


def random_poses(rng: np.random.Generator, n: int) -> Poses:
    """n random poses within the limits, both approach directions, an hour of time and a
    recorded temperature (20-30 deg C, for effects that follow it)."""
    lo, hi = ROBOT.limits.T
    poses = Poses.from_readings(
        rng.uniform(lo, hi, (n, ROBOT.n_joints)), time=np.sort(rng.uniform(0, 3600, n))
    )
    return replace(poses, temperature=rng.uniform(20.0, 30.0, n))


def finite_difference(
    model: KinematicModel, params: ParameterVector, poses: Poses, names: list[str]
) -> np.ndarray:
    """Central differences of the target points w.r.t. `names`, shape (n, 3, len(names))."""
    cols = []
    for name in names:
        step = 1e-6 * max(1.0, abs(params[name]))
        plus = model.target_points(params.with_values({name: params[name] + step}), poses)
        minus = model.target_points(params.with_values({name: params[name] - step}), poses)
        cols.append((plus - minus) / (2 * step))
    return np.stack(cols, axis=-1)


def check_jacobian(cls: type[Effect], seed: int) -> None:
    """The model's analytic Jacobian w.r.t. the effect's parameters (and the geometry, which
    the effect's channels change) equals finite differences at random true values."""
    rng = np.random.default_rng(seed)
    effect, values = cls.draw(ROBOT, rng, int(rng.integers(1, ROBOT.n_joints + 1)))
    assert set(values) <= set(effect.parameter_names(ROBOT)), "draw names unknown parameters"
    model = KinematicModel(ROBOT, (effect,))
    params = model.parameters((2.2, 1.0, -0.3, 0.1, -0.1, 3.0), (0.06, 0.0, 0.05))
    params = params.with_values(values)
    poses = random_poses(rng, 12)
    _, jac = model.jacobian(params, poses)
    names = [n for n in params.names if not n.startswith("base2tracker")]
    fd = finite_difference(model, params, poses, names)
    ours = jac[:, :, [params.index(n) for n in names]]
    scale = np.maximum(np.abs(ours).max(axis=(0, 1)), 1.0)
    np.testing.assert_allclose(ours / scale, fd / scale, atol=2e-7)


def check_text_and_file_forms(cls: type[Effect]) -> None:
    """spec -> parse_effect and to_dict -> effect_from_dict give the same effect back, for
    every ladder candidate and a drawn instance; candidates are vocabulary effects only."""
    rng = np.random.default_rng(1)
    drawn, _ = cls.draw(ROBOT, rng, 2)
    poses = random_poses(rng, 30)
    for effect in [drawn, *cls.ladder_candidates(ROBOT, poses)]:
        assert parse_effect(effect.spec, ROBOT.n_joints) == effect, effect.spec
        assert effect_from_dict(effect.to_dict()) == effect
        assert effect.covers(effect, ROBOT)
        names = effect.parameter_names(ROBOT)
        assert len(names) == len(set(names)) and all(n for n in names)
    listed = ladder_candidates(ROBOT, poses)
    offered = cls.name in vocabulary() and not cls.candidates_from_residuals
    assert offered == any(e.name == cls.name for e in listed)


def check_params_round_trip(cls: type[Effect], tmp_path: Path) -> None:
    """A model with the effect, fitted on simulated data, written as PARAMS.json and loaded
    back: the same effects, parameter values and predictions."""
    rng = np.random.default_rng(2)
    effect, values = cls.draw(ROBOT, rng, 3)
    world = with_effect(WORLD, effect, values)
    plan = paper_test_plan(2)
    q = np.concatenate([plan.q, random_plan(ROBOT, 60, rng).q])
    poses = Poses.from_readings(q, time=np.arange(len(q)) * 3.0)
    celsius = 22.0 + 6.0 * np.sin(poses.time / 300.0)  # a recorded temperature
    poses = replace(poses, temperature=celsius)
    recording = recording_from_arrays(
        q, physical_points(world, poses, rng), poses.time, temperature=celsius
    )
    spec = "geometric+" + effect.spec
    if cls.in_vocabulary:
        assert parse_model(spec, ROBOT)[1] == [effect]
    cal = calibrate(recording, ROBOT, "geometric", log=None)
    if cls.in_vocabulary:
        cal = calibrate(recording, ROBOT, spec, log=None, start=cal)
    path = tmp_path / f"{cls.name}.json"
    write_json_atomic(cal.to_dict(recording), path)
    model, params = (loaded := Calibration.load(path)).model, loaded.parameters
    assert model.effects == cal.model.effects
    np.testing.assert_array_equal(params.values, cal.parameters.values)
    test = random_poses(rng, 10)
    np.testing.assert_allclose(model.target_points(params, test), cal.predict(test), atol=1e-12)
    loaded = load_calibration(path)  # the typed object: the same model, 1-sigma and report
    assert loaded.model.effects == cal.model.effects and loaded.name == cal.name
    np.testing.assert_array_equal(loaded.std, cal.std)
    assert loaded.accuracy == cal.accuracy and loaded.solver == cal.solver
    assert loaded.identifiability == cal.identifiability


def check_simulator_defaults(cls: type[Effect]) -> None:
    """Default magnitudes name real parameters and move the target by a realistic amount:
    more than the tracker noise (1 um), less than a gross error (5 mm) rms."""
    poses = random_poses(np.random.default_rng(3), 200)
    for joints in ([2], [3]) if cls.per_joint else ([],):
        effect = make_effect(cls.name, joints)
        values = effect.default_values(ROBOT)
        assert values and set(values) <= set(effect.parameter_names(ROBOT))
        world = with_effect(WORLD, effect)
        moved = world.model.target_points(world.truth, poses) - WORLD.model.target_points(
            WORLD.truth, poses
        )
        rms = np.sqrt(np.mean(np.sum(moved**2, axis=1)))
        assert 1e-6 < rms < 5e-3, f"{effect.label}: default moves the target {rms * 1e3} mm"


@pytest.mark.parametrize("name", list(EFFECTS))
@pytest.mark.parametrize("seed", [0, 1])
def test_jacobian_matches_finite_differences(name: str, seed: int) -> None:
    check_jacobian(EFFECTS[name], seed)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_text_and_file_forms_round_trip(name: str) -> None:
    check_text_and_file_forms(EFFECTS[name])


@pytest.mark.parametrize("name", list(EFFECTS))
def test_params_file_round_trip(name: str, tmp_path: Path) -> None:
    check_params_round_trip(EFFECTS[name], tmp_path)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_simulator_defaults_are_realistic(name: str) -> None:
    check_simulator_defaults(EFFECTS[name])


def test_registry_order_and_vocabulary_are_the_contracts() -> None:
    """The contract's vocabulary (section 3) is registered, extended (msgs_doc/effects.md)
    and never renamed; simulator-only effects are not in it; model names print and parse
    through the registry."""
    contract = {"eccentricity", "backlash", "compliance", "encoder_scale", "thermal_drift"}
    added = {  # beyond the contract
        "transmission_error",
        "gravity_compliance",
        "thermal_warmup",
        "thermal_temperature",
    } | {"joint_harmonics"}
    assert set(vocabulary()) == contract | added
    assert "joint_ripple" not in vocabulary()
    base, effects = parse_model("geometric+eccentricity:6:order=3+thermal_drift", ROBOT)
    assert base == "geometric" and [e.spec for e in effects] == [
        "eccentricity:6:order=3",
        "thermal_drift",
    ]
    assert [e.joints for e in parse_model("geometric+backlash", ROBOT)[1]] == [tuple(range(1, 7))]
