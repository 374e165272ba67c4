"""Which terms are there: every candidate term of a model's residuals fitted jointly, each
judged against its own uncertainty, and kept only where it lowers the error held out.

A joint-angle error of joint j shaped as a signal s of the pose (harmonic k of the
reading, the approach direction, the reading, the gravity torque) moves each measured
point by m_j s [m] (m_j = axis_j x (point - origin_j), `projection.model_span`); a drift
of the tracker's points with time moves them by t and t^2 along each axis. Tested one at a
time against the tracker's noise, any of these columns takes a share of whatever else the
residual holds (another joint's backlash, a bent link, a drift): images of one effect
showed on every joint at tens to hundreds of "noise sigmas". Here:

- every term of every joint and the time terms are fitted at once, together with the
  model's own free parameters (what a refit would absorb): a term gets only what no
  other term and no parameter can explain;
- its significance is its size over its own 1-sigma in that joint fit, with the scatter
  the joint fit actually leaves (not the tracker's noise alone), as a normal z (Wald
  chi^2 of its 1 or 2 columns, the time terms' 6, turned into the z of the same tail);
- a term whose columns keep less than MIN_RESOLVED of their norm once the model and the
  other terms are projected off is not resolvable from these poses: no value, no
  significance (over a short arc harmonics of neighbouring orders and the reading's slope
  are nearly collinear: their amplitudes could be anything);
- a term counts only if dropping it from the joint fit surely raises the error on poses
  not fitted: in a k-fold over groups of measurements at the same readings
  (`poses.reading_groups`: re-reads and repeats of a pose stay together), the per-pose
  gains' mean over its standard error (`paired_z`) must reach CONFIRM_Z. A term of fitted
  z >= CHECK_Z that does not is reported with significance 0 and `confirmed` false.
- terms of one joint that these poses cannot tell apart (each keeps less than
  MIN_RESOLVED of its norm against all other columns, but enough once its joint's other
  such terms are left out) are each judged in the others' place (`separable` false): a
  compliance seen on a short arc shows as its gravity torque, its reading and its first
  harmonics at once, none of them made up from the others.

Everything is linear (the residuals are those of a converged fit): one normal matrix of
~100-150 columns, downdated per fold and per term.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from robot_calib.diagnosis.frequency import modelled_orders
from robot_calib.diagnosis.projection import MIN_LEVER_M, joint_motion
from robot_calib.effects.compliance import gravity_torques
from robot_calib.effects.link_bending import twist_alignment, twist_axis
from robot_calib.identify.fit import blocked_jacobian
from robot_calib.identify.load_features import frame_loads, point_motions
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import Recording
from robot_calib.measurements.split import N_FOLDS, pose_folds
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses, reading_groups
from robot_calib.records import Record

HARMONICS = 4  # harmonic orders 1..HARMONICS of every joint are candidates
#: a term whose columns keep less than this share of their norm once the model's columns
#: and every other term's are projected off is not resolvable (its 1-sigma would be over
#: 1 / MIN_RESOLVED times that of the same column alone)
MIN_RESOLVED = 0.05
#: terms below this fitted z are not checked on held-out data (they count for nothing)
CHECK_Z = 3.0
#: the k-fold paired z a term needs to count (it lowers the error of poses not fitted at
#: about 98 % confidence); measured on the blind harness (3 seeds per class, 2026-12-07):
#: 0 (any lowering) gave 6.6 % of effect-free joints' rows at >= 5, 2 gave 4.4 % with the
#: same 3 of 57 effect joints missed
CONFIRM_Z = 2.0
MAX_Z = 1e6  # a held-out z where every pose gains exactly the same
#: a term at this significance or more is structure (the reports' and the harness' figure)
STRUCTURE_Z = 5.0
FAMILIES = ("harmonics", "direction", "scale", "gravity", "twist", "time")
UNITS = {
    "harmonics": "urad",
    "direction": "urad",
    "scale": "urad/rad",
    "gravity": "urad/(N m)",
    "twist": "mm",
    "time": "mm",
}


@dataclass(frozen=True)
class TermEvidence(Record):
    """One candidate term. joint: 1-based (0: time, no joint); family: one of FAMILIES;
    order: the harmonic order (harmonics only); value: its size in UNITS[family] (a
    harmonic's amplitude, the coefficient of the direction (+-1), reading [rad] or gravity
    torque [N m] in urad per unit; time: the rms over the recording of the drift it fits
    [mm]), None when not resolvable; sigma: the value's 1-sigma (same unit); significance:
    its normal z when it is resolvable and lowers the held-out error (`confirmed`), else 0;
    fitted_z: its z in the joint fit, whatever the held-out error."""

    joint: int
    family: str
    order: int | None
    value: float | None
    sigma: float | None
    significance: float
    fitted_z: float
    confirmed: bool
    resolvable: bool
    heldout_z: float = 0.0
    separable: bool = True  # False: these poses cannot tell it from other terms of its
    # joint; judged in their place (each alone), so several of them may show the structure

    def words(self) -> str:
        """'2nd harmonic of joint 3', 'joint 4 approach direction', 'time'."""
        if self.family == "time":
            return "a drift with time"
        if self.family == "harmonics":
            return f"{ordinal(int(self.order or 0))} harmonic of joint {self.joint}"
        if self.family == "twist":
            return (
                f"joint {self.joint}'s housing turning with the load about link "
                f"{self.joint - 1}'s axis (the link twisting)"
            )
        return f"joint {self.joint} error following its {FAMILY_WORDS[self.family]}"


FAMILY_WORDS = {
    "direction": "approach direction (backlash-like)",
    "scale": "reading (scale-like)",
    "gravity": "gravity torque (compliance-like)",
}


def ordinal(k: int) -> str:
    """'1st', '2nd', '11th', '21st', ..."""
    if k % 100 in (11, 12, 13):
        return f"{k}th"
    return f"{k}{ {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th') }"


@dataclass(frozen=True)
class Evidence:
    """Every candidate term's evidence; scatter_m: what the joint fit leaves, per component
    [m] (the scale of every term's uncertainty); levers_m: per joint, the median distance
    [m] of the points from its axis (a joint below MIN_LEVER_M has no candidate)."""

    terms: list[TermEvidence]
    scatter_m: float
    levers_m: list[float]

    def term(self, joint: int, family: str, order: int | None = None) -> TermEvidence | None:
        """The term of `joint`, `family` (and harmonic `order`), None when not a candidate."""
        for t in self.terms:
            if t.joint == joint and t.family == family and t.order == order:
                return t
        return None

    def strongest(self) -> TermEvidence | None:
        """The term of the highest significance (None when none is above 0)."""
        best = max(self.terms, key=lambda t: t.significance, default=None)
        return best if best is not None and best.significance > 0 else None


@dataclass(frozen=True)
class _Term:
    joint: int
    family: str
    order: int | None
    columns: IntArray  # into the candidate block


def _signals(
    model: KinematicModel,
    recording: Recording,
    levers: Array,
    orders: dict[int, list[int]],
    time_scale: tuple[float, float] | None,
) -> tuple[list[tuple[int, str, int | None, list[Array]]], list[Array]]:
    """The candidate terms (joint, family, order, signals (n,) each) and the time signals
    (t, t^2 normalised: one column per axis each), for the joints of lever >= MIN_LEVER_M
    (of the signals that vary)."""
    poses = recording.poses
    tau = gravity_torques(model.robot, poses.q)
    out: list[tuple[int, str, int | None, list[Array]]] = []
    for j in range(1, model.robot.n_joints + 1):
        if levers[j - 1] < MIN_LEVER_M:
            continue
        qj = poses.q[:, j - 1]
        if np.ptp(qj) > 1e-9:  # at rest, a joint's harmonics are an offset
            modelled = modelled_orders(model.effects, j)  # the model's own: not candidates
            for k in sorted({*range(1, HARMONICS + 1), *orders.get(j, [])} - modelled):
                out.append((j, "harmonics", k, [np.cos(k * qj), np.sin(k * qj)]))
        for family, signal in (
            ("direction", poses.direction[:, j - 1]),
            ("scale", qj),
            ("gravity", tau[:, j - 1]),
        ):
            if np.ptp(signal) > 1e-9:
                out.append((j, family, None, [signal]))
    time: list[Array] = []
    if time_scale is not None:
        mean, span = time_scale
        u = (poses.time - mean) / span
        time = [u, u**2 - np.mean(u**2)]
    return out, time


#: a link whose twist axis is within about 60 deg of its own joint's axis (|cos| above
#: this) twists the way that joint turns: a joint-angle term, not a twist
MAX_TWIST_ALIGNMENT = 0.5


def _twists(
    model: KinematicModel, params: ParameterVector, poses: Poses, geometry: Array
) -> list[tuple[int, list[Array]]]:
    """The twist terms: per link J - 1 that can twist (`link_bending.twist_axis`) about an
    axis across its joint's (MAX_TWIST_ALIGNMENT), joint J's housing turning about that
    axis by the load's moment about it (the robot's own links beyond, an unknown payload's
    mass and its first moments: `load_features`), as (J, its columns (n, 3) [m per unit,
    tracker frame]): those that keep MIN_RESOLVED of their norm once the model's free
    columns `geometry` (n, 3, P) are projected off (a constant moment turns the housing by
    a constant: geometry, whose remainder is rounding that would absorb anything)."""
    robot = model.robot
    motions = point_motions(model, params, poses)  # (n, 3, J, 6)
    loads = frame_loads(robot, poses.q)  # (n, J, 15): M, P, C_x, C_y, C_z about frame j
    n, _, n_free = geometry.shape
    basis = np.linalg.qr(geometry.reshape(3 * n, n_free))[0] if n_free else np.zeros((3 * n, 0))
    out = []
    for link in range(1, robot.n_joints):
        axis = twist_axis(robot, link)
        if not axis.any() or twist_alignment(robot, link) > MAX_TWIST_ALIGNMENT:
            continue
        turn = motions[:, :, link, 3:] @ axis  # (n, 3) [m/rad] about the link's axis
        if np.median(np.linalg.norm(turn, axis=1)) < MIN_LEVER_M:
            continue
        cols = []
        for k in range(5):
            col = turn * (loads[:, link, 3 * k : 3 * k + 3] @ axis)[:, None]
            flat = col.reshape(-1)
            norm = float(np.linalg.norm(flat))
            if norm > 0 and np.linalg.norm(flat - basis @ (basis.T @ flat)) >= MIN_RESOLVED * norm:
                cols.append(col)
        if cols:
            out.append((link + 1, cols))
    return out


def _design(
    model: KinematicModel,
    params: ParameterVector,
    recording: Recording,
    predicted: Array,
    orders: dict[int, list[int]],
    time_scale: tuple[float, float] | None,
) -> tuple[Array, list[_Term], Array]:
    """X (3n, P + K) [m per unit]: the model's free Jacobian columns, then every candidate
    term's columns; the terms (their columns' indices into X); the joints' levers (J,) [m]."""
    poses = recording.poses
    motion, levers = joint_motion(model, params, poses, predicted)  # (n, J, 3) [m/rad]
    _, jac = blocked_jacobian(model, params, poses)
    geometry = jac[:, :, params.free]  # (n, 3, P)
    del jac
    signals, time = _signals(model, recording, levers, orders, time_scale)
    columns = [
        (joint, family, order, [motion[:, joint - 1, :] * s[:, None] for s in sigs])
        for joint, family, order, sigs in signals
    ]
    twists = _twists(model, params, poses, geometry)
    columns += [(joint, "twist", None, cols) for joint, cols in twists]
    n, p = len(poses), geometry.shape[2]
    k = sum(len(c) for *_, c in columns) + 3 * len(time)
    x = np.empty((n, 3, p + k))
    x[:, :, :p] = geometry
    terms, at = [], p
    for joint, family, order, cols in columns:
        for c in cols:
            x[:, :, at] = c
            at += 1
        terms.append(_Term(joint, family, order, np.arange(at - len(cols), at)))
    if time:
        start = at
        for s in time:
            for axis in range(3):
                x[:, :, at] = 0.0
                x[:, axis, at] = s
                at += 1
        terms.append(_Term(0, "time", None, np.arange(start, at)))
    return x.reshape(3 * n, -1), terms, levers


