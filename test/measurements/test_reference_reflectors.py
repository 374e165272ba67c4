"""Reference reflectors and a drifting tracker, simulated with a known answer: the
simulator's tracker frame drifts 50 um/h (and turns 20 urad/h) while three reflectors on
the floor are read with every pose; the readers find the drift, remove it from the tool's
points, and take the reflectors' scatter as the measured tracker-noise floor."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from robot_calib.bag.read import read_recording
from robot_calib.diagnosis.noise import REFERENCES, estimate_noise
from robot_calib.flows.simulate import simulate as simulate_world
from robot_calib.identify.calibrate import calibrate
from robot_calib.measurements import Recording
from robot_calib.nodes.simulate import simulate_bag
from robot_calib.sim.world import World, build_world

RATE_M_PER_S = 50e-6 / 3600.0  # 50 um/h
TURN_RAD_PER_S = 20e-6 / 3600.0  # 20 urad/h about the tracker's vertical
FLOOR = {"r1": [0.6, 0.7, -0.1], "r2": [0.7, -0.6, -0.1], "r3": [-0.4, 0.5, 0.3]}


def _world(references: bool = True) -> World:
    return build_world(
        {
            "robot": "kr5_sixx_r650",
            "seed": 5,
            "tracker": {
                "drift_m_per_s": [0.6 * RATE_M_PER_S, 0.8 * RATE_M_PER_S, 0.0],
                "drift_rad_per_s": [0.0, 0.0, TURN_RAD_PER_S],
            },
            "timing": {"settle_s": 60.0},  # a pose a minute: two hours of drift
            **({"references": FLOOR} if references else {}),
        },
        "drifting tracker",
    )


def recorded(world: World, bag: Path, poses: int = 80) -> Recording:
    """`poses` random poses of `world` simulated into `bag` and read back."""
    simulate_world(bag, "random", world, n_random=poses, record=simulate_bag)
    return read_recording([bag], world.model.robot)


@pytest.fixture(scope="module")
def drifting(tmp_path_factory: pytest.TempPathFactory) -> tuple[World, Recording]:
    world = _world()
    return world, recorded(world, tmp_path_factory.mktemp("refs") / "drift.mcap", 120)


def test_the_drift_found_is_the_simulated_one(drifting: tuple[World, Recording]) -> None:
    """Where the drift puts each reflector at the last read, against where the simulated
    tracker frame put it (the truth), to a few um over ~100 um of drift."""
    world, recording = drifting
    (refs,) = recording.references
    assert refs.names == ("r1", "r2", "r3") and refs.drift is not None and refs.drift.rigid
    seconds = refs.stamp_ns * 1e-9
    rotation, translation = world.tracker.drift(seconds - seconds[0])
    start = world.reference_points()
    true_end = rotation[-1].apply(start) + translation[-1]
    found_end = refs.drift.expected(seconds)[:, -1]
    moved = float(np.linalg.norm(true_end - start, axis=1).max())
    assert moved > 80e-6, moved  # the campaign drifted
    assert refs.drift.max_mm == pytest.approx(moved * 1e3, rel=0.15)
    assert float(np.linalg.norm(found_end - true_end, axis=1).max()) < 8e-6


def test_the_reflectors_scatter_is_the_floor_and_the_drift_leaves_the_fit(
    drifting: tuple[World, Recording],
) -> None:
    """No repeat poses, no circle sweeps: the floor comes from the reflectors (the
    simulated tracker's noise, 3.75 um per axis: a reflector's centring error stays with its
    nest); the geometric fit of
    the points without the drift lies at that noise, the same points with the drift put
    back (what a tool without references fits) lie far above it."""
    world, recording = drifting
    noise = estimate_noise(recording)
    assert noise.source == REFERENCES
    assert noise.sigma_m == pytest.approx(world.noise.tracker_sigma_m, rel=0.2)
    expected = world.noise.base_sigma_m  # the tool's points: tracker and SMR
    robot = world.model.robot
    (refs,) = recording.references
    assert refs.drift is not None and recording.stamp_ns is not None
    rotation, translation = refs.drift.motion(recording.stamp_ns * 1e-9)
    drifted = replace(recording, points=rotation.apply(recording.points) + translation)
    rms = {}
    for name, rec in (("without drift", recording), ("with drift", drifted)):
        cal = calibrate(rec, robot, "geometric", log=None, screen_outliers=False)
        rms[name] = float(np.sqrt(np.mean((cal.predict(rec.poses) - rec.points) ** 2)))
    # joint repeatability (5 urad at up to ~0.6 m) adds to the tracker's noise at the tool
    assert rms["without drift"] < 2.0 * expected, rms
    assert rms["with drift"] > 2.0 * rms["without drift"], rms


def test_a_world_without_references_publishes_none(tmp_path: Path) -> None:
    """The same drifting tracker without reflectors: no reference topic, nothing to remove
    (the drift stays in the points, as on a real tracker without references)."""
    world = _world(references=False)
    bag = tmp_path / "plain.mcap"
    sim = simulate_world(bag, "random", world, n_random=20, record=simulate_bag)
    assert not any("reference" in topic for topic in sim.counts)
    assert read_recording([bag], world.model.robot).references == ()


def test_references_tell_a_tracker_jump_from_a_robot_error(tmp_path: Path) -> None:
    """Three SMRs on the tool, three reflectors on the floor, and the simulator's events:
    at 3 poses the robot is 2.5 mm off (every SMR the same way, the reflectors in place):
    the robot, named with the reflectors' figure; at 1 pose the tracker's frame jumps 2.5
    mm (the SMRs and the reflectors together): a tracker blunder. Both left out of the fit;
    the jump left out of the drift too."""
    from robot_calib.identify.outliers import ROBOT

    offset = [0.002, -0.0012, 0.0008]
    robot_poses, jump = (10, 30, 50), 65
    world = build_world(
        {
            "robot": "kr5_sixx_r650",
            "seed": 2,
            "references": FLOOR,
            "targets": {"smr2": [0.0, 0.07, 0.04], "smr3": [-0.05, -0.04, 0.06]},
            "events": [
                *({"kind": "robot", "poses": [p, p], "offset_m": offset} for p in robot_poses),
                {"kind": "tracker", "poses": [jump, jump], "offset_m": offset},
            ],
        },
        "three SMRs",
    )
    recording = recorded(world, tmp_path / "three.mcap")
    (refs,) = recording.references
    assert recording.stamp_ns is not None and refs.drift is not None
    pose = recording.pose_index()
    stamps = recording.stamp_ns

    def pose_of(stamp: int | None) -> int:
        return int(pose[stamps == stamp][0])

    cal = calibrate(recording, world.model.robot, "geometric", log=None)
    kinds = {pose_of(o.stamp_ns): o.kind for o in cal.outliers}
    assert kinds == {**dict.fromkeys(robot_poses, ROBOT), jump: "tracker"}, kinds
    assert cal.inliers is not None and not cal.inliers[np.isin(pose, (*robot_poses, jump))].any()
    lines = {pose_of(o.stamp_ns): o.line() for o in cal.outliers}
    assert "while the reference reflectors stayed within" in lines[robot_poses[0]]
    assert "the tracker's frame moved there" in lines[jump]
    # the jump left out of the drift (said so), which the robot's poses then sit on
    assert refs.drift.jumps == 1 and "1 read(s) where they jumped together" in refs.drift.line()
    noise_m = refs.drift.noise_mm * 1e-3
    for o in cal.outliers:
        assert o.references_m is not None
        if o.kind == ROBOT:
            assert o.references_m < 5.0 * noise_m, (o.references_m, noise_m)
        else:
            assert o.references_m == pytest.approx(float(np.linalg.norm(offset)), rel=0.05)


def test_a_world_with_references_drift_and_events_reads_back(tmp_path: Path) -> None:
    """The world file written beside a bag rebuilds the world: references, drift, events;
    a bad event is one line naming the file and the key."""
    from robot_calib.errors import InputError
    from robot_calib.sim.world import load_world, save_world

    world = build_world(
        {
            **{"references": FLOOR, "tracker": {"drift_m_per_s": [1e-8, 0.0, 0.0]}},
            "events": [{"kind": "tracker", "poses": [0, 11], "offset_m": [0.0, 0.005, 0.0]}],
        },
        "events",
    )
    save_world(world, tmp_path / "w.yaml")
    again = load_world(tmp_path / "w.yaml")
    assert again.references == world.references and again.events == world.events
    assert again.tracker == world.tracker
    zero = [0, 0, 0]
    for bad, said in (
        ({"kind": "robto", "poses": [1, 2], "offset_m": zero}, "kind must"),
        ({"kind": "robot", "poses": [5, 2], "offset_m": zero}, "first <= last"),
        ({"kind": "robot", "poses": [1, 2]}, "expected three"),
    ):
        with pytest.raises(InputError, match=said):
            build_world({"events": [bad]}, "bad.yaml")


@pytest.mark.slow
def test_a_still_tracker_shows_no_drift_and_a_real_one_is_found() -> None:
    """False alarms and hits of the drift's significance: 100 campaigns of a still tracker
    (40-600 reads of three reflectors at 12.5 um) never report a drift, 20 campaigns
    drifting 50 um/h over an hour (120 reads) always do, within the stated uncertainty."""
    from robot_calib.measurements.references import estimate_drift

    fixed = np.array([[2.0, 0.5, -0.8], [2.2, -0.6, -0.8], [1.8, 0.0, -0.2]])
    names = ["a", "b", "c"]
    for seed in range(100):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(40, 600))
        reads = np.stack([np.tile(p, (n, 1)) + rng.normal(0, 12.5e-6, (n, 3)) for p in fixed])
        drift = estimate_drift(names, np.sort(rng.uniform(0, 3600, n)), reads)
        assert not drift.significant, (seed, drift.line())
        assert "no drift of the tracker beyond the uncertainty" in drift.line()
    for seed in range(20):
        rng = np.random.default_rng(seed)
        t = np.linspace(0.0, 3600.0, 120)
        shift = np.outer(t / 3600.0 * 50e-6, [0.6, 0.8, 0.0])
        reads = np.stack(
            [np.tile(p, (120, 1)) + shift + rng.normal(0, 12.5e-6, (120, 3)) for p in fixed]
        )
        drift = estimate_drift(names, t, reads)
        assert drift.significant, drift.line()  # and as large as it is, to its uncertainty
        assert drift.max_mm == pytest.approx(0.05, abs=drift.uncertainty_mm), drift.line()


def test_a_tracker_knocked_for_good_is_a_step_not_a_drift(tmp_path: Path) -> None:
    """The tracker's frame moves 0.5 mm at pose 40 of 80 and stays there (a knock): the
    readers find one step of 0.5 mm at that read, fit each stretch on its own, and the
    geometric fit of the corrected points lies at the noise; the floor stays the
    reflectors' noise (where a smooth drift through the step made it ten times that)."""
    world = build_world(
        {
            "robot": "kr5_sixx_r650",
            "seed": 5,
            "references": FLOOR,
            "events": [{"kind": "tracker", "poses": [40, 79], "offset_m": [3e-4, 4e-4, 0.0]}],
        },
        "knocked tracker",
    )
    recording = recorded(world, tmp_path / "knock.mcap")
    (refs,) = recording.references
    assert refs.drift is not None and len(refs.drift.step_mm) == 1
    assert refs.drift.step_mm[0] == pytest.approx(0.5, abs=0.02)
    assert refs.stamp_ns is not None
    seconds = refs.stamp_ns * 1e-9
    assert refs.drift.step_times_s[0] == pytest.approx(seconds[40])  # the first read after it
    assert "1 step(s) where the tracker's frame moved at once and stayed: 0.5" in refs.drift.line()
    tracker = world.noise.tracker_sigma_m
    assert estimate_noise(recording).sigma_m == pytest.approx(tracker, rel=0.2)
    expected = world.noise.base_sigma_m  # the tool's points: tracker and SMR
    cal = calibrate(recording, world.model.robot, "geometric", log=None, screen_outliers=False)
    rms = float(np.sqrt(np.mean((cal.predict(recording.poses) - recording.points) ** 2)))
    assert rms < 1.5 * expected, rms
