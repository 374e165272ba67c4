"""Write the example tracker exports of the README's walk-through into docs/examples/.

Each file is what a laser tracker's software exports after a campaign, simulated with
known truth (the world named in the file's description below) so that the README's
commands have something real to import:

- kr5_single_smr.csv: a KR5 sixx R650 with 2 mrad of joint-4 backlash, one SMR, the seed's
  Test 1 sweeps (120 poses) then 60 random poses; `;`, decimal commas, deg and mm.
- kr5_three_smr.csv: the same KR5 (no backlash) with three SMRs on a plate, Test 1 sweeps;
  `,`, deg and mm; the third SMR hidden at two poses (empty cells).
- ur10_probe.csv: a UR10 (nominal geometry + a few deviations of a few 0.1 mm / mrad)
  with a 6-DoF probe, 150 random poses; `;`, decimal commas, deg,
  mm, the quaternion w first, the tracker's stated standard deviations (um, mdeg) and the
  air temperature.
- kr5_references.csv: the KR5 with joint-4 backlash, one SMR, Test 1 sweeps then 60 random
  poses, 20 s apart (an hour), while the tracker's frame drifts (50 um/h and 20 urad/h
  about its vertical) and three reference reflectors on the floor are read with every pose
  (12.5 um per axis); a time column [s] and the tracker's stated 1-sigma per point [um].

    .venv/bin/python scripts/make_examples.py [--folder docs/examples]

The output is deterministic (fixed seeds): running it again rewrites identical files.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import paper_test_plan, random_plan
from robot_calib.sim.world import World, build_world

ROOT = Path(__file__).resolve().parents[1]
UR_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)


def write(
    path: Path, columns: dict[str, np.ndarray], sep: str, decimals: dict[str, int], comma: bool
) -> None:
    """A CSV as tracker software writes it; NaN: an empty cell."""
    lines = [sep.join(columns)]
    for k in range(len(next(iter(columns.values())))):
        cells = []
        for name, values in columns.items():
            value = values[k]
            text = "" if np.isnan(value) else f"{value:.{decimals.get(name, 6)}f}"
            cells.append(text.replace(".", ",") if comma else text)
        lines.append(sep.join(cells))
    path.write_text("\n".join(lines) + "\n")
    print(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}: {k + 1} rows")


def measure(world: World, q: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Points (n, T, 3) [m] and frames (n, T, 3, 3) or None of every target at readings q."""
    time = np.arange(len(q)) * 20.0  # s: one pose every 20 s
    poses, points = measure_every_target(world, q, time, np.random.default_rng(seed))
    n, t = len(q), len(world.model.targets)
    frames = None if poses.rotation is None else poses.rotation.reshape(n, t, 3, 3)
    return points.reshape(n, t, 3), frames


def single_smr(folder: Path) -> None:
    world = build_world({"seed": 11, "effects": [{"name": "backlash", "joints": [4]}]})
    robot = world.model.robot
    q = np.vstack([paper_test_plan(1).q, random_plan(robot, 60, np.random.default_rng(4)).q])
    points, _ = measure(world, q, seed=12)
    columns = {"Nr": np.arange(1.0, len(q) + 1)}
    columns |= {f"A{j + 1}": np.degrees(q[:, j]) for j in range(6)}
    columns |= {c: points[:, 0, k] * 1e3 for k, c in enumerate("XYZ")}
    write(folder / "kr5_single_smr.csv", columns, ";", {"Nr": 0, "X": 4, "Y": 4, "Z": 4}, True)


def three_smr(folder: Path) -> None:
    world = build_world(
        {"seed": 21, "targets": {"smr_b": [0.0, 0.08, 0.04], "smr_c": [-0.05, -0.05, 0.06]}}
    )
    q = paper_test_plan(1).q
    points, _ = measure(world, q, seed=22)
    points[[17, 64], 2] = np.nan  # smr_c out of the beam's sight at two poses
    columns = {f"J{j + 1}": np.degrees(q[:, j]) for j in range(6)}
    for t, suffix in enumerate(("A", "B", "C")):
        columns |= {f"{c}_{suffix}": points[:, t, k] * 1e3 for k, c in enumerate("XYZ")}
    write(
        folder / "kr5_three_smr.csv", columns, ",", {c: 4 for c in columns if c[0] != "J"}, False
    )


