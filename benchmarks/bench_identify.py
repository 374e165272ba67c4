"""Identification benchmark: how long the fits take, and how they scale with the data.

    .venv/bin/python benchmarks/bench_identify.py [--max-poses N] [--repeat R]

Prints figures (no assertions):

1. `calibrate(..., "geometric")` on the seed's Test 2 recording (580 points): median wall
   time of R runs (CPA + Levenberg-Marquardt + accuracy figures) and LM evaluations.
   Target <= 0.1 s.
2. `calibrate(..., "geometric+eccentricity", start=<geometric>)` (order 1, all 6 joints,
   started from the geometric result as `calibrate` does) on the same data, and on Test 2 +
   100 random general poses. Target <= 0.5 s.
3. `fit_model` time vs number of random general poses (1k .. --max-poses) for the geometric
   model (target: linear, log-log slope ~1), time per pose, peak memory; the same for
   geometric+eccentricity up to --ecc-max-poses (its Jacobians cost ~40 kB per pose).
4. `read_recording` of a Test 2 bag written by `robot-calib simulate`, CPA alone, and the
   O(N^2) pairwise accuracy figure that `calibrate` computes after every fit.

All data come from one world: the default world (seed Table 3 geometry) with the seed's
eccentricity (Tables 5-6) on all six joints, measurement noise on. Fits at large n start
from the true geometry perturbed by 1e-4 (m or rad) with the eccentricity at zero, and call
`fit_model` directly so that only the fit is timed. Timings depend on machine load (the load
average is printed) and on BLAS threads: importing robot_calib sets one unless
OPENBLAS_NUM_THREADS is set; `--blas-threads N` runs with N (the threads in use are printed).
"""

from __future__ import annotations

import argparse
import ctypes
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# isort: split
# First, before NumPy loads: importing robot_calib sets the BLAS thread count (one thread
# unless OPENBLAS_NUM_THREADS is already set), as the console scripts get it.
import robot_calib  # noqa: F401

# isort: split
import numpy as np
import scipy

from robot_calib.accuracy import accuracy
from robot_calib.bag.read import read_recording
from robot_calib.effects import seed_runout
from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.cpa import circle_point_analysis
from robot_calib.identify.fit import fit_model
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.model import KinematicModel, absorb_base_offsets
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import paper_test_plan, random_plan
from robot_calib.sim.world import World, load_world, with_effect

SIZES = (1_000, 3_000, 10_000, 30_000, 100_000)
PAIRWISE_SIZES = (1_000, 3_000, 10_000)
BLAS_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
TARGET_GEOMETRIC_S = 0.1
TARGET_ECCENTRICITY_S = 0.5
TARGET_SLOPE = 1.1  # log(time) vs log(n): "linear" within 10 %
PERTURBATION = 1e-4  # start of the large-n fits: truth + N(0, 1e-4) [m or rad]
MIB = 2.0**20
MEASURE_CHUNK = 5_000  # poses simulated at once
# ROS 2 domains: the same lock files as test/conftest.py, so the simulate run never shares
# a DDS domain with a test or another benchmark running on this machine.


@dataclass
class Timing:
    """Wall times [s] of repeated runs and whatever the last run returned."""

    times: list[float]
    result: Any

    @property
    def median(self) -> float:
        return statistics.median(self.times)

    def short(self) -> str:
        return f"{self.median:.4f} s (min {min(self.times):.4f})"

    def line(self) -> str:
        t = self.times
        return f"median {self.median:.4f} s (min {min(t):.4f}, max {max(t):.4f}, {len(t)} runs)"


def repeat(fn: Callable[[], Any], runs: int, budget_s: float = float("inf")) -> Timing:
    """Run `fn` up to `runs` times (at least once, fewer once `budget_s` is spent)."""
    times: list[float] = []
    result = None
    spent = 0.0
    while len(times) < max(runs, 1) and (not times or spent < budget_s):
        started = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - started)
        spent += times[-1]
    return Timing(times, result)


def traced_peak_mib(fn: Callable[[], object]) -> float:
    """Peak memory [MiB] allocated through Python/NumPy while `fn` runs (tracemalloc)."""
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1] / MIB
    finally:
        tracemalloc.stop()


