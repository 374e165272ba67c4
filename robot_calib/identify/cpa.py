"""Circle point analysis (seed sections 3 and 5): joint axes from circle sweeps, then the
DH/Hayati parameters by the geometry of consecutive axis lines (seed eq. 6-9).

Every sweep turns one joint while the others hold a common reference configuration
`q_ref`, so all axis lines are found in that one configuration, in the tracker frame.
From them, frame by frame, the DH/Hayati links by the line geometry of
`kinematics/axes.py` (`dh_from_axes`, shared with the URDF loader): common normals for
skew or intersecting axes, the Hayati alpha/beta for nominally parallel ones, the signs
chosen nearest the nominal alpha_j and a_j.

Sweeps, reference configuration and turning directions are in the robot's joint variables
(`RobotDescription.joint_variables`: the readings unless the robot declares a mapping), so a
sweep of joint j turns DH joint variable j even where two readings change together.

The base frame lies on axis 1 with d1 and theta1 at their nominal values (they are
redundant with the tracker pose); the target offset in the flange frame comes from the
last joint's sweep; link J keeps its nominal values (redundant with the target offset).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.errors import InputError
from robot_calib.identify.circles import Circle, robust_circle
from robot_calib.kinematics.axes import (
    AxisLine,
    common_normal,
    dh_from_axes,
    link_transform,
    rotate,
    wrap,
)
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array, matrix_to_rpy
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import Recording, Sweep
from robot_calib.messages import target_topic
from robot_calib.model import KinematicModel, geometric_parameters, target_parameters

REF_CONSISTENCY_RAD = 1e-3  # sweeps whose held joints differ by more break the CPA premise


@dataclass(frozen=True)
class SweepFit:
    """The circle of one sweep: joint, number of points, angle span [rad], circle, and the
    largest distance of its points from their centroid [m] (a circle fitted to points that
    hardly move, a target on the axis, can come out with any radius: this bounds it)."""

    joint: int
    n_points: int
    span_rad: float
    circle: Circle
    spread_m: float = float("inf")

    @property
    def lever_m(self) -> float:
        """The radius the axis direction can lean on [m]: the fitted one, at most the
        points' spread."""
        return min(self.circle.radius, self.spread_m)


@dataclass(frozen=True)
class CPAResult:
    """Identified parameters (geometric vector, tracker pose and target included), axis lines
    (J,), per-sweep circle fits, the reference joint variables q_ref (J,) [rad] (the
    reference readings, for a robot without a mapping) and warnings."""

    parameters: ParameterVector
    axes: tuple[AxisLine, ...]
    sweeps: tuple[SweepFit, ...]
    q_ref: Array
    warnings: tuple[str, ...]


#: a circle that fixes its axis direction worse than this [rad] (1-sigma) gets a warning
NEAR_AXIS_SIGMA_RAD = 1e-3


def turning_sign(circle: Circle, points: Array, readings: Array) -> float:
    """+1 when the points (k, 3) [m] turn positively about `circle.normal` as the readings
    (k,) [rad] grow, else -1. Taken from the readings, never from the order of the points:
    each point's angle about the normal must equal +-reading up to one constant, and the
    sign whose differences agree best (largest mean resultant length) wins. Steps above
    180 deg (144 deg over +-360 deg, or every other of those: 288 deg) work, where
    neighbouring points seem to turn the short way, backwards."""
    angles = circle.angles(points)
    return max((1.0, -1.0), key=lambda s: abs(np.mean(np.exp(1j * (angles - s * readings)))))


def direction_sigma(
    circle: Circle, n_points: int, noise: float = 0.0, lever: float | None = None
) -> float:
    """1-sigma [rad] of the axis direction a circle gives: the noise over the lever (the
    radius, or `lever` [m], e.g. `SweepFit.lever_m`) and sqrt(n/2) points' worth of lever.
    The noise is the circle's rms, but at least `noise` [m] (`pooled_circle_noise`): a
    circle of few points fits them nearly exactly (three distinct points: rms 0), which
    says nothing about how well it fixes its axis."""
    rms = max(circle.rms, noise)
    radius = circle.radius if lever is None else lever
    return float(rms / max(radius, 1e-12) / np.sqrt(max(n_points, 2) / 2.0))


