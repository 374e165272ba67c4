"""Which measurements go to the hold-out set (`robot-calib split`): a random share, or the
last share in visiting order or in time (what a later recording would test)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError
from robot_calib.measurements.recording import Recording

SPLITS = ("random", "order", "time")


def holdout_mask(
    recording: Recording, fraction: float, by: str = "random", seed: int = 0
) -> NDArray[np.bool_]:
    """(n,) True for the measurements held out: `fraction` (0 < f < 1) of them, at random
    (`seed`), or the last ones in visiting order or in time. InputError when either set
    would be empty."""
    if by not in SPLITS:
        raise InputError(f"--by {by}: expected one of {', '.join(SPLITS)}")
    if not 0.0 < fraction < 1.0:
        raise InputError(f"--holdout {fraction}: a fraction between 0 and 1")
    n = len(recording)
    k = int(round(fraction * n))
    if not 0 < k < n:
        raise InputError(f"--holdout {fraction} of {n} measurements leaves a set empty")
    if by == "random":
        order = np.random.default_rng(seed).permutation(n)
    elif by == "order":
        order = np.arange(n)[::-1]
    else:
        order = np.argsort(-recording.poses.time, kind="stable")
    mask = np.zeros(n, dtype=bool)
    mask[order[:k]] = True
    return mask
