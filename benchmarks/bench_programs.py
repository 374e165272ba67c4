# ruff: noqa: E402 - the BLAS thread setting must precede the numpy import
"""Program compensation speed (target: >= 1,000 targets/s per language): a taught program
of 10,000 targets (half Cartesian with configuration data, half axis targets; a tool and a
base frame) per language, read, compensated and written, for the language's arm calibrated
in its shop-floor world (geometric + joint 2-3 backlash and compliance).

    .venv/bin/python benchmarks/bench_programs.py [--targets 10000] [--language krl ...]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from robot_calib.compensation.program import WRITTEN, compensate_program
from robot_calib.identify.calibrate import calibrate
from robot_calib.measurements import recording_from_arrays
from robot_calib.programs.registry import language_for, language_names
from robot_calib.programs.source import Frame
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import plan_times, random_plan
from robot_calib.sim.programs import shop_world, taught_program
from robot_calib.sim.world import build_world

TARGET_PER_S = 1000.0
ARMS = {"krl": "kr16_2", "rapid": "irb2600_12_165", "fanuc_tp": "m20ia", "urscript": "ur10"}


def main() -> int:
    """Prints a line per language; 1 when a language is below TARGET_PER_S."""
    below = 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=10000)
    parser.add_argument("--language", action="append", choices=language_names())
    args = parser.parse_args()
    for name in args.language or language_names():
        language = language_for("x", name)
        world = build_world(shop_world(ARMS[name]))
        robot = world.model.robot
        rng = np.random.default_rng(2)
        plan = random_plan(robot, 300, rng)
        poses, points = measure_every_target(world, plan.q, plan_times(plan, world.timing), rng)
        recording = recording_from_arrays(poses.q, points, poses.time, robot=robot)
        cal = calibrate(recording, robot, "geometric+backlash:2,3+compliance:2,3")
        taught = taught_program(robot, language, args.targets, np.random.default_rng(5))
        tools: dict[str, Frame] = {}
        bases: dict[str, Frame] = {}
        if name == "fanuc_tp":  # the controller holds UT/UF: given as options
            tools = {"UT 1": Frame("UT 1", taught.tool2flange, "option")}
            bases = {"UF 1": Frame("UF 1", taught.base2robot, "option")}
        with tempfile.TemporaryDirectory() as folder:
            for file, text in taught.texts.items():
                (Path(folder) / file).write_bytes(text.encode())
            main_file = next(f for f in taught.texts if Path(f).suffix in language.suffixes)
            start = time.perf_counter()
            program = language.read(Path(folder) / main_file)
            read_s = time.perf_counter() - start
            result = compensate_program(cal, program, language, tools, bases)
            for file, text in result.texts.items():
                (Path(folder) / f"out_{file}").write_bytes(text.encode())
            seconds = time.perf_counter() - start
        count = Counter(row.status for row in result.rows)
        written = sum(count[s] for s in WRITTEN)
        rate = len(result.rows) / seconds
        below += rate < TARGET_PER_S
        print(
            f"{language.title}: {len(result.rows)} targets read, compensated and written in "
            f"{seconds:.2f} s (read {read_s:.2f} s): {rate:,.0f} targets/s "
            f"({'meets' if rate >= TARGET_PER_S else 'BELOW'} the target of "
            f"{TARGET_PER_S:,.0f}/s); {written} written, statuses {dict(count)}"
        )

    return 1 if below else 0


if __name__ == "__main__":
    raise SystemExit(main())