def pooled_circle_noise(fits: list[SweepFit]) -> float:
    """The noise of the circle fits [m, per residual component]: the median over the
    circles with residual degrees of freedom to spare (2 n - 6 > 0: plane and radial
    residual per point, 6 circle parameters) of their rms scaled to those degrees of
    freedom (a median: one circle fitted to a target on its axis can diverge and must
    not set the noise of all); 0 when no circle has any to spare."""
    levels = [
        float(
            np.sqrt(
                (np.sum(f.circle.plane_residuals**2) + np.sum(f.circle.radial_residuals**2))
                / (2 * f.n_points - 6)
            )
        )
        for f in fits
        if 2 * f.n_points > 6
    ]
    return float(np.median(levels)) if levels else 0.0


def axis_from_sweep(points: Array, readings: Array, joint: int) -> tuple[AxisLine, Circle]:
    """Axis line and circle of one sweep: points (k, 3) [m], the turning joint's variable
    (k,) [rad] (its reading, without a mapping); the direction follows it (right-hand rule,
    `turning_sign`)."""
    circle, keep = robust_circle(points, f"sweep of joint {joint}")  # blunders left out
    points, readings = points[keep], readings[keep]
    direction = circle.normal * turning_sign(circle, points, readings)
    return AxisLine(circle.centre, direction), circle


def _sweep_name(recording: Recording, sweep: Sweep) -> str:
    """'sweep of joint J at measurements A-B' (and its target, when there are several)."""
    out = (
        f"sweep of joint {sweep.joint} at measurements {sweep.index[0] + 1}-{sweep.index[-1] + 1}"
    )
    if len(recording.target_names) > 1:
        name = recording.target_names[int(recording.poses.target_index[sweep.index[0]])]
        out += f" of {target_topic(name)}"
    return out


def _near_axis_warnings(
    recording: Recording, sweeps: list[Sweep], fits: list[SweepFit], sigma: list[float]
) -> list[str]:
    """A warning for each circle of one joint (its `sweeps`, their `fits` and direction
    1-sigma `sigma` [rad]) too small to fix the axis direction, saying whether other
    circles of the joint (other targets or sweeps) carry it instead."""
    good = sum(sd <= NEAR_AXIS_SIGMA_RAD for sd in sigma)
    out = []
    for s, fit, sd in zip(sweeps, fits, sigma):
        if sd <= NEAR_AXIS_SIGMA_RAD:
            continue
        then = (
            f"CPA leans on the joint's {good} other circle(s) instead"
            if good
            else "put a target farther off this axis"
        )
        out.append(
            f"warning: {_sweep_name(recording, s)}: the target is {fit.lever_m * 1e3:.2f} mm "
            "from the axis, too "
            f"close for its circle ({fit.circle.rms * 1e3:.4f} mm rms) to fix the axis "
            f"direction (1-sigma {np.degrees(sd):.3f} deg): {then}"
        )
    return out


def combine_lines(lines: list[tuple[int, float, AxisLine]]) -> AxisLine:
    """One axis line from the circles of its sweeps, each given as (points, direction
    1-sigma [rad], line): directions averaged by inverse variance, so that a target near
    the axis (a circle too small to fix the direction) gives way to the other targets and
    sweeps; the point on the line is the points-weighted mean of the centres of the
    circles that fix their direction (all, when none does): any well-fixed circle's centre
    lies on the axis, whatever its target, while one fitted to a target on the axis may
    lie anywhere."""
    sigma = np.array([max(sd, 1e-12) for _, sd, _ in lines])
    weights = 1.0 / sigma**2
    direction = sum((w * ln.direction for w, (_, _, ln) in zip(weights, lines)), np.zeros(3))
    direction = direction / np.linalg.norm(direction)
    good = sigma <= NEAR_AXIS_SIGMA_RAD
    counts = np.array([c for c, _, _ in lines], dtype=float) * (good if good.any() else 1.0)
    point = sum((c * ln.point for c, (_, _, ln) in zip(counts, lines)), np.zeros(3))
    return AxisLine(point / counts.sum(), direction)


