"""Start-up benchmark: whole-process wall time of the light verbs against a bare
`python -c "import numpy"`, medians over alternating runs (so machine load hits all alike).

    .venv/bin/python benchmarks/bench_startup.py [--repeat 15]

Prints, per command, the median [s] and its ratio to the numpy baseline. Target:
`robot-calib --help` and `robot-calib predict` within 2.5 x the baseline. `calibrate` of the
sample bag is shown for scale (it imports scipy and mcap: it needs them).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "bags" / "paper_test3.mcap"
TARGET_RATIO = 2.5


def timed(cmd: list[str]) -> float:
    started = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - started


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=15, help="runs per command (15)")
    args = parser.parse_args()
    cli = [sys.executable, "-m", "robot_calib"]
    with tempfile.TemporaryDirectory() as tmp:
        params, joints = Path(tmp) / "params.json", Path(tmp) / "joints.csv"
        subprocess.run(
            [*cli, "calibrate", str(SAMPLE), "-o", str(params)], check=True, capture_output=True
        )
        joints.write_text("q1,q2,q3,q4,q5,q6\n" + "0.1,0.2,0.3,0.4,0.5,0.6\n" * 10)
        commands = {
            "python -c 'import numpy'": [sys.executable, "-c", "import numpy"],
            "robot-calib --help": [*cli, "--help"],
            "robot-calib predict": [
                *cli,
                "predict",
                str(params),
                "--joints",
                str(joints),
                "-o",
                str(Path(tmp) / "points.csv"),
                "--force",
            ],
            "robot-calib calibrate (sample bag)": [
                *cli,
                "calibrate",
                str(SAMPLE),
                "-o",
                str(Path(tmp) / "p2.json"),
                "--force",
            ],
        }
        times: dict[str, list[float]] = {name: [] for name in commands}
        for _ in range(args.repeat):  # alternate: each round runs every command once
            for name, cmd in commands.items():
                times[name].append(timed(cmd))
    base = statistics.median(times["python -c 'import numpy'"])
    print(f"{'command':<38}{'median [s]':>11}{'x numpy':>9}  (target <= {TARGET_RATIO} x)")
    for name, values in times.items():
        med = statistics.median(values)
        print(f"{name:<38}{med:>11.3f}{med / base:>9.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
