"""Equivalent solutions in one canonical form: the one nearest nominal.

Different DH/Hayati values can describe the same robot exactly; a fit may end at any of
them (e.g. theta4 +180 deg with a4 negated is the same arm). Two transforms map a
solution to an equivalent one:

- wrap: theta, alpha and beta enter the chain only through Rz, Rx and Ry, which repeat
  every 2 pi, so each geometric angle is taken to within pi of its nominal value;
- flip of joint i (1 <= i < J): frame i turned by pi about its own z axis. As Rz(pi)
  commutes with Rz and Tz, and turns x into -x and y into -y,

      Rz(theta + pi) Tz(d) Tx(-a) Rx(-alpha) Ry(-beta)
          = Rz(theta) Tz(d) Tx(a) Rx(alpha) Ry(beta) Rz(pi)

  (`kinematics.dh`'s link, Hayati beta included), and Rz(theta_{i+1} - pi) at the start of
  link i+1 takes the turn back: theta_i += pi, a_i, alpha_i, beta_i negated,
  theta_{i+1} -= pi, d_i unchanged; every other frame stays where it was.

A flip is tried only where every parameter it changes is free (a fixed parameter keeps the
value its reason gives: theta1 and theta6 of a 6R arm, so joints 2..J-2), and kept when it
brings the geometry nearer nominal (the sum of squared deviations in units of the prior's
1-sigma, `identify.prior`, angles wrapped). Effects that live in a joint's housing frame
(eccentricity of joint i+1) do not follow the flip: so every transform is verified on the
calibration poses and applied only when the predicted points (and 6-DoF probe frames)
stay within VERIFY_TOLERANCE_M (VERIFY_TOLERANCE_RAD).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robot_calib.identify.prior import prior_sigmas
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses

#: predicted points may move by this much under an equivalence transform [m] (rounding)
VERIFY_TOLERANCE_M = 1e-9
#: ... and 6-DoF probe frames turn by this much [rad]
VERIFY_TOLERANCE_RAD = 1e-9
ANGLE_FIELDS = ("theta", "alpha", "beta")


@dataclass(frozen=True)
class CanonicalForm:
    """A solution in canonical form.

    parameters : the equivalent parameters nearest nominal (same names, free flags).
    applied : one line per transform applied, e.g. 'theta4 wrapped by -360.0 deg',
        'joint 4 flipped (theta4 +180 deg, a4, alpha4 negated, theta5 -180 deg)'.
    refused : one line per transform that would have brought the geometry nearer nominal
        but moved the predictions (an effect that does not follow it), not applied.
    """

    parameters: ParameterVector
    applied: tuple[str, ...] = ()
    refused: tuple[str, ...] = ()


def wrapped(angle: Array | float) -> Array:
    """Angles [rad] taken into [-pi, pi) by whole turns (those within unchanged)."""
    angle = np.asarray(angle, dtype=float)
    turns = 2 * np.pi * np.floor((angle + np.pi) / (2 * np.pi))
    return np.asarray(angle - turns, dtype=float)


def distance_from_nominal(params: ParameterVector) -> float:
    """Sum of squared deviations of the geometric parameters from nominal, each in units
    of its prior 1-sigma (`identify.prior`), angles wrapped to within pi [1]."""
    sigma = prior_sigmas(params)
    out = 0.0
    for k, p in enumerate(params.parameters):
        if p.group != "geometric" or not np.isfinite(sigma[k]):
            continue
        deviation = params.values[k] - p.nominal
        if p.unit == "rad":
            deviation = float(wrapped(deviation))
        out += (deviation / sigma[k]) ** 2
    return out


def canonical_form(model: KinematicModel, params: ParameterVector, poses: Poses) -> CanonicalForm:
    """The equivalent of `params` nearest nominal (module docstring), verified at `poses`.

    Parameters
    ----------
    model : KinematicModel
        The forward model `params` belong to (geometry, effects, targets).
    params : ParameterVector
        A fitted solution, SI units [m, rad, ...].
    poses : Poses
        The calibration poses, n of them: each transform must leave the predicted points
        (n, 3) [m, tracker frame] unchanged there.

    Returns
    -------
    canonical : CanonicalForm
        The parameters, the transforms applied and those refused.
    """
    reference = model.target_points(params, poses)
    frames = model.probe_orientations(params, poses) if model.oriented else None

    def same(candidate: ParameterVector) -> bool:
        moved = model.target_points(candidate, poses) - reference
        if len(moved) and float(np.max(np.abs(moved))) > VERIFY_TOLERANCE_M:
            return False
        if frames is not None and len(frames):
            turned = model.probe_orientations(candidate, poses) - frames
            return float(np.max(np.abs(turned))) <= VERIFY_TOLERANCE_RAD
        return True

    applied: list[str] = []
    refused: list[str] = []
    # wraps: one at a time, each verified
    for p in params.parameters:
        if p.group != "geometric" or p.unit != "rad" or not p.free:
            continue
        deviation = params[p.name] - p.nominal
        if -np.pi <= deviation < np.pi:
            continue
        turns = 2 * np.pi * np.floor((deviation + np.pi) / (2 * np.pi))  # whole turns [rad]
        candidate = params.with_values({p.name: params[p.name] - turns})
        line = f"{p.name} wrapped by {np.degrees(-turns):+.1f} deg"
        if same(candidate):
            params = candidate
            applied.append(line)
        else:
            refused.append(line)
    # flips: greedy, the one that brings the geometry nearest nominal first, while any does
    # (a flip the predictions refuse is not tried again)
    tried: set[str] = set()
    for _ in range(2 * model.robot.n_joints):
        best: tuple[float, ParameterVector, str] | None = None
        for joint in range(1, model.robot.n_joints):
            flipped = _flipped(params, joint)
            if flipped is None:
                continue
            candidate, line = flipped
            gain = distance_from_nominal(params) - distance_from_nominal(candidate)
            if gain > 0 and line not in tried and (best is None or gain > best[0]):
                best = (gain, candidate, line)
        if best is None:
            break
        _, candidate, line = best
        tried.add(line)
        if same(candidate):
            params = candidate
            applied.append(line)
        else:
            refused.append(line)
    return CanonicalForm(params, tuple(applied), tuple(refused))


def _flipped(params: ParameterVector, joint: int) -> tuple[ParameterVector, str] | None:
    """`params` with joint `joint` flipped (module docstring), its two thetas wrapped to
    within pi of nominal, and its line; None where a parameter it changes is not free."""
    theta, theta_next = f"theta{joint}", f"theta{joint + 1}"
    negated = [f"{field}{joint}" for field in ("a", "alpha", "beta")]
    negated = [n for n in negated if n in params and params[n] != 0.0]
    changed = [theta, theta_next, *negated]
    if any(n not in params or not params.parameters[params.index(n)].free for n in changed):
        return None
    updates = {n: -params[n] for n in negated}
    updates[theta] = params[theta] + np.pi
    updates[theta_next] = params[theta_next] - np.pi
    for name in updates:  # the angles taken to within pi of nominal again
        p = params.parameters[params.index(name)]
        if p.unit == "rad":
            updates[name] = p.nominal + float(wrapped(updates[name] - p.nominal))
    line = (
        f"joint {joint} flipped ({theta} {np.degrees(updates[theta] - params[theta]):+.0f} "
        f"deg, {', '.join(negated) or 'nothing'} negated, {theta_next} "
        f"{np.degrees(updates[theta_next] - params[theta_next]):+.0f} deg)"
    )
    return params.with_values(updates), line
