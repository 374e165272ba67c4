"""ISO 9283 pose accuracy (AP) and pose repeatability (RP), of positions and, where a
6-DoF probe measured them, of orientations, from repeat poses: the robot commanded to the
same readings several times (the `iso9283` plan's cube points P1..P5 over its cycles, or
any pose a recording revisits).

For a pose j measured n times at points x_i (tracker frame) and the position x_c a model
says the robot is at (the "command" of ISO 9283: the nominal model before calibration, the
calibrated one after):
  AP_j = |mean(x_i) - x_c|                      (accuracy of the barycentre)
  RP_j = mean(l_i) + 3 S_l, l_i = |x_i - mean(x_i)|, S_l their sample standard deviation
RP does not depend on the model: it is the robot's (and the tracker's) repeatability; AP
is where calibration shows.

Distance accuracy and repeatability (ISO 9283 7.3), between two repeated poses A and B
visited in the same cycles (the cube's P2 and P4, else the first two): D_i the measured
distance |x_B,i - x_A,i| in cycle i, D_c the model's,
  AD = mean(D_i) - D_c,  RD = 3 S_D;
of orientation, with d_i = e_B,i - e_A,i (the change of the orientation error from A to B,
per component a, b, c), AD_a = |mean(d_a)| and RD_a = 3 S_(d_a) [deg].

Orientation (ISO 9283 7.2.2 and 7.2.3, its a, b, c about the x, y, z axes): with e_i the
rotation vector of the model's orientation against the measured one (small angles: its
components are the deviations about x, y, z of the tracker frame),
  AP_a = |mean(e_a)|,  RP_a = 3 S_a  (S_a the sample standard deviation of e_a),
and the same for b and c, in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.measurements import Recording
from robot_calib.poses import JOINT_CHANGE_TOLERANCE
from robot_calib.records import Record

MIN_REPEATS = 3  # measurements of one pose for its figures (ISO 9283 asks for 30 cycles)


@dataclass(frozen=True)
class PoseFigures(Record):
    """One repeated pose: its measurements `n`, AP and RP [mm], its first measurement's
    index in the recording scored (0-based), and where its orientation was measured at
    least MIN_REPEATS times, AP_a, AP_b, AP_c and RP_a, RP_b, RP_c [deg] (None: not)."""

    first_index: int
    n: int
    ap_mm: float
    rp_mm: float
    ap_abc_deg: tuple[float, float, float] | None = None
    rp_abc_deg: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class DistanceFigures(Record):
    """ISO 9283 distance accuracy AD and repeatability RD between two repeated poses (their
    first measurements' indices), over the `n` cycles that visited both [mm], and of
    orientation per component a, b, c [deg] (None without orientations)."""

    first_index_a: int
    first_index_b: int
    n: int
    ad_mm: float
    rd_mm: float
    ad_abc_deg: tuple[float, float, float] | None = None
    rd_abc_deg: tuple[float, float, float] | None = None

    def line(self) -> str:
        orientation = (
            ""
            if self.ad_abc_deg is None or self.rd_abc_deg is None
            else f"; orientation AD max {max(self.ad_abc_deg):.4f} deg, RD max "
            f"{max(self.rd_abc_deg):.4f} deg"
        )
        return f"distance AD {self.ad_mm:+.4f} mm, RD {self.rd_mm:.4f} mm{orientation}"


@dataclass(frozen=True)
class Iso9283(Record):
    """ISO 9283 figures of one model on one recording (DIAGNOSIS.json `iso9283`)."""

    model: str
    scored_on: str
    poses: list[PoseFigures]
    ap_max_mm: float
    rp_max_mm: float
    # the largest AP_a/b/c and RP_a/b/c over the poses [deg]; None without orientations
    ap_orientation_max_deg: float | None = None
    rp_orientation_max_deg: float | None = None
    # AD and RD between two repeated poses (None: fewer than two poses with common cycles)
    distance: DistanceFigures | None = None

    def line(self) -> str:
        orientation = (
            ""
            if self.ap_orientation_max_deg is None or self.rp_orientation_max_deg is None
            else f"; orientation AP max {self.ap_orientation_max_deg:.4f} deg, RP max "
            f"{self.rp_orientation_max_deg:.4f} deg"
        )
        distance = "" if self.distance is None else f"; {self.distance.line()}"
        return (
            f"ISO 9283 ({self.model}, {len(self.poses)} repeated poses, {self.scored_on}): "
            f"AP max {self.ap_max_mm:.4f} mm, RP max {self.rp_max_mm:.4f} mm{orientation}"
            f"{distance}"
        )


def repeat_groups(recording: Recording, min_repeats: int = MIN_REPEATS) -> list[IntArray]:
    """Indices of the measurements of every pose measured at least `min_repeats` times
    (equal readings within JOINT_CHANGE_TOLERANCE, same target, and the same approach
    direction of every joint: ISO 9283 approaches a pose the same way each cycle, and a
    visit from the other side differs by the backlash, which is no repeatability), in
    order of first visit."""
    poses = recording.poses
    key = np.column_stack(
        [np.round(poses.q / JOINT_CHANGE_TOLERANCE), poses.direction, poses.target_index]
    )
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    counts = np.bincount(inverse, minlength=len(first))
    order = np.argsort(inverse, kind="stable")  # each key's measurements in recording order
    members = np.split(order, np.cumsum(counts)[:-1])  # by key, O(n log n)
    return [members[g] for g in np.argsort(first) if counts[g] >= min_repeats]


def iso9283(
    recording: Recording,
    predicted: Array,
    model: str,
    scored_on: str,
    groups: list[IntArray] | None = None,
    orientation_errors: Array | None = None,
) -> Iso9283 | None:
    """AP and RP of every repeated pose of `recording` (`groups`, default its
    `repeat_groups`) for a model predicting `predicted` (n, 3) [m] at its measurements, and
    of orientation from `orientation_errors` (n, 3), the rotation vectors of the model's
    orientation against the measured one [rad] (NaN where none was measured; None:
    none); None when no pose is repeated MIN_REPEATS times."""
    figures = []
    groups = repeat_groups(recording) if groups is None else groups
    for group in groups:
        measured = recording.points[group]
        centre = measured.mean(axis=0)
        command = predicted[group].mean(axis=0)
        distance = np.linalg.norm(measured - centre, axis=1)
        rp = distance.mean() + 3.0 * distance.std(ddof=1)
        ap_abc, rp_abc = _orientation(
            None if orientation_errors is None else orientation_errors[group]
        )
        figures.append(
            PoseFigures(
                int(group[0]),
                len(group),
                float(np.linalg.norm(centre - command) * 1e3),
                float(rp * 1e3),
                ap_abc,
                rp_abc,
            )
        )
    if not figures:
        return None
    oriented = [f for f in figures if f.ap_abc_deg is not None and f.rp_abc_deg is not None]
    return Iso9283(
        model,
        scored_on,
        figures,
        max(f.ap_mm for f in figures),
        max(f.rp_mm for f in figures),
        max((max(f.ap_abc_deg) for f in oriented if f.ap_abc_deg), default=None),
        max((max(f.rp_abc_deg) for f in oriented if f.rp_abc_deg), default=None),
        _distance(recording, predicted, groups, orientation_errors),
    )


Triple = tuple[float, float, float]


def _distance(
    recording: Recording,
    predicted: Array,
    groups: list[IntArray],
    orientation_errors: Array | None,
) -> DistanceFigures | None:
    """AD and RD between the cube's P2 and P4 (the second and fourth repeated pose, as
    ISO 9283 takes them), else the first two; their measurements paired by cycle (the
    k-th visit of each); None with fewer than two poses or MIN_REPEATS common cycles."""
    if len(groups) < 2:
        return None
    a, b = (groups[1], groups[3]) if len(groups) >= 4 else (groups[0], groups[1])
    n = min(len(a), len(b))
    if n < MIN_REPEATS:
        return None
    a, b = a[:n], b[:n]
    measured = np.linalg.norm(recording.points[b] - recording.points[a], axis=1)
    command = np.linalg.norm(predicted[b].mean(axis=0) - predicted[a].mean(axis=0))
    # |mean| and 3 S of the change of the orientation error: as a pose's AP and RP
    ad_abc, rd_abc = _orientation(
        None if orientation_errors is None else orientation_errors[b] - orientation_errors[a]
    )
    return DistanceFigures(
        int(a[0]),
        int(b[0]),
        n,
        float((measured.mean() - command) * 1e3),
        float(3.0 * measured.std(ddof=1) * 1e3),
        ad_abc,
        rd_abc,
    )


def _orientation(errors: Array | None) -> tuple[Triple | None, Triple | None]:
    """AP_a, AP_b, AP_c and RP_a, RP_b, RP_c [deg] of one pose's orientation errors (m, 3)
    [rad] (rows with NaN left out); (None, None) with fewer than MIN_REPEATS."""
    if errors is None:
        return None, None
    rows = errors[np.isfinite(errors).all(axis=1)]
    if len(rows) < MIN_REPEATS:
        return None, None
    ap = np.degrees(np.abs(rows.mean(axis=0)))
    rp = np.degrees(3.0 * rows.std(axis=0, ddof=1))
    return (float(ap[0]), float(ap[1]), float(ap[2])), (float(rp[0]), float(rp[1]), float(rp[2]))