def probe(folder: Path) -> None:
    deviations = {
        "a2": 4.0e-4,
        "a3": -3.0e-4,
        "d4": 2.5e-4,
        "theta2": 6.0e-4,
        "theta3": -5.0e-4,
        "alpha3": 3.0e-4,
        "alpha4": -4.0e-4,
    }
    world = build_world(
        {
            "robot": "ur10",
            "seed": 31,
            "geometry": "nominal",
            "deviations": deviations,
            "six_dof": {"first": [20, 35, -30]},
            "target_in_flange_m": [0.05, 0.0, 0.12],
        }
    )
    q = random_plan(world.model.robot, 150, np.random.default_rng(32)).q
    points, frames = measure(world, q, seed=33)
    assert frames is not None
    quat = Rotation.from_matrix(frames[:, 0]).as_quat()  # x, y, z, w
    sigma_position = float(np.hypot(world.noise.tracker_sigma_m, world.noise.target_sigma_m))
    rng = np.random.default_rng(34)
    columns = {j: np.degrees(q[:, k]) for k, j in enumerate(UR_JOINTS)}
    columns |= {c: points[:, 0, k] * 1e3 for k, c in enumerate("XYZ")}
    columns |= {"Q0": quat[:, 3], "QX": quat[:, 0], "QY": quat[:, 1], "QZ": quat[:, 2]}
    columns["SP"] = sigma_position * 1e6 * rng.uniform(0.9, 1.1, len(q))  # um
    columns["SR"] = (
        np.degrees(world.noise.orientation_sigma_rad) * 1e3 * rng.uniform(0.9, 1.1, len(q))
    )  # mdeg
    columns["T"] = 21.0 + np.linspace(0.0, 0.8, len(q))  # deg C
    decimals = {"X": 4, "Y": 4, "Z": 4, "SP": 2, "SR": 3, "T": 2}
    decimals |= {c: 8 for c in ("Q0", "QX", "QY", "QZ")}
    write(folder / "ur10_probe.csv", columns, ";", decimals, True)


def references(folder: Path) -> None:
    world = build_world({"seed": 41, "effects": [{"name": "backlash", "joints": [4]}]})
    robot = world.model.robot
    q = np.vstack([paper_test_plan(1).q, random_plan(robot, 60, np.random.default_rng(42)).q])
    points, _ = measure(world, q, seed=43)
    time = np.arange(len(q)) * 20.0  # s, as `measure`
    hours = time / 3600.0
    rotation = Rotation.from_rotvec(np.outer(hours * 20e-6, [0.0, 0.0, 1.0]))
    shift = np.outer(hours * 50e-6, [0.6, 0.8, 0.0])
    rng = np.random.default_rng(44)
    fixed = {"R1": [1.2, 1.4, -0.9], "R2": [1.6, -1.1, -0.9], "R3": [2.6, 0.3, -0.4]}  # m
    columns = {"t": time} | {f"A{j + 1}": np.degrees(q[:, j]) for j in range(6)}
    drifted = rotation.apply(points[:, 0]) + shift
    columns |= {c: drifted[:, k] * 1e3 for k, c in enumerate("XYZ")}
    columns["U"] = rng.uniform(4.0, 8.0, len(q))  # um: the tracker's stated 1-sigma
    for name, xyz in fixed.items():
        read = rotation.apply(np.tile(xyz, (len(q), 1))) + shift
        read += rng.normal(0.0, 12.5e-6, read.shape)
        columns |= {f"{c}_{name}": read[:, k] * 1e3 for k, c in enumerate("XYZ")}
    decimals = {"t": 1, "U": 1} | {c: 4 for c in columns if c[0] in "XYZ"}
    write(folder / "kr5_references.csv", columns, ",", decimals, False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--folder", type=Path, default=ROOT / "docs" / "examples")
    args = parser.parse_args()
    args.folder.mkdir(parents=True, exist_ok=True)
    single_smr(args.folder)
    three_smr(args.folder)
    probe(args.folder)
    references(args.folder)


if __name__ == "__main__":
    main()
