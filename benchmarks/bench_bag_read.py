# ruff: noqa: E402 - the BLAS thread setting must precede the numpy import
"""Benchmark (not a test): `read_recording` of a bag of 200k messages (100k JointState +
100k PointStamped, a UR10 random-pose campaign as `bench_diagnose_ur10.py` writes it),
decoded message by message (mcap's stream reader + mcap_ros2, as the reader once did)
and in bulk (`BagReader.channel_messages` + `bag.bulk_decode`), each in a child process so
that its peak RSS is its own.

    .venv/bin/python benchmarks/bench_bag_read.py [--poses 100000] [--repeat 3] [--bag B]

Target: <= 3 s for the 200k messages. Prints per way the median wall time of
`read_recording` (the child's clock: imports and bag writing are not in it), the bag
reading alone (`_bag_messages`), the peak RSS of the child and whether both give the
same recording.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see robot_calib/__init__.py

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 3.0
CHILD = """
import json, resource, sys, time, hashlib
from pathlib import Path
import numpy as np
from robot_calib.bag import mcap_reader, read
from robot_calib.kinematics.loader import load_robot
if sys.argv[2] == "each":  # the earlier reader: every message through mcap_ros2
    mcap_reader.BagReader.channel_messages = lambda self, topics: None
robot, bag = load_robot("ur10"), Path(sys.argv[1])
started = time.perf_counter()
read._bag_messages(bag, robot)
messages = time.perf_counter() - started
started = time.perf_counter()
rec = read.read_recording([bag], robot)
wall = time.perf_counter() - started
digest = hashlib.sha256()
for a in (rec.poses.q, rec.points, rec.poses.time, rec.poses.direction, rec.stamp_ns):
    digest.update(np.ascontiguousarray(a).tobytes())
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print(json.dumps({"wall": wall, "messages": messages, "peak": peak, "n": len(rec),
                  "digest": digest.hexdigest()}))
"""


def _bag(path: Path, poses: int) -> Path:
    """The UR10 campaign's bag (`bench_diagnose_ur10._bag`), written once."""
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_diagnose_ur10 import _bag as write_bag

    from robot_calib.sim.scenarios import ur10_random

    scenario = ur10_random(seed=0, n=poses, holdout_share=0.0)
    return write_bag(path, scenario.calibration, scenario.world.model.robot.joint_names)


def _run(bag: Path, way: str) -> dict[str, float | str]:
    done = subprocess.run(
        [sys.executable, "-c", CHILD, str(bag), way], capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        raise SystemExit(f"reading failed ({way}): {done.stderr.strip()}")
    result: dict[str, float | str] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--poses", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--bag", type=Path, help="an existing bag of the UR10 (else written)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        bag = args.bag
        if bag is None:
            started = time.perf_counter()
            bag = _bag(Path(folder) / f"ur10_{args.poses}.mcap", args.poses)
            print(f"wrote {bag.name} in {time.perf_counter() - started:.1f} s")
        print(
            f"{bag}: {bag.stat().st_size / 2**20:.1f} MiB, load average {os.getloadavg()[0]:.2f}"
        )
        digests = set()
        for way, label in (("each", "message by message (before)"), ("bulk", "in bulk")):
            runs = [_run(bag, way) for _ in range(args.repeat)]
            digests.update(str(r["digest"]) for r in runs)
            wall = statistics.median(float(r["wall"]) for r in runs)
            messages = statistics.median(float(r["messages"]) for r in runs)
            peak = max(float(r["peak"]) for r in runs)
            print(
                f"{label:28s} read_recording {wall:6.2f} s (bag messages {messages:5.2f} s), "
                f"peak RSS {peak:5.0f} MiB, {runs[0]['n']} poses (median of {args.repeat})"
            )
        same = "same recording" if len(digests) == 1 else "RECORDINGS DIFFER"
        verdict = "met" if wall <= TARGET_S else "NOT met"
        print(f"{same}; target <= {TARGET_S:.0f} s in bulk: {verdict}")


if __name__ == "__main__":
    main()
