"""Continuous tracking (msgs_doc/stream.md): a simulated stream with a known latency, whose
truth the world holds; the latency identified, the geometry scored on held-out static
poses against the noise floor, and the same stream with the latency ignored."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli

from robot_calib.bag.read import read_bag, read_stream
from robot_calib.bag.write import write_stream_bag
from robot_calib.flows.simulate import simulation_world
from robot_calib.identify.latency import calibrate_stream, steffensen
from robot_calib.identify.score import score
from robot_calib.measurements.stream import (
    JointStream,
    joints_at,
    stream_recording,
    velocity_directions,
)
from robot_calib.sim.controller import states_at
from robot_calib.sim.measure import record_plan
from robot_calib.sim.plans import random_plan
from robot_calib.sim.stream import SimulatedStream, StreamOptions, simulate_stream

LATENCY_S = 0.002  # the truth
WORLD = simulation_world()


@pytest.fixture(scope="module")
def simulated() -> SimulatedStream:
    rng = np.random.default_rng(7)
    waypoints = random_plan(WORLD.model.robot, 8, rng).q
    return simulate_stream(WORLD, waypoints, StreamOptions(latency_s=LATENCY_S), rng)


@pytest.fixture(scope="module")
def holdout():  # noqa: ANN201 - a Recording of 60 static poses the fit never sees
    rng = np.random.default_rng(8)
    return record_plan(WORLD, random_plan(WORLD.model.robot, 60, rng), rng)


def test_interpolated_readings_match_the_motion(simulated: SimulatedStream) -> None:
    """A cubic spline through 200 Hz joint states reproduces the true motion at the point
    stamps to within 10 urad (~4.5 urad max: the repeatability's size), and the velocity
    signs give the directions."""
    stream = simulated.stream
    at_ns = stream.point_ns[::7] + LATENCY_S * 1e9
    q, velocity, inside, in_gap = joints_at(stream, at_ns)
    tau = (stream.point_ns[::7] - stream.point_ns[0]) * 1e-9  # real time since the start
    q_true, v_true = states_at(simulated.motion, tau)
    ok = inside & ~in_gap
    assert ok.mean() > 0.99
    assert np.max(np.abs(q[ok] - q_true[ok])) < 1e-5
    moving = np.abs(v_true[ok]) > 1e-3
    assert np.array_equal(np.sign(velocity[ok][moving]), np.sign(v_true[ok][moving]))
    held = velocity_directions(np.array([[0.0, 0.5], [1e-9, -0.5], [-2.0, 0.0]]))
    assert held.tolist() == [[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0]]


def test_gaps_and_span_are_dropped_and_counted(simulated: SimulatedStream) -> None:
    """Points in a 0.2 s hole of the joint states, and points stamped before the first
    joint state (no extrapolation), are dropped and counted exactly."""
    s = simulated.stream
    hole = (s.js_ns > s.js_ns[400]) & (s.js_ns < s.js_ns[440])  # 39 removed: a 0.2 s gap
    holed = JointStream(s.js_ns[~hole], s.q[~hole], s.velocity_sign[~hole], s.point_ns, s.points)
    rec, pairing = stream_recording(holed, 0.0)
    expected_gap = int(((s.point_ns > s.js_ns[400]) & (s.point_ns < s.js_ns[440])).sum())
    expected_outside = int((s.point_ns < s.js_ns[0]).sum() + (s.point_ns > s.js_ns[-1]).sum())
    assert pairing.n_in_gaps == expected_gap > 150
    assert pairing.n_outside == expected_outside > 0
    assert rec.n_unpaired == expected_gap + expected_outside
    assert len(rec) == len(s.point_ns) - rec.n_unpaired
    assert any("in gaps" in w for w in rec.warnings)


def test_latency_identified_and_geometry_at_the_noise_floor(
    simulated: SimulatedStream, holdout
) -> None:  # noqa: ANN001
    """Known answer: 2 ms latency identified within 0.2 ms (in fact ~1 us); the calibrated
    geometry's held-out rms near the noise floor (~0.009 mm); ignoring the latency (0)
    is measurably worse on the same points (> 10x)."""
    robot = WORLD.model.robot
    fit = calibrate_stream(simulated.stream, robot, max_points=1500)
    assert abs(fit.latency_s - LATENCY_S) < 0.2e-3
    assert abs(fit.latency_s - LATENCY_S) < 20e-6
    assert fit.rounds >= 2 and fit.pairing.every == 11 and fit.pairing.n_kept <= 1500
    held = score(fit.calibration, holdout).accuracy
    assert held.absolute_rms_mm < 0.02
    ignored = calibrate_stream(simulated.stream, robot, latency_s=0.0, max_points=1500)
    worse = score(ignored.calibration, holdout).accuracy
    assert worse.absolute_rms_mm > 10 * held.absolute_rms_mm


def test_steffensen_jumps_to_the_limit_of_a_linear_iteration() -> None:
    """g(x) = 2 + 0.15 (x - 2): from 0, two rounds and one step reach 2 exactly."""
    g = lambda x: 2.0 + 0.15 * (x - 2.0)  # noqa: E731
    assert steffensen([0.0, g(0.0), g(g(0.0))]) == pytest.approx(2.0, abs=1e-12)
    assert steffensen([0.0, 1.0, 3.0]) == 3.0  # not shrinking: the last value (a copy)


def test_stream_bag_round_trip_hint_and_cli(simulated: SimulatedStream, tmp_path: Path) -> None:
    """A stream written as a contract bag: the default pairing warns and suggests
    --stream; `calibrate --stream --latency 0.002` reads the same stream back and writes
    PARAMS.json with its stream section; a bad --latency is a one-line error."""
    s, robot = simulated.stream, WORLD.model.robot
    short = s.point_ns < s.point_ns[0] + 4_000_000_000  # the first 4 s
    js = s.js_ns < s.point_ns[0] + 4_100_000_000
    bag = tmp_path / "stream.mcap"
    counts = write_stream_bag(
        bag,
        s.js_ns[js],
        s.q[js],
        simulated.velocity[js],
        s.point_ns[short],
        s.points[short],
        robot.joint_names,
    )
    assert counts == {"/joint_states": int(js.sum()), "/laser_tracker/point": int(short.sum())}
    back = read_stream(bag, robot)
    assert np.array_equal(back.point_ns, s.point_ns[short])
    assert np.allclose(back.q, s.q[js], atol=0) and np.array_equal(back.points, s.points[short])
    assert np.array_equal(back.velocity_sign, s.velocity_sign[js])
    paired = read_bag(bag, robot)
    assert any("`stream=True`" in w for w in paired.warnings)
    out = tmp_path / "PARAMS.json"
    run = cli(
        "calibrate",
        str(bag),
        "--stream",
        "--latency",
        "0.002",
        "--stream-max-points",
        "500",
        "-o",
        str(out),
    )
    assert run.returncode == 0, run.stderr
    assert "latency 2.0000 ms (given)" in run.stdout
    doc = json.loads(out.read_text())
    assert doc["stream"]["latency_s"] == pytest.approx(0.002, abs=1e-12)
    assert doc["stream"]["points"] == int(short.sum())
    bad = cli("calibrate", str(bag), "--latency", "0.002", "-o", str(tmp_path / "x"))
    assert bad.returncode == 2 and "--latency applies with --stream only" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
