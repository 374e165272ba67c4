"""The calibrated DH/Hayati table as CSV, one row per joint, for controllers that take DH
corrections: every value in SI with its 1-sigma, then in mm / deg for people.

theta_j is the table's value (the joint variable adds M q + offset of the robot's
`reading_to_joint`, msgs_doc/robots.md); beta_j is 0 on joints without a Hayati beta. A
parameter the calibration did not estimate (fixed: redundant, dropped for the Hayati beta,
or not identifiable from the data) has 1-sigma 0 and is named in the `fixed` column.
"""

from __future__ import annotations

import csv
import io
from typing import TYPE_CHECKING

import numpy as np

from robot_calib.export.base import Exporter, number
from robot_calib.model import DH_UNITS

if TYPE_CHECKING:
    from robot_calib.identify.calibration import Calibration

FIELDS = tuple(DH_UNITS)  # theta, d, a, alpha, beta
HUMAN = {"m": ("mm", 1e3), "rad": ("deg", float(np.degrees(1.0)))}


def header() -> list[str]:
    """The CSV's column names, each with its unit."""
    si = [c for f in FIELDS for c in (f"{f}_{DH_UNITS[f]}", f"{f}_std_{DH_UNITS[f]}")]
    human = [f"{f}_{HUMAN[DH_UNITS[f]][0]}" for f in FIELDS]
    human += [f"{f}_std_{HUMAN[DH_UNITS[f]][0]}" for f in FIELDS]
    return ["joint", "name", *si, *human, "fixed"]


def render(cal: Calibration, source: str) -> str:
    """The CSV text of calibration `cal`'s DH/Hayati table (`source` is not written: a CSV
    has no comment lines that every reader skips)."""
    params, robot = cal.parameters, cal.model.robot
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header())
    for j in range(1, robot.n_joints + 1):
        values, sigmas, fixed = [], [], []
        for field in FIELDS:
            name = f"{field}{j}"
            if name in params:
                k = params.index(name)
                values.append(params[name])
                sigmas.append(float(cal.std[k]) if params.free[k] else 0.0)
                if not params.free[k]:
                    fixed.append(name)
            else:  # no beta on this joint: 0, not a parameter
                values.append(0.0)
                sigmas.append(0.0)
        si = [number(v) for pair in zip(values, sigmas) for v in pair]
        scales = [HUMAN[DH_UNITS[f]][1] for f in FIELDS]
        human = [f"{v * s:.6f}" for v, s in zip(values, scales)]
        human += [f"{v * s:.6f}" for v, s in zip(sigmas, scales)]
        writer.writerow([j, robot.joint_names[j - 1], *si, *human, " ".join(fixed)])
    return out.getvalue()


EXPORTER = Exporter("dh", ".csv", "the DH/Hayati table with 1-sigma (CSV, SI and mm/deg)", render)
