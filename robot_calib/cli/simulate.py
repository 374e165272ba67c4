"""`robot-calib simulate`: a measurement plan simulated in a world and recorded as an MCAP
bag, with the world's truth beside it (flows/simulate.py)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

import numpy as np

from robot_calib.cli.common import log, progress
from robot_calib.cli.options import (
    WORLD_ROBOT,
    add_force,
    add_output,
    count,
    positive,
    rate,
    signed_seconds,
)
from robot_calib.flows import DEFAULT_PLAN, N_RANDOM_POSES

if TYPE_CHECKING:
    from robot_calib.sim.world import World

NAME = "simulate"
HELP = "simulate a measurement plan and record an MCAP bag"
ROBOT = WORLD_ROBOT  # --robot's default, in words


def add_arguments(sim: argparse.ArgumentParser) -> None:
    sim.add_argument(
        "--plan",
        default=DEFAULT_PLAN,
        help=f"paper-test1..6 (seed Table 2), random, iso9283, or a PLAN.yaml file "
        f"(robot-calib plan) (default {DEFAULT_PLAN})",
    )
    sim.add_argument("--world", help="world YAML file (default: the built-in default world)")
    sim.add_argument(
        "--effects",
        nargs="*",
        metavar="EFFECT",
        help="effects to switch on, e.g. backlash:4 eccentricity:1,2 "
        "thermal_drift compliance:2=2e-5 (default magnitudes unless =VALUE)",
    )
    sim.add_argument(
        "--seed", type=count, help="random seed of noise and plan (>= 0; default: the world's)"
    )
    sim.add_argument(
        "--n-random",
        type=positive,
        default=N_RANDOM_POSES,
        help=f"poses of the random plan (default {N_RANDOM_POSES})",
    )
    sim.add_argument(
        "--stream",
        action="store_true",
        help="continuous tracking (msgs_doc/stream.md): move smoothly through the plan's poses "
        "(default plan then: random) while joint states and points stream at their rates, "
        "no ROS graph (default: off, stop-and-go through the simulated graph)",
    )
    for flag, what, default in (
        ("--joint-rate", "joint states", 200.0),
        ("--point-rate", "tracker points", 1000.0),
    ):
        sim.add_argument(
            flag,
            type=rate,
            default=default,
            help=f"with --stream: {what} per second [Hz] (default {default:g})",
        )
    sim.add_argument(
        "--latency",
        dest="sim_latency",
        type=signed_seconds,
        default=0.002,
        metavar="SECONDS",
        help="with --stream: the controller's stamps minus the tracker's for one instant [s] "
        "(default 0.002)",
    )
    add_output(sim, "bag to write (BAG.mcap; + BAG.world.yaml)")
    add_force(sim)


def main(args: argparse.Namespace) -> int:
    """Simulate a plan in a world and record the bag (+ the world's truth beside it)."""
    from robot_calib.flows import simulate as flow

    world = flow.simulation_world(args.world, args.robot, args.effects or (), args.seed)
    plan = args.plan
    if args.stream:
        from robot_calib.sim.stream import StreamOptions

        options = StreamOptions(args.joint_rate, args.point_rate, args.sim_latency)
        plan = "random" if plan == DEFAULT_PLAN else plan
        sim = flow.simulate_stream(
            args.output, plan, world, args.seed, args.n_random, options, args.force
        )
    else:
        from robot_calib.nodes.simulate import simulate_bag

        sim = flow.simulate(
            args.output,
            args.plan,
            world,
            args.seed,
            args.n_random,
            progress(),
            args.force,
            record=simulate_bag,
        )
    print(
        f"{sim.bag}: {', '.join(f'{t}={n}' for t, n in sim.counts.items())} messages "
        f"({plan}{', stream' if args.stream else ''}, effects: "
        f"{', '.join(sim.effects) or 'none'}{_tracker_line(world)}) in {sim.seconds:.1f} s; "
        f"truth in {sim.world_file}"
    )
    poses = sim.counts.get("/joint_states", 0)
    for event in world.events:
        if event.last >= poses:
            log(
                f"warning: {world.source}: the {event.kind} event at poses {event.first}-"
                f"{event.last}: the recording has {poses} poses, so "
                + (
                    "it never happened"
                    if event.first >= poses
                    else f"only poses {event.first}-{poses - 1} of it happened"
                )
            )
    return 0


def _tracker_line(world: World) -> str:
    """'; tracker: 3 reads per pose, 3 reference reflectors, drift 50.0 um/h, 2 events'
    (what the world's tracker does beyond measuring; '' when nothing)."""
    tracker = world.tracker
    parts = []
    if tracker.reads_per_pose > 1:
        parts.append(f"{tracker.reads_per_pose} reads per pose")
    if world.references:
        parts.append(f"{len(world.references)} reference reflector(s)")
    if tracker.drifts:
        rate = float(np.linalg.norm(tracker.drift_m_per_s)) * 3.6e9
        turn = float(np.linalg.norm(tracker.drift_rad_per_s)) * 3.6e9
        parts.append(f"drift {rate:.1f} um/h, {turn:.1f} urad/h")
    if world.noise.point_sigma_range_m[1] > 0:
        low, high = (v * 1e6 for v in world.noise.point_sigma_range_m)
        parts.append(f"each point's accuracy {low:g}-{high:g} um, stated")
    if world.events:
        parts.append(f"{len(world.events)} event(s)")
    return f"; tracker: {', '.join(parts)}" if parts else ""
