"""Where the residual lies: its structure against each joint angle, approach direction, time,
gravity torque and workspace region (residual = predicted - measured, tracker frame).

For a pose in a sweep of joint j, the residual along the arc divided by the lever arm is the
joint-angle error of joint j that would explain it [rad]; its Fourier content against the
reading, its jump between approach directions (backlash), its slope against the reading
(encoder scale) and its correlation with the gravity torque (compliance) are the
signatures of the joint effects.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from robot_calib.bag.recording import Recording
from robot_calib.effects.compliance import gravity_torques
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel

HARMONICS = 4


def arc_angle_errors(model: KinematicModel, params: ParameterVector, recording: Recording,
                     residuals: Array) -> dict[int, tuple[Array, Array, Array]]:  # fmt: skip
    """Per joint j with sweeps: (pose index (k,), angle-equivalent error (k,) [rad] =
    residual along the arc of joint j / lever arm, lever arm (k,) [m]), from its sweeps."""
    origins, axes = model.joint_axes(params, recording.poses)
    points = recording.points + residuals  # predicted
    out: dict[int, tuple[Array, Array]] = {}
    for j in sorted({s.joint for s in recording.sweeps}):
        idx = np.concatenate([s.index for s in recording.sweeps_of(j)])
        tangent = np.cross(axes[idx, j - 1], points[idx] - origins[idx, j - 1])
        lever2 = np.sum(tangent**2, axis=1)
        out[j] = (idx, np.einsum("na,na->n", residuals[idx], tangent) / lever2, np.sqrt(lever2))
    return out


def harmonic_amplitudes(
    q: Array, values: Array, sigma: Array | float, order: int = HARMONICS
) -> tuple[Array, Array]:
    """Amplitudes (order,) of harmonics 1..order of values(q) (least squares with a mean)
    and their 1-sigma from noise `sigma` on each value: over a partial turn the harmonics
    are nearly collinear and their amplitudes are uncertain, which the sigma shows."""
    cols = [np.ones_like(q)]
    for k in range(1, order + 1):
        cols += [np.cos(k * q), np.sin(k * q)]
    weights = np.broadcast_to(1.0 / np.asarray(sigma, dtype=float), q.shape)
    design = np.stack(cols, axis=1) * weights[:, None]
    coef, *_ = np.linalg.lstsq(design, values * weights, rcond=None)
    cov = np.linalg.pinv(design.T @ design)
    var = np.diag(cov)
    return np.hypot(coef[1::2], coef[2::2]), np.sqrt((var[1::2] + var[2::2]) / 2.0)


def where_it_lies(model: KinematicModel, params: ParameterVector, recording: Recording,
                  residuals: Array, noise_sigma_m: float) -> dict[str, Any]:  # fmt: skip
    """The 'where' section of DIAGNOSIS.json (units in the key names)."""
    q, direction = recording.poses.q, recording.poses.direction
    joints = []
    tau = gravity_torques(model.robot, q)
    for j, (idx, err, lever) in arc_angle_errors(model, params, recording, residuals).items():
        qj = q[idx, j - 1]
        forth = direction[idx, j - 1] > 0
        split = (
            float(err[forth].mean() - err[~forth].mean())
            if forth.any() and (~forth).any()
            else 0.0
        )
        slope = float(np.polyfit(qj, err, 1)[0]) if np.ptp(qj) > 0 else 0.0
        t = tau[idx, j - 1]
        corr = float(np.corrcoef(t, err)[0, 1]) if np.ptp(t) > 1e-3 else 0.0
        amps, amp_sigma = harmonic_amplitudes(qj, err, noise_sigma_m / lever)
        joints.append(
            {
                "joint": j,
                "arc_rms_urad": float(np.sqrt(np.mean(err**2)) * 1e6),
                "harmonics_urad": [float(a * 1e6) for a in amps],
                "harmonics_significance": [float(a / s) for a, s in zip(amps, amp_sigma)],
                "direction_split_urad": split * 1e6,
                "slope_vs_angle_urad_per_rad": slope * 1e6,
                "gravity_torque_correlation": corr,
            }
        )
    norm = np.linalg.norm(residuals, axis=1)
    time = recording.poses.time
    quartiles = np.array_split(np.argsort(time, kind="stable"), 4)
    reach = np.linalg.norm((recording.points - recording.points.mean(axis=0))[:, :2], axis=1)
    tertiles = np.array_split(np.argsort(reach, kind="stable"), 3)
    strongest = None  # (joint, harmonic, amplitude, significance): the most significant
    for entry in joints:
        pairs = zip(entry["harmonics_urad"], entry["harmonics_significance"])
        for k, (amp, sig) in enumerate(pairs, start=1):
            if strongest is None or sig > strongest[3]:
                strongest = (entry["joint"], k, amp, sig)
    ordinal = {1: "1st", 2: "2nd", 3: "3rd"}
    return {
        "joints": joints,
        "strongest_signature": None
        if strongest is None
        else {
            "joint": strongest[0],
            "harmonic": strongest[1],
            "amplitude_urad": strongest[2],
            "significance": strongest[3],
            "text": f"{ordinal.get(strongest[1], f'{strongest[1]}th')} harmonic of joint "
            f"{strongest[0]} ({strongest[2]:.1f} urad along the arc, {strongest[3]:.0f} x its "
            "noise)",
        },
        "time": {
            "rms_by_quartile_mm": [float(np.sqrt(np.mean(norm[i] ** 2)) * 1e3) for i in quartiles],
            "slope_mm_per_h": float(np.polyfit(time, norm, 1)[0] * 3.6e6)
            if np.ptp(time) > 0
            else 0.0,
        },
        "workspace": {
            "rms_by_reach_tertile_mm": [
                float(np.sqrt(np.mean(norm[i] ** 2)) * 1e3) for i in tertiles
            ],
        },
        "noise_sigma_mm": noise_sigma_m * 1e3,
    }
