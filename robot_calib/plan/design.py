"""D-optimal capture plans: N poses out of M candidates that pin a model's parameters best.

The information a pose adds is J_i^T J_i, J_i (3, p) the derivatives of its measured point
with respect to the p free parameters; the covariance of a calibration is
sigma^2 (sum J_i^T J_i)^-1. A D-optimal plan maximises log det of the information
matrix, i.e. minimises the volume of the parameters' confidence ellipsoid. Columns are
scaled to unit rms over the candidates (metres and radians compare; the D choice does not
depend on the scaling, its numerics do).

- Candidates: readings uniform within the joint limits (shrunk by 5 % of each range, as
  the `random` plan) whose joint centres (the DH frame origins 1..J-1: elbow, wrist),
  flange and target lie at or above the floor plane z = floor_z of the robot base frame
  (z up; link surfaces are not modelled: keep a margin for the links' radius). The floor
  keeps the arm out of the table or floor the robot stands on: 0.0 m (the default) is the
  base's mounting plane; a robot on a pedestal or a wall may pass a negative value, `-inf`
  disables it.
- Which parameters: the model's free parameters, less those that no subset of the
  candidates can identify, found by `identify.identifiability.fix_unidentifiable` on the
  Jacobian of all the candidates, exactly as `calibrate` fixes them.
- Greedy: from a tiny ridge, add the candidate with the largest gain
  log det(I_3 + J_i M^-1 J_i^T) (the matrix determinant lemma: a rank-3 update, so every
  candidate is scored by one (3M, p) x (p, p) product per step); then exchange (Fedorov):
  add the best candidate, drop the pose whose removal costs least, until the one dropped
  is the one just added.
- Effects that depend on the visiting order: a backlash term moves a point by the play
  times the approach direction, and the contract takes the direction from the order of
  the poses (the sign of each joint's change since the previous pose); a thermal drift
  depends on the time since the first pose. For models whose Jacobian changes with
  direction or time (checked numerically, no effect named), the greedy choice *is* the
  visiting order: at step k every candidate is scored with the direction and time it
  would have if measured next (direction by the contract's rule from pose k-1, time from
  the joint-interpolated move at the plan's speed), so the plan's approach directions are
  the ones scored; no exchange (it would change the next pose's direction). Otherwise
  the chosen poses are ordered by a nearest-neighbour tour in move time, for a shorter
  campaign.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError, param
from robot_calib.identify.identifiability import fix_unidentifiable
from robot_calib.kinematics.dh import chain
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.log import Log
from robot_calib.model import KinematicModel
from robot_calib.plan.plan_file import DEFAULT_SPEED_FRACTION
from robot_calib.poses import Poses, approach_directions, next_direction
from robot_calib.sim.plans import Plan, plan_times, random_plan, step_seconds
from robot_calib.sim.world import Timing

DEFAULT_CANDIDATES = 2000
DEFAULT_FLOOR_Z_M = 0.0
RIDGE = 1e-6  # start of the greedy choice: information of unit-rms columns, far below a pose's
#: the worst-variance exchange minimises sum(var^WORST_POWER): close to the max, yet smooth
WORST_POWER = 32
FLOOR_SLACK_M = 1e-9  # a point exactly on the floor (rounding) is above it
MAX_DRAW_ROUNDS = 50  # batches of candidates drawn before giving up on the floor


@dataclass(frozen=True)
class DesignProblem:
    """What a plan is chosen for.

    model : the forward model (robot + the model's effects).
    params : the linearisation point (nominal geometry, the world's tracker pose and target
        offset, effects at 0) with free flags: the parameters the candidates can identify.
    candidates : shape (M, J), joint readings [rad], uniform within the limits, above the
        floor.
    scale : shape (p,), rms over the candidates of each free parameter's point
        displacement per unit [m per parameter unit]: a parameter's 1-sigma times it is
        the rms point error it causes over the workspace [m].
    fixed : (name, reason) of the parameters no candidate set can identify.
    sequential : the Jacobian depends on the visiting order (approach direction, time).
    timing, speed_fraction : how the robot moves between poses (times of the poses).
    """

    model: KinematicModel
    params: ParameterVector
    candidates: Array
    scale: Array
    fixed: tuple[tuple[str, str], ...]
    sequential: bool
    timing: Timing
    speed_fraction: float = DEFAULT_SPEED_FRACTION

    def plan(self, q: Array, name: str = "planned") -> Plan:
        """Readings q (n, J) [rad] visited in order as a Plan of general poses at the
        problem's speed."""
        return Plan(name, q, np.zeros(len(q), dtype=int), self.speed_fraction)

    def poses(self, plan: Plan) -> Poses:
        """The plan's readings visited in order: directions by the contract's rule, times of
        the joint-interpolated moves at the plan's speed (`sim.plans.plan_times`)."""
        return Poses(plan.q, approach_directions(plan.q), plan_times(plan, self.timing))

    def jacobian(self, plan: Plan) -> Array:
        """d measured point / d free parameter, shape (n, 3, p) [m per parameter unit],
        of the plan's poses visited in order."""
        return self.free_jacobian(self.poses(plan))

    def free_jacobian(self, poses: Poses) -> Array:
        """d measured point / d free parameter, shape (n, 3, p), at `poses`."""
        return self.model.jacobian(self.params, poses)[1][:, :, self.params.free]


def clearance_z(model: KinematicModel, params: ParameterVector, q: Array) -> Array:
    """Height in the robot base frame [m] of the joint centres (DH frame origins 1..J-1,
    geometry only), the flange origin and the first target, shape (n, J + 1), for readings
    q (n, J) [rad]."""
    centres = chain(model.dh_table(params, q))[:, 1:-1, 2, 3]  # (n, J - 1)
    flange2base = model.flange2base(params, Poses.from_readings(q))
    target = flange2base[:, :3, :3] @ model.target_offsets(params)[0] + flange2base[:, :3, 3]
    return np.column_stack([centres, flange2base[:, 2, 3], target[:, 2]])


def draw_candidates(
    model: KinematicModel,
    params: ParameterVector,
    n: int,
    rng: np.random.Generator,
    floor_z_m: float = DEFAULT_FLOOR_Z_M,
) -> Array:
    """`n` readings (n, J) [rad] uniform within the joint limits (as the `random` plan)
    whose joint centres, flange and target are at or above `floor_z_m` (robot base frame,
    z up)."""
    kept: list[Array] = []
    found = drawn = 0
    for _ in range(MAX_DRAW_ROUNDS):
        q = random_plan(model.robot, max(n, 100), rng).q
        drawn += len(q)
        q = q[np.all(clearance_z(model, params, q) >= floor_z_m - FLOOR_SLACK_M, axis=1)]
        kept.append(q)
        found += len(q)
        if found >= n:
            return np.concatenate(kept)[:n]
    raise InputError(
        f"{param('floor_z_m', floor_z_m)}: only {found} of {drawn} random poses keep the joint "
        f"centres, flange and target above z = {floor_z_m} m of the robot base; lower the "
        "floor"
    )


def design_problem(
    model: KinematicModel,
    frames: ParameterVector,
    n_candidates: int,
    rng: np.random.Generator,
    timing: Timing,
    floor_z_m: float = DEFAULT_FLOOR_Z_M,
    speed_fraction: float = DEFAULT_SPEED_FRACTION,
) -> DesignProblem:
    """The problem of planning `model`'s calibration: `n_candidates` candidates drawn with
    `rng`, linearised at the nominal robot with the frames (tracker pose, target offsets)
    of `frames` (a parameter vector holding them, e.g. a world's truth)."""
    nominal = model.parameters()
    params = nominal.with_values(
        {p.name: frames[p.name] for p in nominal.parameters if p.group == "frames"}
    )
    candidates = draw_candidates(model, params, n_candidates, rng, floor_z_m)
    problem = DesignProblem(
        model,
        params,
        candidates,
        np.ones(int(params.free.sum())),
        (),
        False,
        timing,
        speed_fraction,
    )
    # every candidate visited in the order drawn: the directions and times of a campaign
    everything = problem.poses(problem.plan(candidates))
    jac = model.jacobian(params, everything)[1]
    kept, analysis = fix_unidentifiable(params, jac.reshape(-1, len(params)))
    free = jac[:, :, kept.free]
    scale = np.sqrt(np.mean(np.sum(free**2, axis=1), axis=0))
    return replace(
        problem,
        params=kept,
        scale=scale,
        fixed=analysis.fixed,
        sequential=_order_matters(model, kept, candidates[:50]),
    )


def _order_matters(model: KinematicModel, params: ParameterVector, q: Array) -> bool:
    """True when the model's Jacobian at readings q (n, J) depends on the approach
    direction or the time of the poses (backlash, thermal drift, ...)."""
    forth = Poses(q, np.ones(q.shape), np.zeros(len(q)))
    back = Poses(q, -np.ones(q.shape), np.full(len(q), 3600.0))
    return not np.allclose(model.jacobian(params, forth)[1], model.jacobian(params, back)[1])


def _gains(jac: Array, minv: Array) -> Array:
    """log det(I + J_i M^-1 J_i^T) of every candidate, shape (M,), for jac (M, 3, p) and
    M^-1 (p, p): the increase of log det M when candidate i is added."""
    a = np.einsum("map,mbp->mab", jac @ minv, jac)
    return np.asarray(np.linalg.slogdet(np.eye(3) + a)[1])


def _information_inverse(jac: Array, chosen: list[int], p: int) -> Array:
    """(RIDGE I + sum over `chosen` of J_i^T J_i)^-1, shape (p, p)."""
    rows = jac[chosen].reshape(-1, p)
    return np.asarray(np.linalg.inv(RIDGE * np.eye(p) + rows.T @ rows))


def _greedy(jac: Array, n: int, progress: Log | None) -> list[int]:
    """Greedy D-optimal choice of n of the candidates' scaled Jacobians jac (M, 3, p)."""
    p = jac.shape[2]
    chosen: list[int] = []
    minv = np.eye(p) / RIDGE
    for k in range(n):
        gains = _gains(jac, minv)
        gains[chosen] = -np.inf
        chosen.append(int(np.argmax(gains)))
        minv = _information_inverse(jac, chosen, p)
        if progress and (k + 1) % 20 == 0:
            progress(f"  plan: {k + 1}/{n} poses chosen")
    return chosen


def _exchange(jac: Array, chosen: list[int], max_rounds: int) -> list[int]:
    """Fedorov exchange from `chosen`: add the best candidate, drop the chosen pose whose
    removal costs least, until the pose dropped is the one added (or `max_rounds`)."""
    p = jac.shape[2]
    chosen = list(chosen)
    for _ in range(max_rounds):
        gains = _gains(jac, _information_inverse(jac, chosen, p))
        gains[chosen] = -np.inf
        best = int(np.argmax(gains))
        trial = [*chosen, best]
        minv = _information_inverse(jac, trial, p)
        sub = jac[trial]
        # log det(I - J_j M^-1 J_j^T): the change of log det M when pose j is removed
        a = np.einsum("map,mbp->mab", sub @ minv, sub)
        loss = np.linalg.slogdet(np.eye(3) - a)[1]
        drop = int(np.argmax(loss))
        if trial[drop] == best:
            break
        chosen = trial[:drop] + trial[drop + 1 :]
    return chosen


def _variances_after(jac: Array, minv: Array, sign: float) -> Array:
    """Diagonal of the information inverse after adding (sign +1) or removing (sign -1)
    each pose of jac (k, 3, p), shape (k, p), from M^-1 (p, p) (Woodbury: rank-3)."""
    g = jac @ minv  # (k, 3, p)
    s = np.eye(3) + sign * np.einsum("kap,kbp->kab", g, jac)
    return np.diag(minv)[None, :] - sign * np.einsum("kap,kap->kp", g, np.linalg.solve(s, g))


def _worst_exchange(
    jac: Array, chosen: list[int], max_rounds: int, power: int = WORST_POWER, tries: int = 5
) -> list[int]:
    """Exchange for the worst scaled variance: each round tries the `tries` additions that
    lower sum(var_k^power) most (a smooth stand-in for max var_k, which a plain exchange
    gets stuck on), each with its best removal, and keeps the best pair while it helps."""
    p = jac.shape[2]
    chosen = list(chosen)

    def criterion(variances: Array) -> Array:
        return np.sum((variances / top) ** power, axis=-1)

    top = float(np.max(np.diag(_information_inverse(jac, chosen, p))))
    current = float(criterion(np.diag(_information_inverse(jac, chosen, p))))
    for _ in range(max_rounds):
        after = criterion(_variances_after(jac, _information_inverse(jac, chosen, p), 1.0))
        after[chosen] = np.inf
        best: tuple[float, list[int]] | None = None
        for add in np.argsort(after)[:tries]:
            trial = [*chosen, int(add)]
            removed = criterion(
                _variances_after(jac[trial], _information_inverse(jac, trial, p), -1.0)
            )
            removed[-1] = np.inf  # not the one just added
            drop = int(np.argmin(removed))
            if best is None or removed[drop] < best[0]:
                best = (float(removed[drop]), trial[:drop] + trial[drop + 1 :])
        if best is None or best[0] >= current * (1.0 - 1e-9):
            break
        current, chosen = best
    return chosen


def _sequential(problem: DesignProblem, n: int, progress: Log | None) -> list[int]:
    """Greedy choice in visiting order: each step scores every candidate with the approach
    direction and time it would have if measured next."""
    q = problem.candidates
    p = len(problem.scale)
    chosen: list[int] = []
    rows = np.zeros((0, p))
    direction, time = np.ones(q.shape), np.zeros(len(q))
    for k in range(n):
        if chosen:
            last = chosen[-1]
            direction = next_direction(direction[last], q[last], q)
            time = time[last] + step_seconds(q[last], q, problem.timing, problem.speed_fraction)
        jac = problem.free_jacobian(Poses(q, direction, time)) / problem.scale
        minv = np.asarray(np.linalg.inv(RIDGE * np.eye(p) + rows.T @ rows), dtype=np.float64)
        gains = _gains(jac, minv)
        gains[chosen] = -np.inf
        best = int(np.argmax(gains))
        chosen.append(best)
        rows = np.vstack([rows, jac[best]])
        if progress and (k + 1) % 20 == 0:
            progress(f"  plan: {k + 1}/{n} poses chosen (in visiting order)")
    return chosen


def _tour(q: Array, timing: Timing, speed_fraction: float) -> NDArray[np.intp]:
    """A nearest-neighbour visiting order of readings q (n, J) by move time, from q[0]."""
    left = list(range(1, len(q)))
    order = [0]
    while left:
        step = step_seconds(q[order[-1]], q[left], timing, speed_fraction)
        order.append(left.pop(int(np.argmin(step))))
    return np.array(order)


def d_optimal(
    problem: DesignProblem, n: int, progress: Log | None = None, exchange_rounds: int = 0
) -> Array:
    """The D-optimal plan of `n` poses from the problem's candidates: readings (n, J)
    [rad] in visiting order. `exchange_rounds`: Fedorov exchanges after the greedy choice
    (default 4 n; not for order-dependent models). InputError when n poses cannot
    determine the free parameters (3 n <= p) or n exceeds the candidates."""
    p = len(problem.scale)
    if 3 * n <= p:
        raise InputError(
            f"{param('n_poses', n)}: {n} poses ({3 * n} residuals) cannot determine the {p} "
            f"identifiable parameters; at least {p // 3 + 1} poses are needed"
        )
    if n > len(problem.candidates):
        raise InputError(
            f"{param('n_poses', n)}: more than the {len(problem.candidates)} candidates"
        )
    if problem.sequential:
        return problem.candidates[_sequential(problem, n, progress)]
    jac = problem.free_jacobian(Poses.from_readings(problem.candidates)) / problem.scale
    chosen = _greedy(jac, n, progress)
    chosen = _exchange(jac, chosen, exchange_rounds or 4 * n)
    chosen = _worst_exchange(jac, chosen, exchange_rounds or 4 * n)
    q = problem.candidates[chosen]
    return q[_tour(q, problem.timing, problem.speed_fraction)]
