"""`robot-calib plan`: N measurement poses chosen for a model (D-optimal), what they promise
against random poses at equal N, written as PLAN.yaml (robot_calib/plan/)."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

import numpy as np

from robot_calib.cli.common import log
from robot_calib.cli.options import (
    WORLD_ROBOT,
    add_force,
    add_output,
    bounded_count,
    count,
    positive,
)
from robot_calib.errors import InputError
from robot_calib.identify import DEFAULT_ECC_ORDER, DEFAULT_MODEL
from robot_calib.kinematics.frames import Array
from robot_calib.measurements.aliasing import MAX_ORDER

if TYPE_CHECKING:
    from robot_calib.sim.world import World

NAME = "plan"
HELP = "choose measurement poses for a model (D-optimal) -> PLAN.yaml"
ROBOT = WORLD_ROBOT  # --robot's default, in words

MAX_FLOOR_Z_M = 10.0  # --floor-z: no robot reaches a floor 10 m from its base (mm as m?)
MAX_CANDIDATES = 100_000  # --candidates: ~1.5 GB of Jacobian rows for geometric
# the defaults of the D-optimal options (as plan.campaign's, which this light module does
# not import at start-up)
CANDIDATES, TRIALS, HOLDOUT = 2000, 1, 200


def add_arguments(pla: argparse.ArgumentParser) -> None:
    pla.add_argument(
        "--model",
        default=DEFAULT_MODEL,
        help=f"geometric[+EFFECT[:joints]...] to plan for (default {DEFAULT_MODEL})",
    )
    pla.add_argument(
        "--poses", type=positive, help="N: poses to plan (D-optimal; required unless --sweeps)"
    )
    pla.add_argument(
        "--sweeps",
        metavar="paper-testN",
        help="instead of --poses: the seed's circle sweeps of Table 2 test N (1-6) in "
        "irregular steps, so that the sweeps alone tell joint-angle harmonic orders up to "
        "--max-order apart (regular steps alias them; default: none, D-optimal --poses)",
    )
    pla.add_argument(
        "--max-order",
        type=positive,
        default=MAX_ORDER,
        help=f"with --sweeps: the highest harmonic order to tell apart (default {MAX_ORDER})",
    )
    pla.add_argument(
        "--candidates",
        type=bounded_count(MAX_CANDIDATES),
        default=CANDIDATES,
        help=f"M: random candidate poses to choose from (default 2000, at most {MAX_CANDIDATES})",
    )
    pla.add_argument(
        "--floor-z",
        type=float,
        default=0.0,
        metavar="M",
        help="flange and target stay at or above z = M [m] of the robot base frame "
        "(default 0.0: the base's mounting plane; --floor-z=-inf: no floor; within "
        f"+-{MAX_FLOOR_Z_M:g})",
    )
    pla.add_argument(
        "--noise-mm",
        type=float,
        metavar="MM",
        help="tracker noise, 1-sigma per coordinate [mm] (default: the world's "
        "tracker, target and repeatability noise)",
    )
    pla.add_argument(
        "--world",
        help="world YAML file: robot, tracker pose, target, noise "
        "(default: the built-in default world)",
    )
    pla.add_argument(
        "--seed",
        type=count,
        default=0,
        help="random seed of candidates and simulations (default 0)",
    )
    pla.add_argument(
        "--trials",
        type=count,
        default=TRIALS,
        help="simulated calibrations (random true robots) per plan for the "
        "held-out error (default 1; 0: none)",
    )
    pla.add_argument(
        "--holdout",
        type=positive,
        default=HOLDOUT,
        help="random held-out poses per simulated calibration (default 200)",
    )
    pla.add_argument(
        "--ecc-order",
        type=positive,
        default=DEFAULT_ECC_ORDER,
        help=f"eccentricity Fourier order (default {DEFAULT_ECC_ORDER})",
    )
    add_output(pla, "PLAN.yaml to write")
    add_force(pla)


def resolved_orders_line(q: Array, label: str = "the plan") -> str:
    """'joint-angle harmonics the plan resolves per joint (...): joint 1 up to order 29 (29
    together), joint 2 up to order 32 (14 together; orders 1 apart alike on its 157 deg
    arc), ...': per joint of readings q (n, J) [rad], the highest order below which its
    readings alias none (`measurements.aliasing`), how many orders its distinct readings
    fit together (`orders_at_once`) and, on a partial turn, how far apart orders may be
    that its arc itself makes alike (`OrderSimilarity.overlap`)."""
    from robot_calib.measurements.aliasing import (
        distinct_readings,
        order_similarity,
        orders_at_once,
    )

    parts = []
    for j in range(q.shape[1]):
        similarity = order_similarity(q[:, j])
        overlap = similarity.overlap()
        arc = np.degrees(np.ptp(distinct_readings(q[:, j])))
        alike = f"; orders {overlap} apart alike on its {arc:.0f} deg arc" if overlap else ""
        parts.append(
            f"joint {j + 1} up to order {similarity.resolvable()} "
            f"({orders_at_once(q[:, j])} together{alike})"
        )
    return (
        f"joint-angle harmonics {label} resolves per joint (the highest order its readings "
        "never alias with another; in brackets, how many orders its distinct readings can "
        f"fit together): {', '.join(parts)}"
    )


def sweeps_main(args: argparse.Namespace) -> int:
    """`plan --sweeps paper-testN`: the seed's sweeps in irregular steps (`plan.sweeps`),
    what they and the seed's regular steps tell apart, written as PLAN.yaml."""
    from robot_calib.atomic import output_path, write_text_atomic
    from robot_calib.flows.simulate import simulation_inputs, simulation_world
    from robot_calib.plan.plan_file import plan_text
    from robot_calib.plan.sweeps import DESIGN_TRIALS, irregular_sweeps
    from robot_calib.sim.plans import paper_test_number, paper_test_plan

    name = args.sweeps
    optimal_only = {
        "--model": (args.model, DEFAULT_MODEL),
        "--noise-mm": (args.noise_mm, None),
        "--candidates": (args.candidates, CANDIDATES),
        "--trials": (args.trials, TRIALS),
        "--holdout": (args.holdout, HOLDOUT),
        "--ecc-order": (args.ecc_order, DEFAULT_ECC_ORDER),
    }
    given = [flag for flag, (value, default) in optimal_only.items() if value != default]
    if given:
        raise InputError(
            f"--sweeps {name}: {', '.join(given)} belong to D-optimal poses "
            "(--poses), not to the seed's sweeps"
        )
    try:
        test = paper_test_number(name)
    except InputError as exc:
        raise InputError(f"--sweeps {exc}") from None
    world = simulation_world(args.world, args.robot, (), args.seed)
    robot = world.model.robot
    output = output_path(args.output, "PLAN.yaml", simulation_inputs(world), args.force)
    if output.suffix.lower() not in (".yaml", ".yml"):  # after the input check: never an input
        raise InputError(f"{output}: a plan is written as YAML: give a .yaml or .yml name")
    plan = irregular_sweeps(test, args.max_order, args.seed)
    regular = paper_test_plan(test)
    q = robot.readings(plan.q)
    robot.check_joints(q, f"--sweeps {name} on {robot.name}")
    floor = _below_floor(world, q, args.floor_z)
    print(resolved_orders_line(robot.readings(regular.q), f"{name} in regular steps"))
    print(resolved_orders_line(q, f"{name} in irregular steps"))
    design = {
        "criterion": f"the seed's {name} sweeps (same start, end and points per pass) in "
        "irregular steps: the forward pass's inner readings jittered, the way back between "
        f"them; the draw of {DESIGN_TRIALS} that tells the most harmonic orders apart",
        "max_order": int(args.max_order),
        "seed": int(args.seed),
        "floor_z_m": float(args.floor_z),
    }
    if floor:
        print(f"warning: {floor}")
        design["warning"] = floor
    write_text_atomic(output, plan_text(robot, "cpa", q, plan.speed_fraction, design, {}))
    print(
        f"{output}: {len(q)} poses, {len(set(plan.sweep.tolist()))} circle sweeps "
        "(msgs_doc/plan.md)"
    )
    return 0


