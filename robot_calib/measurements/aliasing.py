"""Which joint-angle harmonic orders a joint's readings tell apart.

A harmonic C cos(k q) + S sin(k q) of a joint's reading q is only known at the readings
measured. Single-joint sweeps in regular steps alias orders: on a full turn in n equal
steps order k and n - k take the same values; over a partial turn they nearly do, and
neighbouring orders overlap by the arc's resolution (as much on any steps over that arc).
`order_similarity` measures how alike two orders look on the readings (the canonical
correlation of their centred (cos, sin) pairs) and on the arc, its `aliases` are the
orders the readings alone confuse with one, and `resolvable_order` is the highest order
below which the readings alias none (the arc's own overlap of neighbouring orders apart: a
short arc confuses orders on any steps): what
`diagnose`'s frequency scan can tell apart and what `plan` reports for a plan. Random
general poses and sweeps of irregular steps (`plan.sweeps`) resolve every order up to
MAX_ORDER.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robot_calib.kinematics.frames import Array

MAX_ORDER = 64  # the orders considered: 1..MAX_ORDER per turn of the joint
READING_RESOLUTION_RAD = 1e-4  # readings closer than this count as one (joint at rest)
#: two orders whose (cos, sin) pairs on a joint's readings correlate this much or more
#: (canonical correlation) are aliases: the readings cannot tell which of them the robot has
ALIAS_CORRELATION = 0.9
#: the arc is sampled this densely to tell aliasing from the arc's own resolution
DENSE_READINGS = 2048
DEGENERATE = 1e-6  # a pair whose centred columns keep less than this share of their power


def distinct_readings(q: Array) -> Array:
    """The distinct readings of q (n,) [rad], sorted (readings closer than
    READING_RESOLUTION_RAD are one: a joint at rest)."""
    scaled = np.asarray(q, dtype=float) / READING_RESOLUTION_RAD
    return np.unique(np.round(scaled)) * READING_RESOLUTION_RAD


def _canonical(u: Array, max_order: int) -> tuple[Array, NDArray[np.bool_]]:
    """(K, K) the canonical correlation between the centred pairs cos(k q), sin(k q) of
    orders 1..K over the readings u (m,) (the joint's offset absorbs a constant, so only
    the centred columns count), and (K,) True for an order whose centred pair is degenerate
    there (e.g. sin(k q) = 0 at every reading: its phase is unknown). From the sums of
    cos(d q), sin(d q), d = 0..2K, not from the (m, 2K) columns."""
    k = np.arange(1, max_order + 1)
    angle = np.outer(np.arange(0, 2 * max_order + 1), u)
    sum_c, sum_s = np.cos(angle).sum(axis=1), np.sin(angle).sum(axis=1)
    diff = np.abs(k[:, None] - k[None, :])
    add = k[:, None] + k[None, :]
    sign = np.sign(k[:, None] - k[None, :])
    # Gram blocks of the pairs: [[cos.cos, cos.sin], [sin.cos, sin.sin]] for orders (k, m)
    gram = np.empty((max_order, max_order, 2, 2))
    gram[..., 0, 0] = (sum_c[diff] + sum_c[add]) / 2
    gram[..., 1, 1] = (sum_c[diff] - sum_c[add]) / 2
    gram[..., 0, 1] = (sum_s[add] - sign * sum_s[diff]) / 2  # cos(k q) . sin(m q)
    gram[..., 1, 0] = (sum_s[add] + sign * sum_s[diff]) / 2  # sin(k q) . cos(m q)
    means = np.stack([sum_c[k], sum_s[k]], axis=1) / len(u)  # (K, 2): the columns' means
    gram -= len(u) * np.einsum("ka,mb->kmab", means, means)  # centred
    own = gram[k - 1, k - 1]  # (K, 2, 2)
    values, vectors = np.linalg.eigh(own)
    keep = values > DEGENERATE * len(u)
    inv_sqrt = np.where(keep, 1.0 / np.sqrt(np.maximum(values, 1e-300)), 0.0)
    white = np.einsum("kab,kb,kcb->kac", vectors, inv_sqrt, vectors)  # own^(-1/2)
    whitened = np.einsum("kab,kmbc,mcd->kmad", white, gram, white)
    corr = np.minimum(np.linalg.svd(whitened, compute_uv=False)[..., 0], 1.0)
    degenerate: NDArray[np.bool_] = np.logical_not(np.all(keep, axis=1))
    return corr, degenerate


@dataclass(frozen=True)
class OrderSimilarity:
    """How alike orders 1..K of a harmonic look on a joint's readings: `on_readings` (K, K)
    the canonical correlation of their centred pairs over the distinct readings (diagonal:
    1 for an order degenerate there, else 0), `on_arc` (K, K) the same over the densely
    sampled arc (what no choice of steps on that arc changes: over a partial turn
    neighbouring orders overlap by resolution)."""

    on_readings: Array
    on_arc: Array

    def aliases(self, order: int) -> list[int]:
        """The orders the readings make as alike as `order` (ALIAS_CORRELATION or more)
        where the arc itself does not: what other steps, or general poses, tell apart."""
        alike = self.on_readings[order - 1] >= ALIAS_CORRELATION
        alike &= self.on_arc[order - 1] < ALIAS_CORRELATION
        alike[order - 1] = False
        return [int(m) + 1 for m in np.flatnonzero(alike)]

    def resolvable(self) -> int:
        """The highest K such that no order of 1..K is an alias of a lower one (`aliases`)
        or degenerate on the readings; how alike the arc itself makes neighbouring orders
        is `overlap`."""
        alias = (self.on_readings >= ALIAS_CORRELATION) & (self.on_arc < ALIAS_CORRELATION)
        np.fill_diagonal(alias, np.diag(self.on_readings) >= 1.0)  # degenerate
        for k in range(len(alias)):
            if alias[k, : k + 1].any():
                return k
        return len(alias)

    def overlap(self) -> int:
        """The largest gap between two orders the arc itself makes alike (0: none, a full
        turn): over a partial turn orders closer than about a turn per arc overlap, on any
        steps."""
        k = np.arange(1, len(self.on_arc) + 1)
        gaps = np.abs(k[:, None] - k[None, :])[self.on_arc >= ALIAS_CORRELATION]
        return int(gaps.max()) if gaps.size else 0


def order_similarity(q: Array, max_order: int = MAX_ORDER) -> OrderSimilarity:
    """`OrderSimilarity` of orders 1..max_order on readings q (n,) [rad]."""
    u = distinct_readings(q)
    if len(u) < 3:  # at most two readings: no order is told from any other
        ones = np.ones((max_order, max_order))
        return OrderSimilarity(ones, np.zeros((max_order, max_order)))
    corr, degenerate = _canonical(u, max_order)
    np.fill_diagonal(corr, np.where(degenerate, 1.0, 0.0))
    arc, _ = _canonical(np.linspace(u[0], u[-1], DENSE_READINGS), max_order)
    np.fill_diagonal(arc, 0.0)
    return OrderSimilarity(corr, arc)


def resolvable_order(q: Array, max_order: int = MAX_ORDER) -> int:
    """The highest order K such that the readings q (n,) [rad] alias no two orders of 1..K
    (`OrderSimilarity.resolvable`); max_order when they alias none. A full turn in
    n equal steps resolves (n - 1) // 2 (order k and n - k coincide there); the same number
    of steps over a partial turn, or irregular steps, resolve more, a short arc fewer."""
    return order_similarity(q, max_order).resolvable()


def orders_at_once(q: Array) -> int:
    """How many harmonic orders readings q (n,) [rad] can fit together: half the distinct
    readings less one (each order takes two unknowns, the mean one more)."""
    return max((len(distinct_readings(q)) - 1) // 2, 0)
