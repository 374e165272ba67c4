"""What the simulated laser tracker measures: the physical target of the world's true
model at the physical joint angles (reading + repeatability noise, effects acting on the
direction history and time), plus tracker and target noise, latency and dropouts.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.measurements import Recording, recording_from_arrays
from robot_calib.model import KinematicModel
from robot_calib.poses import JOINT_CHANGE_TOLERANCE, Poses, approach_directions, next_direction
from robot_calib.sim.plans import Plan, plan_times
from robot_calib.sim.world import NoiseModel, World


def line_of_sight(p_in_tracker: Array) -> tuple[Array, Array, Array, Array]:
    """Of points (n, 3) [m] seen from the tracker at the origin: their range (n, 1) [m], the
    unit vector along the line of sight and two unit vectors across it (each (n, 3))."""
    distance = np.linalg.norm(p_in_tracker, axis=1, keepdims=True)
    radial = p_in_tracker / distance
    helper = np.where(np.abs(radial[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    across1 = np.cross(radial, helper)
    across1 /= np.linalg.norm(across1, axis=1, keepdims=True)
    return distance, radial, across1, np.cross(radial, across1)


def tracker_noise(
    noise: NoiseModel, p_in_tracker: Array, rng: np.random.Generator, reads: int = 1
) -> Array:
    """Noise vectors (n, 3) [m] for points p_in_tracker (n, 3) (tracker at the origin).
    `reads`: the rows are that many reads of the same n / reads targets in turn (a still
    pose read again): the target's centring error drawn once per target, shared by its
    reads; the tracker's own noise drawn per read."""
    n = p_in_tracker.shape[0]
    target = np.tile(rng.normal(0.0, noise.target_sigma_m, (n // reads, 3)), (reads, 1))
    if not noise.anisotropic:
        return target + rng.normal(0.0, noise.tracker_sigma_m, (n, 3))
    distance, radial, across1, across2 = line_of_sight(p_in_tracker)
    sigma_t = noise.tracker_transverse_sigma_rad * distance
    return (
        target
        + radial * rng.normal(0.0, noise.tracker_radial_sigma_m, (n, 1))
        + across1 * rng.normal(0.0, 1.0, (n, 1)) * sigma_t
        + across2 * rng.normal(0.0, 1.0, (n, 1)) * sigma_t
    )


def stated_accuracy(noise: NoiseModel, p_in_tracker: Array) -> Array:
    """The standard deviations (n, 2) [m, rad] the simulated tracker states with its
    measurements at p_in_tracker (n, 3) [m] (tracker at the origin), as a 6-DoF tracker
    reports them (msgs_doc/six_dof.md): position per coordinate, the rms over x, y, z of
    the tracker and target noise of `tracker_noise` (anisotropic: radial and transverse at
    the point's range); orientation per axis, noise.orientation_sigma_rad. The robot's
    repeatability is not the tracker's to state: not included. 0 = no noise (not stated)."""
    n = p_in_tracker.shape[0]
    if noise.anisotropic:
        across = noise.tracker_transverse_sigma_rad * np.linalg.norm(p_in_tracker, axis=1)
        tracker_variance = (noise.tracker_radial_sigma_m**2 + 2.0 * across**2) / 3.0
    else:
        tracker_variance = np.full(n, noise.tracker_sigma_m**2)
    position = np.sqrt(noise.target_sigma_m**2 + tracker_variance)
    return np.column_stack([position, np.full(n, noise.orientation_sigma_rad)])


def physical_poses(world: World, poses: Poses, rng: np.random.Generator) -> Poses:
    """`poses` at their physical joint angles: readings plus the robot's repeatability
    jitter, one draw per pose (targets measured at the same pose, same readings and time,
    consecutive, share it)."""
    new_pose = np.ones(len(poses), dtype=bool)
    if len(poses) > 1:
        new_pose[1:] = np.any(np.diff(poses.q, axis=0) != 0, axis=1) | (np.diff(poses.time) != 0)
    jitter = rng.normal(0.0, world.noise.joint_sigma_rad, (int(new_pose.sum()), poses.q.shape[1]))
    return replace(poses, q=poses.q + jitter[np.cumsum(new_pose) - 1])


def physical_points(
    world: World, poses: Poses, rng: np.random.Generator, noisy: bool = True
) -> Array:
    """Measured target centres in the tracker frame, shape (n, 3) [m], for `poses`
    (readings, approach directions, time). noisy=False gives the exact true points."""
    return measure_six_dof(world, poses, rng, noisy)[0]


def measure_six_dof(
    world: World, poses: Poses, rng: np.random.Generator, noisy: bool = True, reads: int = 1
) -> tuple[Array, Array | None]:
    """What the tracker measures at `poses`: points (n, 3) [m] as `physical_points` and,
    where the world has 6-DoF probes (`model.oriented`), their frames (n, 3, 3) in the
    tracker frame, each turned by a random rotation vector of noise.orientation_sigma_rad
    per axis (NaN rows for targets without a probe; None when the world has none). The
    random draws of the points come first, so the points equal `physical_points`'."""
    model, truth = world.model, world.truth
    physical = physical_poses(world, poses, rng) if noisy else poses
    points = model.target_points(truth, physical)
    if noisy:
        points = points + tracker_noise(world.noise, points, rng, reads)
    if not model.oriented:
        return points, None
    frames = model.probe_orientations(truth, physical)
    if noisy:
        turn = rng.normal(0.0, world.noise.orientation_sigma_rad, (len(poses), 3))
        frames = Rotation.from_rotvec(turn).as_matrix() @ frames
    probes = [model.targets.index(t) for t in model.oriented]
    frames[~np.isin(poses.target_index, probes)] = np.nan
    return points, frames


POINT_SIGMA_STREAM = 0x51A  # the side generator of each point's own accuracy (with the seed)
BATCH_CHECK_POSES = 32
"""Poses of the first batch `StreamingTracker.measure_batch` checks against `measure_all`."""


@dataclass(frozen=True)
class TrackerReading:
    """What the streaming tracker measured at one pose.

    points : (T, 3) every target's point, tracker frame [m] (the world's targets in order)
    frames : (T, 3, 3) the 6-DoF probes' measured frames in the tracker frame, NaN for a
      target without a probe; None when the world has no probe (msgs_doc/six_dof.md)
    sigma : (T, 2) the standard deviations the tracker states [m, rad] (`stated_accuracy`)
    latency_s : by how much the measurement precedes the joint state's stamp [s]
    references : (R, 3) the world's reference reflectors read with this pose, tracker frame
      [m] (None: the world has none; msgs_doc/references.md)
    rereads : (N - 1, T, 3) the further reads of every target at this pose when the tracker
      reads each pose N times (`TrackerOptions.reads_per_pose`; the robot still: the same
      physical pose, the tracker's noise drawn again), tracker frame [m]; None: one read
    The tracker's drift (`TrackerOptions.drift`) is in the points, frames and references.
    """

    points: Array
    frames: Array | None
    sigma: Array
    latency_s: float
    references: Array | None = None
    rereads: Array | None = None


@dataclass
class StreamingTracker:
    """The tracker as a stream: one reading at a time, keeping the direction history and
    the start time that effects need (the state a real robot carries)."""

    world: World
    rng: np.random.Generator
    _last_q: Array | None = None
    _direction: Array | None = None
    _t0: float | None = None
    count: int = field(default=0)
    _batch_ok: bool | None = field(default=None, repr=False)  # measure_batch's check

    def measure(self, q: Array, stamp_s: float) -> tuple[Array, float] | None:
        """Point (3,) [m] of the first target for reading q (J,) stamped `stamp_s`, and the
        latency [s] by which the tracker's measurement precedes that stamp; None when the
        point is dropped."""
        result = self.measure_targets(q, stamp_s)
        return None if result is None else (result[0][0], result[1])

    def measure_targets(self, q: Array, stamp_s: float) -> tuple[Array, float] | None:
        """Every target's point (T, 3) [m] (the world's targets, in order; one physical
        joint angle for all) for reading q (J,) stamped `stamp_s`, and the latency [s];
        None when the pose is dropped."""
        reading = self.measure_all(q, stamp_s)
        return None if reading is None else (reading.points, reading.latency_s)

    def measure_all(self, q: Array, stamp_s: float) -> TrackerReading | None:
        """What the tracker measures of every target at reading q (J,) stamped `stamp_s`
        (`TrackerReading`: points, 6-DoF probe frames, stated accuracies, latency), None
        when the pose is dropped. Points and frames come from `measure_six_dof`: those of
        one pose share its physical joint angles (one repeatability draw)."""
        q = np.asarray(q, dtype=float)
        if self._last_q is None:
            self._direction = np.ones_like(q)
            self._t0 = stamp_s
        else:
            assert self._direction is not None  # set with the first reading
            self._direction = next_direction(self._direction, self._last_q, q)
        self._last_q = q
        assert self._direction is not None and self._t0 is not None
        options = self.world.tracker
        latency = self.rng.uniform(0.0, options.latency_max_s)
        if self.rng.random() < options.dropout_probability:
            return None
        n_rows, targets = self._rows()
        poses = Poses(
            np.repeat(q[None, :], n_rows, axis=0),
            np.repeat(self._direction[None, :], n_rows, axis=0),
            np.full(n_rows, stamp_s - self._t0),
            targets,
        )
        self.count += 1
        reads = self.world.tracker.reads_per_pose
        points, frames = measure_six_dof(self.world, poses, self.rng, reads=reads)
        sigma = stated_accuracy(self.world.noise, points)
        points, sigma = self._point_accuracy(np.array([self.count - 1]), points, sigma)
        noise = self._reference_noise(1)
        points, frames, refs = self._drifted(
            np.array([self.count - 1]),
            np.array([stamp_s - self._t0]),
            points[None],
            None if frames is None else frames[None],
            noise,
        )
        return self._reading(
            points[0],
            None if frames is None else frames[0],
            sigma,
            latency,
            None if refs is None else refs[0],
        )

    def _rows(self) -> tuple[int, IntArray | None]:
        """The rows a pose is measured in (every target, `reads_per_pose` times over) and
        their target indices (None for a single row)."""
        n_targets = len(self.world.model.targets)
        n_rows = n_targets * self.world.tracker.reads_per_pose
        return n_rows, (np.tile(np.arange(n_targets), n_rows // n_targets) if n_rows > 1 else None)

    def _reading(
        self, points: Array, frames: Array | None, sigma: Array, latency: float, refs: Array | None
    ) -> TrackerReading:
        """One pose's reading from its rows (`_rows`): the first read's points (T, 3),
        frames and stated accuracies, the further reads as `rereads`."""
        n_targets = len(self.world.model.targets)
        rereads = points[n_targets:].reshape(-1, n_targets, 3) if len(points) > n_targets else None
        return TrackerReading(
            points[:n_targets],
            None if frames is None else frames[:n_targets],
            sigma[:n_targets],
            latency,
            refs,
            rereads,
        )

    def _point_accuracy(self, index: IntArray, points: Array, sigma: Array) -> tuple[Array, Array]:
        """Points (m R, 3) [m] of the measured poses `index` (m,) (R rows each) and their
        stated accuracies (m R, 2) with each point's own accuracy (`point_sigma_range_m`):
        drawn per pose from a generator of the world's seed and the pose's index (the same
        in every path and batch, the main draws untouched), the noise beyond the tracker's
        and target's added, the accuracy stated. Unchanged without a range."""
        noise = self.world.noise
        low, high = noise.point_sigma_range_m
        if high <= 0:
            return points, sigma
        rows = len(points) // len(index)
        base = noise.base_sigma_m
        extra, stated = np.zeros((len(points), 3)), np.zeros(len(points))
        for i, pose in enumerate(np.asarray(index).tolist()):
            side = np.random.default_rng((self.world.seed, POINT_SIGMA_STREAM, pose))
            s = (
                low * (high / low) ** side.uniform(0.0, 1.0, rows)
                if low > 0
                else side.uniform(0.0, high, rows)
            )
            beyond = np.sqrt(np.maximum(s**2 - base**2, 0.0))
            extra[i * rows : (i + 1) * rows] = side.normal(0.0, 1.0, (rows, 3)) * beyond[:, None]
            stated[i * rows : (i + 1) * rows] = s
        sigma = sigma.copy()
        sigma[:, 0] = stated
        return points + extra, sigma

    def _reference_noise(self, m: int) -> Array | None:
        """The noise draws (m, R, 3) [m] of the reference reflectors' reads at m poses
        (the tracker's noise, isotropic: a reflector left in its nest keeps its centring
        error, part of its place; one draw per pose, after the pose's others), None when
        the world has none."""
        n_refs = len(self.world.references)
        if not n_refs:
            return None
        sigma = self.world.noise.tracker_sigma_m  # a nest's centring error is its place
        return np.stack([self.rng.normal(0.0, sigma, (n_refs, 3)) for _ in range(m)])

    def _drifted(
        self,
        index: IntArray,
        time_s: Array,
        points: Array,
        frames: Array | None,
        ref_noise: Array | None,
    ) -> tuple[Array, Array | None, Array | None]:
        """Points (m, T, 3) [m] and frames (m, T, 3, 3) of the measured poses `index` (m,)
        (0-based) read at times (m,) [s] since the first measurement, with the world's
        events (`SimEvent`) and the tracker's drift in them, and the references (m, R, 3)
        read then (with `ref_noise` (m, R, 3); None without references)."""
        options = self.world.tracker
        refs = None
        if ref_noise is not None:
            refs = np.broadcast_to(self.world.reference_points(), ref_noise.shape).copy()
        if self.world.events:
            points, refs = self._events(index, points, refs)
        if not options.drifts:
            return points, frames, None if refs is None or ref_noise is None else refs + ref_noise
        rotation, translation = options.drift(time_s)
        m = len(time_s)
        turn = rotation.as_matrix()  # (m, 3, 3)
        points = np.einsum("mab,mtb->mta", turn, points) + translation[:, None]
        if frames is not None:
            frames = np.einsum("mab,mtbc->mtac", turn, frames)
        if refs is not None and ref_noise is not None:
            refs = np.einsum("mab,mrb->mra", turn, refs) + translation[:, None] + ref_noise
        assert len(points) == m
        return points, frames, refs

    def _events(
        self, index: IntArray, points: Array, refs: Array | None
    ) -> tuple[Array, Array | None]:
        """Points (m, T, 3) and references (m, R, 3) [m, tracker frame] of the measured
        poses `index` (m,) moved by the world's events there (before the drift)."""
        points = points.copy()
        refs = None if refs is None else refs.copy()
        turn = self.world.model.base2tracker(self.world.truth)[:3, :3]
        for event in self.world.events:
            at = event.at(index)
            if not at.any():
                continue
            if event.kind == "robot":
                points[at] += turn @ np.asarray(event.offset_m)
            else:
                points[at] += np.asarray(event.offset_m)
                if refs is not None:
                    refs[at] += np.asarray(event.offset_m)
        return points, refs

    def measure_batch(self, q: Array, stamp_s: Array) -> list[TrackerReading | None]:
        """`measure_all` of each reading q (m, J) stamped stamp_s (m,) [s] in turn, bit for
        bit (the same random draws in the same order), the kinematics of all m poses in a
        few numpy calls instead of m model evaluations (~100x faster).

        The first batch is checked against `measure_all` pose by pose (up to
        BATCH_CHECK_POSES, from a copy of the state): the batched arithmetic must give the
        same bits (a model whose points depend on how many poses it evaluates at once
        would not); if it does not, this tracker measures pose by pose from then on."""
        q = np.asarray(q, dtype=float)
        stamps = np.asarray(stamp_s, dtype=float)
        if self._batch_ok is False or len(q) == 0:
            return [self.measure_all(q[k], float(stamps[k])) for k in range(len(q))]
        if self._batch_ok is None:
            reference = StreamingTracker(
                self.world,
                copy.deepcopy(self.rng),
                self._last_q,
                self._direction,
                self._t0,
                self.count,
            )
            state = copy.deepcopy(self.rng.bit_generator.state)
            before = (self._last_q, self._direction, self._t0, self.count)
            readings = self._measure_batch(q, stamps)
            check = min(len(q), BATCH_CHECK_POSES)
            expected = [reference.measure_all(q[k], float(stamps[k])) for k in range(check)]
            self._batch_ok = all(_same(a, b) for a, b in zip(readings, expected))
            if self._batch_ok:
                return readings
            self.rng.bit_generator.state = state  # measure this batch again, pose by pose
            self._last_q, self._direction, self._t0, self.count = before
            return self.measure_batch(q, stamps)
        return self._measure_batch(q, stamps)

    def _measure_batch(self, q: Array, stamps: Array) -> list[TrackerReading | None]:
        """`measure_batch` without its check: the random draws pose by pose in
        `measure_all`'s order (`physical_poses`, `tracker_noise`, `measure_six_dof` for
        one pose of T targets), the arithmetic on all poses at once."""
        m, n_joints = q.shape
        world, rng = self.world, self.rng
        model, noise, options = world.model, world.noise, world.tracker
        n_targets, targets = self._rows()  # rows per pose: every target, every read
        reads = options.reads_per_pose  # the reads share each target's centring error
        # approach directions: each joint's last move beyond the tolerance (next_direction)
        if self._last_q is None:
            start, previous, self._t0 = np.ones(n_joints), q[:1], float(stamps[0])
        else:
            assert self._direction is not None
            start, previous = self._direction, self._last_q[None, :]
        step = q - np.concatenate([previous, q[:-1]])
        moved = np.abs(step) > JOINT_CHANGE_TOLERANCE
        last = np.maximum.accumulate(np.where(moved, np.arange(m)[:, None], -1), axis=0)
        direction = np.where(
            last >= 0, np.sign(step)[np.maximum(last, 0), np.arange(n_joints)], start
        )
        self._direction, self._last_q = direction[-1].copy(), q[-1].copy()
        assert self._t0 is not None
        # the draws, pose by pose
        latency = np.empty(m)
        measured = np.zeros(m, dtype=bool)
        draws: list[list[Array]] = []
        for k in range(m):
            latency[k] = rng.uniform(0.0, options.latency_max_s)
            if rng.random() < options.dropout_probability:
                continue
            measured[k] = True
            pose = [
                rng.normal(0.0, noise.joint_sigma_rad, (1, n_joints)),
                np.tile(
                    rng.normal(0.0, noise.target_sigma_m, (n_targets // reads, 3)), (reads, 1)
                ),
            ]
            if noise.anisotropic:
                pose += [
                    rng.normal(0.0, noise.tracker_radial_sigma_m, (n_targets, 1)),
                    rng.normal(0.0, 1.0, (n_targets, 1)),
                    rng.normal(0.0, 1.0, (n_targets, 1)),
                ]
            else:
                pose.append(rng.normal(0.0, noise.tracker_sigma_m, (n_targets, 3)))
            if model.oriented:
                pose.append(rng.normal(0.0, noise.orientation_sigma_rad, (n_targets, 3)))
            refs = self._reference_noise(1)
            if refs is not None:
                pose.append(refs[0])
            draws.append(pose)
        self.count += len(draws)
        out: list[TrackerReading | None] = [None] * m
        if not draws:
            return out
        columns = [np.concatenate(c) for c in zip(*draws)]
        rows = np.flatnonzero(measured)
        physical = Poses(
            np.repeat(q[rows], n_targets, axis=0) + np.repeat(columns[0], n_targets, axis=0),
            np.repeat(direction[rows], n_targets, axis=0),
            np.repeat(stamps[rows] - self._t0, n_targets),
            None if targets is None else np.tile(targets, len(rows)),
        )
        points = _target_points(model, world.truth, physical, n_targets)
        n = len(points)
        if noise.anisotropic:
            radial_draw, across1_draw, across2_draw = columns[2:5]
            distance, radial, across1, across2 = line_of_sight(points)
            sigma_t = noise.tracker_transverse_sigma_rad * distance
            points = points + (
                columns[1]
                + radial * radial_draw
                + across1 * across1_draw * sigma_t
                + across2 * across2_draw * sigma_t
            )
        else:
            points = points + (columns[1] + columns[2])
        frames = None
        if model.oriented:
            frames = model.probe_orientations(world.truth, physical)
            turn = columns[-2 if world.references else -1]
            frames = Rotation.from_rotvec(turn).as_matrix() @ frames
            probes = [model.targets.index(t) for t in model.oriented]
            frames[~np.isin(physical.target_index, probes)] = np.nan
        sigma = stated_accuracy(noise, points)
        k = len(rows)
        points, sigma = self._point_accuracy(self.count - k + np.arange(k), points, sigma)
        ref_noise = columns[-1].reshape(k, -1, 3) if world.references else None
        index = self.count - k + np.arange(k)  # the measured poses' 0-based count
        drifted, drifted_frames, refs = self._drifted(
            index,
            stamps[rows] - self._t0,
            points.reshape(k, n_targets, 3),
            None if frames is None else frames.reshape(k, n_targets, 3, 3),
            ref_noise,
        )
        for i, row in enumerate(rows.tolist()):
            out[row] = self._reading(
                drifted[i],
                None if drifted_frames is None else drifted_frames[i],
                sigma[i * n_targets : (i + 1) * n_targets],
                float(latency[row]),
                None if refs is None else refs[i],
            )
        assert n == len(rows) * n_targets
        return out


def _target_points(
    model: KinematicModel, truth: ParameterVector, poses: Poses, n_targets: int
) -> Array:
    """`model.target_points(truth, poses)` for poses of n_targets consecutive rows each, as
    evaluating each pose's rows alone gives them: with one target per pose that is one row
    per evaluation, whose last product numpy hands to BLAS as a vector times a matrix
    (gemv), not a matrix product (gemm): the same point to the last bit only this way."""
    if n_targets > 1:
        return model.target_points(truth, poses)
    flange = model.flange2base(truth, poses)
    target = model.target_offsets(truth)[poses.target_index]
    p_in_base = np.einsum("nab,nb->na", flange[:, :3, :3], target) + flange[:, :3, 3]
    b2t = model.base2tracker(truth)
    return np.asarray((p_in_base[:, None, :] @ b2t[:3, :3].T)[:, 0] + b2t[:3, 3])


def _same(a: TrackerReading | None, b: TrackerReading | None) -> bool:
    """Two readings equal to the last bit (NaN frames equal)."""
    if a is None or b is None:
        return a is b
    if a.frames is None or b.frames is None:
        frames_equal = a.frames is None and b.frames is None
    else:
        frames_equal = np.array_equal(a.frames, b.frames, equal_nan=True)
    refs_equal = all(
        (x is None and y is None) or (x is not None and y is not None and np.array_equal(x, y))
        for x, y in ((a.references, b.references), (a.rereads, b.rereads))
    )
    return (
        frames_equal
        and refs_equal
        and np.array_equal(a.points, b.points)
        and np.array_equal(a.sigma, b.sigma)
        and a.latency_s == b.latency_s
    )


def measure_every_target(
    world: World, q: Array, time: Array, rng: np.random.Generator, noisy: bool = True
) -> tuple[Poses, Array]:
    """Every target of the world measured at each of the poses q (m, J) [rad] visited in
    order at `time` (m,) [s]: poses (m T,) in order, each pose's targets together in the
    model's order (they share the pose's physical joint angles; with 6-DoF probes their
    measured frames as `rotation`; with a temperature profile the recorded temperature),
    and their points (m T, 3) [m] in the tracker frame."""
    n_targets = len(world.model.targets)
    rows_q = np.repeat(np.asarray(q, dtype=float), n_targets, axis=0)
    rows_t = np.repeat(np.asarray(time, dtype=float), n_targets)
    poses = Poses(
        rows_q,
        approach_directions(rows_q),
        rows_t,
        np.tile(np.arange(n_targets), len(q)),
        temperature=None if world.temperature is None else world.temperature.at(rows_t),
    )
    points, rotation = measure_six_dof(world, poses, rng, noisy)
    return replace(poses, rotation=rotation), points


def record_plan(world: World, plan: Plan, rng: np.random.Generator) -> Recording:
    """A recording of `plan` in `world`, in memory (no bag, no ROS graph): the first
    target's points (`physical_points`) at the plan's readings in order, at the plan's
    times (`plan_times`), with the world's temperature profile where it has one."""
    time = plan_times(plan, world.timing)
    celsius = None if world.temperature is None else world.temperature.at(time)
    poses = replace(Poses.from_readings(plan.q, time=time), temperature=celsius)
    return recording_from_arrays(
        plan.q,
        physical_points(world, poses, rng),
        time,
        robot=world.model.robot,
        temperature=celsius,
    )
