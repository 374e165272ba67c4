"""Peak memory of the geometric fit: the whole process's peak RSS, one fresh process per size.

    .venv/bin/python benchmarks/bench_memory.py [--sizes 10000 50000] [--repeat 3]

Prints figures (no assertions). For every size, this script runs itself in a fresh Python
process (`--child N`), which imports robot_calib (before NumPy, one BLAS thread, as the
console scripts), simulates N random general poses of the same world as bench_identify
(default world + seed eccentricity on all joints, noise on; poses simulated 1000 at a time),
builds the same start (true geometry + N(0, 1e-4)), and calls `fit_model` with the geometric
model. Columns, in MiB (2^20 bytes):

- import: peak RSS of a process that only imported NumPy, SciPy and robot_calib (size 0);
- setup: RSS just before the fit (import + world + poses and points);
- peak: the process's peak RSS (VmHWM) during the first fit, whole process: import and data
  included. The high-water mark is reset just before the fit (`/proc/self/clear_refs`, Linux
  >= 4.0) so that the simulation of the data does not count; where that is refused, peak is
  `ru_maxrss` since the process started (flagged);
- fit: peak - setup, what the fit itself adds;
- traced: tracemalloc peak of one more, untimed fit (NumPy/Python allocations only);
- time: median wall time of --repeat fits [s].

Target: peak < 300 MiB at 50k poses.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

# isort: split
# First, before NumPy loads: importing robot_calib sets one BLAS thread (as console scripts).
import robot_calib  # noqa: F401

# isort: split
import numpy as np

from robot_calib.effects import seed_runout
from robot_calib.identify.fit import fit_model
from robot_calib.model import KinematicModel
from robot_calib.sim.plans import random_plan
from robot_calib.sim.world import load_world, with_effect

SIZES = (10_000, 50_000)
TARGET_MIB = 300.0  # geometric fit peak at 50k poses
SIM_CHUNK = 1_000  # poses simulated at once: keeps the setup far below the fit
MIB = 2.0**20


def _status_mib(field: str) -> float:
    """A `VmXxx:` line of /proc/self/status [MiB] (nan where /proc is missing)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def _maxrss_mib() -> float:
    """ru_maxrss of this process [MiB] (Linux: kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _reset_peak() -> bool:
    """Reset this process's peak RSS to its current RSS; False where the kernel refuses."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return False
    return True


def child(n: int, repeat: int, seed: int) -> dict[str, float | int | bool]:
    """Figures of one process that fits `n` poses (n = 0: import only), see the module doc."""
    out: dict[str, float | int | bool] = {"poses": n, "import": _maxrss_mib()}
    if n == 0:
        return out
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_identify import measured, perturbed_start  # same data and start

    base = load_world()
    world = with_effect(base, seed_runout(base.model.robot.n_joints))
    model = KinematicModel(world.model.robot)
    start = perturbed_start(world, model, seed)
    q = random_plan(world.model.robot, n, np.random.default_rng(seed + n)).q
    poses, points = measured(world, q, seed + n + 1, chunk=SIM_CHUNK)
    out["setup_peak"] = _maxrss_mib()
    out["setup"] = _status_mib("VmRSS")
    out["reset"] = _reset_peak()
    times = []
    for _ in range(max(repeat, 1)):
        started = time.perf_counter()
        fit = fit_model(model, start, poses, points)
        times.append(time.perf_counter() - started)
        if len(times) == 1:
            out["peak"] = _status_mib("VmHWM") if out["reset"] else _maxrss_mib()
    out["time"] = statistics.median(times)
    out["evaluations"] = int(fit.solver.evaluations or 0)
    out["free"] = int(fit.parameters.free.sum())
    tracemalloc.start()
    fit_model(model, start, poses, points)
    out["traced"] = tracemalloc.get_traced_memory()[1] / MIB
    tracemalloc.stop()
    return out


def run_child(n: int, repeat: int, seed: int) -> dict[str, float | int | bool]:
    """`child(n)` in a fresh interpreter (this script with --child)."""
    command = [sys.executable, __file__, "--child", str(n), "--repeat", str(repeat)]
    done = subprocess.run(
        [*command, "--seed", str(seed)], capture_output=True, text=True, check=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--repeat", type=int, default=3, help="timed fits per size")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        print(json.dumps(child(args.child, args.repeat, args.seed)))
        return 0

    base = run_child(0, 1, args.seed)
    print("bench_memory: geometric fit_model, one fresh process per size (MiB = 2^20 B)")
    print(f"  import numpy/scipy/robot_calib alone: peak RSS {base['import']:.0f} MiB")
    print(
        f"  {'poses':>7} {'free':>4} {'evals':>5} {'setup':>6} {'peak':>6} {'fit':>6} "
        f"{'traced':>6} {'time s':>7}"
    )
    rows = []
    for n in args.sizes:
        r = run_child(n, args.repeat, args.seed)
        rows.append(r)
        flag = "" if r["reset"] else "  (peak since process start: clear_refs refused)"
        print(
            f"  {n:>7} {r['free']:>4} {r['evaluations']:>5} {r['setup']:>6.0f} "
            f"{r['peak']:>6.0f} {r['peak'] - r['setup']:>6.0f} {r['traced']:>6.0f} "
            f"{r['time']:>7.3f}{flag}",
            flush=True,
        )
    for r in rows:
        if r["poses"] == 50_000:
            verdict = "PASS" if r["peak"] < TARGET_MIB else "MISS"
            print(f"  target: peak < {TARGET_MIB:.0f} MiB at 50000 poses: {verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
