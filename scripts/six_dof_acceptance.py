"""6-DoF measurements over several seeds: a simulated KR5 with a tracker 6-DoF
probe (roll/pitch/yaw 20/35/-30 deg in the flange, 50 urad orientation noise per axis),
150 random poses with stated accuracies. Prints the worst tool-frame errors (orientation
[urad], offset [um]) and their ratio to the reported 1-sigma, the in-sample orientation
and point residuals, and the effect of the stated accuracies: with half the points 20 x
noisier, the model error on the accurate half, weighted (accuracies stated) and unweighted.

    .venv/bin/python scripts/six_dof_acceptance.py --seeds 10
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import Calibration
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import recording_from_arrays
from robot_calib.model import absorb_base_offsets, target_parameters, tool_rotation_parameters
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import plan_times, random_plan
from robot_calib.sim.world import build_world

SIGMA_ORIENTATION = 50e-6  # rad per axis
SIGMA_POINT = 4.8e-6  # m per coordinate: the default world's tracker + target noise


def worst(cal: Calibration, truth: ParameterVector, names: tuple[str, ...]) -> tuple[float, float]:
    """The largest |fitted - true| of `names` and the largest ratio to its 1-sigma."""
    errors = [abs(cal.parameters[n] - truth[n]) for n in names]
    ratios = [e / cal.std[cal.parameters.index(n)] for e, n in zip(errors, names)]
    return max(errors), max(ratios)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--poses", type=int, default=150)
    args = parser.parse_args()
    frame, offset, z_frame, z_offset, rot_rms, pt_rms, weighted, unweighted = (
        [] for _ in range(8)
    )
    for seed in range(args.seeds):
        world = build_world(
            {
                "seed": seed,
                "six_dof": {"first": [20.0, 35.0, -30.0]},
                "noise": {"orientation_sigma_rad": SIGMA_ORIENTATION},
            }
        )
        robot = world.model.robot
        plan = random_plan(robot, args.poses, np.random.default_rng(seed))
        poses, points = measure_every_target(
            world, plan.q, plan_times(plan, world.timing), np.random.default_rng(seed + 100)
        )
        stated = np.tile([SIGMA_POINT, SIGMA_ORIENTATION], (len(poses), 1))
        recording = recording_from_arrays(
            poses.q, points, poses.time, robot=robot, rotation=poses.rotation, sigma=stated
        )
        cal = calibrate(recording, robot, "geometric")
        truth = absorb_base_offsets(robot, world.truth)

        e, z = worst(cal, truth, tool_rotation_parameters(""))
        frame.append(e * 1e6), z_frame.append(z)
        e, z = worst(cal, truth, target_parameters(""))
        offset.append(e * 1e6), z_offset.append(z)
        assert cal.orientation_residuals is not None
        rot_rms.append(float(np.sqrt(np.mean(cal.orientation_residuals**2))) * 1e6)
        pt_rms.append(float(np.sqrt(np.mean(cal.residuals**2))) * 1e6)
        # stated accuracies: half the points 20 x noisier, said so or not
        noisy = np.arange(len(points)) % 2 == 1
        rng = np.random.default_rng(seed + 200)
        bad = points.copy()
        bad[noisy] += rng.normal(0.0, 20 * SIGMA_POINT, (int(noisy.sum()), 3))
        exact = world.model.target_points(world.truth, poses)
        for out, sigma in (
            (weighted, np.where(noisy, 20 * SIGMA_POINT, SIGMA_POINT)),
            (unweighted, None),
        ):
            stated_pt = (
                None if sigma is None else np.column_stack([sigma, np.full(len(sigma), np.nan)])
            )
            rec = recording_from_arrays(poses.q, bad, poses.time, robot=robot, sigma=stated_pt)
            fit = calibrate(rec, robot, "geometric", screen_outliers=False)
            err = fit.predict(replace(poses, rotation=None)) - exact
            out.append(float(np.sqrt(np.mean(err[~noisy] ** 2))) * 1e6)
    print(f"{args.seeds} seeds x {args.poses} random poses, KR5 with a 6-DoF probe")
    print(f"tool frame orientation: worst error {max(frame):.1f} urad ({max(z_frame):.2f} sigma)")
    print(f"tool frame offset:      worst error {max(offset):.2f} um ({max(z_offset):.2f} sigma)")
    print(
        f"in-sample orientation residual rms per axis: {np.mean(rot_rms):.1f} urad "
        f"(simulated noise {SIGMA_ORIENTATION * 1e6:.0f})"
    )
    print(
        f"in-sample point residual rms per coordinate: {np.mean(pt_rms):.2f} um "
        f"(simulated noise {SIGMA_POINT * 1e6:.1f})"
    )
    print(
        f"half the points 20x noisier: model error on the accurate half, stated accuracies "
        f"{np.mean(weighted):.2f} um vs not stated {np.mean(unweighted):.2f} um rms per "
        "coordinate"
    )


if __name__ == "__main__":
    main()