def _target_from_geometry(
    recording: Recording, robot: RobotDescription, params: ParameterVector, name: str
) -> ParameterVector:
    """`params` with target `name`'s offset the mean of its points mapped into the flange
    frame by the geometry and tracker pose in `params` (every measurement of it)."""
    model = KinematicModel(robot, targets=recording.target_names)
    rows = recording.poses.target_index == recording.target_names.index(name)
    flange = model.flange2base(params, recording.poses.subset(rows))  # (k, 4, 4) base
    b2t = model.base2tracker(params)
    in_base = (recording.points[rows] - b2t[:3, 3]) @ b2t[:3, :3]  # R^T (p - t), (k, 3)
    rel = in_base - flange[:, :3, 3]
    offset = np.einsum("nji,nj->ni", flange[:, :3, :3], rel).mean(axis=0)
    return params.with_values(dict(zip(target_parameters(name), map(float, offset))))


def reference_readings(
    recording: Recording, n_joints: int, q: Array | None = None
) -> tuple[Array, list[str]]:
    """q_ref (J,) [rad]: each joint's value in `q` (n, J) [rad] (default: the readings)
    while later joints sweep (median), and warnings where sweeps were taken in different
    configurations of the joints before them."""
    q = recording.poses.q if q is None else q
    q_ref = np.zeros(n_joints)
    warnings = []
    for i in range(1, n_joints + 1):
        held = [s.index for s in recording.sweeps if s.joint != i]
        later = [s.index for s in recording.sweeps if s.joint > i] or held
        if not later:
            continue
        values = q[np.concatenate(later), i - 1]
        q_ref[i - 1] = np.median(values)
        if np.ptp(values) > REF_CONSISTENCY_RAD:
            warnings.append(
                f"warning: joint {i} is not held at one reading while the later joints sweep "
                f"(spread {np.degrees(np.ptp(values)):.3f} deg): CPA assumes one configuration"
            )
    return q_ref, warnings