def normal_z(chi2: float, dof: int) -> float:
    """The normal z of the same upper tail as chi^2 with `dof` degrees of freedom (1 dof:
    sqrt(chi^2)); for tails beyond double precision, the asymptotic sqrt(chi^2 - dof + 1).
    (scipy.special's distribution functions: scipy.stats costs 0.7 s to import.)"""
    if chi2 <= 0:
        return 0.0
    if dof == 1:
        return float(np.sqrt(chi2))
    tail = float(special.chdtrc(dof, chi2))
    if tail > 1e-300:
        return max(-float(special.ndtri(tail)), 0.0)
    return float(np.sqrt(max(chi2 - dof + 1, 0.0)))


def _fit_without(gram: Array, rhs: Array, drop: IntArray) -> Array:
    """The joint fit's coefficients (P + K,) with the columns `drop` left out (zero there):
    the minimum-norm least-squares solution of the normal equations `gram`, `rhs` of unit-
    norm columns (inseparable terms share what they explain, none is made up)."""
    return _inverse_without(gram, drop) @ rhs


def _sum_of_squares(r2: float, gram: Array, rhs: Array, beta: Array) -> float:
    """|r - X beta|^2 from the normal equations (r2 = |r|^2)."""
    return max(r2 - 2.0 * float(beta @ rhs) + float(beta @ gram @ beta), 0.0)


