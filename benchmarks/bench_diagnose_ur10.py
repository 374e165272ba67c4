# ruff: noqa: E402 - the BLAS thread setting must precede the numpy import
"""Benchmark (not a test): `robot-calib diagnose` of a UR10 random-pose campaign like issue
22's real arm: 2773 random poses (joint 2 over 140 deg), gear harmonics on joints 1-2 in the
simulated world (`sim.scenarios.ur10_random`), written as bags, diagnosed by the CLI as a
user runs it, in a child process so that its wall time and peak RSS are its own.

    .venv/bin/python benchmarks/bench_diagnose_ur10.py [--poses 2773] [--repeat 3]

Two runs per repeat: all poses in one bag (5-fold CV), and the 70/30 split as calibration
+ hold-out bags. Targets: <= 10 s on an idle 2-core machine, and <= 5 s for
the 5-fold run. Prints the median
wall time, CPU time and peak RSS of each, the verdict and the held-out figures, and the
load average (timings on a loaded machine are not the target's).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see robot_calib/__init__.py

import argparse
import json
import statistics
import tempfile
from pathlib import Path

import numpy as np
from measure import robot_calib

from robot_calib.bag.write import START_NS, STEP_NS, write_measurements
from robot_calib.measurements import Recording
from robot_calib.sim.scenarios import ur10_random

TARGET_S = 10.0  # both runs
FIVE_FOLD_TARGET_S = 5.0  # the 5-fold run (bench_lean.py's row)


def _bag(path: Path, recording: Recording, names: tuple[str, ...], first: int = 0) -> Path:
    """A contract bag of `recording`, stamped 1 s apart from pose number `first` on (the
    hold-out bag's stamps follow the calibration bag's: two bags of one campaign)."""
    stamps = START_NS + (first + np.arange(len(recording))) * STEP_NS
    write_measurements(path, recording.poses.q, recording.points, names, stamps)
    return path


def _run(args: list[str]) -> tuple[float, float, float]:
    """Wall [s], CPU [s], peak RSS [MiB] of `robot-calib ARGS` as a user runs it
    (`measure.robot_calib`); its failure ends the benchmark."""
    run = robot_calib(args)
    if run.status not in (0, 3):
        raise SystemExit(
            f"robot-calib {' '.join(args)} failed ({run.status}): {run.stderr.strip()[-400:]}"
        )
    return run.wall_s, run.cpu_s, run.peak_mib


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--poses", type=int, default=2773)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    scenario = ur10_random(seed=0, n=args.poses, holdout_share=0.3)
    names = scenario.world.model.robot.joint_names
    print(
        f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; "
        f"{args.poses} poses, UR10 scenario (gear harmonics on joints 1-2)"
    )
    print(f"{'run':<34}{'wall [s]':>10}{'cpu [s]':>9}{'peak RSS [MiB]':>16}  verdict, held-out")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        every = Recording.concatenate([scenario.calibration, scenario.holdout])
        n_cal = len(scenario.calibration)
        runs = {
            "all poses, 5-fold CV": [str(_bag(folder / "all.mcap", every, names))],
            "70/30: calibration + hold-out": [
                str(_bag(folder / "cal.mcap", scenario.calibration, names)),
                "--holdout",
                str(_bag(folder / "hold.mcap", scenario.holdout, names, n_cal)),
            ],
        }
        worst, medians = 0.0, {}
        for label, bags in runs.items():
            out = folder / f"{label.split(',')[0].replace(' ', '_').replace('/', '_')}.json"
            times, cpus, rss = [], [], 0.0
            for _ in range(args.repeat):
                wall, cpu, peak = _run(
                    ["diagnose", *bags, "--robot", "ur10", "-o", str(out), "--force"]
                )
                times.append(wall)
                cpus.append(cpu)
                rss = max(rss, peak)
            doc = json.loads(out.read_text())
            dom = doc.get("dominant_effect") or {}
            best = doc["ladder"][-1]
            verdict = f"{dom.get('effect')} {dom.get('joints')}, {best['holdout_abs_mean_mm']:.4f}"
            wall = statistics.median(times)
            worst, medians[label] = max(worst, wall), wall
            print(
                f"{label:<34}{wall:>10.2f}{statistics.median(cpus):>9.2f}{rss:>16.0f}  "
                f"{verdict} mm ({best['model']})"
            )
    print(
        f"target <= {TARGET_S:.0f} s: {'PASS' if worst <= TARGET_S else 'MISS'} "
        f"(worst median {worst:.2f} s)"
    )
    five = medians["all poses, 5-fold CV"]
    print(
        f"target <= {FIVE_FOLD_TARGET_S:.0f} s for the 5-fold run: "
        f"{'PASS' if five <= FIVE_FOLD_TARGET_S else 'MISS'} (median {five:.2f} s)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
