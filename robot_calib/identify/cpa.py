"""Circle point analysis (seed sections 3 and 5): joint axes from circle sweeps, then the
DH/Hayati parameters by the geometry of consecutive axis lines (seed eq. 6-9).

Every sweep turns one joint while the others hold a common reference configuration
`q_ref`, so all axis lines are found in that one configuration, in the tracker frame.
From them, frame by frame (`frame_{j}` = `frame_{j-1}` * link j):

- DH link (axes j, j+1 skew or intersecting): x_j along the common normal of the two axis
  lines, sign chosen nearest the nominal alpha_j; d_j = offset along axis j to the common
  normal's foot, a_j = length of the common normal, alpha_j = angle between the axes about
  x_j, theta_j = angle from x_{j-1} to x_j about axis j (eq. 6-9).
- Hayati link (axes j, j+1 nominally parallel): d_j = 0, x_j points from frame j-1's
  origin to where axis j+1 meets the plane normal to axis j through that origin; alpha_j and
  beta_j turn axis j onto axis j+1 (Rx(alpha) Ry(beta)).

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
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.dh import DHTable, link_transforms
from robot_calib.kinematics.frames import Array, matrix_to_rpy
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import Recording
from robot_calib.model import geometric_parameters

REF_CONSISTENCY_RAD = 1e-3  # sweeps whose held joints differ by more break the CPA premise


@dataclass(frozen=True)
class AxisLine:
    """A joint axis in the tracker frame: `point` (3,) [m] on it, unit `direction` (3,),
    oriented so that increasing the joint's variable (its reading, without a mapping) turns
    positively about it."""

    point: Array
    direction: Array


@dataclass(frozen=True)
class SweepFit:
    """The circle of one sweep: joint, number of points, angle span [rad], circle."""

    joint: int
    n_points: int
    span_rad: float
    circle: Circle


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


def _link(theta: float, d: float, a: float, alpha: float, beta: float) -> Array:
    return link_transforms(DHTable(*(np.array([[v]]) for v in (theta, d, a, alpha, beta))))[0, 0]


def _wrap(angle: float) -> float:
    return float((angle + np.pi) % (2 * np.pi) - np.pi)


def _angle_about(axis: Array, start: Array, end: Array) -> float:
    """Angle [rad] turning `start` to `end` about unit `axis` (both perpendicular to it)."""
    return float(np.arctan2(np.cross(start, end) @ axis, start @ end))


def axis_from_sweep(points: Array, readings: Array, joint: int) -> tuple[AxisLine, Circle]:
    """Axis line and circle of one sweep: points (k, 3) [m], the turning joint's variable
    (k,) [rad]; the direction follows it (right-hand rule)."""
    circle, keep = robust_circle(points, f"sweep of joint {joint}")  # blunders left out
    points, readings = points[keep], readings[keep]
    rel = points - circle.centre
    step = np.sign(np.diff(readings))
    turning = (np.cross(rel[:-1], rel[1:]) * step[:, None]).sum(axis=0)
    direction = circle.normal if turning @ circle.normal >= 0 else -circle.normal
    return AxisLine(circle.centre, direction), circle


def common_normal(o: Array, z: Array, c: Array, u: Array) -> tuple[float, Array, Array]:
    """Closest points of lines (o, z) and (c, u): offset s along z of the foot on the first
    line, the foot on the first line, the foot on the second (unit directions)."""
    b = z @ u
    w0 = o - c
    denom = 1.0 - b * b
    if denom < 1e-12:
        raise InputError("common normal of parallel axes: use the Hayati parameters")
    s = (b * (u @ w0) - z @ w0) / denom
    t = (u @ w0 - b * (z @ w0)) / denom
    return float(s), o + s * z, c + t * u


def _dh_link(frame: Array, line: AxisLine, alpha_nominal: float) -> tuple[float, ...]:
    """(theta_full, d, a, alpha, 0) of a DH link from `frame` (4, 4) to the next axis line."""
    x_prev, z, o = frame[:3, 0], frame[:3, 2], frame[:3, 3]
    u = line.direction
    d, foot, foot_next = common_normal(o, z, line.point, u)
    cross = np.cross(z, u)
    best = None
    for sign in (1.0, -1.0):
        x = sign * cross / np.linalg.norm(cross)
        alpha = float(np.arctan2(cross @ x, z @ u))
        miss = abs(_wrap(alpha - alpha_nominal))
        if best is None or miss < best[0]:
            best = (miss, x, alpha)
    assert best is not None
    _, x, alpha = best
    a = float((foot_next - foot) @ x)
    return _angle_about(z, x_prev, x), d, a, alpha, 0.0


def _hayati_link(frame: Array, line: AxisLine, a_nominal: float) -> tuple[float, ...]:
    """(theta_full, 0, a, alpha, beta) of a Hayati link (nearly parallel axes)."""
    x_prev, z, o = frame[:3, 0], frame[:3, 2], frame[:3, 3]
    u = line.direction
    s = (o - line.point) @ z / (u @ z)
    to_axis = line.point + s * u - o
    a = float(np.linalg.norm(to_axis))
    x = to_axis / a
    if a_nominal < 0:
        a, x = -a, -x
    theta = _angle_about(z, x_prev, x)
    turned = frame[:3, :3] @ _link(theta, 0.0, 0.0, 0.0, 0.0)[:3, :3]
    uu = turned.T @ u
    beta = float(np.arcsin(np.clip(uu[0], -1.0, 1.0)))
    alpha = float(np.arctan2(-uu[1], uu[2]))
    return theta, 0.0, a, alpha, beta


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
    fits, axes = [], []
    for j in range(1, n + 1):
        lines = []
        for s in recording.sweeps_of(j):
            turned = variables[s.index, j - 1]
            line, circle = axis_from_sweep(recording.points[s.index], turned, j)
            n_fitted = len(circle.plane_residuals)
            if n_fitted < s.n_poses:
                warnings.append(
                    f"warning: sweep of joint {j} at measurements {s.index[0] + 1}-"
                    f"{s.index[-1] + 1}: {s.n_poses - n_fitted} point(s) far off its circle "
                    "left out of the circle fit (blunders?)"
                )
            fits.append(SweepFit(j, n_fitted, float(np.ptp(turned)), circle))
            lines.append((s.n_poses, line))
        weights = np.array([w for w, _ in lines], dtype=float)
        direction = sum((w * ln.direction for w, ln in lines), np.zeros(3))
        direction = direction / np.linalg.norm(direction)
        point = sum((w * ln.point for w, ln in lines), np.zeros(3)) / weights.sum()
        axes.append(AxisLine(point, direction))

    # Base frame: on axis 1, d1 and theta1 nominal.
    z0 = axes[0].direction
    _, foot, _ = common_normal(axes[0].point, z0, axes[1].point, axes[1].direction)
    cross = np.cross(z0, axes[1].direction)
    x1 = cross / np.linalg.norm(cross)
    if abs(_wrap(np.arctan2(cross @ x1, z0 @ axes[1].direction) - robot.alpha[0])) > np.pi / 2:
        x1 = -x1
    x0 = _rotate(x1, z0, -(robot.theta[0] + q_ref[0]))
    frame = np.eye(4)
    frame[:3, :3] = np.column_stack([x0, np.cross(z0, x0), z0])
    frame[:3, 3] = foot - robot.d[0] * z0
    base2tracker = frame.copy()

    values: dict[str, float] = {}
    for j in range(1, n):
        if robot.hayati[j - 1]:
            link = _hayati_link(frame, axes[j], robot.a[j - 1])
        else:
            link = _dh_link(frame, axes[j], robot.alpha[j - 1])
        theta, d, a, alpha, beta = link
        values.update({f"theta{j}": _wrap(theta - q_ref[j - 1]), f"a{j}": a, f"alpha{j}": alpha})
        if robot.hayati[j - 1]:
            values[f"beta{j}"] = beta
        else:
            values[f"d{j}"] = d
        frame = frame @ _link(theta, d, a, alpha, beta)
    # Unwrap thetas to the nominal branch.
    for j in range(1, n):
        nominal = robot.theta[j - 1]
        values[f"theta{j}"] = nominal + _wrap(values[f"theta{j}"] - nominal)
    values["theta1"], values["d1"] = float(robot.theta[0]), float(robot.d[0])

    # Target in the flange frame from the last joint's sweep(s).
    last = np.concatenate([s.index for s in recording.sweeps_of(n)])
    qn = variables[last, n - 1]
    flanges = np.array(
        [
            frame @ _link(robot.theta[n - 1] + q, robot.d[n - 1], robot.a[n - 1],
                          robot.alpha[n - 1], robot.beta[n - 1])
            for q in qn
        ]
    )  # fmt: skip
    rel = recording.points[last] - flanges[:, :3, 3]
    target = np.einsum("nji,nj->ni", flanges[:, :3, :3], rel).mean(axis=0)

    rpy = matrix_to_rpy(base2tracker[:3, :3])
    params = geometric_parameters(
        robot, tuple(base2tracker[:3, 3]) + rpy, tuple(target)
    ).with_values(values)
    return CPAResult(params, tuple(axes), tuple(fits), q_ref, tuple(warnings))


def _rotate(v: Array, axis: Array, angle: float) -> Array:
    """v (3,) turned by `angle` [rad] about unit `axis` (Rodrigues)."""
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * (axis @ v) * (1 - c)
