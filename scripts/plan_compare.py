"""Capture plans compared (README "Capture planning"): predicted worst 1-sigma and the
simulated held-out error of D-optimal plans, random poses at equal N and the seed's Test 2
(paper-test2, 580 points), for `geometric` on the default world's KR5; the ratio of the
worst 1-sigma (random median over 15 draws / planned) against N; and the time to plan
N=60 of M=2000.

    .venv/bin/python scripts/plan_compare.py [--trials 3] [--model geometric]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from robot_calib.plan.campaign import plan_figures, planning_problem
from robot_calib.plan.design import d_optimal
from robot_calib.plan.evaluate import predict, world_noise_m
from robot_calib.sim.plans import paper_test_plan
from robot_calib.sim.world import load_world


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="geometric", help="model (default geometric)")
    parser.add_argument("--trials", type=int, default=3, help="simulated calibrations (3)")
    args = parser.parse_args()
    world = load_world()
    started = time.perf_counter()
    problem = planning_problem(world, args.model, 2000, np.random.default_rng(0))
    q60 = d_optimal(problem, 60)
    print(
        f"plan N=60 of M=2000 for {args.model}: {time.perf_counter() - started:.2f} s "
        "(candidates, identifiability, D-optimal choice)"
    )
    noise = world_noise_m(world, problem)
    print(f"noise per coordinate: {noise * 1e3:.4f} mm")
    plans = [("D-optimal", problem.plan(q60)), ("random", problem.plan(problem.candidates[:60]))]
    test2 = paper_test_plan(2)
    plans.append(("paper-test2", test2))
    started = time.perf_counter()
    plans.append(("D-optimal", problem.plan(d_optimal(problem, len(test2)))))
    print(f"plan N=580 of M=2000: {time.perf_counter() - started:.2f} s")
    print(
        "| plan | N | worst 1-sigma (rms over the workspace) | worst length | worst angle "
        "| held-out abs rms / model error [mm] | campaign [min] |"
    )
    print("|---|---|---|---|---|---|---|")
    rng = np.random.default_rng(1)
    for name, plan in plans:
        fig = plan_figures(world, problem, args.model, plan, noise, rng, args.trials)
        pred = fig.prediction
        length, angle = pred.worst_of_unit("m"), pred.worst_of_unit("rad")
        assert fig.holdout is not None and length is not None and angle is not None
        print(
            f"| {name} | {len(plan)} | {pred.names[pred.worst]} {pred.rms_m.max() * 1e3:.5f} mm "
            f"| {pred.names[length]} {pred.std[length] * 1e3:.5f} mm "
            f"| {pred.names[angle]} {pred.std[angle] * 1e6:.2f} urad "
            f"| {fig.holdout.abs_rms_mm:.4f} / {fig.holdout.model_rms_mm:.4f} "
            f"| {fig.hours * 60:.0f} |"
        )
    print("| N | planned worst [mm] | random median worst [mm] (15 draws) | ratio |")
    print("|---|---|---|---|")
    draws = np.random.default_rng(5)
    for n in (14, 20, 30, 60, 120):
        planned = predict(problem, problem.plan(d_optimal(problem, n)), noise).rms_m.max()
        subsets = [draws.choice(2000, n, replace=False) for _ in range(15)]
        random = np.median(
            [
                predict(problem, problem.plan(problem.candidates[s]), noise).rms_m.max()
                for s in subsets
            ]
        )
        print(f"| {n} | {planned * 1e3:.5f} | {random * 1e3:.5f} | {random / planned:.2f} |")


if __name__ == "__main__":
    main()
