"""Resuming a campaign: which plan poses the bags written so far already hold, and the
name of the next bag part.

A campaign writes OUT.mcap; a resumed one (OUT.mcap exists) writes OUT.part2.mcap, then
OUT.part3.mcap, ... and never touches the parts before (an input is never overwritten).
A plan pose counts as measured when a paired measurement of some part lies within
`match_rad` of it on every joint (matched in visiting order: `measured`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array

MAX_PARTS = 999


def part_path(output: Path, part: int) -> Path:
    """Part `part` (1 = OUT.mcap itself) of campaign bag `output`."""
    return output if part == 1 else output.with_name(f"{output.stem}.part{part}{output.suffix}")


def existing_parts(output: Path) -> list[Path]:
    """The campaign's bags written so far, in order (none: [])."""
    parts = []
    for part in range(1, MAX_PARTS + 1):
        path = part_path(output, part)
        if not path.exists():
            break
        parts.append(path)
    return parts


def measured(plan_q: Array, parts: list[Path], robot: RobotDescription, match_rad: float) -> Array:
    """(n,) bool: plan poses plan_q (n, J) [rad] already measured in `parts` (BagError for a
    part that cannot be read, e.g. one whose writer was killed: repair it first).

    Matched in visiting order, one plan pose per recorded pose: each recorded pose takes
    the first unmeasured plan pose within `match_rad` after the one matched before it (else
    the first unmeasured one anywhere), so a plan that visits a pose twice (forth and back,
    ISO 9283 cycles) still has its second visit to do."""
    from robot_calib.bag.read import read_recording

    done = np.zeros(len(plan_q), dtype=bool)
    if not parts:
        return done
    recorded = read_recording([str(p) for p in parts], robot).poses.q  # (m, J)
    after = 0
    for q in recorded:
        close = np.all(np.abs(plan_q - q) <= match_rad, axis=1) & ~done
        later = np.flatnonzero(close[after:])
        if len(later):
            k = after + int(later[0])
        elif close.any():
            k = int(np.flatnonzero(close)[0])
        else:
            continue
        done[k] = True
        after = k + 1
    return done
