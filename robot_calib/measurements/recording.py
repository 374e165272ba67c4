"""A recording as the identifier sees it: paired measurements (msgs_doc/specification.md
section 1).

Why one module: the `Recording` type and the two ways of building it
(`recording_from_arrays` from paired arrays, `recording_from_stream` from stamped streams it
pairs) share their checks and helpers (targets, side data, sweeps, copies); together they
are the measurement model of msgs_doc/specification.md section 1 and change with it.

Each tracker point is paired with the joint state nearest in stamp (within
`PAIR_TOLERANCE_S`); approach directions and time since the first measurement follow;
circle sweeps are found (in the robot's joint variables where a robot with a reading-to-joint
mapping is given: a coupled sweep moves two readings but one joint). Unpaired points are
counted and reported, never dropped silently.
This is the measurement model only: where the stamps and values come from (a bag, live
topics, arrays in memory) is the caller's business (`robot_calib.bag.read`, the nodes).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from robot_calib.errors import InputError
from robot_calib.kinematics.frames import Array, IntArray
from robot_calib.measurements.references import ReferenceReads
from robot_calib.measurements.sweeps import MIN_SWEEP_POSES, Sweep, usable_sweeps
from robot_calib.messages import target_topic
from robot_calib.poses import PRIMARY_TARGET, Poses, approach_directions, reading_groups

if TYPE_CHECKING:
    from robot_calib.kinematics.description import RobotDescription

PAIR_TOLERANCE_S = 0.05  # contract default: the one place this number is written
MAX_PLAUSIBLE_RANGE_M = 50.0  # a laser tracker's range; larger coordinates look like mm


@dataclass(frozen=True)
class Recording:
    """Paired measurements of one or more sources, in visiting order.

    poses : readings q (n, J) [rad], approach directions, time since the first measurement
      of each source [s]; points : (n, 3) measured target centres, tracker frame [m];
    sweeps : circle sweeps found; bag_index : (n,) which source each pose came from;
    n_unpaired : points without a joint state in tolerance (dropped, reported);
    warnings : labelled problems that did not stop the reading;
    point_index : (n,) 0-based index of each point's message among its source's tracker
      points, in the order read (None: 0, 1, ... per source);
    stamp_ns : (n,) the points' header stamps [ns] (None: unknown, e.g. arrays in memory);
    target_names : the targets measured (several SMRs on one flange, msgs_doc/targets.md);
      `poses.target` indexes them ('' = the contract's single target).
    references : the reference reflectors read with the poses, per source that has them
      (msgs_doc/references.md); `points` are without the drift they show (`without_drift`)
    """

    sources: tuple[str, ...]
    poses: Poses
    points: Array
    sweeps: tuple[Sweep, ...]
    bag_index: IntArray
    n_unpaired: int = 0
    warnings: tuple[str, ...] = field(default=())
    point_index: IntArray | None = None
    stamp_ns: IntArray | None = None
    target_names: tuple[str, ...] = (PRIMARY_TARGET,)
    references: tuple[ReferenceReads, ...] = ()

    def __len__(self) -> int:
        return len(self.poses)

    def message_indices(self) -> IntArray:
        """(n,) index of each point's message in its source (see `point_index`)."""
        if self.point_index is not None:
            return self.point_index
        out = np.zeros(len(self), dtype=np.int64)
        for b in np.unique(self.bag_index):
            rows = self.bag_index == b
            out[rows] = np.arange(int(rows.sum()))
        return out

    def subset(self, keep: NDArray[np.bool_]) -> Recording:
        """The recording without the measurements where `keep` (n,) is False (e.g.
        outliers): sweeps keep their remaining poses (one left with fewer than
        MIN_SWEEP_POSES becomes general poses); sources, warnings and counts unchanged."""
        keep = np.asarray(keep, dtype=bool)
        new_index = np.cumsum(keep) - 1
        sweeps = []
        for s in self.sweeps:
            kept = s.index[keep[s.index]]
            if len(kept) >= MIN_SWEEP_POSES:
                sweeps.append(Sweep(s.joint, new_index[kept]))
        return Recording(
            self.sources,
            self.poses.subset(keep),
            self.points[keep],
            tuple(sweeps),
            self.bag_index[keep],
            self.n_unpaired,
            self.warnings,
            self.message_indices()[keep],
            None if self.stamp_ns is None else self.stamp_ns[keep],
            self.target_names,
            self.references,
        )

    def at_most(self, limit: int, seed: int = 0) -> Recording:
        """This recording, or a fixed random subset (`seed`) of `limit` of its poses (every
        target measured at a kept pose kept) when it has more: for statistics whose
        precision does not grow with 100k poses (screening, signatures)."""
        keep = self.sample_mask(limit, seed)
        return self if keep is None else self.subset(keep)

    def sample_mask(self, limit: int, seed: int = 0) -> NDArray[np.bool_] | None:
        """(n,) the measurements of `at_most`'s subset, None when every pose is kept."""
        pose = self.pose_index()
        n_poses = int(pose[-1]) + 1 if len(pose) else 0
        if n_poses <= limit:
            return None
        kept = np.zeros(n_poses, dtype=bool)
        kept[np.random.default_rng(seed).choice(n_poses, limit, replace=False)] = True
        return kept[pose]

    def pose_index(self) -> IntArray:
        """(n,) 0-based pose of each measurement: consecutive measurements of one source at
        the same readings (paired with one joint state), each of a target not yet measured
        there, are one pose (the targets measured there, whatever their own stamps)."""
        n = len(self)
        out = np.zeros(n, dtype=np.int64)
        q, bag, target = self.poses.q, self.bag_index, self.poses.target_index
        if n == 0:
            return out
        # runs of consecutive measurements of one source at the same readings; where no
        # target repeats within a run (the usual case), every run is one pose
        repeated = np.zeros(n, dtype=bool)
        repeated[1:] = (bag[1:] == bag[:-1]) & np.all(q[1:] == q[:-1], axis=1)
        run = np.cumsum(~repeated) - 1
        pairs = run.astype(np.int64) * (int(target.max()) + 1) + target
        if len(np.unique(pairs)) == n:
            return run.astype(np.int64)
        pose, seen = -1, set[int]()
        for i in range(n):
            same = (
                i > 0
                and bag[i] == bag[i - 1]
                and int(target[i]) not in seen
                and bool(np.array_equal(q[i], q[i - 1]))
            )
            if not same:
                pose, seen = pose + 1, set()
            seen.add(int(target[i]))
            out[i] = pose
        return out

    def points_by_target(self) -> tuple[IntArray, Array]:
        """Per pose (`pose_index`): its first measurement (m,) and every target's point
        (T, m, 3) [m], NaN where that target was not measured at the pose."""
        return self.by_target(self.points)

    def by_target(self, values: Array) -> tuple[IntArray, Array]:
        """Per pose (`pose_index`): its first measurement (m,) and every target's value of
        the per-measurement `values` (n, ...) as (T, m, ...), NaN where that target was not
        measured at the pose."""
        pose = self.pose_index()
        m = int(pose[-1]) + 1 if len(pose) else 0
        out = np.full((len(self.target_names), m, *values.shape[1:]), np.nan)
        out[self.poses.target_index, pose] = values
        first = np.flatnonzero(np.r_[True, np.diff(pose) != 0]) if m else pose
        return first, out

    def only_target(self, name: str) -> Recording:
        """The measurements of target `name` alone, as a one-target recording."""
        if name not in self.target_names:
            raise InputError(f"{', '.join(self.sources)}: no target {target_topic(name)}")
        part = self.subset(self.poses.target_index == self.target_names.index(name))
        poses = replace(part.poses, target=None)
        return replace(part, poses=poses, target_names=(name,))

    def with_targets(self, names: Sequence[str]) -> Recording:
        """The same measurements with targets indexed by `names` (e.g. a model's), which
        must include every target measured here; InputError naming the unknown ones."""
        names = tuple(names)
        if names == self.target_names:
            return self
        unknown = [t for t in self.target_names if t not in names]
        if unknown:
            raise InputError(
                f"{', '.join(self.sources)}: measurements of target(s) "
                f"{[target_topic(t) for t in unknown]} that the model does not have "
                f"({[target_topic(t) for t in names]})"
            )
        remap = np.array([names.index(t) for t in self.target_names], dtype=np.int64)
        poses = replace(self.poses, target=remap[self.poses.target_index])
        return replace(self, poses=poses, target_names=names)

    @property
    def oriented_targets(self) -> tuple[str, ...]:
        """The targets of which some measurement carries an orientation (6-DoF probes,
        msgs_doc/six_dof.md), in `target_names` order."""
        which = np.unique(self.poses.target_index[self.poses.oriented])
        return tuple(self.target_names[int(k)] for k in which)

    @property
    def general(self) -> NDArray[np.bool_]:
        """Boolean mask (n,): poses that belong to no sweep."""
        mask = np.ones(len(self), dtype=bool)
        for s in self.sweeps:
            mask[s.index] = False
        return mask

    def sweeps_of(self, joint: int) -> list[Sweep]:
        return [s for s in self.sweeps if s.joint == joint]

    def summary(self) -> str:
        """One human line: sources, poses, sweeps per joint, unpaired."""
        per_joint = ", ".join(
            f"J{j}:{sum(s.n_poses for s in self.sweeps_of(j))}"
            for j in sorted({s.joint for s in self.sweeps})
        )
        return (
            f"{', '.join(self.sources)}: {len(self)} measurements "
            f"({len(self.sweeps)} sweeps [{per_joint or 'none'}], "
            f"{int(self.general.sum())} general poses), {self.n_unpaired} unpaired"
        )

    @classmethod
    def concatenate(cls, parts: Sequence[Recording]) -> Recording:
        """One recording of several sources in the given order (each keeps its own time
        origin and direction history; sweeps never cross a source boundary)."""
        if not parts:
            raise InputError("no recording given")
        names: list[str] = []
        for part in parts:
            names += [t for t in part.target_names if t not in names]
        parts = [p.with_targets(names) for p in parts]
        sweeps: list[Sweep] = []
        offset = 0
        for part in parts:
            sweeps += [s.shifted(offset) for s in part.sweeps]
            offset += len(part)
        return cls(
            tuple(s for p in parts for s in p.sources),
            Poses.concatenate([p.poses for p in parts], with_target=len(names) > 1),
            np.concatenate([p.points for p in parts]),
            tuple(sweeps),
            np.concatenate([np.full(len(p), b) for b, p in enumerate(parts)]),
            sum(p.n_unpaired for p in parts),
            tuple(w for p in parts for w in p.warnings),
            np.concatenate([p.message_indices() for p in parts]),
            None
            if any(p.stamp_ns is None for p in parts)
            else np.concatenate([p.stamp_ns for p in parts if p.stamp_ns is not None]),
            tuple(names),
            tuple(
                replace(r, source=r.source + b) for b, p in enumerate(parts) for r in p.references
            ),
        )

    def distinct_points(self) -> int:
        """How many different points the recording measured: one per target at each
        distinct pose (`reading_groups`); re-reads and repeats of a pose add none (they
        tell the noise, not the kinematics)."""
        if not len(self):
            return 0
        groups = reading_groups(self.poses.q) * len(self.target_names) + self.poses.target_index
        return len(np.unique(groups))

    def reference_leftover_m(self) -> Array:
        """(n,) [m] per measurement, the largest distance of a reference reflector read with
        its pose (same source, stamp within PAIR_TOLERANCE_S) from where the tracker's drift
        puts it (`ReferenceReads.leftover_m`); NaN where none was read or is known."""
        out = np.full(len(self), np.nan)
        if self.stamp_ns is None:
            return out
        for reads in self.references:
            rows = np.flatnonzero(self.bag_index == reads.source)
            if not len(rows) or not len(reads.stamp_ns):
                continue
            near = pair_nearest(reads.stamp_ns, self.stamp_ns[rows], int(PAIR_TOLERANCE_S * 1e9))
            close = near >= 0
            out[rows[close]] = reads.leftover_m()[near[close]]
        return out

    def without_drift(self, reads: ReferenceReads) -> Recording:
        """This recording with the reference reflectors `reads` of its source `reads.source`
        attached, and the tracker's drift they show removed from that source's points (and
        a 6-DoF probe's frames): as the tracker would have read them at its first read.
        Needs `stamp_ns`; without a drift (too few reads) or one within the noise of its
        estimate (`TrackerDrift.significant`), only attached."""
        recording = replace(self, references=self.references + (reads,))
        if reads.drift is None or not reads.drift.significant or self.stamp_ns is None:
            return recording
        rows = self.bag_index == reads.source
        time_s = self.stamp_ns[rows] * 1e-9
        points = self.points.copy()
        points[rows] = reads.drift.removed(time_s, points[rows])
        poses = self.poses
        if poses.rotation is not None:
            rotation = poses.rotation.copy()
            turn, _ = reads.drift.motion(time_s)
            rotation[rows] = turn.inv().as_matrix() @ rotation[rows]
            poses = replace(poses, rotation=rotation)
        return replace(recording, points=points, poses=poses)


def check_metres(points: Array, where: str, error: type[Exception] = InputError) -> None:
    """Raise `error` when points (n, 3) look like millimetres rather than metres."""
    if len(points) and np.median(np.linalg.norm(points, axis=1)) > MAX_PLAUSIBLE_RANGE_M:
        raise error(
            f"{where}: tracker points are {np.median(np.abs(points)):.0f} units from the "
            "tracker: they look like millimetres; the contract wants metres"
        )


MAX_COORDINATE_M = 1e4  # no tracker measures 10 km away: a corrupt value, not a point
MAX_READING_RAD = 1e4  # 1600 turns (28 in degrees): no joint reading in rad or deg
COPY_RESOLUTION = 1e-9  # readings [rad] and points [m] equal to 1 nrad / 1 nm: one measurement


def implausible_values(values: Array, bound: float) -> IntArray:
    """Rows of `values` (n, k) holding a value not finite or beyond +-`bound`."""
    values = np.asarray(values, dtype=float).reshape(len(values), -1)
    with np.errstate(invalid="ignore"):
        return np.flatnonzero(~(np.abs(values) <= bound).all(axis=1))


def copies(
    q: Array, points: Array, target: IntArray | None = None, direction: Array | None = None
) -> NDArray[np.bool_]:
    """Mask (n,) of the measurements that are copies of an earlier one: the same readings
    q (n, J) [rad] and point (n, 3) [m] of the same target, to COPY_RESOLUTION, reached
    from the same side (`direction` (n, J) of approach when given: a visit from the other
    side is another measurement, backlash apart). A tracker measuring again never gives
    the same point to 1 nm; a copy is the same measurement."""
    n = len(points)
    if n < 2:
        return np.zeros(n, dtype=bool)
    _, first = np.unique(_copy_key(q, points, target, direction), axis=0, return_index=True)
    out = np.ones(n, dtype=bool)
    out[first] = False
    return out


#: a run of this many consecutive rows repeating earlier consecutive rows exactly is a
#: pasted block, not the tracker reading again
MIN_PASTED_ROWS = 3
#: more than this share of rows exact copies of earlier ones is a copied file, not re-reads
#: (an export rounding to 1 um repeats a still pose's point now and then, 38 of 1134 rows;
#: one rounding to 10 um, 3 reads a pose, about a third)
MAX_REREAD_SHARE = 0.5


def copied_rows(
    q: Array, points: Array, target: IntArray | None = None, direction: Array | None = None
) -> dict[int, int]:
    """Each copied measurement (`copies`) -> the first earlier one it repeats."""
    if len(points) < 2:
        return {}
    key = _copy_key(q, points, target, direction)
    _, first, group = np.unique(key, axis=0, return_index=True, return_inverse=True)
    original = first[group.reshape(-1)]  # each measurement's first occurrence
    return {int(k): int(original[k]) for k in np.flatnonzero(original != np.arange(len(key)))}


def _copy_key(q: Array, points: Array, target: IntArray | None, direction: Array | None) -> Array:
    """(n, K) what makes two measurements the same (`copies`): readings and point rounded
    to COPY_RESOLUTION, target, side of approach."""
    n = len(points)
    return np.column_stack(
        [
            np.round(np.asarray(q, dtype=float).reshape(n, -1) / COPY_RESOLUTION),
            np.round(np.asarray(points, dtype=float) / COPY_RESOLUTION),
            np.zeros(n) if target is None else target,
            np.zeros((n, 1)) if direction is None else np.sign(direction).reshape(n, -1),
        ]
    )


def pasted_block(original: dict[int, int]) -> tuple[int, int] | None:
    """(first row, length) of the first run of MIN_PASTED_ROWS or more consecutive copied
    rows whose originals (`original`: copied row -> the earlier row it repeats) are
    consecutive too, in the same or the reverse order, else None."""
    for step in (1, -1):
        start, length = -1, 0
        for k in [*sorted(original), -2]:
            if length and k == start + length and original[k] == original[start] + step * length:
                length += 1
                continue
            if length >= MIN_PASTED_ROWS:
                return start, length
            start, length = k, 1
    return None


def are_rereads(original: dict[int, int], n: int) -> bool:
    """True when the copies `original` (`copied_rows`) among n measurements read as a
    tracker reading a still pose again with an export that rounds: no pasted block
    (`pasted_block`) and at most MAX_REREAD_SHARE of them; else they are copies."""
    return pasted_block(original) is None and len(original) <= MAX_REREAD_SHARE * n


def without_copies(recording: Recording, source: str) -> Recording:
    """`recording` with each copied measurement (`copies`) kept once, and a warning naming
    how many were dropped (none, or re-reads of still poses, `are_rereads`: unchanged)."""
    poses = recording.poses
    copied = copies(poses.q, recording.points, poses.target_index, poses.direction)
    if not copied.any():
        return recording
    original = copied_rows(poses.q, recording.points, poses.target_index, poses.direction)
    if are_rereads(original, len(copied)):
        return recording
    k = int(np.flatnonzero(copied)[0])
    warning = (
        f"warning: {source}: {int(copied.sum())} of {len(copied)} measurements are copies of "
        f"others (the same joint readings and point to 1 nrad / 1 nm; first: measurement "
        f"{k + 1}): a tracker measuring again never repeats a point exactly, so each is "
        "counted once"
    )
    kept = recording.subset(~copied)
    return replace(kept, warnings=(*kept.warnings, warning))


def pair_nearest(reference_ns: IntArray, query_ns: IntArray, tolerance_ns: int) -> IntArray:
    """Index into sorted `reference_ns` of the stamp nearest each of `query_ns`, -1 where
    none lies within `tolerance_ns`; shape of `query_ns`."""
    right = np.clip(np.searchsorted(reference_ns, query_ns), 1, len(reference_ns) - 1)
    left = right - 1
    if len(reference_ns) == 1:
        left = right = np.zeros_like(query_ns)
    pick = np.where(
        np.abs(reference_ns[left] - query_ns) <= np.abs(reference_ns[right] - query_ns),
        left,
        right,
    )
    return np.where(np.abs(reference_ns[pick] - query_ns) <= tolerance_ns, pick, -1)


def _distinct_joint_states(
    js_ns: IntArray, q: Array, order: IntArray, source: str, error: type[Exception]
) -> NDArray[np.bool_]:
    """Mask (m,) of the joint states to keep (sorted by stamp): of identical duplicates
    (same stamp, same readings) the first; two with the same stamp and different readings
    raise `error` naming both (their position in `source`, the stamp and the readings)."""
    keep = np.ones(len(js_ns), dtype=bool)
    for k in np.flatnonzero(np.diff(js_ns) == 0) + 1:
        if np.array_equal(q[k], q[k - 1]):
            keep[k] = False
            continue
        raise error(
            f"{source}: joint states {int(order[k - 1]) + 1} and {int(order[k]) + 1} have "
            f"the same stamp {int(js_ns[k])} ns but different readings "
            f"{np.round(q[k - 1], 6).tolist()} vs {np.round(q[k], 6).tolist()} rad: "
            "which one the robot was at is unknown"
        )
    return keep


def _sweeps(
    q: Array,
    robot: RobotDescription | None,
    source: str,
    warnings: list[str],
    target: IntArray | None = None,
    target_names: tuple[str, ...] = (PRIMARY_TARGET,),
) -> list[Sweep]:
    """Usable sweeps of readings q (n, J) [rad], found on `robot`'s joint variables (the
    readings themselves without a robot or a mapping); with several targets (`target` (n,)
    indexing `target_names`) among the measurements of each target, so that every target
    has its own circles of each sweep."""
    variables = q if robot is None else robot.joint_variables(q)
    if target is None or len(target_names) == 1:
        return usable_sweeps(variables, source, warnings)
    out: list[Sweep] = []
    for k, name in enumerate(target_names):
        rows = np.flatnonzero(target == k)
        out += usable_sweeps(variables[rows], f"{source} {target_topic(name)}", warnings, rows)
    return sorted(out, key=lambda s: (int(s.index[0]), s.joint))


def recording_from_arrays(
    q: Array,
    points: Array,
    time: Array | None = None,
    source: str = "arrays",
    robot: RobotDescription | None = None,
    target: IntArray | None = None,
    target_names: tuple[str, ...] = (PRIMARY_TARGET,),
    rotation: Array | None = None,
    sigma: Array | None = None,
    temperature: Array | None = None,
) -> Recording:
    """A recording of measurements already paired in memory (one source, visiting order):
    q (n, J) [rad], points (n, 3) [m], time (n,) [s], target (n,) which of `target_names`
    each point is of (None: the first); rotation (n, 3, 3) and sigma (n, 2) what a 6-DoF
    probe measured and the stated accuracies, temperature (n,) [deg C] (`Poses`); sweeps
    are found on `robot`'s joint variables (None: the readings), per target.

    Returns
    -------
    recording : Recording
        Fields as in `recording_from_stream`: sources (`source`,); poses the n readings
        in the given order, approach directions from that order, time `time` [s] (else
        0); points (n, 3) [m]; sweeps the usable circle sweeps; bag_index (n,) zeros;
        n_unpaired 0; warnings for sweeps too short to use.
    """
    poses = Poses.from_readings(q, time=time)
    index = _target_index(target, len(poses), target_names, source)
    extra = _extras(rotation, sigma, temperature, len(poses), source)
    poses = replace(poses, target=index, **extra._asdict())
    warnings: list[str] = []
    sweeps = _sweeps(poses.q, robot, source, warnings, index, target_names)
    return Recording(
        (source,),
        poses,
        np.asarray(points, dtype=float),
        tuple(sweeps),
        np.zeros(len(poses), dtype=int),
        0,
        tuple(warnings),
        target_names=tuple(target_names),
    )


class Extras(NamedTuple):
    """What a measurement carries besides its point, aligned with the points (`Poses`):
    rotation (n, 3, 3) a 6-DoF probe's frame, sigma (n, 2) stated accuracies [m, rad],
    temperature (n,) [deg C]; None where the source has none."""

    rotation: Array | None = None
    sigma: Array | None = None
    temperature: Array | None = None

    def take(self, index: IntArray | NDArray[np.bool_]) -> Extras:
        """The extras of the measurements `index` selects (reordered as it says)."""
        return Extras(*(None if v is None else v[index] for v in self))


def _extras(
    rotation: Array | None, sigma: Array | None, temperature: Array | None, n: int, source: str
) -> Extras:
    """The extras checked: shapes; a rotation orthonormal (1e-6) or all NaN; a standard
    deviation > 0 or NaN; a temperature finite."""
    out = Extras()
    if rotation is not None:
        r = np.asarray(rotation, dtype=float)
        if r.shape != (n, 3, 3):
            raise InputError(f"{source}: orientations of shape {r.shape} for {n} points")
        given = np.all(np.isfinite(r), axis=(1, 2))
        if np.any(np.isfinite(r[~given])):
            raise InputError(f"{source}: an orientation partly given (NaN and numbers)")
        error = np.abs(np.einsum("nji,njk->nik", r[given], r[given]) - np.eye(3)).max(axis=(1, 2))
        det = np.linalg.det(r[given]) if given.any() else np.ones(0)
        if np.any(error > 1e-6) or np.any(det < 0):
            bad = int(np.flatnonzero(given)[np.argmax(error)]) + 1
            raise InputError(f"{source}: orientation {bad} is not a rotation")
        out = out._replace(rotation=r if given.any() else None)
    if sigma is not None:
        sd = np.asarray(sigma, dtype=float)
        if sd.shape != (n, 2) or np.any(sd[np.isfinite(sd)] <= 0) or np.any(np.isinf(sd)):
            raise InputError(
                f"{source}: standard deviations must be (n, 2) [m, rad], > 0 or NaN "
                f"(not stated); got shape {sd.shape}"
            )
        out = out._replace(sigma=sd if np.isfinite(sd).any() else None)
    if temperature is not None:
        celsius = np.asarray(temperature, dtype=float)
        if celsius.shape != (n,) or not np.all(np.isfinite(celsius)):
            raise InputError(f"{source}: temperatures must be finite, one per point")
        out = out._replace(temperature=celsius)
    return out


def _target_index(
    target: IntArray | None, n: int, target_names: tuple[str, ...], source: str
) -> IntArray | None:
    """`target` (n,) checked against `target_names` (None stays None: all the first)."""
    if len(set(target_names)) != len(target_names) or not target_names:
        raise InputError(f"{source}: target names {list(target_names)} must be distinct")
    if target is None:
        return None
    index = np.asarray(target, dtype=np.int64)
    if index.shape != (n,) or (n and (index.min() < 0 or index.max() >= len(target_names))):
        raise InputError(
            f"{source}: target indices of shape {index.shape} for {n} points and "
            f"{len(target_names)} target(s)"
        )
    return index


def recording_from_stream(
    js_ns: IntArray,
    q: Array,
    velocity_sign: Array,
    point_ns: IntArray,
    points: Array,
    pair_tolerance: float = PAIR_TOLERANCE_S,
    source: str = "live",
    error: type[Exception] = InputError,
    robot: RobotDescription | None = None,
    point_target: IntArray | None = None,
    target_names: tuple[str, ...] = (PRIMARY_TARGET,),
    rotation: Array | None = None,
    sigma: Array | None = None,
    temperature: Array | None = None,
    received: IntArray | None = None,
) -> Recording:
    """A recording of one source from its stamped messages (a bag's or live), paired by
    the contract's rule; sweeps are found on `robot`'s joint variables (None: readings).
    point_target (n,): which of `target_names` each point is of (several targets on the
    flange, msgs_doc/targets.md; None: all the first); measurements of one stamp are
    ordered by target. rotation (n, 3, 3), sigma (n, 2): what 6-DoF probes measured
    besides each point and the stated accuracies (`Poses`; NaN rows: none); temperature
    (n,) [deg C] at each point (the side topic, interpolated to the point stamps).

    js_ns (m,) joint-state stamps [ns], q (m, J) readings [rad], velocity_sign (m, J) (+1/-1,
    0 = no velocity); point_ns (n,) point stamps [ns], points (n, 3) tracker frame [m]; each
    in any order (sorted here by stamp, stable). received (m,): the joint states' order of
    arrival (a bag's file order, the order a live node received them), which is the order
    the robot visited the poses (it publishes as it moves): the approach directions follow
    it, even where stamps go backwards (a clock jump); None: the stamps' order. Raises
    `error` (naming `source`) when the points look like millimetres or none pairs.

    Returns
    -------
    recording : Recording
        The paired measurements, with the following fields:

        sources : tuple of str
            (`source`,).
        poses : Poses
            One pose per paired point, in stamp order: q (k, J) the nearest joint state's
            readings [rad]; direction (k, J) its velocity signs, else the approach
            direction from the readings' order; time (k,) since the first paired point [s].
        points : ndarray, shape (k, 3)
            The paired points, tracker frame [m].
        sweeps : tuple of Sweep
            The circle sweeps usable for CPA (pose indices, joint).
        bag_index : ndarray, shape (k,)
            Zeros (one source).
        n_unpaired : int
            Points with no joint state within `pair_tolerance` (dropped).
        warnings : tuple of str
            'warning: ...' lines: points dropped, sweeps too short to use.
    """
    js_ns, point_ns = np.asarray(js_ns, dtype=np.int64), np.asarray(point_ns, dtype=np.int64)
    q, velocity_sign = np.asarray(q, dtype=float), np.asarray(velocity_sign, dtype=float)
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(point_ns) != len(points) or len(js_ns) != len(q) or q.shape != velocity_sign.shape:
        raise InputError(
            f"{source}: stamps and values differ in length (joint states {len(js_ns)} vs "
            f"{q.shape}, points {len(point_ns)} vs {points.shape})"
        )
    if not (np.isfinite(pair_tolerance) and pair_tolerance >= 0):
        raise InputError(f"pair tolerance {pair_tolerance} s: need a finite number >= 0")
    check_metres(points, source, error)
    target = _target_index(point_target, len(points), target_names, source)
    extra = _extras(rotation, sigma, temperature, len(points), source)
    js_order = np.argsort(js_ns, kind="stable")
    if target is None:
        pt_order = np.argsort(point_ns, kind="stable")
    else:
        pt_order = np.lexsort((target, point_ns))
        target = target[pt_order]
    js_ns, q, velocity_sign = js_ns[js_order], q[js_order], velocity_sign[js_order]
    point_ns, points = point_ns[pt_order], points[pt_order]
    extra = extra.take(pt_order)
    keep = _distinct_joint_states(js_ns, q, js_order, source, error)
    js_ns, q, velocity_sign = js_ns[keep], q[keep], velocity_sign[keep]
    warnings: list[str] = []
    same_target = np.ones(max(len(point_ns) - 1, 0), dtype=bool)
    if target is not None:
        same_target = np.diff(target) == 0
    shared = np.flatnonzero((np.diff(point_ns) == 0) & same_target)
    if len(shared):
        warnings.append(
            f"warning: {source}: {len(shared)} tracker points share their stamp with the "
            f"point before (first at stamp {point_ns[shared[0]]} ns): each is paired with "
            "the same joint state"
        )
    if len(js_ns) == 0:
        pick = np.full(len(point_ns), -1)
    else:
        pick = pair_nearest(js_ns, point_ns, int(round(pair_tolerance * 1e9)))
    ok = pick >= 0
    if not ok.all():
        warnings.append(
            f"warning: {source}: {int((~ok).sum())} of {len(ok)} points have no joint "
            f"state within {pair_tolerance} s: dropped"
        )
    if not ok.any():
        raise error(
            f"{source}: none of {len(point_ns)} tracker points has a joint state within "
            f"{pair_tolerance} s ({len(js_ns)} joint states)"
        )
    q, velocity = q[pick[ok]], velocity_sign[pick[ok]]
    # the visiting order: the joint states' arrival where known, else their stamps'
    if received is not None and np.shape(received) != np.shape(js_order):
        raise InputError(
            f"{source}: {np.shape(received)} arrival ranks for {len(js_order)} joint states"
        )
    arrival = np.arange(len(js_order)) if received is None else np.asarray(received)[js_order]
    direction = np.where(
        velocity != 0, velocity, _approach_in_receive_order(q, arrival[keep][pick[ok]])
    )
    time = (point_ns[ok] - point_ns[ok][0]) * 1e-9
    target = None if target is None else target[ok]
    extra = extra.take(ok)
    sweeps = _sweeps(q, robot, source, warnings, target, target_names)
    return Recording(
        (source,),
        Poses(q, direction, time, target, *extra),
        points[ok],
        tuple(sweeps),
        np.zeros(len(q), dtype=int),
        int((~ok).sum()),
        tuple(warnings),
        _per_target_index(pt_order[ok], point_target),
        point_ns[ok],
        tuple(target_names),
    )


def _approach_in_receive_order(q: Array, received: IntArray) -> Array:
    """Approach directions (n, J) (+1/-1) of the poses q (n, J) [rad] in the order their
    joint states were received (`received` (n,): each one's position in the input, the
    file order): the robot publishes as it moves, so that is the order it visited them,
    also where header stamps go backwards (a clock jump, re-stamped messages), which would
    flip the approach side of the poses around the jump. With monotonic stamps the same as
    in stamp order."""
    by_receipt = np.argsort(received, kind="stable")
    out = np.empty_like(q)
    out[by_receipt] = approach_directions(q[by_receipt])
    return out


def _per_target_index(order: IntArray, point_target: IntArray | None) -> IntArray:
    """Index of each kept point's message among its own target's messages (the order
    read), from its position `order` among all points read and their targets."""
    if point_target is None:
        return order
    point_target = np.asarray(point_target, dtype=np.int64)
    rank = np.zeros(len(point_target), dtype=np.int64)
    for k in np.unique(point_target):
        rows = point_target == k
        rank[rows] = np.arange(int(rows.sum()))
    return rank[order]
