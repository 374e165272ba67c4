"""Measurement plans: which joint readings the robot visits, in which order, how fast.

- `paper-test1` .. `paper-test6`: the seed's Table 2. Each joint in turn sweeps from Start
  to End in `points` steps and back (forth and back = the "measured points" row:
  120/580/290/290/290/290), the other joints at the home pose. The angles are DH joint
  variables; `make_plan` turns them into the robot's readings (the same numbers unless the
  robot declares a reading-to-joint mapping).
- `random`: general poses uniform within the joint limits.
- `iso9283`: the ISO 9283 cube positions P1..P5 (centre and four points on the diagonal
  plane, 10 % of the diagonal in from the corners), visited in cycles.
- a PLAN.yaml file (`robot-calib plan`, msgs_doc/plan.md): its poses in the order listed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from robot_calib.errors import InputError, param
from robot_calib.ik import solve_ik
from robot_calib.kinematics.description import (
    HOME_DEG,
    RobotDescription,
    random_readings,
)
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel
from robot_calib.plan.plan_file import is_plan_file, load_plan
from robot_calib.poses import Poses
from robot_calib.sim.world import Timing

# Seed Table 2: per test, per joint (start, end) [deg] and points; and % of max speed.
#: the joints' (start, end) [deg] of Tests 1-3 (whole ranges) and of Tests 4-6 (reduced)
WHOLE_RANGES = ((167, -167), (-5, -162), (145, -114), (177, -177), (90, -90), (178, -178))
REDUCED_RANGES = ((80, -80), (-40, -120), (80, -50), (90, -90), (45, -45), (90, -90))


def _sweeps(
    ranges: tuple[tuple[int, int], ...], points: tuple[int, ...]
) -> list[tuple[float, float, int]]:
    """Table 2's row of one test: each joint's (start, end) [deg] and its points."""
    return [(start, end, n) for (start, end), n in zip(ranges, points)]


HALF_POINTS = (30, 15, 25, 30, 15, 30)  # Tests 3-6
PAPER_TESTS: dict[int, tuple[list[tuple[float, float, int]], float]] = {
    1: (_sweeps(WHOLE_RANGES, (10,) * 6), 0.03),
    2: (_sweeps(WHOLE_RANGES, (60, 30, 50, 60, 30, 60)), 0.03),
    3: (_sweeps(WHOLE_RANGES, HALF_POINTS), 0.03),
    4: (_sweeps(REDUCED_RANGES, HALF_POINTS), 0.01),
    5: (_sweeps(REDUCED_RANGES, HALF_POINTS), 0.03),
    6: (_sweeps(REDUCED_RANGES, HALF_POINTS), 0.10),
}

PLAN_NAMES = (*(f"paper-test{k}" for k in PAPER_TESTS), "random", "iso9283")


@dataclass(frozen=True)
class Plan:
    """Joint readings to visit in order.

    q : shape (n, J) [rad]; sweep : shape (n,), the 1-based joint a circle sweep turns
    (0 = general pose); speed_fraction : fraction of each joint's max speed [1].
    """

    name: str
    q: Array
    sweep: Array
    speed_fraction: float

    def __len__(self) -> int:
        return int(self.q.shape[0])


def paper_test_number(name: str) -> int:
    """N of a plan name 'paper-testN' (1-6, the seed's Table 2); InputError otherwise."""
    test = name[len("paper-test") :] if name.startswith("paper-test") else ""
    if not test.isdigit() or int(test) not in PAPER_TESTS:
        raise InputError(f"{name}: not one of paper-test1 .. paper-test6 (the seed's Table 2)")
    return int(test)


def sweep_plan(
    name: str,
    test: int,
    angles: Callable[[int, float, float, int], Array],
    home_deg: tuple[float, ...] = HOME_DEG,
) -> Plan:
    """Table 2 test `test`'s single-joint sweeps, each joint in turn through the readings
    `angles(joint, start, end, points)` ((m,) [deg], in visiting order) of its row, the other
    joints at `home_deg`; the plan `name` of joint variables [rad], rows labelled with the
    joint they sweep, at the test's speed."""
    sweeps, speed = PAPER_TESTS[test]
    rows, labels = [], []
    for j, (start, end, points) in enumerate(sweeps, start=1):
        for angle in angles(j, start, end, points):
            q = np.array(home_deg, dtype=float)
            q[j - 1] = angle
            rows.append(q)
            labels.append(j)
    return Plan(name, np.radians(rows), np.array(labels), speed)


def paper_test_plan(test: int, home_deg: tuple[float, ...] = HOME_DEG) -> Plan:
    """The seed's Table 2 test `test` (1-6) for a 6-joint robot: each sweep `points` regular
    steps from Start to End and back over the same readings."""
    if test not in PAPER_TESTS:
        raise InputError(f"paper-test{test}: the seed's Table 2 has tests 1-6")

    def forth_and_back(_joint: int, start: float, end: float, points: int) -> Array:
        forth = np.linspace(start, end, points)
        return np.concatenate([forth, forth[::-1]])

    return sweep_plan(f"paper-test{test}", test, forth_and_back, home_deg)


def random_plan(
    robot: RobotDescription,
    n: int,
    rng: np.random.Generator,
    margin: float = 0.05,
    speed_fraction: float = 0.1,
) -> Plan:
    """`n` general poses uniform in the joint limits shrunk by `margin` of each range."""
    q = random_readings(robot, n, rng, margin)
    return Plan("random", q, np.zeros(n, dtype=int), speed_fraction)


def inverse_kinematics(
    model: KinematicModel,
    params: ParameterVector,
    goal2base: Array,
    q_seed: Array,
    iterations: int = 50,
) -> Array:
    """Readings (J,) [rad] that put the flange at `goal2base` (4, 4), position and
    orientation, from `q_seed` (J,) (`ik.solve_ik`, one pose); raises InputError if it
    fails."""
    found = solve_ik(
        model,
        params,
        Poses.from_readings(np.asarray(q_seed, dtype=float)[None]),
        goal2base[None],
        np.eye(4),
        tolerance_m=1e-12,
        max_iterations=iterations,
    )
    if not found.converged[0]:
        raise InputError("inverse kinematics did not converge (goal out of reach?)")
    return found.q[0]


def iso9283_plan(
    model: KinematicModel,
    params: ParameterVector,
    cycles: int = 10,
    side_m: float = 0.2,
    home_deg: tuple[float, ...] = HOME_DEG,
) -> Plan:
    """ISO 9283 cube test: P1 (centre) then P2..P5 on the cube's diagonal plane, `cycles`
    times P1 -> P2 -> P3 -> P4 -> P5, flange orientation of the home pose throughout.
    The cube (edge `side_m`) is centred on the home pose's flange."""
    home_q = model.robot.readings(np.radians(home_deg)[None, :])[0]  # home_deg: variables
    home = model.flange2base(params, Poses.from_readings(home_q[None, :]))[0]
    half = side_m / 2
    # Diagonal plane through cube corners C1 (-,-,-), C2 (+,+,-), C7 (+,+,+), C8 (-,-,+):
    # points 10 % of the diagonal in from each corner (0.8 of the half-diagonal offsets).
    corners = np.array([[1, 1, -1], [1, 1, 1], [-1, -1, 1], [-1, -1, -1]]) * half * 0.8
    offsets = np.vstack([np.zeros(3), corners])
    qs = []
    for offset in offsets:
        goal = home.copy()
        goal[:3, 3] += offset
        qs.append(inverse_kinematics(model, params, goal, home_q))
    q = np.tile(np.array(qs), (cycles, 1))
    return Plan("iso9283", q, np.zeros(len(q), dtype=int), 0.1)


def check_plan(name: str, robot: RobotDescription) -> None:
    """InputError unless `name` is a built-in plan (PLAN_NAMES) or a PLAN.yaml file valid
    for `robot` (read and checked whole: `load_plan`)."""
    if is_plan_file(name):
        load_plan(name, robot)
    elif name not in PLAN_NAMES:
        raise InputError(
            f"{param('plan', name)}: unknown plan (known: {', '.join(PLAN_NAMES)}, or a "
            "PLAN.yaml file)"
        )


def make_plan(
    name: str,
    model: KinematicModel,
    params: ParameterVector,
    rng: np.random.Generator,
    n_random: int = 200,
) -> Plan:
    """A plan by name (PLAN_NAMES) or a PLAN.yaml file's (`load_plan`: its poses in the
    order listed); `params` are the controller's (nominal) parameters."""
    if is_plan_file(name):
        planned = load_plan(name, model.robot)
        return Plan(name, planned.q, np.zeros(len(planned.q), dtype=int), planned.speed_fraction)
    if name.startswith("paper-test") and name[10:].isdigit():
        plan = paper_test_plan(paper_test_number(name))
        # Table 2's angles are joint variables: single-joint sweeps of the DH joints, which
        # a robot with coupled readings (reading_to_joint) reads as two readings changing.
        return replace(plan, q=model.robot.readings(plan.q))
    if name == "random":
        return random_plan(model.robot, n_random, rng)
    if name == "iso9283":
        return iso9283_plan(model, params)
    raise InputError(
        f"unknown plan {name!r} (known: {', '.join(PLAN_NAMES)}, or a PLAN.yaml file)"
    )


def step_seconds(q_from: Array, q_to: Array, timing: Timing, speed_fraction: float) -> Array:
    """Time from measuring at readings q_from to measuring at q_to [s], shape (n,), for
    readings (n, J) or (J,) [rad] each (broadcast): a joint-interpolated move at
    `speed_fraction` of each joint's max speed, plus acceleration, settling and measurement."""
    q_from, q_to = np.atleast_2d(q_from), np.atleast_2d(q_to)
    speed = timing.speeds(q_to.shape[1]) * speed_fraction
    move = np.max(np.abs(q_to - q_from) / speed, axis=1)
    return move + timing.accel_overhead_s + timing.settle_s + timing.measure_s


def plan_times(plan: Plan, timing: Timing) -> Array:
    """Measurement time of every pose since the first [s], shape (n,): `step_seconds` from
    each pose to the next."""
    step = step_seconds(plan.q[:-1], plan.q[1:], timing, plan.speed_fraction)
    return np.concatenate([[0.0], np.cumsum(step)])
