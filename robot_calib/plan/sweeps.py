"""The seed's circle sweeps in irregular steps: every joint-angle harmonic order up to
MAX_ORDER told apart by the sweeps alone.

The seed's Table 2 sweeps each joint from Start to End in `points` regular steps and back
over the same readings. Regular steps alias orders (`measurements.aliasing`): a full turn
in 60 steps of 6 deg cannot tell order 23 from 37, 30 steps over 157 deg not 23 from 43.
Here each joint keeps its Start, End and number of points per pass, but the forward pass's
inner readings are shifted by up to JITTER_STEPS of a step, and the way back reads End
again (the turn-around re-read of a still pose, as in the seed's sweeps: the tracker's own
noise) and then measures between the forward readings (half a step on, up to
BACK_JITTER_STEPS either way): twice the distinct readings, and no regular grid to alias
on. DESIGN_TRIALS seeded draws per joint; the draw kept is the one that tells the most
orders apart (`resolvable_order`), then the one whose most alike pair of orders is least
alike. The harmonic's order is then told apart up to MAX_ORDER on every joint of the
seed's Test 1-6; how many orders can be fitted together still depends on the number of
distinct readings (`orders_at_once`).
"""

from __future__ import annotations

import numpy as np

from robot_calib.errors import InputError, param
from robot_calib.kinematics.frames import Array
from robot_calib.measurements.aliasing import MAX_ORDER, order_similarity
from robot_calib.sim.plans import HOME_DEG, Plan, sweep_plan

DESIGN_TRIALS = 40
JITTER_STEPS = 0.3  # forward pass: inner readings moved by up to this share of a step
BACK_JITTER_STEPS = 0.2  # way back: midpoints moved by up to this share of a step
GOOD_ENOUGH = 0.5  # a draw whose most alike pair of orders correlates below this is kept


def sweep_readings(
    start: float, end: float, points: int, max_order: int, rng: np.random.Generator
) -> Array:
    """One joint's readings [deg] in visiting order, forth then back (2 `points`), from
    `start` to `end` [deg], End read again, then back between the forward readings,
    resolving orders up to `max_order` if any of DESIGN_TRIALS draws does (module
    docstring)."""
    regular = np.linspace(start, end, points)
    step = (end - start) / max(points - 1, 1)
    best: tuple[int, float, Array] | None = None
    for _ in range(DESIGN_TRIALS):
        forth = regular.copy()
        forth[1:-1] += rng.uniform(-JITTER_STEPS, JITTER_STEPS, points - 2) * step
        between = rng.uniform(-BACK_JITTER_STEPS, BACK_JITTER_STEPS, points - 1)
        back = regular[:-1] + step * (0.5 + between)
        q = np.concatenate([forth, [end], back[::-1]])
        similarity = order_similarity(np.radians(q), max_order)
        found = (similarity.resolvable(), float(similarity.on_readings.max()), q)
        if best is None or (found[0], -found[1]) > (best[0], -best[1]):
            best = found
        if found[0] >= max_order and found[1] < GOOD_ENOUGH:
            break  # every order told apart with room to spare
    assert best is not None
    return best[2]


def irregular_sweeps(
    test: int, max_order: int = MAX_ORDER, seed: int = 0, home_deg: tuple[float, ...] = HOME_DEG
) -> Plan:
    """The seed's Table 2 test `test` (1-6) in irregular steps (module docstring): joint
    variables q (n, J) [rad] (a robot's readings: `RobotDescription.readings`), each row
    labelled with the joint it sweeps, at the test's speed."""
    if not 1 <= max_order <= MAX_ORDER:
        raise InputError(f"{param('max_order', max_order)}: an order from 1 to {MAX_ORDER}")
    rng = np.random.default_rng(seed)

    def readings(_joint: int, start: float, end: float, points: int) -> Array:
        return sweep_readings(start, end, points, max_order, rng)

    return sweep_plan(f"paper-test{test}-irregular", test, readings, home_deg)
