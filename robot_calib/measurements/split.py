"""Which measurements go to the hold-out set (`robot-calib split`): a random share, or the
last share in visiting order or in time (what a later recording would test)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError
from robot_calib.measurements.recording import Recording
from robot_calib.poses import reading_groups

SPLITS = ("random", "order", "time")


def holdout_mask(
    recording: Recording, fraction: float, by: str = "random", seed: int = 0
) -> NDArray[np.bool_]:
    """(n,) True for the measurements held out: about `fraction` (0 < f < 1) of them, at
    random (`seed`), or the last ones in visiting order or in time, always whole poses (every
    measurement at the readings of a held-out one: its targets, re-reads and repeats, which
    would otherwise be fitted copies of held-out points). InputError when either set would
    be empty."""
    if by not in SPLITS:
        raise InputError(f"--by {by}: expected one of {', '.join(SPLITS)}")
    if not 0.0 < fraction < 1.0:
        raise InputError(f"--holdout {fraction}: a fraction between 0 and 1")
    n = len(recording)
    k = int(round(fraction * n))
    if not 0 < k < n:
        raise InputError(f"--holdout {fraction} of {n} measurements leaves a set empty")
    group = reading_groups(recording.poses.q)  # one pose's reads and targets together
    if by == "random":
        order = np.random.default_rng(seed).permutation(int(group.max()) + 1)[group]
        order = np.argsort(order, kind="stable")
    elif by == "order":
        order = np.arange(n)[::-1]
    else:
        order = np.argsort(-recording.poses.time, kind="stable")
    mask = np.isin(group, group[order[:k]])  # whole poses: about `fraction` of them
    if mask.all():
        raise InputError(f"--holdout {fraction}: every measurement is of a pose held out "
                         "(its other reads): nothing left to fit")  # fmt: skip
    return mask
