"""Simulated situations of real measurement campaigns, with known answers.

`fanuc_like`: a large FANUC arm modelled on a real one: the controller reports
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
    "a1": -3.0e-4,
    "a2": 4.5e-4,
    "a3": 2.6e-4,
    "d4": -3.5e-4,
    "theta2": -6.0e-4,
    "theta3": 8.0e-4,
    "theta4": 2.1e-3,
    "theta5": -1.2e-3,
    "alpha1": 4.0e-4,
    "alpha3": -5.2e-4,
    "alpha4": 5.1e-4,
    "alpha5": -3.0e-4,
    "beta2": 7.0e-4,
    "d5": 1.5e-4,
}


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


def sweep_plan(
    world: World,
    sweeps: tuple[tuple[float, float], ...],
    points: int = 6,
    home_deg: tuple[float, ...] = FANUC_HOME_DEG,
) -> Plan:
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
        poses.q,
        points,
        poses.time,
        source,
        world.model.robot,
        poses.target,
        world.model.targets,
    )


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


UR10_ROBOT = "ur10"
# A UR10's random-pose campaign as a real one looks [deg, DH joint variables]: joint 2
# (shoulder lift) spans 140 deg above the table, the others wide.
UR10_RANGES_DEG = ((-170, 170), (-160, -20), (-150, 150), (-180, 180), (-180, 180), (-180, 180))
# True deviations from the nominal table, of a calibrated UR10's size [m, rad].
UR10_DEVIATIONS = {
    "a2": 6.0e-4,
    "a3": -4.0e-4,
    "d1": 3.0e-4,
    "d4": -2.5e-4,
    "d5": 2.0e-4,
    "d6": -1.5e-4,
    "theta1": 4.0e-4,
    "theta2": -1.1e-3,
    "theta3": 9.0e-4,
    "theta4": 1.3e-3,
    "theta5": -7.0e-4,
    "alpha1": 6.0e-4,
    "alpha4": -4.0e-4,
    "alpha5": 5.0e-4,
    "beta2": 3.0e-4,
    "beta3": -2.0e-4,
}
# What the arm hides: joint-angle harmonics of gear stages [rad]
UR10_HARMONICS = (
    {
        "name": "joint_harmonics",
        "joints": [1],
        "orders": [17],
        "values": {"jh1_c17": 1.2e-4, "jh1_s17": -0.8e-4},
    },
    {
        "name": "joint_harmonics",
        "joints": [2],
        "orders": [11, 27],
        "values": {"jh2_c11": 2.0e-4, "jh2_s11": 1.5e-4, "jh2_c27": -0.6e-4, "jh2_s27": 0.9e-4},
    },
)


def ur10_world(seed: int = 0, effects: tuple[dict, ...] = UR10_HARMONICS) -> World:  # type: ignore[type-arg]
    """A UR10 modelled on a real one: nominal geometry plus UR10_DEVIATIONS, one SMR 0.1 m
    off the flange, the tracker 3 m from the base, `effects` (world-file entries)."""
    return build_world(
        {
            "robot": UR10_ROBOT,
            "seed": seed,
            "geometry": "nominal",
            "deviations": UR10_DEVIATIONS,
            "target_in_flange_m": [0.05, -0.03, 0.10],
            "base2tracker": {"xyz_m": [2.6, 1.4, -0.2], "rpy_deg": [0.0, 0.0, 205.0]},
            "effects": [dict(e) for e in effects],
        }
    )


def ur10_random_plan(n: int, rng: np.random.Generator) -> Plan:
    """`n` random poses uniform in UR10_RANGES_DEG."""
    lo, hi = np.radians(np.array(UR10_RANGES_DEG, dtype=float)).T
    return Plan("random", rng.uniform(lo, hi, (n, len(lo))), np.zeros(n, dtype=int), 0.1)


def ur10_random(
    seed: int = 0,
    n: int = 2773,
    holdout_share: float = 0.3,
    effects: tuple[dict, ...] = UR10_HARMONICS,
) -> Scenario:  # type: ignore[type-arg]
    """A UR10 random-pose campaign: `n` random poses (UR10_RANGES_DEG) measured in
    `ur10_world(seed, effects)`, split at random into calibration and hold-out
    (`holdout_share` of the poses), as a user splits a real data set."""
    world = ur10_world(seed, effects)
    rng = np.random.default_rng(seed + 2000)
    plan = ur10_random_plan(n, rng)
    every = _recording(world, plan.q, plan_times(plan, world.timing), seed, "random")
    held = np.zeros(n, dtype=bool)
    held[rng.choice(n, int(round(holdout_share * n)), replace=False)] = True
    return Scenario(world, every.subset(~held), every.subset(held))