def maxrss_mib() -> float:
    """High-water resident set size of this process so far [MiB] (Linux: ru_maxrss in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def load_line() -> str:
    one, five, _ = os.getloadavg()
    busy = "  <- CPU contention: timings inflated" if one > (os.cpu_count() or 1) else ""
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} CPUs{busy}"


def blas_threads() -> str:
    """Threads of each OpenBLAS loaded in this process (NumPy's, SciPy's), read back from
    the libraries; '?' where the library has none of the known symbols."""
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return "unknown (no /proc/self/maps)"
    paths = sorted(
        {ln.split()[-1] for ln in maps.splitlines() if "openblas" in ln and "/" in ln.split()[-1]}
    )
    names = (
        "scipy_openblas_get_num_threads64_",
        "scipy_openblas_get_num_threads",
        "openblas_get_num_threads64_",
        "openblas_get_num_threads",
    )
    out = []
    for path in paths:
        lib = ctypes.CDLL(path)
        getter = next((getattr(lib, n) for n in names if hasattr(lib, n)), None)
        out.append(f"{Path(path).name.split('-')[0]} {getter() if getter else '?'}")
    return ", ".join(out) or "no OpenBLAS loaded"


def loglog_slope(n: list[int], t: list[float]) -> float:
    """Least-squares slope of log(t) vs log(n) (1 = linear); nan with fewer than 2 sizes."""
    if len(n) < 2:
        return float("nan")
    return float(np.polyfit(np.log(n), np.log(t), 1)[0])


def section(title: str) -> None:
    print(f"\n== {title} ==", flush=True)


# --- data ------------------------------------------------------------------------------


def measured(
    world: World, q: np.ndarray, seed: int, chunk: int = MEASURE_CHUNK
) -> tuple[Poses, np.ndarray]:
    """Poses of readings q (n, J) and their simulated measured points (n, 3) [m], made in
    chunks of `chunk` poses: the simulator's eccentricity costs ~22 kB per pose at once,
    which would set the process's peak RSS far above that of the fits measured here."""
    poses = Poses.from_readings(q)
    rng = np.random.default_rng(seed)
    chunks = [
        physical_points(world, poses.subset(slice(k, k + chunk)), rng)
        for k in range(0, len(poses), chunk)
    ]
    return poses, np.concatenate(chunks)


def perturbed_start(world: World, model: KinematicModel, seed: int) -> ParameterVector:
    """The world's true geometry (theta1/d1 moved into the tracker pose, as identified
    vectors keep them nominal), every free geometric parameter perturbed by
    N(0, PERTURBATION); effect parameters of `model` at 0 (as after a geometric fit)."""
    robot = world.model.robot
    truth = absorb_base_offsets(robot, world.truth)
    geometric = KinematicModel(robot).parameters()
    rng = np.random.default_rng(seed)
    values = {
        name: truth[name] + (rng.normal(0.0, PERTURBATION) if free else 0.0)
        for name, free in zip(geometric.names, geometric.free)
    }
    return model.parameters().with_values(values)


# --- sections --------------------------------------------------------------------------


def bench_bag(robot: RobotDescription, runs: int, tmp: Path) -> dict[str, Timing]:
    section("read_recording of a Test 2 bag (robot-calib simulate --plan paper-test2)")
    bag = tmp / "test2.mcap"
    cli = Path(sys.executable).with_name("robot-calib")
    command = [str(cli)] if cli.exists() else [sys.executable, "-m", "robot_calib"]
    command += ["simulate", "--plan", "paper-test2", "-o", str(bag)]
    from robot_calib.nodes.private_domain import claim  # the suite's and simulate's claim

    domain, lock = claim()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_LOG_DIR=str(tmp / "roslog"))
    started = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True, cwd=tmp)
    simulate_s = time.perf_counter() - started
    lock.close()
    if done.returncode != 0 or not bag.is_file():
        print(f"  simulate failed (exit {done.returncode}): {done.stderr.strip()[-500:]}")
        return {}
    print(
        f"  {' '.join(command[-5:])}: {simulate_s:.2f} s once (ROS_DOMAIN_ID {domain}), "
        f"{bag.stat().st_size / 1024:.0f} KiB"
    )
    timing = repeat(lambda: read_recording([bag], robot), runs)
    rec: Recording = timing.result
    print(f"  read_recording: {timing.line()}")
    print(f"    {rec.summary()}")
    return {"read_recording": timing}


