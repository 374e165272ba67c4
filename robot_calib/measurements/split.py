"""Which measurements go to the hold-out set (`robot-calib split`): a random share, or the
last share in visiting order or in time (what a later recording would test)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError, param
from robot_calib.kinematics.frames import IntArray
from robot_calib.measurements.recording import Recording
from robot_calib.poses import reading_groups

SPLITS = ("random", "order", "time")
N_FOLDS = 5  # the folds of every k-fold over poses (the ladder's, the evidence's)


def holdout_mask(
    recording: Recording, fraction: float, by: str = "random", seed: int = 0
) -> NDArray[np.bool_]:
    """(n,) True for the measurements held out: `fraction` (0 < f < 1) of them (up to the
    last pose's measurements), whole poses (every measurement at the readings of a
    held-out one: its targets, re-reads and repeats, which would otherwise be fitted copies
    of held-out points): poses at random (`seed`), or those first measured last in visiting
    order or in time (a pose revisited at the end stays with its first visit). InputError
    when either set would be empty."""
    if by not in SPLITS:
        raise InputError(f"{param('by', by)}: expected one of {', '.join(SPLITS)}")
    if not 0.0 < fraction < 1.0:
        raise InputError(f"{param('fraction', fraction)}: a fraction between 0 and 1")
    n = len(recording)
    k = int(round(fraction * n))
    if not 0 < k < n:
        raise InputError(f"{param('fraction', fraction)} of {n} measurements leaves a set empty")
    group = reading_groups(recording.poses.q)  # one pose's reads and targets together
    n_groups = int(group.max()) + 1
    if by == "random":
        key = np.random.default_rng(seed).permutation(n_groups).astype(float)
    else:  # the poses first measured last (a pose revisited late stays with its first visit)
        when = np.arange(n, dtype=float) if by == "order" else recording.poses.time
        first = np.full(n_groups, np.inf)
        np.minimum.at(first, group, when)
        key = -first
    picked = np.argsort(key, kind="stable")
    sizes = np.bincount(group, minlength=n_groups)[picked]
    taken = picked[: int(np.searchsorted(np.cumsum(sizes), k)) + 1]  # whole poses, >= k
    mask = np.isin(group, taken)
    if mask.all():
        raise InputError(
            f"{param('fraction', fraction)}: every measurement is of a pose held out "
            "(its other reads): nothing left to fit"
        )
    return mask


def folds(n: int, k: int = N_FOLDS, seed: int = 0) -> IntArray:
    """Fold number (n,) of every pose: a fixed random split into k folds of whole poses."""
    return np.random.default_rng(seed).permutation(n) % k


def pose_folds(recording: Recording) -> IntArray:
    """Fold number (n,) of every measurement: `folds` of the groups of measurements at the
    same joint readings (`poses.reading_groups`), so that the targets measured at one pose,
    its re-reads and its repeats fall in one fold (a re-read in another fold is a copy of
    a fitted point: the k-fold figure of a campaign of 3 reads per pose was 5 x too good)."""
    group = reading_groups(recording.poses.q)
    return folds(int(group.max()) + 1 if len(group) else 0)[group]
