"""The frequency scan: which orders of joint-angle harmonics the residuals hold, per joint.

A joint-angle error e_j(q_j) moves each measured point along the joint's motion direction
m_j = axis_j x (point - origin_j) [m/rad]. For every joint j and order k = 1..max_order
the pair of columns m_j cos(k q_j), m_j sin(k q_j) (3n each) is projected off the columns
the model's free parameters already span (what a refit would absorb), and the share of
the residual it explains is its significance: sqrt(chi^2 explained) in units of the
residual's scatter per component (pure noise gives about 1.4, the largest of 64 orders x
6 joints about 3.5). That is the periodogram of the joint-angle projection of the
residuals, corrected for the geometry.

Orders are then picked greedily per joint: the most significant, then the most
significant of the rest once it is explained, and so on while the significance stays at
PICK_SIGNIFICANCE or more (a picked order's side lobes vanish with it: over a partial
turn neighbouring orders are nearly collinear). A pair whose columns keep less than
MIN_LEFT of their norm after the projection is collinear with the model and is skipped,
never reported with a meaningless amplitude; so is one whose amplitude alone would exceed
MAX_AMPLITUDE_RAD (no gear error is that large). Regular single-joint sweeps alias orders:
on a full turn in n equal steps order k and n - k coincide, over a partial turn they nearly
do (`measurements.aliasing`); a picked order lists the orders the readings alone cannot
tell it from, the ladder tries each of them against the held-out data, and the spectrum's
`resolvable_order` is the highest order below which no two orders look alike (random
poses and irregular sweeps, `plan --sweeps`, resolve every scanned order). The picked
orders become the ladder's `joint_harmonics` candidates and the report's dominant orders
(`effects.joint_harmonics` says what an order usually means).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from robot_calib.diagnosis.projection import MIN_LEFT, MIN_LEVER_M, model_span
from robot_calib.effects import Effect
from robot_calib.effects.joint_harmonics import JointHarmonics, meaning
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import Recording
from robot_calib.measurements.aliasing import ALIAS_CORRELATION, MAX_ORDER, order_similarity
from robot_calib.model import KinematicModel
from robot_calib.parallel import aside
from robot_calib.records import Record

MAX_SCAN_ORDER = MAX_ORDER
MAX_PICKS = 6  # orders picked per joint and round
PICK_SIGNIFICANCE = 6.0  # sqrt(chi^2 explained) / scatter an order needs to be picked
SCAN_POSES = 4000  # measurements scanned (a seeded random subset above)
#: from this many measurements on, the ladder's scans and screenings share their work with
#: a forked child (`forked.Aside`: half of the joints, half of the rows); below, the fork
#: costs more than it saves
ASIDE_POSES = 500
#: a harmonic whose amplitude alone would exceed this is no gear error [rad] (the weak
#: prior's sigma of a joint-angle term): a column the model nearly absorbs, or an alias
MAX_AMPLITUDE_RAD = 2e-3


@dataclass(frozen=True)
class JointSpectrum(Record):
    """The scan of one joint: significance of every order 1..max_order (0 for orders the
    model already has or that are collinear with it), and the orders picked, with their
    amplitudes [urad] (fitted together) and their significance when picked, and what each
    usually means. Not `observable` (nothing scanned) when the measured points sit within
    MIN_LEVER_M of the axis (`lever_mm` their median distance)."""

    joint: int
    observable: bool
    lever_mm: float
    significance: list[float]
    dominant_orders: list[int]
    dominant_urad: list[float]
    dominant_significance: list[float]
    meaning: list[str]
    # the highest order the joint's distinct readings resolve (`resolvable_order`): single-
    # joint sweeps of a few dozen regular steps alias orders above it; None: not scanned
    resolvable_order: int | None = None
    # per dominant order, the scanned orders these readings cannot tell it from (`aliases`):
    # the robot may have any of them (the ladder tries each on the held-out data)
    dominant_aliases: list[list[int]] = field(default_factory=list)

    def aliases_of(self, order: int) -> list[int]:
        """The aliases of dominant order `order` on the scanned readings ([] if none)."""
        for k, alias in zip(self.dominant_orders, self.dominant_aliases):
            if k == order:
                return alias
        return []

    def line(self) -> str:
        """One human line, e.g. 'joint 2: orders 11 (212 urad, 40 x), 27 (...)'."""
        limit = ""
        if self.resolvable_order is not None and self.resolvable_order < len(self.significance):
            limit = (
                f" (its readings tell orders apart up to {self.resolvable_order} only: "
                "random poses or irregular sweeps tell the higher ones)"
            )
        if not self.dominant_orders:
            return f"joint {self.joint}: no harmonic stands out{limit}"
        parts = [
            f"{k} ({a:.0f} urad, "
            + (f"{s:.0f} x" if s > 0 else "not confirmed by the k-fold of the calibration poses")
            + f"{_alias_clause(self.aliases_of(k))})"
            for k, a, s in zip(
                self.dominant_orders, self.dominant_urad, self.dominant_significance
            )
        ]
        return f"joint {self.joint}: orders " + ", ".join(parts) + limit


def _alias_clause(alias: list[int]) -> str:
    """'; or its alias 43 on these readings' (aliases 43, 44), '' for none."""
    if not alias:
        return ""
    word = "alias" if len(alias) == 1 else "aliases"
    return f"; or its {word} {', '.join(map(str, alias))} on these readings"


def modelled_orders(effects: tuple[Effect, ...], joint: int) -> set[int]:
    """The orders of joint-angle harmonics of `joint` that `effects` already have."""
    return set().union(*(e.harmonic_orders(joint) for e in effects))


def _pair_explained(cols: Array, r: Array) -> tuple[Array, Array]:
    """For pairs of columns cols (m, K, 2): the chi^2 each pair explains of r (m,) on its
    own (K,), and its least-squares coefficients (K, 2)."""
    c, s = cols[:, :, 0], cols[:, :, 1]
    cc, ss, cs = np.sum(c * c, axis=0), np.sum(s * s, axis=0), np.sum(c * s, axis=0)
    rhs = np.stack([r @ c, r @ s], axis=1)  # (K, 2)
    det = cc * ss - cs**2
    safe = np.where(det > 0, det, 1.0)
    coef = np.stack([ss * rhs[:, 0] - cs * rhs[:, 1], cc * rhs[:, 1] - cs * rhs[:, 0]], 1)
    coef = np.where((det > 0)[:, None], coef / safe[:, None], 0.0)
    return np.einsum("ka,ka->k", coef, rhs), coef


def joint_spectra(
    model: KinematicModel,
    params: ParameterVector,
    recording: Recording,
    residuals: Array,
    max_order: int = MAX_SCAN_ORDER,
    seed: int = 0,
) -> list[JointSpectrum]:
    """The scan of every joint (module docstring) of the residuals (n, 3) [m] (predicted -
    measured, tracker frame) of `model` at `params` on `recording`; the model's free
    parameters' columns are projected off first."""
    n = len(recording)
    rows = np.arange(n)
    if n > SCAN_POSES:
        rows = np.sort(np.random.default_rng(seed).choice(n, SCAN_POSES, replace=False))
    poses = recording.poses.subset(rows)
    res = residuals[rows]
    span = model_span(model, params, poses, recording.points[rows] + res)
    motion = span.motion
    r = span.project_off(res.reshape(-1))
    scatter = float(np.sqrt(np.mean(r**2))) or 1.0
    orders = np.arange(1, max_order + 1)

    def joint(j: int) -> JointSpectrum:
        """The scan of joint j + 1 (0-based j)."""
        lever = float(span.lever_m[j])
        if lever < MIN_LEVER_M:
            return JointSpectrum(j + 1, False, lever * 1e3, [0.0] * max_order, [], [], [], [])
        angle = poses.q[:, j, None] * orders  # (n, K)
        trig = np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # (n, K, 2)
        cols = (motion[:, j, :, None, None] * trig[:, None]).reshape(-1, max_order, 2)
        norms = np.linalg.norm(cols, axis=0)  # (K, 2)
        cols = span.project_off(cols)
        left = np.linalg.norm(cols, axis=0) / np.where(norms > 0, norms, 1.0)
        usable = np.all(left >= MIN_LEFT, axis=1)
        usable[[k - 1 for k in modelled_orders(model.effects, j + 1) if k <= max_order]] = False
        similarity = order_similarity(poses.q[:, j], max_order)
        chi2, coef = _pair_explained(cols, r)
        usable &= np.hypot(coef[:, 0], coef[:, 1]) <= MAX_AMPLITUDE_RAD  # beyond physics
        significance = np.where(usable, np.sqrt(np.maximum(chi2, 0.0)) / scatter, 0.0)
        picked, picked_z = _pick(cols, r, usable, scatter)
        amps: list[float] = []
        if picked:
            design = cols[:, [k - 1 for k in picked], :].reshape(len(cols), -1)
            together = np.linalg.lstsq(design, r, rcond=None)[0].reshape(-1, 2)
            amps = [float(np.hypot(*c) * 1e6) for c in together]
        values = [float(s) for s in significance]
        why = [meaning(k) for k in picked]
        modelled = modelled_orders(model.effects, j + 1)
        alias = [[m for m in similarity.aliases(k) if m not in modelled] for k in picked]
        return JointSpectrum(
            j + 1,
            True,
            lever * 1e3,
            values,
            picked,
            amps,
            picked_z,
            why,
            similarity.resolvable(),
            alias,
        )

    # the joints are independent: the second half scanned by a forked child meanwhile
    # (`parallel.aside`; the same numbers either way) when the scan is large enough to pay
    joints = list(range(model.robot.n_joints))
    theirs = joints[len(joints) // 2 :] if n >= ASIDE_POSES else []
    with aside([(j, partial(joint, j)) for j in theirs]) as others:
        mine = {j: joint(j) for j in joints if j not in theirs}
        return [mine[j] if j in mine else others.result(j) for j in joints]


def _pick(cols: Array, r: Array, usable: Array, scatter: float) -> tuple[list[int], list[float]]:
    """Greedy orders (1-based) of the pairs cols (m, K, 2): the most significant usable
    pair, explained away, then the next, while significance >= PICK_SIGNIFICANCE."""
    cols = cols.copy()
    r = r.copy()
    norms = np.linalg.norm(cols, axis=0)
    usable = usable.copy()
    picked: list[int] = []
    z_picked: list[float] = []
    for _ in range(MAX_PICKS):
        left = np.linalg.norm(cols, axis=0) / np.where(norms > 0, norms, 1.0)
        ok = usable & np.all(left >= MIN_LEFT, axis=1)
        if not ok.any():
            break
        chi2, coef = _pair_explained(cols, r)
        ok &= np.hypot(coef[:, 0], coef[:, 1]) <= MAX_AMPLITUDE_RAD
        z = np.where(ok, np.sqrt(np.maximum(chi2, 0.0)) / scatter, 0.0)
        best = int(np.argmax(z))
        if z[best] < PICK_SIGNIFICANCE:
            break
        picked.append(best + 1)
        z_picked.append(float(z[best]))
        usable[best] = False
        q, _ = np.linalg.qr(cols[:, best, :])  # the picked pair, orthonormal (m, 2)
        r -= q @ (q.T @ r)
        flat = cols.reshape(len(cols), -1)
        flat -= q @ (q.T @ flat)
    return picked, z_picked


def harmonic_candidates(spectra: list[JointSpectrum], present: tuple[Effect, ...]) -> list[Effect]:
    """The ladder's joint_harmonics candidates: per joint with dominant orders, the joint's
    present harmonics plus the first 1, 2, ... of them (nested, the screening picks how
    many), and each of those with the last order added replaced by one of its aliases (the
    readings cannot tell them apart: the held-out data may)."""
    out: list[Effect] = []
    for spectrum in spectra:
        new = spectrum.dominant_orders
        if not new:
            continue
        j = spectrum.joint
        have = next((e for e in present if isinstance(e, JointHarmonics) and j in e.joints), None)
        base = set(have.orders) if have is not None else set()
        for m in range(1, len(new) + 1):
            for last in (new[m - 1], *spectrum.aliases_of(new[m - 1])):
                orders = base | set(new[: m - 1]) | {last}
                if len(orders) == len(base) + m:  # an alias already among the orders: not new
                    out.append(JointHarmonics(joints=(j,), orders=tuple(sorted(orders))))
    return out


def alias_warnings(
    effects: tuple[Effect, ...], recording: Recording, holdout: Recording | None
) -> list[str]:
    """One line per joint-angle harmonic of `effects` (a chosen model) that the readings
    of `recording` cannot tell from another scanned order (`aliases`) and that `holdout`
    (its own readings) does not settle either: the robot may have that order instead."""
    out: list[str] = []
    for effect in effects:
        if not isinstance(effect, JointHarmonics):
            continue
        for j in effect.joints:
            q = recording.poses.q[:, j - 1]
            similar = order_similarity(q)
            held = None if holdout is None else order_similarity(holdout.poses.q[:, j - 1])
            for k in effect.orders:
                if k > MAX_SCAN_ORDER:
                    continue
                left = [
                    m
                    for m in similar.aliases(k)
                    if m not in effect.orders
                    and (held is None or held.on_readings[k - 1, m - 1] >= ALIAS_CORRELATION)
                ]
                if left:
                    word = "order" if len(left) == 1 else "orders"
                    out.append(
                        f"joint {j}'s harmonic of order {k} is not told from {word} "
                        f"{', '.join(map(str, left))} by these poses (regular sweeps alias "
                        "them): the robot may have either; measure random general poses, or "
                        "sweeps of irregular steps (msgs_doc/plan.md), to tell"
                    )
    return out