def circle_point_analysis(recording: Recording, robot: RobotDescription) -> CPAResult:
    """The seed's CPA on the sweeps of `recording`: needs >= 1 sweep of every joint."""
    n = robot.n_joints
    missing = [j for j in range(1, n + 1) if not recording.sweeps_of(j)]
    if missing:
        raise InputError(
            f"{', '.join(recording.sources)}: circle point analysis needs a sweep of every "
            f"joint; none of joint(s) {missing}"
        )
    if robot.hayati[0]:
        raise InputError(f"{robot.name}: CPA needs axes 1 and 2 not parallel")
    variables = robot.joint_variables(recording.poses.q)  # (n, J) [rad]
    q_ref, warnings = reference_readings(recording, n, variables)
    fits: dict[int, list[SweepFit]] = {j: [] for j in range(1, n + 1)}
    lines: dict[int, list[AxisLine]] = {j: [] for j in range(1, n + 1)}
    used: dict[int, list[Sweep]] = {j: [] for j in range(1, n + 1)}
    for j in range(1, n + 1):
        for s in recording.sweeps_of(j):
            turned = variables[s.index, j - 1]
            where = _sweep_name(recording, s)
            try:
                line, circle = axis_from_sweep(recording.points[s.index], turned, j)
            except InputError as exc:  # e.g. a target on the axis, noise-free: no circle
                if len(recording.sweeps_of(j)) == 1:
                    raise InputError(f"{where}: {exc}") from None
                warnings.append(
                    f"warning: {where}: {exc}: left out, the joint's other circles give its axis"
                )
                continue
            n_fitted = len(circle.plane_residuals)
            if n_fitted < s.n_poses:
                warnings.append(
                    f"warning: {where}: {s.n_poses - n_fitted} point(s) far off its circle "
                    "left out of the circle fit (blunders?)"
                )
            fitted = recording.points[s.index]
            spread = float(np.linalg.norm(fitted - fitted.mean(axis=0), axis=1).max())
            fits[j].append(SweepFit(j, n_fitted, float(np.ptp(turned)), circle, spread))
            lines[j].append(line)
            used[j].append(s)
    every = [f for j in fits for f in fits[j]]
    noise = pooled_circle_noise(every)
    axes = []
    for j in range(1, n + 1):
        sigma = [direction_sigma(f.circle, f.n_points, noise, f.lever_m) for f in fits[j]]
        warnings += _near_axis_warnings(recording, used[j], fits[j], sigma)
        axes.append(
            combine_lines([(f.n_points, sd, ln) for f, sd, ln in zip(fits[j], sigma, lines[j])])
        )

    # Base frame: on axis 1, d1 and theta1 nominal.
    z0 = axes[0].direction
    _, foot, _ = common_normal(axes[0].point, z0, axes[1].point, axes[1].direction)
    cross = np.cross(z0, axes[1].direction)
    x1 = cross / np.linalg.norm(cross)
    if abs(wrap(np.arctan2(cross @ x1, z0 @ axes[1].direction) - robot.alpha[0])) > np.pi / 2:
        x1 = -x1
    x0 = rotate(x1, z0, -(robot.theta[0] + q_ref[0]))
    frame = np.eye(4)
    frame[:3, :3] = np.column_stack([x0, np.cross(z0, x0), z0])
    frame[:3, 3] = foot - robot.d[0] * z0
    base2tracker = frame.copy()

    links = dh_from_axes(axes, frame, robot.hayati, robot.alpha, robot.a)
    frame = links.frames[-1]
    values: dict[str, float] = {}
    for j in range(1, n):
        theta, d, a, alpha, beta = (
            float(row[j - 1]) for row in (links.theta, links.d, links.a, links.alpha, links.beta)
        )
        values.update({f"theta{j}": wrap(theta - q_ref[j - 1]), f"a{j}": a, f"alpha{j}": alpha})
        if robot.hayati[j - 1]:
            values[f"beta{j}"] = beta
        else:
            values[f"d{j}"] = d
    # Unwrap thetas to the nominal branch.
    for j in range(1, n):
        nominal = robot.theta[j - 1]
        values[f"theta{j}"] = nominal + wrap(values[f"theta{j}"] - nominal)
    values["theta1"], values["d1"] = float(robot.theta[0]), float(robot.d[0])

    # Each target's centre in the flange frame from the last joint's sweep(s).
    last = np.concatenate([s.index for s in recording.sweeps_of(n)])
    qn = variables[last, n - 1]
    flanges = np.array(
        [
            frame
            @ link_transform(
                robot.theta[n - 1] + q,
                robot.d[n - 1],
                robot.a[n - 1],
                robot.alpha[n - 1],
                robot.beta[n - 1],
            )
            for q in qn
        ]
    )
    rel = recording.points[last] - flanges[:, :3, 3]
    in_flange = np.einsum("nji,nj->ni", flanges[:, :3, :3], rel)  # (k, 3)
    which = recording.poses.target_index[last]
    offsets: dict[str, tuple[float, float, float]] = {}
    unswept = []
    for k, name in enumerate(recording.target_names):
        if not np.any(which == k):
            unswept.append(k)
            continue
        x, y, z = (float(v) for v in in_flange[which == k].mean(axis=0))
        offsets[name] = (x, y, z)
    if not offsets:
        raise InputError(
            f"{', '.join(recording.sources)}: no target has a sweep of joint {n}: CPA finds "
            "the targets' offsets from the last joint's circles"
        )

    rpy = matrix_to_rpy(base2tracker[:3, :3])
    first = offsets.get(recording.target_names[0], next(iter(offsets.values())))
    params = geometric_parameters(
        robot, tuple(base2tracker[:3, 3]) + rpy, first, recording.target_names, offsets
    ).with_values(values)
    for k in unswept:  # from all its measurements, through the geometry just found
        name = recording.target_names[k]
        params = _target_from_geometry(recording, robot, params, name)
        warnings.append(
            f"warning: target {target_topic(name)} has no sweep of joint {n}: its offset "
            "comes from its measurements through the CPA geometry (less exact)"
        )
    return CPAResult(params, tuple(axes), tuple(every), q_ref, tuple(warnings))
