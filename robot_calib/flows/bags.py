"""The paired measurements of bags for every flow: each bag given once, each measurement
recorded once (a copy of a bag under another name is refused)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.log import Log
from robot_calib.measurements import PAIR_TOLERANCE_S

if TYPE_CHECKING:
    from robot_calib.measurements import Recording


def read_bags(
    bags: Sequence[str | Path],
    robot: RobotDescription,
    pair_tolerance: float = PAIR_TOLERANCE_S,
    log: Log | None = None,
) -> Recording:
    """The paired measurements of `bags` (msgs_doc/specification.md section 1).

    Returns
    -------
    recording : Recording
        As `robot_calib.bag.read.read_recording`: poses (n), points (n, 3) [m], sweeps,
        the bag of each pose, unpaired points and warnings.
    """
    from robot_calib.bag.read import read_recording

    check_distinct_bags(bags)
    recording = read_recording(bags, robot, pair_tolerance, log=log)
    check_distinct_recordings(recording)
    return recording


@dataclass(frozen=True)
class ReadBags:
    """The measurements of calibration bags and hold-out bags (`read_inputs`), and the
    lines their reading logged (warnings) when they were kept rather than logged."""

    recording: Recording
    holdout: Recording | None
    lines: tuple[str, ...] = ()

    def replay(self, log: Log | None) -> None:
        """Log the kept lines (a reading done in another process: `read_inputs`)."""
        if log is not None:
            for line in self.lines:
                log(line)


def read_inputs(
    bags: Sequence[str | Path],
    holdout: Sequence[str | Path],
    robot: RobotDescription,
    pair_tolerance: float = PAIR_TOLERANCE_S,
    log: Log | None = None,
) -> ReadBags:
    """The paired measurements of `bags` and of the `holdout` bags (none: None), each bag
    given once and each measurement recorded once (`check_distinct_bags`,
    `check_distinct_recordings`). The reading's lines (warnings) go to `log` as they come;
    without one they are kept (`ReadBags.lines`, `ReadBags.replay`): for a reading in
    another process whose output is not this one's."""
    kept: list[str] = []
    say = kept.append if log is None else log
    check_distinct_bags(bags, holdout)
    recording = read_bags(bags, robot, pair_tolerance, say)
    held = read_bags(holdout, robot, pair_tolerance, say) if holdout else None
    if held is not None:
        check_distinct_recordings(recording, held)
    return ReadBags(recording, held, tuple(kept))


def check_distinct_bags(bags: Sequence[str | Path], holdout: Sequence[str | Path] = ()) -> None:
    """InputError naming the bag when one is given twice, or as calibration and hold-out
    bag (a "held-out" score would be in-sample, and sigmas would shrink by sqrt 2)."""
    seen: list[tuple[Path, str]] = []
    for raw, role in [(b, "calibration") for b in bags] + [(b, "hold-out") for b in holdout]:
        path = Path(raw)
        for other, other_role in seen:
            same = (
                path.exists() and other.exists() and os.path.samefile(path, other)
            ) or path.resolve() == other.resolve()
            if same:
                how = "twice" if role == other_role else "as calibration and as hold-out bag"
                raise InputError(f"{path}: the same bag given {how} (as {other}); give it once")
        seen.append((path, role))


def check_distinct_recordings(*recordings: Recording) -> None:
    """InputError when two sources (bags) of `recordings` hold the same measurements, as a
    copy of a bag under another name does: half or more of one's measurements (readings
    and point, to 1 nrad / 1 nm: a tracker never measures a point twice alike) are also the
    other's, whatever their stamps (the path check, `check_distinct_bags`, cannot see a
    copy; two halves of one CSV imported apart share synthetic stamps, not measurements)."""
    sources = [
        (rec.sources[b], _measurement_keys(rec, rec.bag_index == b))
        for rec in recordings
        for b in range(len(rec.sources))
    ]
    for k, (first, keys) in enumerate(sources):
        for second, others in sources[k + 1 :]:
            shared = len(keys & others)
            if keys and others and shared >= 0.5 * min(len(keys), len(others)):
                raise InputError(
                    f"{second}: {shared} of its measurements (readings and point) are also in "
                    f"{first}: the same measurements twice (a copy?); give them once"
                )


def _measurement_keys(rec: Recording, rows: NDArray[np.bool_]) -> set[bytes]:
    """Each measurement of `rec` at `rows` as a key: its readings [nrad] and point [nm]."""
    values = np.column_stack([rec.poses.q[rows], rec.points[rows]])
    ok = np.all(np.isfinite(values), axis=1)
    scaled = np.round(values[ok] * 1e9).astype(np.int64)
    return {row.tobytes() for row in scaled}
