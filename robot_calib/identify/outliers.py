"""Tracker blunders (a lost beam, a reseated target): measured points far from what the
model predicts, relative to a robust scale of all the residuals.

The scale is robust: the median of the points' residual norms, divided by the median of
chi(3 dof) = 1.5382 (for isotropic Gaussian noise of sigma per axis the norm is sigma x
chi(3)), which blunders (fewer than half the points) do not move. Norms, not components:
the residual of an unmodelled joint effect lies mostly along one direction (a turn about a
vertical axis moves nothing in z), and pooled components would put a third of the values
near zero and the scale far too low. A point whose norm exceeds OUTLIER_K of those sigmas
is flagged: for Gaussian noise that is a 1e-13 event, never seen on clean data, while a
1 mm blunder is 100-200 sigmas for a tracker of a few um. The systematic structure of an
unmodelled effect is smooth and spread over many poses (judged per sweep: `group_sigmas`),
so it raises the scale rather than standing out: the diagnosis still sees it.

Robot or tracker (`robot_errors`): with several targets on the tool, a pose whose targets
are all off together as one rigid tool is the robot (or the whole set-up) not where the
model puts it, not the tracker: reported as such, a place where the model misses. Like
blunders they are left out of the fit: a few poses millimetres off would pull every other
pose (on a simulated KR5, 3 such poses of 80 at 2.4 mm raise the other poses' residual of
the geometric fit from 0.009 to 0.163 mm rms). With reference reflectors read at the pose
(msgs_doc/references.md) the tracker is ruled in or out directly: references off as far as
the tool (its frame moved) make the pose's flagged points the tracker's; references in
place confirm the robot.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from robot_calib.identify.reports import ROBOT, Outlier
from robot_calib.kinematics.frames import Array
from robot_calib.measurements import Recording
from robot_calib.messages import target_topic

#: a point whose residual norm exceeds this many robust sigmas (per axis) is a blunder
OUTLIER_K = 8.0
#: the robust sigma never goes below this [m]: no tracker resolves better, and exact
#: (noise-free) data would otherwise flag round-off
MIN_SIGMA_M = 1e-7
MEDIAN_CHI3 = 1.5382  # median of chi with 3 degrees of freedom (the norm of 3 unit normals)


def robust_sigma(residuals: Array) -> float:
    """Robust sigma [m] per axis from residuals (n, 3) [m]: the median residual norm over
    MEDIAN_CHI3 (at least MIN_SIGMA_M)."""
    norms = np.linalg.norm(np.asarray(residuals, dtype=float).reshape(-1, 3), axis=1)
    if not len(norms):
        return MIN_SIGMA_M
    return max(float(np.median(norms)) / MEDIAN_CHI3, MIN_SIGMA_M)


def outlier_mask(
    residuals: Array, sigma: float | Array, k: float = OUTLIER_K
) -> NDArray[np.bool_]:
    """(n,) True where a point's residual norm [m] exceeds k x `sigma` [m] (one scale, or
    one per point (n,))."""
    return np.asarray(np.linalg.norm(residuals, axis=1) > k * np.asarray(sigma))


def group_sigmas(recording: Recording, residuals: Array) -> Array:
    """(n,) robust sigma [m] for judging each measurement: that of its group (its circle
    sweep; the general poses of its source), never below that of all points.

    An unmodelled effect of one joint leaves its residual mostly in that joint's own
    sweeps, tens of sigmas of the other sweeps' noise: judged against its own sweep, such
    structure is the bulk and not flagged, while a blunder still stands out among its
    neighbours. residuals : (n, 3) of every measurement [m], flagged ones included (a
    median ignores a minority of blunders; leaving them out would shrink the scale)."""
    floor = robust_sigma(residuals)
    out = np.full(len(recording), floor)
    groups = [s.index for s in recording.sweeps]
    general = recording.general
    groups += [
        np.flatnonzero(general & (recording.bag_index == b))
        for b in np.unique(recording.bag_index)
    ]
    for index in groups:
        if len(index):
            out[index] = max(floor, robust_sigma(residuals[index]))
    return out


def outlier_counts(outliers: Sequence[Outlier]) -> str:
    """'3 tracker blunder(s)', or '2 tracker blunder(s), 6 measurement(s) of poses where
    the robot was off (every target together)'."""
    robot = sum(o.kind == ROBOT for o in outliers)
    parts = [f"{len(outliers) - robot} tracker blunder(s)"] if len(outliers) > robot else []
    if robot:
        parts.append(
            f"{robot} measurement(s) of poses where the robot was off (every target together)"
        )
    return ", ".join(parts)


