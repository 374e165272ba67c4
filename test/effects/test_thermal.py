"""Thermal effects real robots have: a first-order warm-up (amplitude and time
constant identified, where thermal_drift is a line) and an expansion that follows the
robot's recorded temperature (the side topic /temperature, read from bags). Known
answers: simulated worlds."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from robot_calib.bag.read import read_recording
from robot_calib.bag.write import write_measurement_bag
from robot_calib.diagnosis.diagnosis import diagnose
from robot_calib.effects import parse_effect
from robot_calib.identify.calibrate import calibrate
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import Plan, paper_test_plan, plan_times, random_plan
from robot_calib.sim.world import TemperatureProfile, World, load_world, with_effect

BASE = load_world()
ROBOT = BASE.model.robot


def recorded(world: World, plan: Plan, seed: int) -> Recording:
    time = plan_times(plan, world.timing)
    celsius = None if world.temperature is None else world.temperature.at(time)
    poses = replace(Poses.from_readings(plan.q, time=time), temperature=celsius)
    points = physical_points(world, poses, np.random.default_rng(seed))
    return recording_from_arrays(plan.q, points, time, robot=ROBOT, temperature=celsius)


def test_a_warm_up_gives_its_amplitude_and_time_constant() -> None:
    effect = parse_effect("thermal_warmup", ROBOT.n_joints)
    truth = {"thermal_warmup_strain": 4e-4, "thermal_warmup_ln_tau": float(np.log(500.0))}
    world = with_effect(BASE, effect, truth)
    cal = calibrate(recorded(world, paper_test_plan(2), 1), ROBOT, "geometric+thermal_warmup")
    for name, value in truth.items():
        k = cal.parameters.index(name)
        assert abs(cal.parameters[name] - value) < 4 * cal.std[k], (name, cal.parameters[name])
    assert cal.accuracy.absolute_rms_mm < 0.012


def test_expansion_follows_the_recorded_temperature_through_a_bag(tmp_path: Path) -> None:
    """A warm-up plus the hall's air conditioning (not monotonic in time): the bag's
    /temperature is read back per point, alpha is identified, and the diagnosis names
    thermal_temperature, not a drift in time."""
    effect = parse_effect("thermal_temperature", ROBOT.n_joints)
    world = replace(
        with_effect(BASE, effect, {"thermal_temperature_alpha": 2.5e-5}),
        temperature=TemperatureProfile(),
    )
    sim = recorded(world, paper_test_plan(2), 2)
    assert sim.poses.temperature is not None
    bag = tmp_path / "warm.mcap"
    write_measurement_bag(
        bag,
        sim.poses.q,
        sim.points,
        ROBOT.joint_names,
        sim.poses.time,
        temperature=sim.poses.temperature,
    )
    recording = read_recording([bag], ROBOT)
    assert recording.poses.temperature is not None
    np.testing.assert_allclose(recording.poses.temperature, sim.poses.temperature, atol=1e-9)
    cal = calibrate(recording, ROBOT, "geometric+thermal_temperature")
    k = cal.parameters.index("thermal_temperature_alpha")
    assert abs(cal.parameters["thermal_temperature_alpha"] - 2.5e-5) < 4 * cal.std[k]
    held = recorded(world, random_plan(ROBOT, 100, np.random.default_rng(3)), 4)
    diagnosis, _ = diagnose(recording, ROBOT, held)
    dom = diagnosis.dominant_effect
    assert dom is not None and dom.effect == "thermal_temperature"
    ratio = diagnosis.unexplained.ratio_to_noise_floor
    assert ratio is not None and ratio < 1.5


def test_points_a_thermal_effect_explains_are_no_blunders() -> None:
    """A UR10 warming by 7 deg C over 600 random poses: the geometric fit alone flags the
    coldest points as tracker blunders; the best rung (thermal_temperature) explains them,
    so they are re-admitted and the ladder climbed again: no outlier left, the effect
    named."""
    from robot_calib.sim.measure import record_plan
    from robot_calib.sim.world import build_world

    world = build_world(
        {
            "robot": "ur10",
            "geometry": "nominal",
            "temperature": {"start_c": 21.0},
            "effects": [
                {"name": "thermal_temperature", "values": {"thermal_temperature_alpha": 2e-5}}
            ],
            "base2tracker": {"xyz_m": [2.5, 0.5, -0.2], "rpy_deg": [0, 0, 180]},
            "target_in_flange_m": [0.05, 0.02, 0.08],
        }
    )
    robot = world.model.robot
    rng = np.random.default_rng(1)
    recording = record_plan(world, random_plan(robot, 600, rng), rng)
    held = np.zeros(len(recording), dtype=bool)
    held[rng.permutation(len(recording))[:180]] = True
    cal, hold = recording.subset(~held), recording.subset(held)
    assert calibrate(cal, robot, "geometric").outliers  # the precondition: flagged alone
    diagnosis, _ = diagnose(cal, robot, hold)
    assert diagnosis.outliers == []
    dom = diagnosis.dominant_effect
    assert dom is not None and dom.effect == "thermal_temperature"
