"""The measurement noise level, estimated from the data, not assumed.

1. Repeat poses: measurements of one bag at the same readings and approach directions,
   anywhere in the recording but at most MAX_REPEAT_GAP_S apart (e.g. the turn-around of a
   forth-and-back sweep, or a pose revisited a few rows later), differ only by noise:
   sigma^2 = mean |p_a - p_b|^2 / 6 per axis. (Farther apart in time, a warming robot
   would add its drift to the noise.)
2. Circle sweeps: each circle fit leaves 2 of the 3 noise components (plane, radial):
   sigma^2 = sum(residual^2) / (2 n - 6 per sweep) (an upper bound if effects bend circles).
   Where both exist and agree (circles within 1.5 x), they are pooled by degrees of freedom
   (a handful of repeat pairs alone scatters by +-20 %); else the repeat poses win.
3. Else a stated accuracy: the user's `--tracker-accuracy`, or the rms of the position
   standard deviations the tracker stated per point (msgs_doc/six_dof.md; the rms, since
   the floor is compared with an rms over points of unequal accuracy).
4. Else reference reflectors (msgs_doc/references.md): their scatter about the tracker's
   drift is the tracker's own noise at a fixed reflector (the robot's repeatability and the
   SMR on the tool not in it: a lower bound of the tool's noise, said so in its source).
   Stated accuracies come first: they are of the tool's own points.
5. Else the floor is unknown: the in-sample residual of a fitted model with its degrees of
   freedom serves the ladder's internal tests only (`NoiseLevel.independent` is False), and
   every output says the floor is unknown.
The verdict's floor is the independent estimate alone (1-3): a model's own residual, even
where it agrees, is no evidence of the floor it is judged against.
Repeat poses are told from re-reads (`moved_between`): a pose measured again after the
robot left it holds the robot's repeatability, a still pose read again only the tracker's
noise; re-reads serve only where no pose was repeated, and the source says so.

A stated accuracy is checked against the evidence (`NoiseLevel.warning`): not
used beside repeat poses or circle fits (said so, naming both figures); FAR_ABOVE x or more
above them, or above the geometric fit's in-sample residual, a warning (a unit slip: 5 mm
typed for 5 um); REFUTED x or more above that residual (no fit lies that far below the
noise) it is not used at all and the floor is unknown.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from robot_calib.identify.circles import fit_circle
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.measurements import Recording
from robot_calib.poses import JOINT_CHANGE_TOLERANCE

MIN_REPEATS = 3
STATED = "stated tracker accuracy"
#: the source of a floor from re-reads of still poses: the tracker's noise only
#: re-reads of a still target scattering more than this per axis [m] are no tracker's noise
#: (laser trackers re-read a still SMR to a few um; 0.1 mm is far beyond any)
MAX_REREAD_SIGMA_M = 1e-4
REREADS = "re-reads of still poses (the tracker alone, not the robot's repeatability)"
REFERENCES = "reference reflectors (the tracker alone, not the robot's repeatability)"
LOWER_BOUNDS = (REREADS, REFERENCES)  # floors of the tracker's noise alone
MAX_REPEAT_GAP_S = 60.0  # repeats farther apart in time may include drift, not only noise
MAX_REPEAT_LAG = 50  # rows between a pose and its repeat, at most
AGREE = 1.5  # circle-fit noise within this factor of the repeat-pose noise: pool them
FAR_ABOVE = 3.0  # a stated accuracy this many times the data's evidence: a warning
REFUTED = 10.0  # ... this many times the geometric fit's residual: not used (floor unknown)
UNIT_HINT = "check its unit: a 1-sigma in mm (0.005 for 5 um)"


def noise_basis(source: str, n: int) -> str:
    """How a noise level was found, for people: its source and what its n counts
    ('circle fits, 601 degrees of freedom'; 'stated tracker accuracy (per point), median
    of 300 values'; a user's --tracker-accuracy has no n)."""
    if source.startswith(STATED):
        return f"{source}, rms of {n} values" if n else source
    return f"{source}, {n} degrees of freedom"


@dataclass(frozen=True)
class NoiseLevel:
    """sigma_m: per-axis 1-sigma noise of a measured point [m]; source: how it was found;
    n: the number of repeat pairs / points behind it."""

    sigma_m: float
    source: str
    n: int
    # what a stated accuracy is against the evidence (a warning line, '' when none)
    warning: str = ""

    @property
    def basis(self) -> str:
        """Source and n, labelled (`noise_basis`)."""
        return noise_basis(self.source, self.n)

    @property
    def independent(self) -> bool:
        """True when estimated without any model (repeat poses, circle fits): only then can
        a model's error be compared with it (a model's own residual is no floor)."""
        return self.source != "model residual"

    @property
    def lower_bound(self) -> bool:
        """True for a floor of the tracker's noise alone (re-reads of still poses, reference
        reflectors): the robot's repeatability and the SMR's centring add to what a correct
        model reaches, so a model above it is no evidence of a missing effect by itself."""
        return self.source in LOWER_BOUNDS

    @property
    def floor_rms_m(self) -> float:
        """Expected rms of |predicted - measured| for the true model [m] (3-D)."""
        return float(np.sqrt(3.0) * self.sigma_m)

    @property
    def floor_mean_m(self) -> float:
        """Expected mean of |predicted - measured| for the true model [m]."""
        return float(np.sqrt(8.0 / np.pi) * self.sigma_m)


def _circle_noise(recording: Recording) -> NoiseLevel | None:
    total, dof = 0.0, 0
    for s in recording.sweeps:
        circle = fit_circle(recording.points[s.index])
        total += float(np.sum(circle.plane_residuals**2 + circle.radial_residuals**2))
        dof += 2 * s.n_poses - 6
    return NoiseLevel(float(np.sqrt(total / dof)), "circle fits", dof) if dof > 0 else None


def moved_between(recording: Recording, pairs: IntArray) -> NDArray[np.bool_]:
    """(k,) per repeat pair [a, b] of `repeat_pairs`: True when the robot left the pose
    between the two (a step of some joint by more than JOINT_CHANGE_TOLERANCE from one
    measurement to the next in between: a repeat, which holds the robot's repeatability),
    False for re-reads of a still pose (the tracker's noise alone; encoder jitter below the
    tolerance is no move)."""
    if not len(pairs):
        return np.zeros(0, dtype=bool)
    q = recording.poses.q
    step = np.zeros(len(q), dtype=np.int64)
    step[1:] = np.max(np.abs(np.diff(q, axis=0)), axis=1) > JOINT_CHANGE_TOLERANCE
    moves = np.cumsum(step)  # moves[i]: steps up to and including the one into row i
    return moves[pairs[:, 1]] > moves[pairs[:, 0]]


def repeat_pairs(recording: Recording) -> IntArray:
    """Index pairs (k, 2) [a, b], a < b: each measurement with the next one of the same bag
    and target at equal readings (within JOINT_CHANGE_TOLERANCE) and approach directions, at most
    MAX_REPEAT_GAP_S later (and at most MAX_REPEAT_LAG rows on)."""
    q, d, t = recording.poses.q, recording.poses.direction, recording.poses.time
    target = recording.poses.target_index
    n = len(q)
    partner = np.full(n, -1)
    max_lag = MAX_REPEAT_LAG * len(recording.target_names)  # rows: every target of a pose
    for lag in range(1, min(max_lag, n - 1) + 1):
        a = np.arange(n - lag)
        b = a + lag
        same = np.all(np.abs(q[b] - q[a]) <= JOINT_CHANGE_TOLERANCE, axis=1)
        same &= np.all(d[b] == d[a], axis=1)
        same &= recording.bag_index[b] == recording.bag_index[a]
        same &= target[b] == target[a]
        same &= np.abs(t[b] - t[a]) <= MAX_REPEAT_GAP_S
        same &= partner[a] < 0  # the nearest repeat only
        partner[a[same]] = b[same]
    first = np.flatnonzero(partner >= 0)
    return np.stack([first, partner[first]], axis=1)


def estimate_noise(
    recording: Recording,
    fallback_residuals: Array | None = None,
    fallback_dof: int = 0,
    stated_sigma_m: float | None = None,
) -> NoiseLevel:
    """The noise level of `recording` (see the module docstring for the order of methods);
    fallback_residuals (n, 3) [m] of a fitted model with `fallback_dof` free parameters;
    stated_sigma_m: the tracker's accuracy as the user states it (1-sigma per axis [m]).
    A stated accuracy the evidence contradicts leaves a `warning` (module docstring), as
    do re-reads that scatter beyond any tracker (`_reread_check`)."""
    level = _estimate(recording, fallback_residuals, fallback_dof, stated_sigma_m)
    refused = _reread_check(recording)
    if not refused:
        return level
    return replace(level, warning="; ".join(w for w in (refused, level.warning) if w))


def _estimate(
    recording: Recording,
    fallback_residuals: Array | None,
    fallback_dof: int,
    stated_sigma_m: float | None,
) -> NoiseLevel:
    """`estimate_noise` without the re-read check."""
    measured = _measured_noise(recording)
    stated = _stated(recording, stated_sigma_m)
    if measured is None and stated is None:
        measured = _reference_noise(recording)
    if measured is not None:
        return replace(measured, warning=_unused(stated, measured, stated_sigma_m is not None))
    model = None if fallback_residuals is None else _model_noise(fallback_residuals, fallback_dof)
    if stated is not None:
        if model is None or stated.sigma_m < FAR_ABOVE * model.sigma_m:
            return stated
        ratio = _ratio(stated.sigma_m, model.sigma_m)
        figures = (
            f"the {stated.source} {stated.sigma_m * 1e3:.4g} mm per axis is {ratio:.0f} x "
            f"the geometric fit's in-sample residual ({model.sigma_m * 1e3:.4g} mm per "
            "axis)"
        )
        if ratio >= REFUTED:
            return replace(
                model,
                warning=(
                    f"warning: {figures}: no fit lies that far below the noise, so it is not used "
                    f"and the noise floor is unknown; {UNIT_HINT}"
                ),
            )
        return replace(
            stated,
            warning=(
                f"warning: {figures}: the noise floor and the verdict rest on the stated accuracy "
                f"alone (no repeat poses or circle sweeps to check it); {UNIT_HINT}"
            ),
        )
    if model is not None:
        return model
    return NoiseLevel(float("nan"), "unknown", 0)


def _measured_noise(recording: Recording) -> NoiseLevel | None:
    """The noise measured without a model: repeat poses, circle fits, both pooled, or None."""
    pairs = repeat_pairs(recording)
    moved = moved_between(recording, pairs)
    repeat = None
    if int(moved.sum()) >= MIN_REPEATS:  # the robot came back: repeatability and noise
        pairs, source = pairs[moved], "repeat poses"
    else:  # re-reads of still poses: the tracker's noise, not the robot's repeatability
        pairs, source = pairs[~moved], REREADS
    if len(pairs) >= MIN_REPEATS:
        repeat = _pair_noise(recording, pairs, source)
        if source == REREADS and repeat.sigma_m > MAX_REREAD_SIGMA_M:
            repeat = None  # no tracker's noise (`_reread_check` says so)
    circles = _circle_noise(recording)
    if repeat is not None and circles is not None:
        if circles.sigma_m <= AGREE * repeat.sigma_m:  # circles not bent by effects: pool
            return _pooled(repeat, circles, f"{repeat.source} + circle fits")
        return repeat
    return repeat if repeat is not None else circles


def _reference_noise(recording: Recording) -> NoiseLevel | None:
    """The reference reflectors' scatter about the tracker's drift, pooled over the
    sources that have one (degrees of freedom: 3 per reference read), or None."""
    drifts = [r.drift for r in recording.references if r.drift is not None]
    if not drifts:
        return None
    dof = [3 * d.reads * len(d.references) for d in drifts]
    var = sum(n * (d.noise_mm * 1e-3) ** 2 for n, d in zip(dof, drifts)) / sum(dof)
    return NoiseLevel(float(np.sqrt(var)), REFERENCES, sum(dof))


def _pair_noise(recording: Recording, pairs: IntArray, source: str) -> NoiseLevel:
    """The noise per axis [m] of the pairs [a, b] of measurements that differ by noise only:
    sigma^2 = mean |p_a - p_b|^2 / 6."""
    diff = recording.points[pairs[:, 0]] - recording.points[pairs[:, 1]]
    return NoiseLevel(float(np.sqrt(np.mean(diff**2) / 2.0)), source, 3 * len(pairs))


def _reread_check(recording: Recording) -> str:
    """A warning when the re-reads of still poses (`repeat_pairs` not `moved_between`)
    scatter by more than MAX_REREAD_SIGMA_M per axis: no tracker re-measuring a still
    target does (a target knocked between reads, blunders, readings that moved): they are
    not used as the noise floor; '' otherwise (or with fewer than MIN_REPEATS re-reads)."""
    pairs = repeat_pairs(recording)
    still = pairs[~moved_between(recording, pairs)]
    if len(still) < MIN_REPEATS:
        return ""
    level = _pair_noise(recording, still, REREADS)
    if level.sigma_m <= MAX_REREAD_SIGMA_M:
        return ""
    return (
        f"warning: re-reads of still poses differ by {level.sigma_m * 1e3:.4g} mm per axis "
        f"(1-sigma, {len(still)} pairs): far beyond any tracker re-measuring a still target "
        f"({MAX_REREAD_SIGMA_M * 1e3:g} mm): a target knocked between reads, blunders, or "
        "readings that moved? They are not used as the noise floor"
    )


def _ratio(stated: float, evidence: float) -> float:
    """stated / evidence; inf when the evidence is 0 (identical points)."""
    return stated / evidence if evidence > 0 else float("inf")


def _unused(stated: NoiseLevel | None, measured: NoiseLevel, given: bool) -> str:
    """The word on a stated accuracy that measured noise makes unused: always for the
    user's --tracker-accuracy (`given`), for the recording's own figures when FAR_ABOVE x
    the measured noise; '' otherwise."""
    if stated is None:
        return ""
    ratio = _ratio(stated.sigma_m, measured.sigma_m)
    far = ratio >= FAR_ABOVE
    if not given and not far:
        return ""
    return (
        f"{'warning' if far else 'note'}: the {stated.source} {stated.sigma_m * 1e3:.4g} mm "
        f"per axis is not used: the noise floor rests on {measured.source} "
        f"({measured.sigma_m * 1e3:.4g} mm per axis, measured)"
        + (f"; the stated accuracy is {ratio:.0f} x that: {UNIT_HINT}" if far else "")
    )


def _stated(recording: Recording, stated_sigma_m: float | None) -> NoiseLevel | None:
    """The user's stated accuracy, else the rms of the per-point position standard
    deviations the recording states, else None."""
    if stated_sigma_m is not None:
        return NoiseLevel(float(stated_sigma_m), f"{STATED} (given by the user)", 0)
    sigma = recording.poses.sigma
    if sigma is not None and np.isfinite(sigma[:, 0]).any():
        stated = sigma[np.isfinite(sigma[:, 0]), 0]
        return NoiseLevel(float(np.sqrt(np.mean(stated**2))), f"{STATED} (per point)", len(stated))
    return None


def _model_noise(residuals: Array, n_free: int) -> NoiseLevel:
    """Per-axis noise from a fitted model's in-sample residuals (n, 3) [m] and its dof."""
    dof = max(residuals.size - n_free, 1)
    return NoiseLevel(float(np.sqrt(np.sum(residuals**2) / dof)), "model residual", dof)


def _pooled(a: NoiseLevel, b: NoiseLevel, source: str) -> NoiseLevel:
    """Two estimates of one noise pooled by their degrees of freedom."""
    dof = a.n + b.n
    var = (a.n * a.sigma_m**2 + b.n * b.sigma_m**2) / dof
    return NoiseLevel(float(np.sqrt(var)), source, dof)
