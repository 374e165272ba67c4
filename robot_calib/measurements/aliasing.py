"""Which joint-angle harmonic orders a joint's readings tell apart.

A harmonic C cos(k q) + S sin(k q) of a joint's reading q is only known at the readings
measured. Single-joint sweeps in regular steps alias orders: on a full turn in n equal
steps order k and n - k take the same values; over a partial turn they nearly do, and
orders closer than about one cycle per arc overlap by resolution. `order_correlation`
measures how alike two orders look on the readings (the canonical correlation of their
(cos, sin) pairs), `aliases` lists the orders one cannot be told from, and
`resolvable_order` is the highest order below which no two are aliases: what
`diagnose`'s frequency scan can tell apart and what `plan` reports for a plan. Random
general poses and sweeps of irregular steps (`plan.sweeps`) resolve every order up to
MAX_ORDER.
"""

from __future__ import annotations

import numpy as np

from robot_calib.kinematics.frames import Array

MAX_ORDER = 64  # the orders considered: 1..MAX_ORDER per turn of the joint
READING_RESOLUTION_RAD = 1e-4  # readings closer than this count as one (joint at rest)
#: two orders whose (cos, sin) pairs on a joint's readings correlate this much or more
#: (canonical correlation) are aliases: the readings cannot tell which of them the robot has
ALIAS_CORRELATION = 0.9
#: orders closer than this many cycles per the readings' arc are neighbours, not aliases
NEIGHBOUR_CYCLES = 1.5


def order_correlation(q: Array, max_order: int = MAX_ORDER) -> Array:
    """How alike orders 1..max_order of a harmonic look on readings q (n,) [rad]: (K, K) the
    canonical correlation of each order's pair cos(k q), sin(k q) with each other order's
    over the distinct readings (1: the readings cannot tell them apart at all). The
    diagonal is 1 for an order whose pair is degenerate there (e.g. sin(k q) = 0 at every
    reading: its phase is unknown), else 0; neighbours closer than NEIGHBOUR_CYCLES cycles
    per the readings' arc get 0: over a partial turn neighbouring orders overlap by
    resolution, not by aliasing. From the sums of cos(d q), sin(d q), d = 0..2K, not
    from the (n, 2K) columns."""
    u = np.unique(np.round(np.asarray(q, dtype=float) / READING_RESOLUTION_RAD))
    u = u * READING_RESOLUTION_RAD
    k = np.arange(1, max_order + 1)
    if len(u) < 3:  # at most two readings: no order is told from any other
        return np.ones((max_order, max_order))
    d = np.arange(0, 2 * max_order + 1)
    angle = np.outer(d, u)
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
    own = gram[k - 1, k - 1]  # (K, 2, 2)
    values, vectors = np.linalg.eigh(own)
    degenerate = values[:, 0] <= 1e-6 * len(u)
    inv_sqrt = np.where(values > 1e-6 * len(u), 1.0 / np.sqrt(np.maximum(values, 1e-300)), 0.0)
    white = np.einsum("kab,kb,kcb->kac", vectors, inv_sqrt, vectors)  # own^(-1/2)
    whitened = np.einsum("kab,kmbc,mcd->kmad", white, gram, white)
    corr = np.linalg.svd(whitened, compute_uv=False)[..., 0]
    arc = min(float(u[-1] - u[0]), 2.0 * np.pi)
    corr[diff < NEIGHBOUR_CYCLES * 2.0 * np.pi / max(arc, 1e-9)] = 0.0
    np.fill_diagonal(corr, np.where(degenerate, 1.0, 0.0))
    return np.minimum(corr, 1.0)


def aliases(correlation: Array, order: int) -> list[int]:
    """The orders the readings of `correlation` (`order_correlation`) cannot tell `order`
    from (canonical correlation >= ALIAS_CORRELATION), lowest first."""
    row = correlation[order - 1]
    return [int(m) + 1 for m in np.flatnonzero(row >= ALIAS_CORRELATION) if m != order - 1]


def resolvable_order(q: Array, max_order: int = MAX_ORDER) -> int:
    """The highest order K such that the readings q (n,) [rad] tell orders 1..K apart (no
    two of them aliases: `order_correlation` >= ALIAS_CORRELATION; an order whose pair is
    degenerate on them counts as aliased); max_order when every scanned order is. A full
    turn in n equal steps resolves (n - 1) // 2 (order k and n - k coincide there); the
    same number of steps over a partial turn, or irregular steps, resolve more."""
    if len(np.unique(np.round(np.asarray(q, dtype=float) / READING_RESOLUTION_RAD))) < 3:
        return 0
    return resolvable(order_correlation(q, max_order))


def resolvable(correlation: Array) -> int:
    """`resolvable_order` from the readings' `order_correlation` (K, K): the highest K
    such that no order of 1..K is an alias of a lower one."""
    clash = correlation >= ALIAS_CORRELATION
    for k in range(len(clash)):
        if clash[k, : k + 1].any():  # order k + 1 is degenerate or an alias of a lower one
            return k
    return len(clash)


def orders_at_once(q: Array) -> int:
    """How many harmonic orders readings q (n,) [rad] can fit together: half the distinct
    readings less one (each order takes two unknowns, the mean one more)."""
    distinct = len(np.unique(np.round(np.asarray(q, dtype=float) / READING_RESOLUTION_RAD)))
    return max((distinct - 1) // 2, 0)
