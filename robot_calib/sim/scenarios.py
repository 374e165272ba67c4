"""Simulated situations of real measurement campaigns, with known answers.

`fanuc_like`: a large FANUC arm as issue 13 describes a real one: the controller reports
J3 coupled to J2 (the built-in `r2000ic_165f`'s reading_to_joint), three SMRs per pose on
a plate 0.34 m from the flange (one of them on the joint-6 axis), six single-joint sweeps
of 6 poses each with 144 deg steps over +-360 deg on joints 4 and 6, plus random general
poses as the hold-out. Everything is in raw controller readings: no preprocessing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.kinematics.frames import Array
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import Plan, plan_times, random_plan
from robot_calib.sim.world import World, build_world

FANUC_ROBOT = "r2000ic_165f"
# SMRs on a plate 0.34 m out from the flange [m, flange frame]: smr_axis on the J6 axis.
FANUC_TARGETS = {"smr_b": [-0.08, 0.09, 0.33], "smr_axis": [0.0, 0.0, 0.34]}
FANUC_FIRST_TARGET = [0.11, 0.0, 0.335]
# Sweeps in DH joint variables [deg]: (start, end) of 6 poses each, the others at HOME.
FANUC_SWEEPS = ((-60, 60), (-35, 35), (-35, 35), (-360, 360), (-90, 60), (-360, 360))
FANUC_HOME_DEG = (0.0, 0.0, 0.0, 0.0, -45.0, 0.0)
# True deviations from the nominal table, of the size of the seed's Table 3 [m, rad].
FANUC_DEVIATIONS = {
    "a1": -3.0e-4, "a2": 4.5e-4, "a3": 2.6e-4, "d4": -3.5e-4, "theta2": -6.0e-4,
    "theta3": 8.0e-4, "theta4": 2.1e-3, "theta5": -1.2e-3, "alpha1": 4.0e-4,
    "alpha3": -5.2e-4, "alpha4": 5.1e-4, "alpha5": -3.0e-4, "beta2": 7.0e-4, "d5": 1.5e-4,
}  # fmt: skip


@dataclass(frozen=True)
class Scenario:
    """A simulated campaign: the world (truth), the calibration recording (sweeps) and a
    hold-out recording (random general poses), both of every target, in raw readings."""

    world: World
    calibration: Recording
    holdout: Recording


def fanuc_world(seed: int = 0, robot: str = FANUC_ROBOT) -> World:
    """The FANUC-like world: nominal geometry plus FANUC_DEVIATIONS, three SMRs, the
    tracker about 3.3 m from the base."""
    return build_world(
        {
            "robot": robot,
            "seed": seed,
            "geometry": "nominal",
            "deviations": FANUC_DEVIATIONS,
            "target_in_flange_m": FANUC_FIRST_TARGET,
            "targets": FANUC_TARGETS,
            "base2tracker": {"xyz_m": [3.0, 1.2, -0.4], "rpy_deg": [0.0, 0.0, 195.0]},
        }
    )


def sweep_plan(world: World, sweeps: tuple[tuple[float, float], ...], points: int = 6,
               home_deg: tuple[float, ...] = FANUC_HOME_DEG) -> Plan:  # fmt: skip
    """Single-joint sweeps of the DH joint variables (start, end) [deg] in `points` equal
    steps, the other joints at `home_deg`, turned into the robot's readings."""
    robot = world.model.robot
    rows, which = [], []
    for j, (start, end) in enumerate(sweeps):
        for angle in np.linspace(start, end, points):
            variables = np.radians(home_deg)
            variables[j] = np.radians(angle)
            rows.append(variables)
            which.append(j + 1)
    q = robot.readings(np.array(rows))
    return Plan("sweeps", q, np.array(which), 0.05)


def _recording(world: World, q: Array, time: Array, seed: int, source: str) -> Recording:
    poses, points = measure_every_target(world, q, time, np.random.default_rng(seed))
    return recording_from_arrays(
        poses.q, points, poses.time, source, world.model.robot, poses.target,
        world.model.targets,
    )  # fmt: skip


def fanuc_like(seed: int = 0, n_holdout: int = 100, robot: str = FANUC_ROBOT) -> Scenario:
    """The FANUC-like campaign of this module's docstring (seeded)."""
    world = fanuc_world(seed, robot)
    plan = sweep_plan(world, FANUC_SWEEPS)
    calibration = _recording(world, plan.q, plan_times(plan, world.timing), seed, "sweeps")
    rng = np.random.default_rng(seed + 1000)
    held = random_plan(world.model.robot, n_holdout, rng, margin=0.15)
    holdout = _recording(world, held.q, plan_times(held, world.timing), seed + 1, "holdout")
    return Scenario(world, calibration, holdout)


def noise_rms_mm(world: World, recording: Recording) -> float:
    """rms of measured - exact true points of `recording` in `world` [mm]: the floor no
    model can beat."""
    exact = world.model.target_points(world.truth, recording.poses)
    return float(np.sqrt(np.mean(np.sum((recording.points - exact) ** 2, axis=1))) * 1e3)


def wrist_288_subset(recording: Recording) -> Recording:
    """A `fanuc_like` calibration recording with only poses 1, 3, 5, 6 of its J4 and J6
    sweeps (-360, -72, 216, 360 deg: steps of 288 deg, two of them the same place)."""
    pose = recording.pose_index()
    keep = np.ones(len(recording), dtype=bool)
    for joint in (4, 6):
        for k in (1, 3):
            keep[pose == 6 * (joint - 1) + k] = False
    return recording.subset(keep)