def _below_floor(world: World, q: Array, floor_z_m: float) -> str:
    """'' when every pose of readings q (n, J) [rad] keeps the joint centres, flange and
    target at or above z = floor_z_m [m] of the robot base (nominal geometry), else how many
    do not and how low they go (the seed's sweeps are fixed: they are not moved up)."""
    from robot_calib.plan.design import FLOOR_SLACK_M, clearance_z

    lowest = clearance_z(world.model, world.model.parameters(), q).min(axis=1)
    below = lowest < floor_z_m - FLOOR_SLACK_M
    if not below.any():
        return ""
    return (
        f"{int(below.sum())} of {len(q)} poses put a joint centre, the flange or the "
        f"target below z = {floor_z_m:g} m of the robot base (lowest {lowest.min():.3f} m): "
        "the seed's sweeps assume a robot on a pedestal; check the clearance before "
        "running them (--floor-z sets the plane checked)"
    )


def main(args: argparse.Namespace) -> int:
    """Plan N measurement poses for a model (D-optimal), print what they promise against
    random poses at equal N, write PLAN.yaml."""
    from robot_calib.atomic import output_path, write_text_atomic
    from robot_calib.flows.simulate import simulation_inputs, simulation_world
    from robot_calib.plan.campaign import campaign_yaml, plan_campaign
    from robot_calib.plan.evaluate import human

    if (args.poses is None) == (args.sweeps is None):
        raise InputError(
            "give either --poses N (D-optimal poses) or --sweeps paper-testN "
            "(the seed's sweeps in irregular steps)"
        )
    if args.sweeps is not None:
        return sweeps_main(args)
    if args.max_order != MAX_ORDER:
        raise InputError(
            "--max-order belongs to --sweeps (D-optimal poses resolve what "
            "their random readings do)"
        )
    noise = args.noise_mm
    if noise is not None and not (math.isfinite(noise) and 0 < noise < 10):
        raise InputError(f"--noise-mm {noise}: a 1-sigma per coordinate in mm, > 0 and < 10")
    floor = args.floor_z
    if math.isnan(floor) or (math.isfinite(floor) and abs(floor) > MAX_FLOOR_Z_M):
        raise InputError(
            f"--floor-z {floor:g}: a height in m of the robot base frame within "
            f"+-{MAX_FLOOR_Z_M:g} m (or -inf: no floor); mm given as m? ({floor:g} mm = "
            f"{floor * 1e-3:g} m)"
        )
    world = simulation_world(args.world, args.robot, (), args.seed)
    output = output_path(args.output, "PLAN.yaml", simulation_inputs(world), args.force)
    if output.suffix.lower() not in (".yaml", ".yml"):  # after the input check: never an input
        raise InputError(f"{output}: a plan is written as YAML: give a .yaml or .yml name")
    c = plan_campaign(
        world,
        args.model,
        args.poses,
        args.candidates,
        args.seed,
        args.floor_z,
        None if noise is None else noise * 1e-3,
        args.ecc_order,
        args.trials,
        args.holdout,
        log,
    )
    planned, rand = c.planned.prediction, c.random.prediction
    print(
        f"{args.model} on {world.model.robot.name}: {args.poses} poses of "
        f"{len(c.problem.candidates)} candidates in {c.design_seconds:.2f} s; noise "
        f"{planned.noise_m * 1e3:.4f} mm per coordinate; predicted 1-sigma:"
    )
    print(f"{'parameter':<22}{'planned':>34}{'random (same N)':>34}")
    for k, name in enumerate(planned.names):
        unit = planned.units[k]
        print(
            f"{name:<22}{human(float(planned.std[k]), unit):>34}"
            f"{human(float(rand.std[k]), unit):>34}"
        )
    for name, reason in c.problem.fixed:
        print(f"{name:<22} fixed: {reason}")
    for label, fig in (("planned", c.planned), ("random", c.random)):
        pred = fig.prediction
        held = (
            "not simulated"
            if fig.holdout is None
            else (
                f"{fig.holdout.abs_rms_mm:.4f} mm abs rms, seed criterion mean "
                f"{fig.holdout.pairwise_mean_mm:.4f} mm, model error (vs the true points) "
                f"{fig.holdout.model_rms_mm:.4f} mm rms ({fig.holdout.trials} random true "
                f"robot(s), {fig.holdout.n_poses} held-out poses)"
            )
        )
        print(
            f"{label}: worst {pred.line(pred.worst)}; held-out {held}; campaign "
            f"{fig.hours * 60:.1f} min"
        )
    ratio = rand.rms_m.max() / planned.rms_m.max()
    print(f"worst predicted 1-sigma: {ratio:.2f} x smaller than random poses at equal N")
    print(resolved_orders_line(c.planned.plan.q))
    write_text_atomic(output, campaign_yaml(c, args.floor_z))
    print(f"{output}: {args.poses} poses (msgs_doc/plan.md)")
    return 0
