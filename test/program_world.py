"""The program tests' worlds: one vendor arm per language, its true geometry off the
nominal by tenths of a millimetre and milliradian, with joint 2-3 backlash and gravity
compliance under a 15 kg tool; calibrated once per process (geometric + backlash +
compliance) on 300 random poses, scored on 200 others (the held-out error), and a taught
program of 50 targets per language. `drive` is the true robot run by the nominal
controller: where the tool really goes for a program's targets."""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robot_calib.compensation.solve import BRANCH_SHARES, nominal_counterpart
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import Calibration
from robot_calib.ik import solve_ik
from robot_calib.kinematics.frames import Array
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.poses import Poses, approach_directions
from robot_calib.programs.language import Language
from robot_calib.programs.registry import language_for
from robot_calib.programs.source import Frame, Program
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import plan_times, random_plan
from robot_calib.sim.programs import TaughtProgram, shop_world, taught_program
from robot_calib.sim.world import World, build_world

#: the arm each language's test uses
ROBOTS = {"krl": "kr16_2", "rapid": "irb2600_12_165", "fanuc_tp": "m20ia", "urscript": "ur10"}
MODEL = "geometric+backlash:2,3+compliance:2,3"


@dataclass(frozen=True)
class ProgramWorld:
    world: World
    calibration: Calibration
    recording: Recording  # what it was calibrated on
    held_out_rms_m: float  # the calibration's rms error on the 200 held-out poses


@functools.cache
def program_world(language: str, robot: str | None = None) -> ProgramWorld:
    """The world of a language's arm (or of `robot`), calibrated and scored."""
    world = build_world(shop_world(robot or ROBOTS[language]))
    robot = world.model.robot
    rng = np.random.default_rng(2)
    recordings = []
    for n in (300, 200):
        plan = random_plan(robot, n, rng)
        poses, points = measure_every_target(world, plan.q, plan_times(plan, world.timing), rng)
        recordings.append(recording_from_arrays(poses.q, points, poses.time, robot=robot))
    calibration = calibrate(recordings[0], robot, MODEL)
    held_out = calibration.score(recordings[1]).accuracy.absolute_rms_mm * 1e-3
    return ProgramWorld(world, calibration, recordings[0], held_out)


def taught(language: str, folder: Path, n: int = 50, seed: int = 5) -> tuple[TaughtProgram, Path]:
    """A taught program of `n` targets for the language's arm, written into `folder`;
    returns it and the path of its main file."""
    lang = language_for("x", language)
    robot = program_world(language).world.model.robot
    program = taught_program(robot, lang, n, np.random.default_rng(seed))
    for name, text in program.texts.items():
        (folder / name).write_bytes(text.encode())
    main = next(name for name in program.texts if Path(name).suffix in lang.suffixes)
    return program, folder / main


def frame_options(
    language: str, program: TaughtProgram
) -> tuple[dict[str, Frame], dict[str, Frame]]:
    """The frames a FANUC program cannot hold (UT 1, UF 1: the controller's), as options."""
    if language != "fanuc_tp":
        return {}, {}
    return (
        {"UT 1": Frame("UT 1", program.tool2flange, "test")},
        {"UF 1": Frame("UF 1", program.base2robot, "test")},
    )


def controller_solutions(
    language: Language, program: Program, world: ProgramWorld, goal: Array, start: Array
) -> Array:
    """(n, J) readings the nominal controller moves to for pose targets with flange goals
    (n, 4, 4): every solution the nominal inverse kinematics finds from the start readings
    and from seeds spread over the arm's branches (both facings of axis 1, elbow and wrist
    both ways, axes 1, 4, 6 +-1 turn), kept where it is within the limits and, for a
    language with configuration data, has the target's configuration; of those, the one
    nearest the start (a controller's choice without configuration data)."""
    cal = world.calibration
    nominal, params = nominal_counterpart(cal.model, cal.parameters)
    robot = nominal.robot
    limits = robot.limits
    seeds = [start]
    for turn in (0.0, np.pi):
        for shares in BRANCH_SHARES:
            seed = start.copy()
            seed[:, 0] = np.angle(np.exp(1j * (seed[:, 0] + turn)))
            seed[:, 3:] = 0.0
            for joint, share in zip((1, 2, 4), shares):
                seed[:, joint] = limits[joint, 0] + share * np.diff(limits[joint])[0]
            seeds.append(seed)
    found = []
    for seed in seeds:
        ik = solve_ik(
            nominal,
            params,
            Poses.from_readings(seed),
            goal,
            np.eye(4),
            tolerance_m=1e-12,
            max_iterations=100,
        )
        for shift in itertools.product((-1, 0, 1), repeat=3):
            q = ik.q.copy()
            q[:, [0, 3, 5]] += 2 * np.pi * np.array(shift)
            ok = ik.converged & np.all((q >= limits[:, 0]) & (q <= limits[:, 1]), axis=1)
            found.append(np.where(ok[:, None], q, np.nan))
    candidates = np.stack(found, axis=1)  # (n, m, J)
    targets = [t for t in program.targets if t.kind == "pose"]
    out = np.full_like(start, np.nan)
    for k, target in enumerate(targets):
        rows = candidates[k][np.isfinite(candidates[k]).all(axis=1)]
        if language.configuration is not None and target.configuration is not None:
            configs = language.configuration(robot, rows)
            rows = rows[
                [
                    all(w < 0 or c == w for c, w in zip(config, target.configuration))
                    for config in configs
                ]
            ]
        assert len(rows), f"{target.name}: the controller finds no solution on its configuration"
        out[k] = rows[np.argmin(np.abs(rows - start[k]).max(axis=1))]
    return out


def drive(
    language: Language,
    program: Program,
    taught_q: Array,
    world: ProgramWorld,
    tool2flange: Array,
    base2robot: Array,
) -> Array:
    """(n, 4, 4) where the true robot puts the tool at each target of `program` (program
    order) driven by the nominal controller: axis targets as written; pose targets at the
    controller's solution (`controller_solutions`: on the target's configuration, the one
    nearest the taught readings), with the approach directions of the sequence."""
    q = np.array(taught_q, dtype=float)
    kinds = np.array([t.kind for t in program.targets])
    poses = np.flatnonzero(kinds == "pose")
    joints = np.flatnonzero(kinds == "joints")
    if poses.size:
        values = np.array([program.targets[k].values for k in poses])
        goal = base2robot @ language.pose_to_base(values) @ np.linalg.inv(tool2flange)
        q[poses] = controller_solutions(language, program, world, goal, q[poses])
    if joints.size:
        q[joints] = np.array([program.targets[k].values for k in joints]) * language.joint_unit
    truth = world.world
    at = Poses(q, approach_directions(q), np.zeros(len(q)))
    return truth.model.flange2base(truth.truth, at) @ tool2flange