def bench_test2(world: World, runs: int, seed: int) -> dict[str, Timing]:
    robot = world.model.robot
    plan = paper_test_plan(2)
    _, points = measured(world, plan.q, seed)
    rec = recording_from_arrays(plan.q, points, source="paper-test2")
    out: dict[str, Timing] = {}

    section(f"Test 2 recording: {rec.summary()}")
    cpa = repeat(lambda: circle_point_analysis(rec, robot), runs)
    out["cpa"] = cpa
    print(f"  CPA alone (circle_point_analysis): {cpa.line()}")

    geo = repeat(lambda: calibrate(rec, robot, "geometric"), runs)
    cal = geo.result
    out["geometric"] = geo
    print(f"  calibrate geometric (CPA + LM + accuracy): {geo.line()}")
    print(
        f"    LM: {cal.solver.evaluations} evaluations, fit_model {cal.solver.time_s:.4f} s "
        f"(last run), {int(cal.parameters.free.sum())} free, "
        f"rms {cal.accuracy.absolute_rms_mm:.4f} mm"
    )
    fit_only = repeat(
        lambda: fit_model(KinematicModel(robot), cpa.result.parameters, rec.poses, rec.points),
        runs,
    )
    print(f"    fit_model alone from the CPA result: {fit_only.line()}")
    pairwise = repeat(lambda: accuracy(rec.points, cal.predict(rec.poses)), runs)
    print(f"    accuracy figures alone (O(N^2) pairwise): {pairwise.line()}")

    general = random_plan(robot, 100, np.random.default_rng(seed + 1)).q
    q_mixed = np.concatenate([plan.q, general])
    _, points_mixed = measured(world, q_mixed, seed + 2)
    mixed = recording_from_arrays(q_mixed, points_mixed, source="paper-test2+100")
    for label, recording in (("Test 2", rec), ("Test 2 + 100 general poses", mixed)):
        section(f"geometric+eccentricity (order 1, joints 1-6) from geometric, {label}")
        start = calibrate(recording, robot, "geometric")
        ecc = repeat(
            lambda r=recording, s=start: calibrate(r, robot, "geometric+eccentricity", start=s),
            runs,
        )
        res = ecc.result
        out[f"ecc {label}"] = ecc
        n_ecc = sum(1 for n in res.parameters.names if n.startswith("ecc"))
        print(f"  {len(recording)} points; calibrate(start=geometric): {ecc.line()}")
        print(
            f"    LM: {res.solver.evaluations} evaluations (status {res.solver.status}),"
            f" fit_model {res.solver.time_s:.4f} s (last run), "
            f"{int(res.parameters.free.sum())} free of {len(res.parameters)} "
            f"({n_ecc} eccentricity terms, the rest fixed as unidentifiable), "
            f"rms {res.accuracy.absolute_rms_mm:.4f} mm "
            f"(geometric {start.accuracy.absolute_rms_mm:.4f} mm)"
        )
        ladder = repeat(lambda r=recording: calibrate(r, robot, "geometric+eccentricity"), 1)
        print(
            f"    whole ladder, calibrate(model) without start (CPA, geometric, "
            f"eccentricity): {ladder.times[0]:.4f} s once"
        )
    return out


def bench_scaling(
    world: World,
    model: KinematicModel,
    sizes: list[int],
    runs: int,
    budget_s: float,
    seed: int,
) -> tuple[list[int], list[float], list[float]]:
    """Median fit_model time [s] and traced peak memory [MiB] per size."""
    robot = world.model.robot
    start = perturbed_start(world, model, seed)
    print(
        f"  start: true geometry + N(0, {PERTURBATION:g}) [m, rad], effects at 0; "
        f"{int(start.free.sum())} free before the identifiability check; "
        f"up to {runs} runs per size (fewer once {budget_s:.0f} s are spent)"
    )
    print(
        f"  {'poses':>7} {'evals':>5} {'free':>4} {'median s':>9} {'us/pose':>8} "
        f"{'us/pose/eval':>12} {'runs':>4} {'peak MiB':>9} {'kB/pose':>8} {'maxrss MiB':>10}"
        f"  {'rms um':>6}"
    )
    done_n, times, peaks = [], [], []
    for n in sizes:
        q = random_plan(robot, n, np.random.default_rng(seed + n)).q
        poses, points = measured(world, q, seed + n + 1)
        timing = repeat(lambda p=poses, x=points: fit_model(model, start, p, x), runs, budget_s)
        fit = timing.result
        peak = traced_peak_mib(lambda p=poses, x=points: fit_model(model, start, p, x))
        evals = int(fit.solver.evaluations)
        rms = float(np.sqrt(np.mean(np.sum(fit.residuals**2, axis=1)))) * 1e6
        t = timing.median
        print(
            f"  {n:>7} {evals:>5} {int(fit.parameters.free.sum()):>4} {t:>9.3f} "
            f"{t / n * 1e6:>8.1f} {t / n / evals * 1e6:>12.2f} {len(timing.times):>4} "
            f"{peak:>9.0f} {peak * MIB / n / 1e3:>8.1f} {maxrss_mib():>10.0f}  {rms:>6.2f}",
            flush=True,
        )
        if (fit.solver.status or 0) <= 0:
            print(f"    ! LM stopped without converging: {fit.solver.message}")
        done_n.append(n)
        times.append(t)
        peaks.append(peak)
    return done_n, times, peaks


