# ruff: noqa: E402 - the BLAS thread setting must precede the numpy import
"""Blind harness at scale: N random cases per class, hit rate and the chosen rung's
held-out error over the right model's per class (robot_calib/sim/blind.py lists the
classes: single effects, combinations, other forms).

    .venv/bin/python scripts/blind_harness.py [--cases 20] [--classes backlash ...]

A hit: the diagnosis names the withheld effect and its joints (null for `none`; several
effects: each in the chosen rung; joint harmonics: their joints and orders in the chosen
rung; out of the vocabulary: the dominant effect, any name, on the right joints, e.g. a
bending link's J or J + 1) and its chosen rung brings the held-out error to within 1.5 x
the noise floor (not required out of the vocabulary). ratio to right: the chosen rung's
held-out rms over that of the right model (the withheld effects fitted on the same
data), median and worst.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see robot_calib/__init__.py

import argparse
import json
import statistics
import sys
import time

from robot_calib.flows.blind import run_case
from robot_calib.forked import FORKED
from robot_calib.parallel import using
from robot_calib.sim.blind import classes


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cases", type=int, default=20, help="cases per class (20)")
    parser.add_argument("--classes", nargs="*", default=list(classes()), choices=classes())
    parser.add_argument("--json", help="write every case's verdict to this file")
    args = parser.parse_args()
    results = []
    false_rows = free_rows = missed = joints = strongest_wrong = not_loading = 0
    for effect in args.classes:
        hits = named = 0
        to_right: list[float] = []
        started = time.perf_counter()
        for seed in range(args.cases):
            with using(FORKED):  # the other core, as the command line's diagnosis
                r = run_case(effect, 1000 + seed)
            results.append(r)
            hits += r["hit"]
            named += r["named"]
            false_rows += len(r["false_rows"])
            free_rows += r["free_rows"]
            missed += len(r["missed"])
            joints += len(r["joints"])
            strongest_wrong += not r["strongest_ok"]
            if r["best_loads"]:
                not_loading += 1
                print(
                    f"  params_best.json of {effect} seed {1000 + seed}: {r['best_loads']}",
                    file=sys.stderr,
                )
            if r["ratio_to_right"] is not None:
                to_right.append(r["ratio_to_right"])
            mark = "hit " if r["hit"] else "MISS"
            ratio = r["ratio_to_floor"]
            floor = "unknown" if ratio is None else f"{ratio:.2f}"
            print(
                f"  {effect:<14} seed {1000 + seed}: {mark} truth {r['joints']} answer "
                f"{r['answer']} held-out {floor} x floor",
                file=sys.stderr,
            )
        per_case = (time.perf_counter() - started) / args.cases
        right = (
            f"ratio to right model median {statistics.median(to_right):.2f} worst "
            f"{max(to_right):.2f}"
            if to_right
            else ""
        )
        print(
            f"{effect:<38} hit rate {hits}/{args.cases}  (named {named}/{args.cases})  "
            f"{right}  {per_case:.1f} s per case",
            flush=True,
        )
    print(
        f"evidence: effect-free joints' rows at >= 5 x {false_rows} of {free_rows} "
        f"({100 * false_rows / max(free_rows, 1):.1f} %); effect joints missed {missed} of "
        f"{joints}; strongest structure elsewhere in {strongest_wrong} of {len(results)} "
        "cases"
    )
    print(f"params_best.json that does not load: {not_loading} of {len(results)} cases")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(results, handle, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