@dataclass(frozen=True)
class _Unit:
    """One term as it is judged: its columns, and the columns of the terms of its joint
    these poses cannot tell it apart from (`siblings`), left out of every fit that judges
    it (it stands in for them: each is judged in its siblings' place)."""

    term: int
    columns: IntArray
    siblings: IntArray


def joint_evidence(
    model: KinematicModel,
    params: ParameterVector,
    recording: Recording,
    residuals: Array,
    orders: dict[int, list[int]] | None = None,
) -> Evidence:
    """The evidence of every candidate term (module docstring) in `residuals` (n, 3) [m,
    predicted - measured, tracker frame] of `model` at `params` on `recording`.

    orders : joint (1-based) -> harmonic orders beyond 1..HARMONICS to test too (the
        frequency scan's picks)
    """
    orders = orders or {}
    if len(recording) == 0:
        return Evidence([], 0.0, [0.0] * model.robot.n_joints)
    time = recording.poses.time
    span_t = float(np.ptp(time)) if len(time) else 0.0
    time_scale = (float(np.mean(time)), span_t) if span_t > 0 else None
    x, terms, levers = _design(
        model, params, recording, recording.points + residuals, orders, time_scale
    )
    r = residuals.reshape(-1)
    norms = np.linalg.norm(x, axis=0)
    norms[norms == 0] = 1.0
    x = x / norms
    gram, rhs, r2 = x.T @ x, x.T @ r, float(r @ r)
    inverses = _Inverses(gram)
    none = np.zeros(0, dtype=np.int64)
    separable = [bool(v >= MIN_RESOLVED) for v in inverses.kept_share(terms, none)]
    units = []
    for i, term in enumerate(terms):
        siblings = [
            k
            for k, t in enumerate(terms)
            if k != i and not separable[k] and not separable[i] and t.joint == term.joint
        ]
        cols = np.concatenate([terms[k].columns for k in siblings]) if siblings else none
        units.append(_Unit(i, term.columns, cols))
    rss = _sum_of_squares(r2, gram, rhs, inverses.fit(rhs, none))
    rank = int(np.sum(np.linalg.eigvalsh(gram) > 1e-12 * max(float(np.trace(gram)), 1e-300)))
    scatter2 = rss / max(len(r) - rank, 1)
    fitted: dict[int, tuple[float, float, float]] = {}  # unit -> value, sigma, z
    for u, unit in enumerate(units):
        if inverses.kept_share([terms[unit.term]], unit.siblings)[0] < MIN_RESOLVED:
            continue  # not resolvable even in its siblings' place
        kept = inverses.fit(rhs, unit.siblings)
        without = _fit_without(gram, rhs, np.concatenate([unit.siblings, unit.columns]))
        chi2 = (
            _sum_of_squares(r2, gram, rhs, without) - _sum_of_squares(r2, gram, rhs, kept)
        ) / max(scatter2, 1e-300)
        cov = inverses.without(unit.siblings) * scatter2
        value, sigma = _value(terms[unit.term], kept, cov, x, norms)
        fitted[u] = (value, sigma, normal_z(chi2, len(unit.columns)))
    check = [u for u, (_, _, z) in fitted.items() if z >= CHECK_Z]
    held = _held_out_gains(recording, residuals, units, check, x, gram, rhs)
    out = []
    for u, unit in enumerate(units):
        term = terms[unit.term]
        if u not in fitted:
            out.append(
                TermEvidence(
                    term.joint, term.family, term.order, None, None, 0.0, 0.0, False, False
                )
            )
            continue
        value, sigma, z = fitted[u]
        held_z = float(held.get(u, 0.0))
        confirmed = bool(held_z >= CONFIRM_Z)
        shown = z if confirmed or z < CHECK_Z else 0.0
        out.append(
            TermEvidence(
                term.joint,
                term.family,
                term.order,
                value,
                sigma,
                shown,
                z,
                confirmed,
                True,
                held_z,
                separable[unit.term],
            )
        )
    return Evidence(out, float(np.sqrt(scatter2)), [float(v) for v in levers])