#: the targets of a pose that one rigid motion takes from their predicted points to their
#: measured ones, to this many robust sigmas, moved as one tool
RIGID_K = 5.0


def tracker_moved(recording: Recording, residuals: Array) -> NDArray[np.bool_]:
    """(n,) True where the reference reflectors read with a measurement's pose lay off the
    tracker's drift by half its residual (n, 3) [m] or more, and by RIGID_K of their own
    noise: the tracker's frame moved there, whatever the tool did."""
    leftover = recording.reference_leftover_m()
    noise = np.zeros(len(recording))
    for reads in recording.references:
        if reads.drift is not None:
            noise[recording.bag_index == reads.source] = reads.drift.noise_mm * 1e-3
    size = np.linalg.norm(residuals, axis=1)
    with np.errstate(invalid="ignore"):
        return np.asarray(
            np.isfinite(leftover) & (leftover >= 0.5 * size) & (leftover > RIGID_K * noise)
        )


def robot_errors(
    recording: Recording, mask: NDArray[np.bool_], residuals: Array, sigma: Array
) -> NDArray[np.bool_]:
    """(n,) True for the flagged measurements (mask (n,)) that are a robot error, not a
    tracker blunder: at a pose (`Recording.pose_index`) with two or more targets, one rigid
    motion takes every target's predicted point to its measured one, flagged or not, to
    RIGID_K robust `sigma` (n,) [m] (Kabsch; with two targets, their distance kept): the
    tool moved as one (a turn about one target leaves that one unflagged); and the
    reference reflectors read there, if any, did not move with it (`tracker_moved`).
    residuals (n, 3): predicted - measured [m]."""
    from scipy.spatial.transform import Rotation

    out = np.zeros(len(mask), dtype=bool)
    if len(recording.target_names) < 2 or not mask.any():
        return out
    mask = mask & ~tracker_moved(recording, residuals)
    pose = recording.pose_index()
    predicted = recording.points + residuals
    for p in np.unique(pose[mask]):
        rows = np.flatnonzero(pose == p)
        if len(rows) < 2:
            continue
        measured, model = recording.points[rows], predicted[rows]
        if len(rows) == 2:
            gap = abs(
                float(np.linalg.norm(measured[0] - measured[1]))
                - float(np.linalg.norm(model[0] - model[1]))
            )
        else:
            rotation, _ = Rotation.align_vectors(
                measured - measured.mean(0), model - model.mean(0)
            )
            moved = rotation.apply(model - model.mean(0)) + measured.mean(0)
            gap = float(np.linalg.norm(moved - measured, axis=1).max())
        if gap <= RIGID_K * float(np.max(sigma[rows])):
            out[rows[mask[rows]]] = True
    return out


def describe_outliers(
    recording: Recording, mask: NDArray[np.bool_], residuals: Array, sigma: float | Array
) -> tuple[Outlier, ...]:
    """The flagged measurements of `recording` (mask (n,)) with residuals (n, 3) predicted
    minus measured [m] of the model they were judged against, robust `sigma` [m] (one, or
    one per measurement)."""
    sigmas = np.broadcast_to(np.asarray(sigma, dtype=float), (len(recording),))
    robot = robot_errors(recording, mask, residuals, sigmas)
    several = len(recording.target_names) > 1
    refs = recording.reference_leftover_m()
    out = []
    indices = recording.message_indices()
    for i in np.flatnonzero(mask):
        offset = -np.asarray(residuals[i], dtype=float)  # measured - predicted
        size = float(np.linalg.norm(offset))
        direction = (offset / size if size > 0 else offset).tolist()
        out.append(
            Outlier(
                recording.sources[int(recording.bag_index[i])],
                int(indices[i]),
                None if recording.stamp_ns is None else int(recording.stamp_ns[i]),
                size,
                [float(c) for c in direction],
                size / float(sigmas[i]),
                target_topic(recording.target_names[int(recording.poses.target_index[i])])
                if several
                else "",
                ROBOT if robot[i] else "tracker",
                None if not np.isfinite(refs[i]) else float(refs[i]),
            )
        )
    return tuple(out)
