# ruff: noqa: E402 - the BLAS thread setting must precede the numpy import
"""Acceptance figures on effect-free simulated worlds with known truth.

    .venv/bin/python scripts/identify_acceptance.py [--seeds 10] [--plan 2]

For each seed: the seed's Test 2 sweeps are calibrated (`geometric`); printed are the
largest |value - truth| / sigma over the free parameters (must stay below 3) and the error
on 200 held-out random poses relative to the true model's (the noise floor; must stay
below 1.2), in absolute and in the seed's criterion.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: see robot_calib/__init__.py

import argparse

import numpy as np

from robot_calib.accuracy import accuracy
from robot_calib.identify.calibrate import calibrate
from robot_calib.measurements import recording_from_arrays
from robot_calib.model import absorb_base_offsets
from robot_calib.poses import Poses
from robot_calib.sim.measure import physical_points
from robot_calib.sim.plans import paper_test_plan, random_plan
from robot_calib.sim.world import load_world


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--plan", type=int, default=2, help="seed Table 2 test (1-6)")
    args = parser.parse_args()
    world = load_world()
    robot = world.model.robot
    truth = absorb_base_offsets(robot, world.truth)
    plan = paper_test_plan(args.plan)
    print(
        "seed  max|z|  worst               n>3  holdout abs / floor"
        "  holdout seed-criterion / floor"
    )
    worst_z, worst_ratio = 0.0, 0.0
    for seed in range(args.seeds):
        rng = np.random.default_rng(seed)
        points = physical_points(world, Poses.from_readings(plan.q), rng)
        cal = calibrate(recording_from_arrays(plan.q, points), robot, "geometric")
        free = cal.parameters.free
        z = (cal.parameters.values - truth.values)[free] / cal.std[free]
        held = Poses.from_readings(random_plan(robot, 200, np.random.default_rng(100 + seed)).q)
        measured = physical_points(world, held, rng)
        fitted = accuracy(measured, cal.predict(held))
        floor = accuracy(measured, world.model.target_points(world.truth, held))
        ratio = fitted.absolute_mean_mm / floor.absolute_mean_mm
        pair = fitted.pairwise_mean_mm / floor.pairwise_mean_mm
        name = np.array(cal.parameters.free_names)[np.argmax(np.abs(z))]
        print(
            f"{seed:>4}  {np.abs(z).max():6.2f}  {name:<18} {int((np.abs(z) > 3).sum()):>4}"
            f"  {ratio:19.3f}  {pair:30.3f}"
        )
        worst_z, worst_ratio = max(worst_z, float(np.abs(z).max())), max(worst_ratio, ratio, pair)
    print(
        f"largest |z| {worst_z:.2f} (target < 3); largest hold-out ratio {worst_ratio:.3f} "
        "(target <= 1.2)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