class _Inverses:
    """The pseudo-inverse of a normal matrix `gram` with some columns left out, computed
    once per set of columns left out (every term of one joint's inseparable set leaves out
    the same siblings but its own: most sets recur)."""

    def __init__(self, gram: Array) -> None:
        self.gram = gram
        self._known: dict[tuple[int, ...], Array] = {}

    def without(self, drop: IntArray) -> Array:
        """`_inverse_without(gram, drop)`, once per `drop`."""
        key = tuple(sorted(int(c) for c in drop))
        if key not in self._known:
            self._known[key] = _inverse_without(self.gram, drop)
        return self._known[key]

    def fit(self, rhs: Array, drop: IntArray) -> Array:
        """The joint fit's coefficients without the columns `drop` (`_fit_without`)."""
        return self.without(drop) @ rhs

    def kept_share(self, terms: list[_Term], drop: IntArray) -> list[float]:
        """Per term: the smallest share of its (unit-norm) columns' norm left once every
        other column but `drop` is projected off (1 / sqrt of the inverse's diagonal)."""
        left = 1.0 / np.sqrt(np.maximum(np.diag(self.without(drop)), 1e-300))
        return [float(left[t.columns].min()) for t in terms]


def _inverse_without(gram: Array, drop: IntArray) -> Array:
    """The pseudo-inverse of `gram` with the columns `drop` left out (zero rows and columns
    there), in the full size."""
    keep = np.ones(len(gram), dtype=bool)
    keep[drop] = False
    idx = np.flatnonzero(keep)
    out = np.zeros_like(gram)
    out[np.ix_(idx, idx)] = np.linalg.pinv(gram[np.ix_(idx, idx)], hermitian=True, rcond=1e-12)
    return out


