"""Joint axis lines -> DH/Hayati links, by line geometry (seed eq. 6-9).

One implementation for everything that knows a robot's joint axes as lines in space: circle
point analysis (axes measured by circle sweeps, `identify/cpa.py`) and the URDF loader (axes
read from a description at its zero configuration, `kinematics/urdf.py`).

Frame by frame (`frame_j` = `frame_{j-1}` * link j, frame 0 given on axis 1):

- DH link (axes j, j+1 skew or intersecting): x_j along the common normal of the two axis
  lines, sign chosen nearest a hint for alpha_j; d_j = offset along axis j to the common
  normal's foot, a_j = length of the common normal, alpha_j = angle between the axes about
  x_j, theta_j = angle from x_{j-1} to x_j about axis j.
- Hayati link (axes j, j+1 nominally parallel): d_j = 0, x_j points from frame j-1's origin
  to where axis j+1 meets the plane normal to axis j through that origin (sign from a hint
  for a_j); alpha_j and beta_j turn axis j onto axis j+1 (Rx(alpha) Ry(beta)).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from robot_calib.errors import InputError
from robot_calib.kinematics.dh import DHTable, link_transforms
from robot_calib.kinematics.frames import Array


@dataclass(frozen=True)
class AxisLine:
    """A joint axis as a line: `point` (3,) [m] on it, unit `direction` (3,), oriented so
    that increasing the joint's reading turns positively about it (both in one frame)."""

    point: Array
    direction: Array


@dataclass(frozen=True)
class AxisLinks:
    """DH/Hayati links 1..J-1 found from J axis lines, each field shape (J - 1,).

    theta : full joint angle at the configuration the axes were taken in [rad] (table value
        plus reading); d, a [m]; alpha, beta [rad] (d = 0 on Hayati links, beta = 0 on DH
        links); frames : shape (J, 4, 4), DH frames 0..J-1 in the frame of the axis lines
        (frame j-1 has z along axis j).
    """

    theta: Array
    d: Array
    a: Array
    alpha: Array
    beta: Array
    frames: Array


def link_transform(theta: float, d: float, a: float, alpha: float, beta: float) -> Array:
    """One link transform ``Rz(theta) Tz(d) Tx(a) Rx(alpha) Ry(beta)``, shape (4, 4)."""
    return link_transforms(DHTable(*(np.array([[v]]) for v in (theta, d, a, alpha, beta))))[0, 0]


def wrap(angle: float) -> float:
    """`angle` [rad] wrapped to [-pi, pi)."""
    return float((angle + np.pi) % (2 * np.pi) - np.pi)


def angle_about(axis: Array, start: Array, end: Array) -> float:
    """Angle [rad] turning `start` to `end` about unit `axis` (both perpendicular to it)."""
    return float(np.arctan2(np.cross(start, end) @ axis, start @ end))


def rotate(v: Array, axis: Array, angle: float) -> Array:
    """v (3,) turned by `angle` [rad] about unit `axis` (Rodrigues)."""
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * (axis @ v) * (1 - c)


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


def dh_link(frame: Array, line: AxisLine, alpha_hint: float) -> tuple[float, ...]:
    """(theta_full, d, a, alpha, 0) of a DH link from `frame` (4, 4) to the next axis line;
    of the two directions of the common normal, the one giving alpha nearest `alpha_hint`."""
    x_prev, z, o = frame[:3, 0], frame[:3, 2], frame[:3, 3]
    u = line.direction
    d, foot, foot_next = common_normal(o, z, line.point, u)
    cross = np.cross(z, u)
    best = None
    for sign in (1.0, -1.0):
        x = sign * cross / np.linalg.norm(cross)
        alpha = float(np.arctan2(cross @ x, z @ u))
        miss = abs(wrap(alpha - alpha_hint))
        if best is None or miss < best[0]:
            best = (miss, x, alpha)
    assert best is not None
    _, x, alpha = best
    a = float((foot_next - foot) @ x)
    return angle_about(z, x_prev, x), d, a, alpha, 0.0


def hayati_link(frame: Array, line: AxisLine, a_hint: float) -> tuple[float, ...]:
    """(theta_full, 0, a, alpha, beta) of a Hayati link (nearly parallel axes); a < 0 when
    `a_hint` < 0."""
    x_prev, z, o = frame[:3, 0], frame[:3, 2], frame[:3, 3]
    u = line.direction
    s = (o - line.point) @ z / (u @ z)
    to_axis = line.point + s * u - o
    a = float(np.linalg.norm(to_axis))
    x = to_axis / a
    if a_hint < 0:
        a, x = -a, -x
    theta = angle_about(z, x_prev, x)
    turned = frame[:3, :3] @ link_transform(theta, 0.0, 0.0, 0.0, 0.0)[:3, :3]
    uu = turned.T @ u
    beta = float(np.arcsin(np.clip(uu[0], -1.0, 1.0)))
    alpha = float(np.arctan2(-uu[1], uu[2]))
    return theta, 0.0, a, alpha, beta


def dh_from_axes(
    axes: Sequence[AxisLine],
    base: Array,
    hayati: Array,
    alpha_hint: Array,
    a_hint: Array,
) -> AxisLinks:
    """Links 1..J-1 of a serial chain from its J joint axis lines, all in one frame.

    axes : J lines, taken in one configuration of the joints.
    base : shape (4, 4), DH frame 0 in that frame: z along axis 1, origin on it.
    hayati : shape (>= J - 1,) bool; link j is a Hayati link (axes j, j+1 nominally
        parallel).
    alpha_hint, a_hint : shape (>= J - 1,) [rad, m], the sign conventions: the direction of
        the common normal giving alpha_j nearest alpha_hint[j-1] (DH links); a_j < 0 if
        a_hint[j-1] < 0 (Hayati links).
    The last link (axis J to the flange) is not defined by axis lines: callers add it.
    """
    n = len(axes)
    rows = np.zeros((5, n - 1))
    frames = np.empty((n, 4, 4))
    frame = np.asarray(base, dtype=float)
    frames[0] = frame
    for j in range(1, n):
        if hayati[j - 1]:
            link = hayati_link(frame, axes[j], a_hint[j - 1])
        else:
            link = dh_link(frame, axes[j], alpha_hint[j - 1])
        rows[:, j - 1] = link
        frame = frame @ link_transform(*link)
        frames[j] = frame
    return AxisLinks(rows[0], rows[1], rows[2], rows[3], rows[4], frames)
