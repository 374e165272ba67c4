"""The latency between the tracker's and the controller's clocks, identified from a stream
(msgs_doc/stream.md): the constant offset at which the calibrated model explains the
points best.

Alternation (block coordinate descent): the model is fitted at latency 0; then, with its
parameters held, the latency minimising the rms residual is searched (each trial pairs the
stream again, `stream_recording`: joint readings interpolated at each point's stamp +
latency, and evaluates the forward model: no fit, milliseconds), first by a scan over
+-bound_s (a smooth motion makes this curve one valley) then by Brent's bounded search
(`scipy.optimize.minimize_scalar`) within one scan step of the best, to `LATENCY_XTOL_S`;
the model is fitted again at that latency (warm start), and so on until the latency moves
less than LATENCY_ROUND_TOL_S. The geometry fitted at a wrong latency absorbs part of it,
so each round takes off a nearly constant fraction of the error (~85 % on the simulated
stream): Steffensen's step (`steffensen`) extrapolates every two rounds to the limit,
and three or four fits suffice. The outlier
screening is off during the rounds (a changing inlier set would make the curve jump) and
on for the final fit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from robot_calib.identify.calibrate import calibrate
from robot_calib.identify.calibration import Calibration
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.frames import Array
from robot_calib.log import Log
from robot_calib.measurements.recording import Recording
from robot_calib.measurements.stream import (
    STREAM_MAX_GAP_S,
    STREAM_MAX_POINTS,
    JointStream,
    StreamPairing,
    decimation,
    stream_recording,
)

LATENCY_BOUND_S = 0.05  # the search spans -bound .. +bound [s]
LATENCY_SCAN_STEPS = 21  # coarse scan points over the bounds
LATENCY_XTOL_S = 2e-6  # Brent's absolute tolerance on the latency [s]
LATENCY_MAX_ROUNDS = 6  # alternations of latency search and geometry fit
LATENCY_ROUND_TOL_S = 1e-5  # the rounds stop when the latency moves less than this [s]


@dataclass(frozen=True)
class StreamCalibration:
    """A calibration from a stream.

    calibration : the model fitted at `latency_s`; recording : the paired (decimated)
    points it was fitted on; pairing : how they were paired; latency_s : the latency used
    [s] (identified, or given); rounds : alternations of latency search and geometry fit
    (0: the latency was given); tried_s (k,) and rms_m (k,) : the last round's latencies
    [s] and the rms residual at each at that round's geometry [m] (empty when given).
    """

    calibration: Calibration
    recording: Recording
    pairing: StreamPairing
    latency_s: float
    rounds: int
    tried_s: Array
    rms_m: Array

    def document(self) -> dict[str, Any]:
        """The PARAMS.json document of the calibration (msgs_doc/parameters.md) with a
        `stream` section: latency_s, identified, rounds, every, points, points_kept,
        dropped_outside_span, dropped_in_gaps (msgs_doc/stream.md)."""
        doc = self.calibration.to_dict(self.recording)
        p = self.pairing
        doc["stream"] = {
            "latency_s": self.latency_s,
            "identified": self.rounds > 0,
            "rounds": self.rounds,
            "every": p.every,
            "points": p.n_points,
            "points_kept": p.n_kept,
            "dropped_outside_span": p.n_outside,
            "dropped_in_gaps": p.n_in_gaps,
        }
        return doc

    def line(self) -> str:
        """One human line on the latency."""
        how = f"identified in {self.rounds} round(s)" if self.rounds else "given"
        return f"latency {self.latency_s * 1e3:.4f} ms ({how}); {self.pairing.line()}"


def calibrate_stream(
    stream: JointStream,
    robot: RobotDescription,
    model: str = "geometric",
    latency_s: float | None = None,
    bound_s: float = LATENCY_BOUND_S,
    max_points: int = STREAM_MAX_POINTS,
    max_gap_s: float = STREAM_MAX_GAP_S,
    ecc_order: int = 1,
    log: Log | None = None,
) -> StreamCalibration:
    """Identify `model` from `stream`, every k-th point kept so that at most `max_points`
    are fitted (`decimation`); `latency_s` None: identified within +-`bound_s` (module
    docstring), else used as given [s]."""
    say = log or (lambda _m: None)
    every = decimation(len(stream.point_ns), max_points)
    quiet = lambda _m: None  # noqa: E731 - the search's many fits say nothing
    if latency_s is not None:
        rec, pairing = stream_recording(stream, latency_s, max_gap_s, every)
        cal = calibrate(rec, robot, model, ecc_order, log=log)
        return StreamCalibration(cal, rec, pairing, latency_s, 0, np.zeros(0), np.zeros(0))
    rec, pairing = stream_recording(stream, 0.0, max_gap_s, every)
    cal = calibrate(rec, robot, model, ecc_order, log=quiet, screen_outliers=False)
    latency, rounds, chain = 0.0, 0, [0.0]
    for rounds in range(1, LATENCY_MAX_ROUNDS + 1):
        tried: dict[float, float] = {}
        found = _best_latency(stream, cal, latency, bound_s, max_gap_s, every, tried)
        say(
            f"latency round {rounds}: {found * 1e3:.4f} ms (rms {tried[found] * 1e3:.4f} mm "
            f"at the geometry fitted at {latency * 1e3:.4f} ms)"
        )
        converged = abs(found - latency) < LATENCY_ROUND_TOL_S
        bound_s = max(abs(found - latency) * 4, 20 * LATENCY_XTOL_S)  # narrower after the first
        chain.append(found)
        latency = steffensen(chain) if len(chain) == 3 else found
        chain = [latency] if len(chain) == 3 else chain
        rec, pairing = stream_recording(stream, latency, max_gap_s, every)
        if converged or rounds == LATENCY_MAX_ROUNDS:  # the final fit, outliers screened
            cal = calibrate(rec, robot, model, ecc_order, log=log, start=cal)
            break
        cal = calibrate(rec, robot, model, ecc_order, log=quiet, start=cal, screen_outliers=False)
    order = sorted(tried)
    return StreamCalibration(
        cal,
        rec,
        pairing,
        latency,
        rounds,
        np.array(order),
        np.array([tried[k] for k in order]),
    )


def steffensen(chain: list[float]) -> float:
    """Steffensen's (Aitken's delta-squared) step for the fixed point of the rounds' map
    g from chain = [x, g(x), g(g(x))] [s]: the alternation converges linearly (each round
    takes a nearly constant fraction off the error) and this jumps to its limit; the last
    value when the differences do not shrink."""
    x0, x1, x2 = chain
    curvature = x2 - 2 * x1 + x0
    if curvature == 0 or abs(x2 - x1) >= abs(x1 - x0):
        return x2
    return x0 - (x1 - x0) ** 2 / curvature


def _best_latency(
    stream: JointStream,
    cal: Calibration,
    centre: float,
    bound_s: float,
    max_gap_s: float,
    every: int,
    tried: dict[float, float],
) -> float:
    """The latency [s] within centre +-bound_s that minimises the rms residual of `cal`'s
    model at its parameters (no fit: forward kinematics only): a scan, then Brent's
    search within one scan step of its best; every evaluation recorded in `tried`
    {latency: rms [m]}."""
    from scipy.optimize import minimize_scalar

    def rms(latency: float) -> float:
        rec, _ = stream_recording(stream, latency, max_gap_s, every)
        predicted = cal.model.target_points(cal.parameters, rec.poses)
        tried[latency] = float(np.sqrt(np.mean(np.sum((predicted - rec.points) ** 2, axis=1))))
        return tried[latency]

    grid = centre + np.linspace(-bound_s, bound_s, LATENCY_SCAN_STEPS)
    best = float(grid[np.argmin([rms(float(t)) for t in grid])])
    step = float(grid[1] - grid[0])
    found = minimize_scalar(
        rms, bounds=(best - step, best + step), method="bounded", options={"xatol": LATENCY_XTOL_S}
    )
    return float(found.x)
