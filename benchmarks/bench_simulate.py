"""Benchmark (not a test): `robot-calib simulate` of N random poses (default world), the
in-process ROS 2 graph sim_robot -> sim_tracker -> recorder writing an MCAP bag, as a whole
process per run (imports, rclpy start-up, discovery, the bag's summary included).

    .venv/bin/python benchmarks/bench_simulate.py [--sizes 1000,10000,100000] [--repeat 1]
    .venv/bin/python benchmarks/bench_simulate.py --quick      # 1k and 10k only

Target: 100k poses in <= 30 s (192 s before the graph was stepped in bursts).
Prints per size the process's wall time (min of --repeat), the simulation's own time (what
`simulate` reports: the graph and the bag, no imports), the time per pose, the peak RSS of
the child (its own rusage, os.wait4) and the messages recorded, then PASS/MISS against the
target. The machine's load average is printed with it: timings depend on it.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_POSES = 100_000
TARGET_S = 30.0
CLI = Path(sys.executable).with_name("robot-calib")


def _run(n: int, folder: Path) -> tuple[float, float, float, str]:
    """One `simulate` of n random poses: (wall s, simulation s, peak RSS MiB, counts)."""
    bag = folder / f"random_{n}.mcap"
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", ROS_LOG_DIR=str(folder / "ros_log"))
    command = [
        str(CLI),
        "simulate",
        "--plan",
        "random",
        "--n-random",
        str(n),
        "--seed",
        "0",
        "-o",
        str(bag),
        "--force",
    ]
    log = folder / "simulate.log"
    with open(log, "wb") as output:
        started = time.perf_counter()
        child = subprocess.Popen(command, env=env, stdout=output, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(child.pid, 0)  # the child's own rusage: its peak RSS
        wall = time.perf_counter() - started
    child.returncode = os.waitstatus_to_exitcode(status)
    text = log.read_text()
    if child.returncode != 0:
        raise SystemExit(f"simulate {n} poses failed: {text.strip()[-2000:]}")
    seconds = re.search(r" in ([0-9.]+) s;", text)
    counts = re.search(r": (/joint_states=\d+, [^ ]+) messages", text)
    for path in (bag, bag.with_suffix(".world.yaml")):
        path.unlink(missing_ok=True)
    return (
        wall,
        float(seconds.group(1)) if seconds else float("nan"),
        usage.ru_maxrss / 1024.0,  # KiB on Linux
        counts.group(1) if counts else text.strip()[-200:],
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--sizes", default="1000,10000,100000", help="poses per run, comma-separated"
    )
    parser.add_argument("--quick", action="store_true", help="1000 and 10000 poses only")
    parser.add_argument("--repeat", type=int, default=1, help="runs per size (min reported)")
    args = parser.parse_args()
    sizes = [1000, 10000] if args.quick else [int(s) for s in args.sizes.split(",") if s]
    if not CLI.exists():
        raise SystemExit(f"{CLI}: robot-calib not installed in this environment")
    load = os.getloadavg()
    busy = " (above the CPU count: timings inflated)" if load[0] > (os.cpu_count() or 1) else ""
    print(
        f"robot-calib simulate --plan random (default world); {os.cpu_count()} CPUs, "
        f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}{busy}"
    )
    print(f"{'poses':>8} {'wall s':>8} {'sim s':>8} {'us/pose':>8} {'peak MiB':>9}  messages")
    results: dict[int, float] = {}
    with tempfile.TemporaryDirectory(prefix="bench_simulate_") as tmp:
        for n in sizes:
            runs = [_run(n, Path(tmp)) for _ in range(max(1, args.repeat))]
            wall, sim, peak, counts = min(runs)
            results[n] = wall
            print(
                f"{n:>8} {wall:>8.2f} {sim:>8.2f} {sim / n * 1e6:>8.1f} {peak:>9.0f}  {counts}",
                flush=True,
            )
    if TARGET_POSES in results:
        wall = results[TARGET_POSES]
        verdict = "PASS" if wall <= TARGET_S else "MISS"
        print(
            f"target: simulate {TARGET_POSES} poses <= {TARGET_S:.0f} s wall: {wall:.1f} s "
            f"{verdict}"
        )


if __name__ == "__main__":
    main()
