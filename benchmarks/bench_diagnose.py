# ruff: noqa: E402 - the BLAS thread setting must precede the numpy import
"""Benchmark (not a test): full diagnosis of a Test 2 recording + 200 hold-out poses.

    .venv/bin/python benchmarks/bench_diagnose.py [--repeat 3] [--effects backlash:4 ...]

Target: <= 10 s on 2 cores. Prints the median wall time per effect world, with
the stages (read bags, ladder) timed separately, and the verdict for a sanity check.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see robot_calib/__init__.py

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from robot_calib.bag.read import read_recording
from robot_calib.cli import main as cli
from robot_calib.diagnosis.diagnosis import diagnose
from robot_calib.effects.backlash import Backlash
from robot_calib.effects.eccentricity import Eccentricity
from robot_calib.effects.thermal_drift import ThermalDrift
from robot_calib.forked import FORKED
from robot_calib.kinematics.loader import load_robot
from robot_calib.parallel import using

TARGET_S = 10.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument(
        "--effects",
        nargs="*",
        default=[
            "none",
            Backlash(joints=(4,)).spec,
            Eccentricity(joints=(5,)).spec,
            ThermalDrift().spec,
        ],
        help="worlds: 'none' or an effect of `simulate --effects`",
    )
    args = parser.parse_args()
    robot = load_robot("kr5_sixx_r650")
    print(f"{'world':<16}{'read [s]':>10}{'diagnose [s]':>14}{'total [s]':>11}  verdict")
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for spec in args.effects:
            folder = Path(tmp) / spec.replace(":", "_")
            folder.mkdir()
            bag, hold = folder / "cal.mcap", folder / "hold.mcap"
            effects = [] if spec == "none" else ["--effects", spec]
            cli(["simulate", "--plan", "paper-test2", *effects, "--seed", "1", "-o", str(bag)])
            cli(
                [
                    "simulate",
                    "--plan",
                    "random",
                    "--world",
                    str(bag.with_suffix(".world.yaml")),
                    "--seed",
                    "2",
                    "-o",
                    str(hold),
                ]
            )
            reads, runs = [], []
            for _ in range(args.repeat):
                started = time.perf_counter()
                rec = read_recording([bag], robot)
                held = read_recording([hold], robot)
                reads.append(time.perf_counter() - started)
                started = time.perf_counter()
                with using(FORKED):  # the other core, as the command line's diagnosis
                    diagnosis, _ = diagnose(rec, robot, held)
                runs.append(time.perf_counter() - started)
            total = statistics.median(reads) + statistics.median(runs)
            worst = max(worst, total)
            print(
                f"{spec:<16}{statistics.median(reads):>10.2f}{statistics.median(runs):>14.2f}"
                f"{total:>11.2f}  {diagnosis.verdict}",
                flush=True,
            )
    print(
        f"worst total {worst:.2f} s vs target {TARGET_S:.0f} s: "
        f"{'PASS' if worst <= TARGET_S else 'MISS'}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
