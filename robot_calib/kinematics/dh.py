"""Denavit-Hartenberg chain with the Hayati-Mirmirani beta, batched over poses.

Convention (msgs_doc/specification.md, "Joint and model conventions"; seed paper eq. 1-5):
link j maps frame j-1 to frame j by ``Rz(theta_j) Tz(d_j) Tx(a_j) Rx(alpha_j) Ry(beta_j)``
with ``theta_j = theta_j(table) + q_j``. The axis of joint j is z of frame j-1.
beta_j is used (and d_j dropped) only where axes j and j+1 are nominally parallel.

An optional per-joint error transform ``housing_error[j]`` (eccentricity, seed eq. 10) is
applied in the fixed housing frame j-1 before the joint's rotation:
``frame_j = frame_{j-1} E_j Rz(theta_j) ...``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.kinematics.frames import Array


@dataclass(frozen=True)
class DHTable:
    """DH/Hayati values per pose and joint; every field broadcasts to (n_poses, n_joints).

    theta : full joint angle theta_j(table) + q_j [rad]
    d, a : [m]; alpha, beta : [rad]
    """

    theta: Array
    d: Array
    a: Array
    alpha: Array
    beta: Array

    def broadcast(self) -> DHTable:
        """All fields as arrays of one common shape (n_poses, n_joints)."""
        arrays = np.broadcast_arrays(self.theta, self.d, self.a, self.alpha, self.beta)
        return DHTable(*(np.asarray(x, dtype=float) for x in arrays))


def link_transforms(dh: DHTable) -> Array:
    """Link transforms ``Rz(theta) Tz(d) Tx(a) Rx(alpha) Ry(beta)``, shape (n, J, 4, 4)."""
    t = dh.broadcast()
    n, j = t.theta.shape
    ct, st = np.cos(t.theta), np.sin(t.theta)
    ca, sa = np.cos(t.alpha), np.sin(t.alpha)
    cb, sb = np.cos(t.beta), np.sin(t.beta)
    # Rz(theta) Rx(alpha) Ry(beta) written out: no (n J, 3, 3) factors and no batched
    # products of 3 x 3 matrices (the model's hottest function: every evaluation, per link);
    # the 16 entries written as contiguous planes, then one transposing copy (writing each
    # entry into an (n, J, 4, 4) array strides through memory: 3.6x slower)
    sa_sb, sa_cb = sa * sb, sa * cb
    planes = np.empty((16, n, j))
    planes[0], planes[1], planes[2], planes[3] = (
        ct * cb - st * sa_sb,
        -st * ca,
        ct * sb + st * sa_cb,
        t.a * ct,
    )
    planes[4], planes[5], planes[6], planes[7] = (
        st * cb + ct * sa_sb,
        ct * ca,
        st * sb - ct * sa_cb,
        t.a * st,
    )
    planes[8], planes[9], planes[10], planes[11] = -ca * sb, sa, ca * cb, t.d
    planes[12:15], planes[15] = 0.0, 1.0
    out = planes.transpose(1, 2, 0).copy().reshape(n, j, 4, 4)
    return out


def chain(dh: DHTable, housing_error: Array | None = None) -> Array:
    """Frames of the chain in the robot base frame.

    housing_error : optional, shape (n, J, 4, 4) — error transform of each joint in its
        housing frame j-1, applied before the joint rotation.
    Returns frame2base, shape (n, J + 1, 4, 4): index 0 is the base (identity), index j is
    frame j (the flange for j = J).
    """
    if housing_error is None:
        return _chain_planes(dh)
    links = housing_error @ link_transforms(dh)
    n, j = links.shape[:2]
    # frame-major storage: each frame a contiguous (n, 4, 4) product written in place; the
    # (n, J + 1, 4, 4) result is a view of it (no stacking copy)
    frames = np.empty((j + 1, n, 4, 4))
    frames[0] = np.eye(4)
    frames[1] = links[:, 0]
    for k in range(1, j):
        np.matmul(frames[k], links[:, k], out=frames[k + 1])
    return frames.transpose(1, 0, 2, 3)


def _chain_planes(dh: DHTable) -> Array:
    """`chain` without housing errors, entry by entry: every entry of every frame is a
    contiguous plane of n poses and frame k+1 = frame k x link k is 12 sums of 3 products
    of planes (the link's last row is (0, 0, 0, 1) and its third row the same at every
    pose: alpha and beta are the joint's), so no 4 x 4 link matrix is ever built (a batch
    of n small matrix products and the (n, J, 4, 4) links cost 3 x more). Result as
    `chain`'s, shape (n, J + 1, 4, 4) (one transposing copy)."""
    shape = np.broadcast_shapes(*(np.shape(v) for v in (dh.theta, dh.d, dh.a, dh.alpha, dh.beta)))
    n, joints = shape

    def joint_major(v: Array) -> Array:
        """(J, n) contiguous where `v` varies with the pose, else (J, 1)."""
        v = np.asarray(v, dtype=float)
        if v.ndim == 2 and v.shape[0] == n and n != 1:  # (0, J) too: no poses
            return np.ascontiguousarray(np.broadcast_to(v, shape).T)
        return np.broadcast_to(v, (1, joints)).T.copy()

    theta, d, a = joint_major(dh.theta), joint_major(dh.d), joint_major(dh.a)
    alpha, beta = joint_major(dh.alpha), joint_major(dh.beta)
    ct, st = np.cos(theta), np.sin(theta)  # (J, n)
    ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)  # (J, 1 or n)
    planes = np.empty((joints + 1, 4, 4, n))  # frame, row, column, pose
    planes[0] = np.eye(4)[:, :, None]
    link = np.empty((2, 4, n))  # the link's first two rows (its third: `third` below)
    product = np.empty(n)
    for k in range(joints):
        c, s = ct[k], st[k]
        sa_sb, sa_cb = sa[k] * sb[k], sa[k] * cb[k]
        np.subtract(c * cb[k], s * sa_sb, out=link[0, 0])
        np.multiply(s, -ca[k], out=link[0, 1])
        np.add(c * sb[k], s * sa_cb, out=link[0, 2])
        np.multiply(a[k], c, out=link[0, 3])
        np.add(s * cb[k], c * sa_sb, out=link[1, 0])
        np.multiply(c, ca[k], out=link[1, 1])
        np.subtract(s * sb[k], c * sa_cb, out=link[1, 2])
        np.multiply(a[k], s, out=link[1, 3])
        third = (-ca[k] * sb[k], sa[k], ca[k] * cb[k], d[k])  # each (1,) or (n,)
        before, after = planes[k], planes[k + 1]
        for row in range(3):
            for col in range(4):
                out = after[row, col]
                np.multiply(before[row, 0], link[0, col], out=out)
                np.multiply(before[row, 1], link[1, col], out=product)
                out += product
                np.multiply(before[row, 2], third[col], out=product)
                out += product
                if col == 3:
                    out += before[row, 3]
        after[3] = planes[0, 3]
    return np.ascontiguousarray(planes.transpose(3, 0, 1, 2))


