# ruff: noqa: E402 - the BLAS thread setting must precede the numpy import
"""Compensation speed (target: >= 1,000 poses/s): nominal commands of a program, and
target poses (tool point and orientation, tracker frame, no seeds: the nominal inverse
kinematics starts at the home pose), compensated for a KR5 calibrated with joint-4
backlash, in one batch each.

    .venv/bin/python benchmarks/bench_compensate.py [--poses 10000]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import time

import numpy as np

from robot_calib.compensation import compensate_commands, compensate_targets
from robot_calib.compensation.solve import nominal_counterpart
from robot_calib.compensation.targets import Targets, goals_in_base
from robot_calib.effects import parse_effect
from robot_calib.identify.calibrate import calibrate
from robot_calib.ik import first_tool2flange, tool2base
from robot_calib.measurements import recording_from_arrays
from robot_calib.poses import Poses
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import paper_test_plan, plan_times, random_plan
from robot_calib.sim.world import build_world, with_effect

TARGET_POSES_PER_S = 1000.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=10000)
    args = parser.parse_args()
    world = with_effect(
        build_world({"seed": 4}), parse_effect("backlash:4", 6), {"backlash4": 2e-3}
    )
    robot = world.model.robot
    plan = paper_test_plan(2)
    poses, points = measure_every_target(
        world, plan.q, plan_times(plan, world.timing), np.random.default_rng(1)
    )
    cal = calibrate(
        recording_from_arrays(poses.q, points, poses.time, robot=robot),
        robot,
        "geometric+backlash:4",
    )
    commands = Poses.from_readings(random_plan(robot, args.poses, np.random.default_rng(5)).q)
    started = time.perf_counter()
    result = compensate_commands(cal, commands)
    seconds = time.perf_counter() - started
    rate = args.poses / seconds
    verdict = "PASS" if rate >= TARGET_POSES_PER_S else "FAIL"
    print(
        f"{args.poses} commands compensated in {seconds:.2f} s: {rate:.0f} poses/s "
        f"(target >= {TARGET_POSES_PER_S:.0f}: {verdict}); converged "
        f"{int(result.converged.sum())}/{args.poses}, iterations max "
        f"{int(result.iterations.max())}"
    )

    # targets: the tool frames the nominal model reaches at other random readings
    q = random_plan(robot, args.poses, np.random.default_rng(6)).q
    tool = first_tool2flange(cal.model, cal.parameters)
    nominal, nominal_params = nominal_counterpart(cal.model, cal.parameters)  # the program's
    in_tracker = cal.model.base2tracker(cal.parameters) @ tool2base(
        nominal, nominal_params, Poses.from_readings(q), tool
    )
    targets = Targets(
        in_tracker[:, :3, 3],
        in_tracker[:, :3, :3],
        None,
        None,
        np.zeros(args.poses),
        None,
        tuple(range(2, args.poses + 2)),
    )
    started = time.perf_counter()
    goals = goals_in_base(targets, "tracker", cal.model, cal.parameters)
    found = compensate_targets(cal, targets, goals)
    seconds = time.perf_counter() - started
    rate = args.poses / seconds
    verdict = "PASS" if rate >= TARGET_POSES_PER_S else "FAIL"
    print(
        f"{args.poses} target poses (from the home pose) compensated in {seconds:.2f} s: "
        f"{rate:.0f} poses/s (target >= {TARGET_POSES_PER_S:.0f}: {verdict}); reached "
        f"{int(found.reached.sum())}/{args.poses} (within the joint limits), nominal IK "
        f"iterations max {int(found.nominal.iterations.max())}"
    )


if __name__ == "__main__":
    main()
