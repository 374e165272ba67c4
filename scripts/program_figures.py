"""How close compensated robot programs bring the true robot to what each program meant,
per language, against the calibration's held-out error (the figures of
msgs_doc/programs.md "Known answers").

For each language: the vendor arm in its shop-floor world (`sim.programs.shop_world`:
geometry a tenth of a millimetre / milliradian off, joint 2-3 backlash and compliance
under a 15 kg tool), calibrated (geometric + backlash + compliance) on 300 random poses and
scored on 200 others; `--programs` taught programs of `--targets` targets (half Cartesian,
half axis; a tool and a base frame) compensated and run, with the original, by the nominal
controller on the true robot (`sim.nominal_controller.drive`).

    .venv/bin/python scripts/program_figures.py [--targets 50] [--programs 3]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from robot_calib.compensation.program import compensate_program
from robot_calib.identify.calibrate import calibrate
from robot_calib.measurements import recording_from_arrays
from robot_calib.programs.registry import language_for, language_names
from robot_calib.programs.source import Frame
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.nominal_controller import drive
from robot_calib.sim.plans import plan_times, random_plan
from robot_calib.sim.programs import shop_world, taught_program
from robot_calib.sim.world import build_world

ARMS = {"krl": "kr16_2", "rapid": "irb2600_12_165", "fanuc_tp": "m20ia", "urscript": "ur10"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=50)
    parser.add_argument("--programs", type=int, default=3)
    args = parser.parse_args()
    print(
        f"{'language':<28}{'arm':<16}{'held-out rms':>13}{'original rms/max':>19}"
        f"{'compensated rms/max':>22}{'x held-out':>16}"
    )
    for name in language_names():
        language = language_for("x", name)
        world = build_world(shop_world(ARMS[name]))
        robot = world.model.robot
        rng = np.random.default_rng(2)
        recordings = []
        for n in (300, 200):
            plan = random_plan(robot, n, rng)
            poses, points = measure_every_target(
                world, plan.q, plan_times(plan, world.timing), rng
            )
            recordings.append(recording_from_arrays(poses.q, points, poses.time, robot=robot))
        cal = calibrate(recordings[0], robot, "geometric+backlash:2,3+compliance:2,3")
        held = cal.score(recordings[1]).accuracy.absolute_rms_mm
        before: list[np.ndarray] = []
        after: list[np.ndarray] = []
        for seed in range(args.programs):
            taught = taught_program(robot, language, args.targets, np.random.default_rng(seed))
            frames: tuple[dict[str, Frame], dict[str, Frame]] = ({}, {})
            if name == "fanuc_tp":  # the controller's UT/UF values, as options
                frames = (
                    {"UT 1": Frame("UT 1", taught.tool2flange, "option")},
                    {"UF 1": Frame("UF 1", taught.base2robot, "option")},
                )
            with tempfile.TemporaryDirectory() as folder:
                for file, text in taught.texts.items():
                    (Path(folder) / file).write_bytes(text.encode())
                main_file = next(f for f in taught.texts if Path(f).suffix in language.suffixes)
                program = language.read(Path(folder) / main_file)
                result = compensate_program(cal, program, language, *frames)
                for file, text in result.texts.items():
                    (Path(folder) / file).write_bytes(text.encode())
                compensated = language.read(Path(folder) / main_file)
            meant = taught.meant[:, :3, 3]
            for out, run in ((before, program), (after, compensated)):
                tool = drive(language, run, taught.q, world, taught.tool2flange, taught.base2robot)
                out.append(np.linalg.norm(tool[:, :3, 3] - meant, axis=1) * 1e3)
        miss_before, miss_after = np.concatenate(before), np.concatenate(after)
        rms_before = float(np.sqrt(np.mean(miss_before**2)))
        rms_after = float(np.sqrt(np.mean(miss_after**2)))
        print(
            f"{language.title:<28}{robot.name:<16}{held:>10.4f} mm"
            f"{rms_before:>10.4f}/{miss_before.max():.4f}"
            f"{rms_after:>13.4f}/{miss_after.max():.4f}"
            f"{rms_before / held:>8.1f} -> {rms_after / held:.2f}"
        )


if __name__ == "__main__":
    main()
