"""The FANUC-like campaign over several seeds (`robot_calib.sim.scenarios`): raw
coupled readings, three SMRs 0.34 m out (one on the J6 axis), 6-pose sweeps with 144 deg
steps on J4/J6. Prints, per model, in-sample and held-out rms over the simulated noise
(the floor no model can beat), the worst a3 error, and the same for the 288 deg-step
subset of the wrist sweeps.

    .venv/bin/python scripts/fanuc_acceptance.py --seeds 10
"""

from __future__ import annotations

import argparse

import numpy as np

from robot_calib.accuracy import accuracy
from robot_calib.identify.calibrate import calibrate
from robot_calib.model import absorb_base_offsets
from robot_calib.sim.scenarios import fanuc_like, noise_rms_mm, wrist_288_subset


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args()
    rows: dict[str, list[tuple[float, float, float]]] = {}
    for seed in range(args.seeds):
        scenario = fanuc_like(seed)
        world, held = scenario.world, scenario.holdout
        truth = absorb_base_offsets(world.model.robot, world.truth)
        for label, recording in (
            ("", scenario.calibration),
            (" (288 deg wrist steps)", wrist_288_subset(scenario.calibration)),
        ):
            for model in ("cpa", "geometric"):
                cal = calibrate(recording, world.model.robot, model)
                out = accuracy(held.points, cal.model.target_points(cal.parameters, held.poses))
                rows.setdefault(model + label, []).append(
                    (
                        cal.accuracy.absolute_rms_mm / noise_rms_mm(world, recording),
                        out.absolute_rms_mm / noise_rms_mm(world, held),
                        abs(cal.parameters["a3"] - truth["a3"]) * 1e6,
                    )
                )
    print(f"FANUC-like campaign, {args.seeds} seeds (rms / simulated noise rms; worst of seeds)")
    print(f"{'model':36s} {'in-sample':>10s} {'held-out':>10s} {'|a3 err| um':>12s}")
    for name, values in rows.items():
        v = np.array(values)
        print(f"{name:36s} {v[:, 0].max():10.3f} {v[:, 1].max():10.3f} {v[:, 2].max():12.1f}")


if __name__ == "__main__":
    main()