def _value(term: _Term, beta: Array, cov: Array, x: Array, norms: Array) -> tuple[float, float]:
    """A resolvable term's value and 1-sigma in UNITS[term.family] (see TermEvidence)."""
    cols = term.columns
    coef = beta[cols] / norms[cols]
    var = np.diag(cov)[cols] / norms[cols] ** 2
    if term.family in ("time", "twist"):
        drift = (x[:, cols] @ beta[cols]).reshape(-1, 3)  # [m]
        value = float(np.sqrt(np.mean(np.sum(drift**2, axis=1))))
        block = cov[np.ix_(cols, cols)]
        chi2 = float(beta[cols] @ np.linalg.pinv(block, hermitian=True) @ beta[cols])
        return value * 1e3, value * 1e3 / max(np.sqrt(chi2), 1e-300)
    if len(cols) == 2:
        return float(np.hypot(*coef)) * 1e6, float(np.sqrt(np.mean(var))) * 1e6
    return float(coef[0]) * 1e6, float(np.sqrt(var[0])) * 1e6


def _per_pose(values: Array, group: IntArray) -> Array:
    """Per-row values (3n,) summed per group of measurements (`group`: (n,)) -> (G,)."""
    return np.bincount(np.repeat(group, 3), weights=values).astype(np.float64)


def paired_z(gain: Array) -> float:
    """How surely a term lowers the held-out error: the mean of the per-pose gains (the
    squared error without it minus with it, (m,) [m^2]) over its standard error; poses
    drawn independently make this a fair test even where the term only catches a part of
    an effect it does not model (whose misfit a fitted z does not see)."""
    if len(gain) < 2:
        return 0.0
    spread = float(np.std(gain, ddof=1))
    mean = float(np.mean(gain))
    if spread <= 0:  # every pose gains the same: sure when it is a gain (finite for JSON)
        return 0.0 if mean <= 0 else MAX_Z
    return mean / (spread / np.sqrt(len(gain)))


def _held_out_gains(
    recording: Recording,
    residuals: Array,
    units: list[_Unit],
    check: list[int],
    x: Array,
    gram: Array,
    rhs: Array,
) -> dict[int, float]:
    """Per unit of `check`: how surely it lowers the error of poses not fitted (`paired_z`
    of the per-pose gains in a k-fold over reading groups: > 0 when it does)."""
    if not check:
        return {}
    r = residuals.reshape(-1)
    group = reading_groups(recording.poses.q)
    rows = np.repeat(pose_folds(recording), 3)
    total = {u: np.zeros(len(r)) for u in check}  # per row: squared error dropping it
    for f in range(N_FOLDS):
        test = rows == f
        if not test.any():
            continue
        xt, rt = x[test], r[test]
        g, b = gram - xt.T @ xt, rhs - xt.T @ rt
        inverses = _Inverses(g)
        for u in check:
            unit = units[u]
            kept = inverses.fit(b, unit.siblings)
            without = _fit_without(g, b, np.concatenate([unit.siblings, unit.columns]))
            total[u][test] = (rt - xt @ without) ** 2 - (rt - xt @ kept) ** 2
    return {u: paired_z(_per_pose(d, group)) for u, d in total.items()}
