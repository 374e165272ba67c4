"""When the robot has settled at a pose: every joint within `tolerance_rad` of the target
for `settle_s` without a break (the readings' own stamps, so a late message cannot fake
a settled robot)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robot_calib.kinematics.frames import Array


@dataclass
class Settler:
    """Feed readings with `add(stamp_s, q)`; `settled_since` is the stamp [s] from which the
    robot has stayed within tolerance (None while not), `settled` once that lasted settle_s.

    target : (J,) [rad]; tolerance_rad : per joint [rad]; settle_s : [s]."""

    target: Array
    tolerance_rad: float
    settle_s: float
    settled_since: float | None = None
    last_stamp_s: float | None = None
    largest_error_rad: float = field(default=np.inf)

    def add(self, stamp_s: float, q: Array) -> None:
        """One joint reading (J,) [rad] stamped stamp_s [s]; older stamps are ignored."""
        if self.last_stamp_s is not None and stamp_s <= self.last_stamp_s:
            return
        self.last_stamp_s = stamp_s
        self.largest_error_rad = float(np.max(np.abs(np.asarray(q) - self.target)))
        if self.largest_error_rad <= self.tolerance_rad:
            if self.settled_since is None:
                self.settled_since = stamp_s
        else:
            self.settled_since = None

    @property
    def settled(self) -> bool:
        return (
            self.settled_since is not None
            and self.last_stamp_s is not None
            and self.last_stamp_s - self.settled_since >= self.settle_s
        )
