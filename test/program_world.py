"""The program tests' worlds: one vendor arm per language, its true geometry off the
nominal by tenths of a millimetre and milliradian, with joint 2-3 backlash and gravity
compliance under a 15 kg tool; calibrated once per process (geometric + backlash +
compliance) on 300 random poses, scored on 200 others (the held-out error), and a taught
program of 50 targets per language (`sim.nominal_controller.drive` runs them on the true robot)."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import Calibration
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.programs.registry import language_for
from robot_calib.programs.source import Frame
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.nominal_controller import drive
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


__all__ = ["drive", "frame_options", "program_world", "taught"]