@dataclass(frozen=True)
class ChainDerivatives:
    """Derivatives of a point fixed in the last frame, in the base frame [m per unit].

    Each field has shape (n, 3, J): column j is d p / d (parameter of link j+1).
    """

    theta: Array
    d: Array
    a: Array
    alpha: Array
    beta: Array


def point_derivatives(
    dh: DHTable, frames: Array, p_in_base: Array, housing_error: Array | None = None
) -> ChainDerivatives:
    """Analytic derivatives of the point `p_in_base` (n, 3) [m] w.r.t. every link parameter.

    frames : frame2base from `chain`, shape (n, J + 1, 4, 4), for the same `dh` and
        `housing_error` (n, J, 4, 4) or None.
    Each parameter is a small screw motion of the chain beyond it (rotation about or
    translation along an axis whose line is known from `frames`).
    """
    t = dh.broadcast()
    prev = frames[:, :-1]  # frame j-1 of link j, (n, J, 4, 4)
    if housing_error is not None:
        prev = prev @ housing_error  # the joint turns about the displaced axis
    x_prev, y_prev, z_prev = prev[..., :3, 0], prev[..., :3, 1], prev[..., :3, 2]
    o_prev = prev[..., :3, 3]
    o_link = frames[:, 1:, :3, 3]  # origin of frame j = where the a/alpha/beta axes pass
    y_link = frames[:, 1:, :3, 1]  # Ry(beta) turns about frame j's own y axis
    ct, st = np.cos(t.theta)[..., None], np.sin(t.theta)[..., None]
    x_mid = ct * x_prev + st * y_prev  # x after Rz(theta): the a- and alpha-axis, (n, J, 3)

    lever_prev = p_in_base[:, None, :] - o_prev
    lever_link = p_in_base[:, None, :] - o_link
    d_theta = np.cross(z_prev, lever_prev)
    d_alpha = np.cross(x_mid, lever_link)
    d_beta = np.cross(y_link, lever_link)

    def cols(v: Array) -> Array:
        return np.moveaxis(v, 1, -1)  # (n, J, 3) -> (n, 3, J)

    return ChainDerivatives(
        theta=cols(d_theta),
        d=cols(z_prev),
        a=cols(x_mid),
        alpha=cols(d_alpha),
        beta=cols(d_beta),
    )
