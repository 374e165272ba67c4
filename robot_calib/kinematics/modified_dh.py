"""Modified (Craig) DH tables as the standard DH tables the model uses.

A modified-DH row i gives alpha_{i-1}, a_{i-1} (the common normal from axis i-1 to axis
i), theta_i and d_i: frame i = frame i-1 . Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i)
Tz(d_i), its frame i on joint i's axis. Standard DH puts frame i on joint i+1's axis:
frame i = frame i-1 . Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i). The product of a modified
chain regroups exactly into a standard one (Rx and Tx commute): joint i keeps theta_i and
d_i and takes a_i, alpha_i from modified row i+1; the last joint takes a = alpha = 0, so
both chains end in the same frame n (the flange of the table), and they start in the same
frame 0 when row 1's alpha_0 and a_0 are 0 (joint 1's axis is the base's z axis, as most
tables have it; otherwise the base frame is not DH frame 0 and the table is refused). A
centre of mass given in modified frame i (on joint i's axis) moves into standard frame i:
c_std = Rx(-alpha_i) (c_mdh - (a_i, 0, 0)). A Hayati `beta` (and `hayati`) moves with its
row's alpha and a: it turns the common normal of the axes that row joins (modified row
i + 1, standard joint i).
"""

from __future__ import annotations

import numpy as np

from robot_calib.kinematics.frames import Array

MAX_BASE_OFFSET = 1e-12  # |alpha_0| [rad] and |a_0| [m] taken as 0


def standard_from_modified(alpha: Array, a: Array) -> tuple[Array, Array]:
    """Standard DH alpha (J,) [rad] and a (J,) [m] of the modified rows' alpha_{i-1} (J,)
    [rad] and a_{i-1} (J,) [m] (theta and d are the same in both)."""
    return np.append(alpha[1:], 0.0), np.append(a[1:], 0.0)


def base_offset(alpha: Array, a: Array) -> tuple[float, float]:
    """Row 1's (alpha_0 [rad], a_0 [m]): both 0 for a table the standard chain holds."""
    return float(alpha[0]), float(a[0])


def com_to_standard(com: Array, alpha_std: Array, a_std: Array) -> Array:
    """Centres of mass (J, 3) [m] in the modified frames i -> in the standard frames i
    (module docstring), given the standard alpha (J,) [rad] and a (J,) [m]."""
    shifted = np.asarray(com, dtype=float) - np.column_stack([a_std, np.zeros((len(a_std), 2))])
    c, s = np.cos(alpha_std), np.sin(alpha_std)
    y = c * shifted[:, 1] + s * shifted[:, 2]  # Rx(-alpha) applied to each point
    z = -s * shifted[:, 1] + c * shifted[:, 2]
    return np.column_stack([shifted[:, 0], y, z])
