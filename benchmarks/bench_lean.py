# ruff: noqa: E402 - the BLAS thread setting must precede the numpy import
"""Benchmark (not a test): the lean table in one run, each figure a whole `robot-calib`
process (wall time, CPU time, peak RSS of the child itself) beside its goal and, for the
geometric fit, the plain-numpy limit for the same number of poses.

    .venv/bin/python benchmarks/bench_lean.py [--sizes 1000 10000 50000 100000]
        [--diagnose 2773 100000] [--repeat 1] [--skip-simulate]

Rows:
- `calibrate` of a UR10 random-pose bag of n poses (gear harmonics on joints 1-2, as
  `sim.scenarios.ur10_random`): the whole CLI (bag reading, CPA-free geometric fit,
  reports). Goal: peak RSS below the leanest peer (robotkinecal: 171 / 351 / 508 MiB at
  10k / 50k / 100k), <= 250 MiB at 100k.
- the geometric `fit_model` alone (in-process, from the nominal geometry with the tracker
  pose found by registration, as `calibrate` starts) against the numpy limit: one forward
  kinematics + analytic Jacobian of the same n poses in plain numpy (`numpy_limit`), per
  model evaluation; goal: <= 2 x the limit per evaluation (issue: 100k fit <= 2.5 s).
- `diagnose` of n random poses (5-fold CV): goal <= 5 s at 2773, <= 30 s and 600 MB at 100k.
- reading a bag of 200k messages (`read_recording`): goal <= 3 s.
- `simulate` (benchmarks/bench_simulate.py, its own table): goal 100k poses <= 30 s.

The load average is printed: figures on a loaded machine are not the goals'.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see robot_calib/__init__.py

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from measure import robot_calib

from robot_calib.bag.write import START_NS, STEP_NS, write_measurements
from robot_calib.sim.scenarios import ur10_random

PEER_RSS_MIB = {10_000: 171, 50_000: 351, 100_000: 508}  # robotkinecal's peak RSS
DIAGNOSE_GOAL = {2773: (5.0, None), 100_000: (30.0, 600.0)}  # s, MiB


def _bag(folder: Path, n: int) -> Path:
    path = folder / f"ur10_{n}.mcap"
    if not path.exists():
        scenario = ur10_random(seed=0, n=n, holdout_share=0.0)
        rec = scenario.calibration
        stamps = START_NS + np.arange(len(rec)) * STEP_NS
        write_measurements(
            path, rec.poses.q, rec.points, scenario.world.model.robot.joint_names, stamps
        )
    return path


def _cli(args: list[str]) -> tuple[float, float, float]:
    """Wall [s], CPU [s] and memory [MiB] of `robot-calib ARGS` as a user runs it
    (`measure.robot_calib`): the larger of the largest process's peak RSS and the process
    tree's peak summed PSS (a run with helper processes takes their memory too); its
    failure ends the benchmark."""
    run = robot_calib(args)
    if run.status not in (0, 3):
        raise SystemExit(
            f"robot-calib {' '.join(args)} failed ({run.status}): {run.stderr.strip()[-400:]}"
        )
    return run.wall_s, run.cpu_s, max(run.peak_mib, run.tree_mib)


def numpy_limit(
    q: np.ndarray, d: np.ndarray, a: np.ndarray, alpha: np.ndarray, theta: np.ndarray
) -> np.ndarray:
    """Plain numpy: the flange point of n poses (standard DH, q (n, 6)) and its analytic
    Jacobian with respect to theta, d, a, alpha of every link (n, 3, 24): the least any
    implementation of the same model must compute per evaluation."""
    n, joints = q.shape
    t = q + theta
    ct, st, ca, sa = np.cos(t), np.sin(t), np.cos(alpha), np.sin(alpha)
    frames = np.empty((joints + 1, n, 4, 4))
    frames[0] = np.eye(4)
    for j in range(joints):
        link = np.zeros((n, 4, 4))
        link[:, 0, 0], link[:, 0, 1], link[:, 0, 2] = ct[:, j], -st[:, j] * ca[j], st[:, j] * sa[j]
        link[:, 1, 0], link[:, 1, 1], link[:, 1, 2] = st[:, j], ct[:, j] * ca[j], -ct[:, j] * sa[j]
        link[:, 2, 1], link[:, 2, 2], link[:, 3, 3] = sa[j], ca[j], 1.0
        link[:, 0, 3], link[:, 1, 3], link[:, 2, 3] = a[j] * ct[:, j], a[j] * st[:, j], d[j]
        frames[j + 1] = frames[j] @ link
    point = frames[-1][:, :3, 3]
    jac = np.empty((n, 3, 4 * joints))
    for j in range(joints):
        z, x = frames[j][:, :3, 2], frames[j + 1][:, :3, 0]
        jac[:, :, 4 * j] = np.cross(z, point - frames[j][:, :3, 3])
        jac[:, :, 4 * j + 1] = z
        jac[:, :, 4 * j + 2] = x
        jac[:, :, 4 * j + 3] = np.cross(x, point - frames[j + 1][:, :3, 3])
    return jac


def _fit_vs_limit(n: int) -> tuple[float, int, float]:
    """fit_model wall [s] and model evaluations for n poses, and the numpy limit [s] per
    evaluation (median of 3)."""
    from robot_calib.identify.fit import fit_model
    from robot_calib.identify.registration import initial_frames
    from robot_calib.model import KinematicModel

    scenario = ur10_random(seed=0, n=n, holdout_share=0.0)
    robot = scenario.world.model.robot
    model = KinematicModel(robot)
    rec = scenario.calibration
    # as `calibrate` starts: the nominal geometry, the tracker pose and target offset found
    # globally for it (identify.registration), not timed
    start = initial_frames(model, model.parameters(), rec.poses, rec.points)
    started = time.perf_counter()
    fit = fit_model(model, start, rec.poses, rec.points)
    wall = time.perf_counter() - started
    q = rec.poses.q
    times = []
    for _ in range(3):
        started = time.perf_counter()
        numpy_limit(q, robot.d, robot.a, robot.alpha, robot.theta)
        times.append(time.perf_counter() - started)
    return wall, int(fit.solver.evaluations or 0), float(np.median(times))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[1000, 10_000, 50_000, 100_000])
    parser.add_argument("--diagnose", type=int, nargs="*", default=[2773, 100_000])
    parser.add_argument("--skip-simulate", action="store_true")
    parser.add_argument(
        "--only",
        choices=("calibrate", "fit", "diagnose"),
        default=None,
        help="only these rows (no bag-read and simulate tables)",
    )
    parser.add_argument("--folder", type=Path, default=None, help="keep the bags here")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.folder or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        print("memory: a process's peak RSS, or the summed PSS of it and its helpers if more")
        print(f"{'work':<34}{'wall [s]':>9}{'cpu [s]':>9}{'memory [MiB]':>13}  goal")
        for n in args.sizes if args.only in (None, "calibrate") else []:
            bag = _bag(folder, n)
            wall, cpu, peak = _cli(
                [
                    "calibrate",
                    str(bag),
                    "--robot",
                    "ur10",
                    "-o",
                    str(folder / f"c{n}.json"),
                    "--force",
                ]
            )
            peer = PEER_RSS_MIB.get(n)
            goal = (
                f"RSS < {peer} MiB (peer){' and <= 250' if n == 100_000 else ''}: "
                f"{'met' if peak < min(peer, 250 if n == 100_000 else peer) else 'MISSED'}"
                if peer
                else ""
            )
            print(f"{f'calibrate {n} poses':<34}{wall:>9.2f}{cpu:>9.2f}{peak:>13.0f}  {goal}")
        for n in args.sizes if args.only in (None, "fit") else []:
            wall, evals, limit = _fit_vs_limit(n)
            per = wall / max(evals, 1)
            print(
                f"{f'fit_model {n} poses':<34}{wall:>9.2f}{'':>9}{'':>13}  {evals} evaluations, "
                f"{per:.3f} s each = {per / limit:.1f} x the numpy limit {limit:.3f} s "
                f"(goal <= 2 x)"
            )
        for n in args.diagnose if args.only in (None, "diagnose") else []:
            bag = _bag(folder, n)
            wall, cpu, peak = _cli(
                [
                    "diagnose",
                    str(bag),
                    "--robot",
                    "ur10",
                    "-o",
                    str(folder / f"d{n}.json"),
                    "--force",
                ]
            )
            limit_s, limit_mib = DIAGNOSE_GOAL.get(n, (None, None))
            goal = (
                ""
                if limit_s is None
                else (
                    f"<= {limit_s:.0f} s{f', {limit_mib:.0f} MiB' if limit_mib else ''}: "
                    + (
                        "met"
                        if wall <= limit_s and (limit_mib is None or peak <= limit_mib)
                        else "MISSED"
                    )
                )
            )
            print(
                f"{f'diagnose {n} poses (5-fold)':<34}{wall:>9.2f}{cpu:>9.2f}{peak:>13.0f}  {goal}"
            )
    if args.only is not None:
        return 0
    here = Path(__file__).parent
    print("reading 200k messages: benchmarks/bench_bag_read.py (goal <= 3 s)")
    subprocess.run([sys.executable, str(here / "bench_bag_read.py"), "--repeat", "1"], check=False)
    if not args.skip_simulate and (here / "bench_simulate.py").exists():
        print("simulate: benchmarks/bench_simulate.py (goal 100k poses <= 30 s)")
        subprocess.run([sys.executable, str(here / "bench_simulate.py")], check=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
