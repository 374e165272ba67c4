"""The simulation flow: a world (the truth), a simulated recording of a plan in it and
the world file beside the bag (`robot-calib simulate`; `plan` and `run` use its world).

The recording itself is made by a `Recorder` the caller gives: the simulated robot, tracker
and recorder nodes run in-process (`robot_calib.nodes.simulate.simulate_bag`, what the
command line, the public API and the tests give), so that a simulated bag is recorded as a
real campaign's; this layer imports no node.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from robot_calib.atomic import output_path
from robot_calib.errors import InputError, param
from robot_calib.flows import DEFAULT_PLAN, DEFAULT_ROBOT, N_RANDOM_POSES, Progress

if TYPE_CHECKING:
    from robot_calib.sim.stream import StreamOptions
    from robot_calib.sim.world import World


class Recorder(Protocol):
    """Records `plan` (a name or a PLAN.yaml) in the world of the file `world` into the new
    bag `output`: its messages per topic (`robot_calib.nodes.simulate.simulate_bag`).
    `seed` -1: the world's own; `progress(done, total)` per pose."""

    def __call__(
        self,
        output: Path,
        plan: str,
        world: str | Path | None,
        seed: int,
        n_random: int,
        progress: Callable[[int, int], None] | None,
    ) -> dict[str, int]: ...


@dataclass(frozen=True)
class Simulation:
    """A simulated recording: the bag, its world file (the complete truth), messages per
    topic, the effects switched on (labels) and the wall time [s]."""

    bag: Path
    world_file: Path
    counts: dict[str, int]
    effects: tuple[str, ...]
    seconds: float


def simulation_world(
    world: str | Path | None = None,
    robot: str | None = DEFAULT_ROBOT,
    effects: Sequence[str] = (),
    seed: int | None = None,
) -> World:
    """The world of a world file (default: the built-in one; another robot without a file:
    its nominal geometry in the default set-up), with `effects` switched on (text form of
    `simulate --effects`, e.g. 'backlash:4', 'compliance:2=2e-5') and `seed` if given.
    `robot` None: the world's robot; a world file whose robot differs from `robot` is an
    InputError.

    Returns
    -------
    world : World
        The simulated truth: model (the robot with the effects), truth (every true
        parameter value, SI), noise, tracker options (latency, dropout), timing, seed.
    """
    from robot_calib.kinematics.loader import load_robot
    from robot_calib.sim.world import build_world, load_world, parse_sim_effect, with_effect

    if world is None and robot not in (None, DEFAULT_ROBOT):
        out = build_world({"robot": robot, "geometry": "nominal"}, param("robot", robot))
    else:
        out = load_world(world)
        wanted = None if robot is None else load_robot(robot)
        if wanted is not None and wanted.reference() != out.model.robot.reference():
            raise InputError(
                f"{out.source}: world robot {out.model.robot.reference()} differs from "
                f"{param('robot', robot)}; give one of them"
            )
    if seed is not None:
        out = replace(out, seed=seed)
    for spec in effects:
        effect, value = parse_sim_effect(spec, out.model.robot.n_joints)
        values = effect.default_values(out.model.robot)
        if value is not None:
            values = {k: value for k in values}
        out = with_effect(out, effect, values)
    return out


