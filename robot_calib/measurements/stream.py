"""Continuous tracking: a tracker streaming points while the robot moves (msgs_doc/stream.md).

The contract's pairing (nearest joint state within PAIR_TOLERANCE_S) assumes the robot
stands still at each measurement. When it moves, a point is paired here with the joint
readings *interpolated* to its stamp instead: a cubic spline through the joint-state
stream (see INTERPOLATION), only inside its span (no extrapolation), and only where the two joint
states around the point are at most `max_gap_s` apart (points in longer gaps are dropped
and counted). The tracker's and the controller's clocks differ by a constant latency: a
point stamped t (tracker clock) was measured when the joints were at the readings stamped
t + latency_s (controller clock). The approach direction of each joint at a point is the
sign of its velocity there (the contract's rule with the velocity field); a joint at rest
keeps its previous direction.

Pure numpy/scipy; where the stamps come from (a bag, `robot_calib.bag.read.read_stream`,
or the simulator, `robot_calib.sim.stream`) is the caller's business.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError, param
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.measurements.recording import (
    Recording,
    check_metres,
    pair_nearest,
    recording_from_arrays,
)
from robot_calib.poses import PRIMARY_TARGET

STREAM_MAX_GAP_S = 0.05  # joint states further apart than this: the points between dropped
STREAM_MAX_POINTS = 3000  # points kept for the fit (every k-th point, k chosen to fit)
STREAM_RATIO = 3.0  # points per joint state above which a bag looks like a stream
MOVING_FRACTION = 0.5  # ... when the robot moves at more than this fraction of its points
AT_STATE = 0.05  # points this close to a joint state (of the states' spacing) are not a stream
# The interpolation, chosen on the simulated controller's motion (smooth steps between
# waypoints, accelerations up to ~10 rad/s^2) sampled at 200 Hz, max error over 20000
# instants: linear 29 urad, PCHIP 21 urad, modified Akima 9.6 urad, cubic spline 4.5 urad
# (below the 5 urad repeatability). A cubic spline's overshoot at a stop is of that size.
INTERPOLATION = "cubic spline (scipy CubicSpline, not-a-knot)"
REST_SPEED_RAD_S = 1e-6  # a joint slower than this is at rest (keeps its direction)


@dataclass(frozen=True)
class JointStream:
    """The raw stamped messages of one stream recording, sorted by stamp.

    js_ns : (m,) joint-state stamps, controller clock [ns]; q : (m, J) readings [rad];
    velocity_sign : (m, J) signs of the velocity field (0: none given);
    point_ns : (n,) point stamps, tracker clock [ns]; points : (n, 3) tracker frame [m];
    temperature : (n,) [deg C] at each point, or None; source : the bag (or 'sim').
    """

    js_ns: IntArray
    q: Array
    velocity_sign: Array
    point_ns: IntArray
    points: Array
    source: str = "stream"
    temperature: Array | None = None

    @classmethod
    def from_messages(
        cls,
        js_ns: IntArray,
        q: Array,
        velocity_sign: Array,
        point_ns: IntArray,
        points: Array,
        source: str = "stream",
        temperature: Array | None = None,
    ) -> JointStream:
        """The stream of messages in any order: checked (lengths, metres, >= 2 joint
        states, no two joint states with one stamp) and sorted by stamp; InputError
        naming `source` otherwise."""
        js_ns, point_ns = np.asarray(js_ns, np.int64), np.asarray(point_ns, np.int64)
        q, points = np.asarray(q, float), np.asarray(points, float).reshape(-1, 3)
        velocity_sign = np.asarray(velocity_sign, float)
        if len(js_ns) != len(q) or len(point_ns) != len(points) or q.shape != velocity_sign.shape:
            raise InputError(f"{source}: stamps and values differ in length")
        if len(js_ns) < 2:
            raise InputError(f"{source}: {len(js_ns)} joint state(s): a stream needs >= 2")
        check_metres(points, source)
        js_order, pt_order = np.argsort(js_ns, kind="stable"), np.argsort(point_ns, kind="stable")
        js_ns = js_ns[js_order]
        if np.any(np.diff(js_ns) == 0):
            k = int(np.flatnonzero(np.diff(js_ns) == 0)[0])
            raise InputError(f"{source}: two joint states share the stamp {js_ns[k]} ns")
        return cls(
            js_ns,
            q[js_order],
            velocity_sign[js_order],
            point_ns[pt_order],
            points[pt_order],
            source,
            None if temperature is None else np.asarray(temperature, float)[pt_order],
        )

    @property
    def joint_rate_hz(self) -> float:
        """Median joint-state rate [Hz]."""
        return float(1e9 / np.median(np.diff(self.js_ns)))

    @property
    def point_rate_hz(self) -> float:
        """Median point rate [Hz] (0 with fewer than two points)."""
        if len(self.point_ns) < 2:
            return 0.0
        return float(1e9 / max(np.median(np.diff(self.point_ns)), 1))


@dataclass(frozen=True)
class StreamPairing:
    """How the points of a stream were paired. latency_s : the constant offset used
    [s]; every : every k-th point kept (decimation); n_points : points in the stream;
    n_kept : after decimation; n_outside : of those, outside the joint-state span;
    n_in_gaps : in a gap of the joint states longer than max_gap_s (both dropped)."""

    latency_s: float
    every: int
    n_points: int
    n_kept: int
    n_outside: int
    n_in_gaps: int

    def line(self) -> str:
        """One human line."""
        return (
            f"stream pairing: latency {self.latency_s * 1e3:.4f} ms, "
            f"{'all' if self.every == 1 else f'every {_ordinal(self.every)} of'} "
            f"{self.n_points} points ({self.n_kept} kept), {self.n_outside} outside the "
            f"joint-state span and {self.n_in_gaps} in joint-state gaps dropped"
        )


def _ordinal(k: int) -> str:
    """'2nd', '3rd', '11th', '21st', ..."""
    if k % 100 in (11, 12, 13):
        return f"{k}th"
    return f"{k}{ {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th') }"


def joints_at(
    stream: JointStream, at_ns: Array, max_gap_s: float = STREAM_MAX_GAP_S
) -> tuple[Array, Array, NDArray[np.bool_], NDArray[np.bool_]]:
    """The joint readings interpolated at controller-clock times at_ns (n,) [ns] (a cubic
    spline, not-a-knot: `INTERPOLATION`).

    Returns
    -------
    q : ndarray, shape (n, J)
        Readings [rad] (NaN where not inside).
    velocity : ndarray, shape (n, J)
        The interpolant's derivative [rad/s] (NaN where not inside).
    inside : ndarray of bool, shape (n,)
        Within the joint-state span (first to last stamp).
    in_gap : ndarray of bool, shape (n,)
        Inside, but between two joint states more than `max_gap_s` apart.
    """
    from scipy.interpolate import CubicSpline

    at_ns = np.asarray(at_ns, dtype=float)
    t0 = stream.js_ns[0]
    knots_s = (stream.js_ns - t0) * 1e-9
    at_s = (at_ns - t0) * 1e-9
    inside = (at_s >= 0.0) & (at_s <= knots_s[-1])
    k = np.clip(np.searchsorted(knots_s, at_s, side="right") - 1, 0, len(knots_s) - 2)
    in_gap = inside & ((knots_s[k + 1] - knots_s[k]) > max_gap_s)
    spline = CubicSpline(knots_s, stream.q, axis=0, extrapolate=False)
    q, velocity = spline(at_s), spline.derivative()(at_s)
    bad = ~inside | in_gap
    q[bad], velocity[bad] = np.nan, np.nan
    return q, velocity, inside, in_gap


def stream_directions(stream: JointStream, at_ns: Array, velocity: Array) -> Array:
    """Approach directions (n, J) +1/-1 at controller-clock times at_ns (n,) [ns], in time
    order: the sign of the velocity field of the nearest joint state where it gives one,
    else that of the interpolated `velocity` (n, J) [rad/s] (`velocity_directions`)."""
    nearest = pair_nearest(stream.js_ns, np.round(at_ns).astype(np.int64), 2**62)
    sign = stream.velocity_sign[nearest]
    return velocity_directions(np.where(sign != 0, sign, velocity))


def velocity_directions(velocity: Array) -> Array:
    """Approach directions (n, J) +1/-1 from velocities (n, J) [rad/s] in time order: the
    sign of each joint's velocity; a joint at rest (|velocity| <= REST_SPEED_RAD_S) keeps
    its previous direction (+1 before any motion)."""
    sign = np.where(np.abs(velocity) > REST_SPEED_RAD_S, np.sign(velocity), 0.0)
    rows = np.where(sign != 0, np.arange(len(sign))[:, None], -1)
    last = np.maximum.accumulate(rows, axis=0)  # the last moving row of each joint
    filled = np.take_along_axis(sign, np.maximum(last, 0), axis=0)
    return np.where(last >= 0, filled, 1.0)


def decimation(n_points: int, max_points: int = STREAM_MAX_POINTS) -> int:
    """k: keep every k-th point so that at most `max_points` of `n_points` remain."""
    return max(1, -(-n_points // max(max_points, 1)))


def stream_recording(
    stream: JointStream,
    latency_s: float,
    max_gap_s: float = STREAM_MAX_GAP_S,
    every: int = 1,
) -> tuple[Recording, StreamPairing]:
    """A recording of every `every`-th point of `stream`, each with the joint readings
    interpolated at its stamp + `latency_s` [s] (`joints_at`) and the directions of
    `stream_directions`; points outside the joint-state span or in a gap are dropped and
    counted (StreamPairing, and a warning in the recording). A stream has no circle
    sweeps (they need stop-and-go poses): every point is a general pose. InputError when
    no point remains."""
    if every < 1 or not np.isfinite(latency_s) or not max_gap_s > 0:
        raise InputError(
            f"{stream.source}: stream options: every {every} >= 1, latency "
            f"{latency_s} s finite, max gap {max_gap_s} s > 0"
        )
    keep = np.arange(0, len(stream.point_ns), every)
    at_ns = (stream.point_ns[keep] + latency_s * 1e9).astype(np.float64)
    q, velocity, inside, in_gap = joints_at(stream, at_ns, max_gap_s)
    ok = inside & ~in_gap
    pairing = StreamPairing(
        latency_s,
        every,
        len(stream.point_ns),
        len(keep),
        int((~inside).sum()),
        int(in_gap.sum()),
    )
    if not ok.any():
        raise InputError(
            f"{stream.source}: none of {len(keep)} points lies inside the joint-state stream "
            f"at latency {latency_s} s ({pairing.line()})"
        )
    direction = stream_directions(stream, at_ns[ok], velocity[ok])
    point_ns = stream.point_ns[keep][ok]
    time = (point_ns - point_ns[0]) * 1e-9
    temperature = None if stream.temperature is None else stream.temperature[keep][ok]
    rec = recording_from_arrays(
        q[ok], stream.points[keep][ok], time, stream.source, temperature=temperature
    )
    warnings = []
    dropped = pairing.n_outside + pairing.n_in_gaps
    if dropped:
        warnings.append(
            f"warning: {stream.source}: {dropped} of {len(keep)} points dropped "
            f"({pairing.n_outside} outside the joint-state span, {pairing.n_in_gaps} in gaps "
            f"of the joint states longer than {max_gap_s} s)"
        )
    poses = replace(rec.poses, direction=direction)
    rec = replace(
        rec,
        poses=poses,
        sweeps=(),
        n_unpaired=dropped,
        warnings=tuple(warnings),
        point_index=keep[ok],
        stamp_ns=point_ns,
        target_names=(PRIMARY_TARGET,),
    )
    return rec, pairing


#: what the stream warning advises (`stream_hint`)
STREAM_ADVICE = f"use {param('stream', True)} (msgs_doc/stream.md)"


def stream_hint(
    js_ns: IntArray, q: Array, n_points: int, source: str, point_ns: IntArray | None = None
) -> str | None:
    """A warning line when a bag looks like a stream (more than STREAM_RATIO points per
    joint state while the robot moves between most joint states), for which the
    contract's nearest-stamp pairing is off by up to half a joint-state period of motion:
    it suggests `--stream`. None otherwise, and None when the points (their stamps
    `point_ns` [ns]) lie at the joint states (within AT_STATE of their median spacing:
    re-reads of each pose, not a stream). js_ns (m,) [ns], q (m, J) [rad] sorted."""
    m = len(js_ns)
    if m < 2 or n_points < STREAM_RATIO * m:
        return None
    if point_ns is not None and len(point_ns):
        gap = np.abs(js_ns[pair_nearest(js_ns, point_ns, np.iinfo(np.int64).max)] - point_ns)
        if np.median(gap) < AT_STATE * np.median(np.diff(js_ns)):
            return None
    moving = np.any(np.abs(np.diff(q, axis=0)) > 1e-4, axis=1).mean()
    if moving <= MOVING_FRACTION:
        return None
    return (
        f"warning: {source}: {n_points} points for {m} joint states while the robot moves "
        f"between {moving:.0%} of them: a stream (continuous tracking); nearest-stamp "
        f"pairing pairs a moving robot badly: {STREAM_ADVICE}"
    )