def bench_pairwise(world: World, sizes: list[int], runs: int, seed: int, max_n: int) -> None:
    section("accuracy() that calibrate() computes after each fit: O(N^2) pairwise figure")
    robot = world.model.robot
    ns, ts = [], []
    for n in sizes:
        q = random_plan(robot, n, np.random.default_rng(seed + 7 * n)).q
        poses, points = measured(world, q, seed + n)
        predicted = points + 1e-6
        timing = repeat(lambda x=points, p=predicted: accuracy(x, p), runs, 20.0)
        ns.append(n)
        ts.append(timing.median)
        print(f"  {n:>7} poses: {timing.line()}")
    slope = loglog_slope(ns, ts)
    if len(ns) >= 2:
        projected = ts[-1] * (max_n / ns[-1]) ** 2
        print(
            f"  log-log slope {slope:.2f}; at {max_n} poses ~{projected:.0f} s "
            f"(quadratic from {ns[-1]}): calibrate() at that size would spend it on top of "
            "the fit"
        )


# --- main ------------------------------------------------------------------------------


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--max-poses",
        type=int,
        default=100_000,
        help="largest number of poses of the geometric scaling (default 100000)",
    )
    parser.add_argument(
        "--repeat",
        type=int,
        default=5,
        help="runs per measurement, the median is reported (default 5)",
    )
    parser.add_argument(
        "--ecc-max-poses",
        type=int,
        default=30_000,
        help="largest number of poses of the geometric+eccentricity scaling "
        "(default 30000, ~1.2 GB; 100000 needs ~4 GB)",
    )
    parser.add_argument(
        "--budget",
        type=float,
        default=30.0,
        help="seconds per scaling size after which repeats stop (default 30)",
    )
    parser.add_argument(
        "--blas-threads",
        type=int,
        default=None,
        help="set OPENBLAS/OMP/MKL_NUM_THREADS to N and restart (default: as importing "
        "robot_calib leaves them: 1 unless already set)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulated data")
    parser.add_argument(
        "--skip-bag",
        action="store_true",
        help="skip the simulate + read_recording part (needs rclpy)",
    )
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.blas_threads and any(os.environ.get(v) != str(args.blas_threads) for v in BLAS_ENV):
        # BLAS reads its thread count when NumPy is imported: restart with it set.
        os.environ.update({v: str(args.blas_threads) for v in BLAS_ENV})
        os.execv(sys.executable, [sys.executable, *sys.argv])
    runs = max(args.repeat, 1)
    began = time.perf_counter()
    print("bench_identify: " + " ".join(sys.argv[1:]) if sys.argv[1:] else "bench_identify")
    print(
        f"  python {platform.python_version()}, numpy {np.__version__}, scipy "
        f"{scipy.__version__}, {platform.machine()}, {os.cpu_count()} CPUs"
    )
    print(
        f"  BLAS threads in use: {blas_threads()} ("
        + ", ".join(f"{v}={os.environ.get(v, 'unset')}" for v in BLAS_ENV)
        + ")"
    )
    print(f"  {load_line()}")

    base = load_world()
    world = with_effect(base, seed_runout(base.model.robot.n_joints))
    robot = world.model.robot
    print(
        f"  world: {base.source} + seed eccentricity (order 1, joints 1-6), noise on, "
        f"seed {args.seed}"
    )
    results = bench_test2(world, runs, args.seed)

    if not args.skip_bag:
        with tempfile.TemporaryDirectory(prefix="bench_identify_") as tmp:
            results.update(bench_bag(robot, runs, Path(tmp)))

    sizes = [n for n in SIZES if n <= args.max_poses]
    if args.max_poses not in sizes and args.max_poses > (sizes[-1] if sizes else 0):
        sizes.append(args.max_poses)
    section(f"geometric fit_model vs poses (random general poses, {load_line()})")
    geo_n, geo_t, geo_peak = bench_scaling(
        world, KinematicModel(robot), sizes, runs, args.budget, args.seed
    )
    geo_slope = loglog_slope(geo_n, geo_t)
    print(f"  log-log slope of time vs poses: {geo_slope:.3f} (1 = linear)")
    if len(geo_n) >= 2:
        per_pose = [t / n * 1e6 for n, t in zip(geo_n, geo_t)]
        print(
            f"  time per pose {min(per_pose):.1f} .. {max(per_pose):.1f} us; "
            f"peak memory ~{geo_peak[-1] * MIB / geo_n[-1] / 1e3:.1f} kB per pose"
        )

    ecc_sizes = [n for n in sizes if n <= args.ecc_max_poses]
    section(f"geometric+eccentricity fit_model vs poses ({load_line()})")
    ecc_n, ecc_t, ecc_peak = bench_scaling(
        world, world.model, ecc_sizes, runs, args.budget, args.seed
    )
    ecc_slope = loglog_slope(ecc_n, ecc_t)
    print(f"  log-log slope of time vs poses: {ecc_slope:.3f} (1 = linear)")
    skipped = [n for n in sizes if n not in ecc_n]
    if skipped and len(ecc_n) >= 2:
        per_pose_mib = np.polyfit(ecc_n, ecc_peak, 1)[0]
        per_pose_s = ecc_t[-1] / ecc_n[-1]
        for n in skipped:
            print(
                f"  not run at {n} poses (--ecc-max-poses {args.ecc_max_poses}): would need "
                f"~{per_pose_mib * n / 1024:.1f} GiB peak and ~{per_pose_s * n:.0f} s "
                "(linear from the sizes run)"
            )

    bench_pairwise(
        world,
        [n for n in PAIRWISE_SIZES if n <= args.max_poses],
        runs,
        args.seed,
        max(sizes) if sizes else 1000,
    )

    section("summary: target vs measured")
    rows: list[tuple[str, str, str, str]] = []

    def target(name: str, goal: str, value: str, ok: bool | None) -> None:
        rows.append((name, goal, value, "-" if ok is None else ("PASS" if ok else "MISS")))

    target(
        "geometric, Test 2 (580 pts), calibrate",
        f"<= {TARGET_GEOMETRIC_S} s",
        results["geometric"].short(),
        results["geometric"].median <= TARGET_GEOMETRIC_S,
    )
    for label in ("Test 2", "Test 2 + 100 general poses"):
        value = results[f"ecc {label}"]
        target(
            f"geometric+ecc from geometric, {label}",
            f"<= {TARGET_ECCENTRICITY_S} s",
            value.short(),
            value.median <= TARGET_ECCENTRICITY_S,
        )
    if len(geo_n) >= 2:
        target(
            f"geometric fit vs poses {geo_n[0]}..{geo_n[-1]}",
            f"linear (slope <= {TARGET_SLOPE})",
            f"slope {geo_slope:.3f}",
            geo_slope <= TARGET_SLOPE,
        )
    if len(ecc_n) >= 2:
        target(
            f"geometric+ecc fit vs poses {ecc_n[0]}..{ecc_n[-1]}",
            "(info) linear",
            f"slope {ecc_slope:.3f}",
            None,
        )
    if geo_n:
        target(
            f"geometric fit peak memory, {geo_n[-1]} poses",
            "(info)",
            f"{geo_peak[-1]:.0f} MiB",
            None,
        )
    if ecc_n:
        target(
            f"geometric+ecc peak memory, {ecc_n[-1]} poses",
            "(info)",
            f"{ecc_peak[-1]:.0f} MiB",
            None,
        )
    if "read_recording" in results:
        target("read_recording, Test 2 bag", "(info)", results["read_recording"].short(), None)
    target("CPA alone, Test 2", "(info)", results["cpa"].short(), None)
    widths = [
        max(len(r[i]) for r in [("measurement", "target", "measured", "result"), *rows])
        for i in range(4)
    ]
    for row in [("measurement", "target", "measured", "result"), *rows]:
        print("  " + "  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip())
    print(
        f"\n  {load_line()}; total {time.perf_counter() - began:.0f} s, "
        f"maxrss {maxrss_mib():.0f} MiB"
    )
    print(
        "  Times are medians of wall-clock runs (min in brackets). Other processes on the "
        "CPUs inflate them,\n  a multi-threaded BLAS (--blas-threads 2) many-fold: its "
        "SVD/QR threads wait on each other."
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