def simulate(
    output: str | Path,
    plan: str = DEFAULT_PLAN,
    world: World | None = None,
    seed: int | None = None,
    n_random: int = N_RANDOM_POSES,
    progress: Progress | None = None,
    force: bool = False,
    *,
    record: Recorder,
) -> Simulation:
    """Run the simulated graph (`record`: sim_robot, sim_tracker, recorder) over `plan`
    in `world` (default: `simulation_world()`) and record the bag `output` (in an existing
    folder; an existing bag or world file is replaced only with `force`, the world file
    read never) and its world file beside it. Both are written in a staging folder and
    moved in at the end: nothing is left on failure or Ctrl-C. A recording without a
    single tracker point is an InputError.

    Returns
    -------
    simulation : Simulation
        What was recorded, with the following fields:

        bag : Path
            The MCAP bag written (`output`).
        world_file : Path
            The world used (the complete truth), beside the bag: `<bag>.world.yaml`.
        counts : dict of str to int
            Messages recorded per topic.
        effects : tuple of str
            Labels of the effects switched on in `world`.
        seconds : float
            Wall time of the simulation [s].
    """
    from robot_calib.atomic import staged_outputs
    from robot_calib.messages import POINT_TOPIC
    from robot_calib.sim.world import save_world

    world = world if world is not None else simulation_world(seed=seed)
    bag, world_file = _simulation_outputs(output, plan, world, force)
    started = time.monotonic()
    with staged_outputs(bag.parent, force) as stage:
        save_world(world, stage / world_file.name)
        counts = record(
            stage / bag.name,
            plan,
            stage / world_file.name,
            -1 if seed is None else seed,
            n_random,
            None if progress is None else partial(progress, plan),
        )
        if not counts.get(POINT_TOPIC):
            raise InputError(
                f"{bag}: the simulation recorded no tracker point (dropout probability "
                f"{world.tracker.dropout_probability}); nothing written"
            )
    labels = tuple(e.label for e in world.effects)
    return Simulation(bag, world_file, counts, labels, time.monotonic() - started)


def simulation_inputs(world: World, plan: str | None = None) -> list[str]:
    """The files a simulation or a plan reads, which it may never overwrite: the world file,
    the robot's description file (YAML or URDF) and a PLAN.yaml."""
    from robot_calib.plan.plan_file import is_plan_file

    files = [world.source, world.model.robot.path.split("#", 1)[0]]
    if plan is not None and is_plan_file(plan):
        files.append(plan)
    return [f for f in files if f]


def simulate_stream(
    output: str | Path,
    plan: str = "random",
    world: World | None = None,
    seed: int | None = None,
    n_random: int = 20,
    options: StreamOptions | None = None,
    force: bool = False,
) -> Simulation:
    """A stream recording (continuous tracking, msgs_doc/stream.md) of a smooth move through
    the poses of `plan` in `world` (`sim.stream.simulate_stream`, no ROS graph), written as
    the bag `output` with its world file beside it (staged as `simulate`'s). The world file
    holds the truth of the robot; the stream's own truth (latency, rates) is `options`.

    Returns
    -------
    simulation : Simulation
        As `simulate`'s.
    """
    from robot_calib.atomic import staged_outputs
    from robot_calib.bag.write import write_stream_bag
    from robot_calib.sim.plans import make_plan
    from robot_calib.sim.stream import StreamOptions, simulate_stream
    from robot_calib.sim.world import save_world

    world = world if world is not None else simulation_world(seed=seed)
    bag, world_file = _simulation_outputs(output, plan, world, force)
    started = time.monotonic()
    rng = np.random.default_rng(world.seed if seed is None else seed)
    model = world.model
    waypoints = make_plan(plan, model, model.parameters(), rng, n_random).q
    sim = simulate_stream(world, waypoints, options or StreamOptions(), rng)
    with staged_outputs(bag.parent, force) as stage:
        save_world(world, stage / world_file.name)
        s = sim.stream
        counts = write_stream_bag(
            stage / bag.name,
            s.js_ns,
            s.q,
            sim.velocity,
            s.point_ns,
            s.points,
            model.robot.joint_names,
            force=True,
        )
    labels = tuple(e.label for e in world.effects)
    return Simulation(bag, world_file, counts, labels, time.monotonic() - started)


def _simulation_outputs(
    output: str | Path, plan: str, world: World, force: bool
) -> tuple[Path, Path]:
    """The bag and world file paths of a simulation (`output_path`'s policy), after
    checking `plan` against the world's robot."""
    from robot_calib.sim.plans import check_plan

    check_plan(plan, world.model.robot)
    inputs = simulation_inputs(world, plan)
    bag = output_path(output, "the bag", inputs, force)
    world_file = output_path(bag.with_suffix(".world.yaml"), "the world file", inputs, force)
    return bag, world_file
