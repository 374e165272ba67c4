"""The weak prior of every fit: how far a parameter may plausibly sit from nominal.

Real data leave some directions of a rich model nearly flat: over a 140 deg range of joint 2
the columns [1, cos kq, sin kq] of a low-order harmonic are collinear to 1 part in 1e7, so
theta2 and the harmonic's constant term can trade hundreds of radians for a micrometre of
fit, and Levenberg-Marquardt wanders there (on a UR10 campaign: theta2 -11762 deg, a2 +15.7 m). The
prior closes those directions without moving well-determined ones: each parameter with a
prior adds one residual row

    prior_row = sigma_ref * (value - nominal) / PRIOR_SIGMA

where sigma_ref [m] is the larger of the stated position accuracy (`identify.weights`: the
median stated, else 10 um) and the rms residual per axis at the fit's start (the simpler
model's solution): what one measurement really scatters by, unmodelled structure included.
A parameter at one PRIOR_SIGMA from nominal costs as much as one measurement off by that
scatter: nothing next to the thousands of measurements that pin a well-determined
parameter, everything in a direction the data do not see. msgs_doc/parameters.md states
the table.

Priors apply to the geometric parameters (their nominal is the manufacturer's table) and
to effect parameters whose nominal is 0 (the effect absent); never to the tracker and
target frames (arbitrary placements); parameters whose nominal is a value only by name
(NAME_PRIOR: thermal_warmup's ln time constant).
"""

from __future__ import annotations

import numpy as np

from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.parameters import Parameter, ParameterVector

#: prior 1-sigma of a geometric parameter by unit: far beyond any manufacturing tolerance
#: (20 mm, 1.1 deg), so a wrong --robot still shows as parameters far from nominal
GEOMETRIC_PRIOR = {"m": 0.02, "rad": 0.02}
#: prior 1-sigma of an effect's parameter by unit: of the size of the largest effects real
#: arms show (2 mrad of joint-angle error: a worn gear's backlash; 10 mm of housing
#: offset, ...); weak all the same: one pseudo-measurement per sigma
EFFECT_PRIOR = {
    "rad": 2e-3,
    "m": 1e-2,
    "1": 1e-2,
    "rad/m": 1e-2,
    "rad/(N m)": 1e-3,
    "1/K": 1e-3,
    "1/s": 1e-5,
}
#: single parameters with a prior about a nominal that is a value: thermal_warmup's ln time
#: constant [ln s] about ln 600 s, 1-sigma 3 (a factor 20: 30 s .. 3 h within one sigma;
#: without it a fit can slide to tau = e^-3600 s, a step no warm-up has)
NAME_PRIOR = {"thermal_warmup_ln_tau": 3.0}
#: groups without a prior: placements chosen by the user, not properties of the robot
NO_PRIOR_GROUPS = ("frames",)


def prior_sigma(p: Parameter) -> float:
    """The prior 1-sigma of `p` in its unit; inf for no prior."""
    if p.name in NAME_PRIOR:
        return NAME_PRIOR[p.name]
    if p.group in NO_PRIOR_GROUPS:
        return np.inf
    if p.group == "geometric":
        return GEOMETRIC_PRIOR.get(p.unit, np.inf)
    if p.nominal != 0.0:
        return np.inf
    return EFFECT_PRIOR.get(p.unit, np.inf)


def prior_sigmas(params: ParameterVector) -> Array:
    """(P,) the prior 1-sigma of every parameter of `params` in its unit (inf: none)."""
    return np.array([prior_sigma(p) for p in params.parameters], dtype=float)
