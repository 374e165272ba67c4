"""The simulated world: true robot (nominal + geometric deviations + effects), tracker pose,
target offset, noise models and timing. One YAML format describes it (see
`worlds/default.yaml`); a seed makes every draw reproducible.

Default world: the true geometry is the seed's Table 3 "Avg. 2-6" column, the tracker
about 2.5 m from the base, an active target on a bracket off the flange axis.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from robot_calib.effects import (
    Effect,
    effect_class,
    effect_from_dict,
    option_types,
    parse_effect,
)
from robot_calib.errors import InputError, RobotCalibError, check_keys, param
from robot_calib.kinematics.description import with_payload
from robot_calib.kinematics.frames import Array, IntArray, matrix_to_rpy, rpy_to_matrix
from robot_calib.kinematics.loader import load_robot
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel, target_parameters, tool_rotation_parameters
from robot_calib.poses import PRIMARY_TARGET, TARGET_NAME

WORLDS_DIR = Path(__file__).resolve().parent / "worlds"
DEG = np.pi / 180.0

# Seed Table 3, column "Avg. 2-6" (circle point parameters of the real KR5) [mm, deg].
SEED_TABLE3_AVG_2_6 = {
    "d1": 335.2389,
    "d3": -0.3457,
    "d4": 295.2779,
    "d5": 0.0063,
    "theta1": 0.0803,
    "theta2": -0.0288,
    "theta3": 89.9488,
    "theta4": 0.2123,
    "theta5": 180.0611,
    "a1": 74.8367,
    "a2": 270.3405,
    "a3": 90.2756,
    "a4": -0.0318,
    "a5": -0.0003,
    "alpha1": 90.0171,
    "alpha2": 0.0077,
    "alpha3": 89.9702,
    "alpha4": 90.0290,
    "alpha5": 90.0182,
    "beta2": 0.0541,
}


@dataclass(frozen=True)
class NoiseModel:
    """Measurement noise (1 sigma).

    tracker_sigma_m : isotropic tracker noise [m] (seed: +-3.75 um at 2.5 m), or with
    anisotropic=True: tracker_radial_sigma_m along the line of sight (ADM) and
    tracker_transverse_sigma_rad x range across it (angle encoders), as tracker MPE specs give.
    target_sigma_m : target centring noise [m] (seed: active target +-3 um).
    joint_sigma_rad : robot repeatability noise on the physical joint angle [rad].
    orientation_sigma_rad : a 6-DoF probe's orientation noise per axis [rad] (worlds with
      `six_dof` probes; msgs_doc/six_dof.md).
    point_sigma_range_m : (low, high) [m]: each point's accuracy drawn log-uniformly in the
      range and stated with it (a tracker's uncertainty column, msgs_doc/sim_tracker.md):
      its noise per axis then has that 1-sigma (the tracker's and target's noise above,
      plus what each point adds); (0, 0): every point as accurate as the others.
    """

    tracker_sigma_m: float = 3.75e-6
    anisotropic: bool = False
    tracker_radial_sigma_m: float = 2.5e-6
    tracker_transverse_sigma_rad: float = 2.0e-6
    target_sigma_m: float = 3.0e-6
    joint_sigma_rad: float = 5.0e-6
    orientation_sigma_rad: float = 50e-6
    point_sigma_range_m: tuple[float, float] = (0.0, 0.0)

    @property
    def base_sigma_m(self) -> float:
        """The isotropic tracker and target noise per axis [m] every point has."""
        return float(np.hypot(self.tracker_sigma_m, self.target_sigma_m))


@dataclass(frozen=True)
class TrackerOptions:
    """latency_max_s: the joint-state stamp lags the tracker's measurement by U(0, max) [s];
    dropout_probability: chance that a point is lost (line of sight) [1];
    drift_m_per_s, drift_rad_per_s: the tracker frame's drift (3,) [m/s], [rad/s] (a
    translation and a rotation vector growing linearly from the first measurement): a point
    p of the first read's frame is read at time t as Rotation(drift_rad_per_s t) p +
    drift_m_per_s t (what reference reflectors show, msgs_doc/references.md; 50 um/h is
    1.39e-8 m/s); reads_per_pose: how many times the tracker reads each pose, the robot
    standing still (the same physical pose, the tracker's and target's noise drawn again;
    published as that many messages per target, 1 ms apart; not with 6-DoF probes)."""

    latency_max_s: float = 0.002
    dropout_probability: float = 0.0
    reads_per_pose: int = 1
    drift_m_per_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    drift_rad_per_s: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def drift(self, time_s: Array) -> tuple[Rotation, Array]:
        """The tracker frame's motion at times (n,) [s] since its first measurement:
        rotation and translation (n, 3) [m]."""
        t = np.asarray(time_s, dtype=float)[:, None]
        return (
            Rotation.from_rotvec(t * np.asarray(self.drift_rad_per_s)),
            t * np.asarray(self.drift_m_per_s),
        )

    @property
    def drifts(self) -> bool:
        """True when the tracker frame drifts."""
        return any(self.drift_m_per_s) or any(self.drift_rad_per_s)


@dataclass(frozen=True)
class Timing:
    """Realistic timing between poses: joint-interpolated move at `speed_fraction` of each
    joint's max speed, plus acceleration overhead, settling and the measurement itself."""

    max_joint_speed_rad_s: tuple[float, ...] = tuple(
        np.radians([375, 300, 375, 410, 410, 660])
    )  # KR5 sixx R650 data sheet

    def speeds(self, n_joints: int) -> Array:
        """(n_joints,) the max joint speeds [rad/s] of an arm of n_joints: those given, the
        last repeated for joints beyond them (a 7-axis arm's wrist as fast as its 6th)."""
        given = np.asarray(self.max_joint_speed_rad_s, dtype=float)
        return np.concatenate([given, np.full(max(n_joints - len(given), 0), given[-1])])[
            :n_joints
        ]

    accel_overhead_s: float = 0.3
    settle_s: float = 0.5
    measure_s: float = 0.2


@dataclass(frozen=True)
class TemperatureProfile:
    """The robot's temperature over a recording [deg C], t since its first measurement:
    start_c + rise_c (1 - exp(-t / tau_s)) + wave_c sin(2 pi t / period_s) (a warm-up and
    the hall's air conditioning), recorded on the side topic (msgs_doc/temperature.md)."""

    start_c: float = 21.0
    rise_c: float = 6.0
    tau_s: float = 900.0
    wave_c: float = 1.5
    period_s: float = 700.0

    def at(self, time: Array) -> Array:
        """Temperatures (n,) [deg C] at times (n,) [s]."""
        t = np.asarray(time, dtype=float)
        return (
            self.start_c
            + self.rise_c * (1.0 - np.exp(-t / self.tau_s))
            + self.wave_c * np.sin(2.0 * np.pi * t / self.period_s)
        )


EVENT_KINDS = ("robot", "tracker")
MAX_READS = 20  # reads of one pose a simulated tracker makes, at most


@dataclass(frozen=True)
class SimEvent:
    """Something that happened at measured poses first..last (0-based, inclusive; the count
    of points the tracker measured, as the outlier lines count them):

    kind 'robot': the tool was `offset_m` (3,) [m, robot base frame] away from where the
      readings put it (a cable pulling, a brake slipping, the robot in a region it misses):
      every target of those poses together, the reference reflectors not;
    kind 'tracker': the tracker's frame jumped by `offset_m` [m, tracker frame] (a knock,
      a re-levelling): every point and reference reflector read then.
    """

    kind: str
    first: int
    last: int
    offset_m: tuple[float, float, float]

    def at(self, index: IntArray) -> NDArray[np.bool_]:
        """(n,) True where the measured poses `index` (n,) fall in this event."""
        return np.asarray((index >= self.first) & (index <= self.last))


@dataclass(frozen=True)
class World:
    """A complete simulated world; `truth` holds every true parameter value (SI)."""

    model: KinematicModel
    truth: ParameterVector
    noise: NoiseModel = field(default_factory=NoiseModel)
    tracker: TrackerOptions = field(default_factory=TrackerOptions)
    timing: Timing = field(default_factory=Timing)
    seed: int = 0
    source: str = "built-in default"
    temperature: TemperatureProfile | None = None  # recorded when given (no effect alone)
    # reference reflectors fixed off the robot {NAME: (x, y, z) [m, robot base frame]}, read
    # with every pose (msgs_doc/references.md)
    references: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    # things that happened at some poses (a robot off, a tracker jump): `SimEvent`
    events: tuple[SimEvent, ...] = ()

    def reference_points(self) -> Array:
        """(R, 3) [m, tracker frame at the first read] the reference reflectors' places."""
        if not self.references:
            return np.zeros((0, 3))
        base = np.array(list(self.references.values()), dtype=float)
        b2t = self.model.base2tracker(self.truth)
        return np.asarray(base @ b2t[:3, :3].T + b2t[:3, 3])

    @property
    def effects(self) -> tuple[Effect, ...]:
        return self.model.effects


TOP_KEYS = (
    "robot",
    "seed",
    "geometry",
    "deviations",
    "base2tracker",
    "target_in_flange_m",
    "targets",
    "effects",
    "truth",
    "noise",
    "tracker",
    "timing",
    "six_dof",
    "payload",
    "temperature",
    "references",
    "events",
)
EVENT_KEYS = ("kind", "poses", "offset_m")
PAYLOAD_KEYS = ("mass_kg", "com_m")
FIRST_TARGET_KEY = "first"  # the first target's key in `six_dof` (its name is '')
FRAME_KEYS = ("xyz_m", "rpy_deg")
EFFECT_KEYS = ("name", "joints", "values")  # plus the effect's own options (e.g. order)


def _effect(spec: Any, source: str) -> tuple[Effect, dict[str, float] | None]:
    """An effect of a world file's `effects` list and its true values (None: defaults)."""
    if not isinstance(spec, dict) or "name" not in spec:
        raise InputError(f"{source}: effects: each entry is a mapping with a name, got {spec!r}")
    options = tuple(option_types(effect_class(spec["name"])))
    check_keys(spec, EFFECT_KEYS + options, f"{source}: effect {spec['name']}")
    values = spec.get("values")
    if values is not None and not isinstance(values, dict):
        raise InputError(f"{source}: effect {spec['name']}: values must be a mapping")
    return effect_from_dict({k: v for k, v in spec.items() if k != "values"}), values


def _mapping(data: dict[str, Any], key: str, source: str) -> dict[str, Any]:
    value = data.get(key, {}) or {}
    if not isinstance(value, dict):
        raise InputError(f"{source}: '{key}' must be a mapping")
    return value


def _triple(value: Any, where: str) -> tuple[float, float, float]:  # noqa: ANN401 - YAML
    """Three finite numbers (x, y, z or roll, pitch, yaw) of a world file, else InputError."""
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected three numbers, got {value!r}") from None
    if len(out) != 3 or not all(math.isfinite(v) for v in out):
        raise InputError(f"{where}: expected three finite numbers, got {value!r}")
    return out[0], out[1], out[2]


def _section(data: dict[str, Any], key: str, cls: type, source: str) -> dict[str, Any]:
    """The mapping `key` of a world file, checked against the fields of dataclass `cls`
    (timing also takes `max_joint_speed_deg_s`)."""
    value = dict(_mapping(data, key, source))
    known = tuple(f.name for f in fields(cls))
    check_keys(
        value, known + (("max_joint_speed_deg_s",) if cls is Timing else ()), f"{source}: {key}"
    )
    return value


def _checked_values(value: dict[str, Any], key: str, cls: type, source: str) -> dict[str, Any]:
    """The numbers of section `key` (a NoiseModel, TrackerOptions or Timing mapping): each
    float field a finite number >= 0, each bool field a bool; InputError naming the key."""
    defaults = {f.name: f.default for f in fields(cls)}
    out = dict(value)
    for name, item in value.items():
        if not isinstance(defaults.get(name), bool | float):
            continue  # tuples (speeds) are checked by the caller
        where = f"{source}: {key}.{name}"
        if isinstance(defaults[name], bool):
            if not isinstance(item, bool):
                raise InputError(f"{where}: expected true or false, got {item!r}")
            continue
        if isinstance(item, bool) or not isinstance(item, int | float):
            raise InputError(f"{where}: expected a number, got {item!r}")
        if not math.isfinite(item) or item < 0:
            raise InputError(f"{where}: expected a finite number >= 0, got {item!r}")
        out[name] = float(item)
    return out


def _speeds(value: Any, n_joints: int, where: str) -> tuple[float, ...]:  # noqa: ANN401
    """Max joint speeds of a world file: one positive finite number per joint."""
    if not isinstance(value, list | tuple) or len(value) != n_joints:
        raise InputError(f"{where}: expected one speed per joint ({n_joints}), got {value!r}")
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        raise InputError(f"{where}: expected numbers, got {value!r}")
    if not all(math.isfinite(v) and v > 0 for v in value):
        raise InputError(f"{where}: every speed must be finite and > 0, got {value!r}")
    return tuple(float(v) for v in value)


def _targets(
    value: Any,
    source: str,  # noqa: ANN401 - YAML
    key: str = "targets",
) -> dict[str, tuple[float, float, float]]:
    """Further targets on the flange of a world file (`targets: {NAME: [x, y, z]}` [m], each
    measured on /laser_tracker/NAME/point beside the first, msgs_doc/targets.md), or with
    `key` 'references' the reference reflectors in the robot base frame [m]
    (/laser_tracker/reference/NAME/point, msgs_doc/references.md)."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise InputError(f"{source}: {key}: expected a mapping NAME: [x, y, z], got {value!r}")
    out = {}
    for name, xyz in value.items():
        if not isinstance(name, str) or not TARGET_NAME.fullmatch(name):
            raise InputError(
                f"{source}: {key}: name {name!r} must be a ROS topic token "
                "(letters, digits, underscores; not starting with a digit)"
            )
        out[name] = _triple(xyz, f"{source}: {key}.{name}")
    return out


def _six_dof(
    value: Any,
    targets: tuple[str, ...],
    source: str,  # noqa: ANN401 - YAML
) -> dict[str, tuple[float, float, float]]:
    """The 6-DoF probes of a world file (`six_dof: {first|NAME: [roll, pitch, yaw]}` [deg],
    the probe frame in the flange frame, msgs_doc/six_dof.md): {target name: angles [rad]}."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise InputError(f"{source}: six_dof: expected a mapping first|NAME: [roll, pitch, yaw]")
    out = {}
    for key, rpy_deg in value.items():
        name = PRIMARY_TARGET if key == FIRST_TARGET_KEY else str(key)
        if name not in targets:
            known = [FIRST_TARGET_KEY, *targets[1:]]
            raise InputError(f"{source}: six_dof: {key!r} is not a target ({known})")
        angles = _triple(rpy_deg, f"{source}: six_dof.{key}")
        out[name] = (math.radians(angles[0]), math.radians(angles[1]), math.radians(angles[2]))
    return out


def _event(spec: Any, source: str) -> SimEvent:  # noqa: ANN401 - YAML
    """An entry of a world file's `events`: {kind: robot | tracker, poses: [first, last],
    offset_m: [x, y, z]} (`SimEvent`)."""
    where = f"{source}: events"
    if not isinstance(spec, dict):
        raise InputError(f"{where}: each entry is a mapping kind, poses, offset_m; got {spec!r}")
    check_keys(spec, EVENT_KEYS, where)
    kind = spec.get("kind")
    if kind not in EVENT_KINDS:
        raise InputError(f"{where}: kind must be one of {', '.join(EVENT_KINDS)}, got {kind!r}")
    poses = spec.get("poses")
    if (
        not isinstance(poses, list)
        or len(poses) != 2
        or not all(isinstance(p, int) and not isinstance(p, bool) for p in poses)
        or not 0 <= poses[0] <= poses[1]
    ):
        raise InputError(
            f"{where}: poses must be [first, last], 0 <= first <= last, got {poses!r}"
        )
    return SimEvent(kind, poses[0], poses[1], _triple(spec.get("offset_m"), f"{where}.offset_m"))


#: what a simulated world's tracker can plausibly do; beyond, a unit slip (mm or um as m)
MAX_POINT_SIGMA_M = 1e-3  # a point's stated 1-sigma
MAX_DRIFT_M_PER_S = 1e-5  # 36 mm/h
MAX_DRIFT_RAD_PER_S = 1e-5  # 2 deg/h
MAX_REFERENCE_M = 30.0  # a reference reflector's distance from the robot's base
MAX_EVENT_M = 0.1  # an event's offset


def _check_magnitudes(
    noise: NoiseModel,
    tracker: TrackerOptions,
    references: dict[str, tuple[float, float, float]],
    events: tuple[SimEvent, ...],
    source: str,
) -> None:
    """InputError naming the key when a world's tracker figure is beyond any tracker (the
    MAX_* bounds): most likely a unit slip."""
    checks = [
        (noise.point_sigma_range_m[1], MAX_POINT_SIGMA_M, "noise.point_sigma_range_m", "m"),
        (
            float(np.linalg.norm(tracker.drift_m_per_s)),
            MAX_DRIFT_M_PER_S,
            "tracker.drift_m_per_s",
            "m/s (50 um/h is 1.39e-8)",
        ),
        (
            float(np.linalg.norm(tracker.drift_rad_per_s)),
            MAX_DRIFT_RAD_PER_S,
            "tracker.drift_rad_per_s",
            "rad/s",
        ),
        *(
            (float(np.linalg.norm(xyz)), MAX_REFERENCE_M, f"references.{name}", "m")
            for name, xyz in references.items()
        ),
        *(
            (float(np.linalg.norm(e.offset_m)), MAX_EVENT_M, "events.offset_m", "m")
            for e in events
        ),
    ]
    for value, bound, key, unit in checks:
        if value > bound:
            raise InputError(
                f"{source}: {key}: {value:.4g} is beyond any tracker's (at most "
                f"{bound:g} {unit}): a unit slip?"
            )


def _pair(value: Any, where: str) -> tuple[float, float]:  # noqa: ANN401 - YAML
    """Two finite numbers >= 0 of a world file, else InputError."""
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected two numbers, got {value!r}") from None
    if len(out) != 2 or not all(math.isfinite(v) and v >= 0 for v in out):
        raise InputError(f"{where}: expected two finite numbers >= 0, got {value!r}")
    return out[0], out[1]


def _seed(value: Any, source: str) -> int:  # noqa: ANN401 - YAML
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise InputError(f"{source}: seed: expected an integer >= 0, got {value!r}")
    return value


def build_world(data: dict[str, Any], source: str = "built-in default") -> World:
    """A world from a parsed world-file mapping; errors name `source`."""
    if not isinstance(data, dict):
        raise InputError(f"{source}: a world file is a mapping (see worlds/default.yaml)")
    check_keys(data, TOP_KEYS, source)
    try:
        robot = load_robot(data.get("robot", "kr5_sixx_r650"))
        payload = _mapping(data, "payload", source)
        if payload:  # the true robot carries it (gravity compliance acts on it)
            check_keys(payload, PAYLOAD_KEYS, f"{source}: payload")
            com = _triple(payload.get("com_m", [0.0, 0.0, 0.0]), f"{source}: payload.com_m")
            robot = with_payload(robot, float(payload.get("mass_kg", 0.0)), com)
        effects = []
        effect_values: dict[str, float] = {}
        for spec in data.get("effects", []) or []:
            effect, values = _effect(spec, source)
            effects.append(effect)
            effect_values.update(values or effect.default_values(robot))
        model = KinematicModel(robot, tuple(effects))
        frame = _mapping(data, "base2tracker", source)
        check_keys(frame, FRAME_KEYS, f"{source}: base2tracker")
        xyz = _triple(frame.get("xyz_m", [2.2, 1.0, -0.3]), f"{source}: base2tracker.xyz_m")
        roll, pitch, yaw = _triple(
            frame.get("rpy_deg", [0.0, 0.0, 200.0]), f"{source}: base2tracker.rpy_deg"
        )
        target = _triple(
            data.get("target_in_flange_m", [0.06, 0.0, 0.05]), f"{source}: target_in_flange_m"
        )
        rpy = (math.radians(roll), math.radians(pitch), math.radians(yaw))
        extra = _targets(data.get("targets"), source)
        probes = _six_dof(data.get("six_dof"), (PRIMARY_TARGET, *extra), source)
        model = model.with_targets((PRIMARY_TARGET, *extra), tuple(probes))
        truth = model.parameters((*xyz, *rpy), target, extra)
        for name, (r, p, y) in probes.items():
            rotvec = Rotation.from_matrix(rpy_to_matrix(r, p, y)).as_rotvec()
            truth = truth.with_values(dict(zip(tool_rotation_parameters(name), rotvec)))
        geometry = data.get("geometry", "seed_table3_avg_2_6")
        if geometry == "seed_table3_avg_2_6":
            if robot.name != "kr5_sixx_r650":
                raise InputError(
                    f"{source}: geometry {geometry} (the default) is the "
                    f"kr5_sixx_r650's: for {robot.name} write geometry: nominal "
                    "(and any deviations)"
                )
            truth = truth.with_values(
                {
                    k: v * (DEG if k.startswith(("theta", "alpha", "beta")) else 1e-3)
                    for k, v in SEED_TABLE3_AVG_2_6.items()
                }
            )
        elif geometry != "nominal":
            raise InputError(f"{source}: geometry must be seed_table3_avg_2_6 or nominal")
        deviations = _mapping(data, "deviations", source)
        truth = truth.with_values({k: truth[k] + float(v) for k, v in deviations.items()})
        truth = truth.with_values(effect_values)
        # `truth`: absolute values of any parameters, applied last (written by world_to_dict).
        truth = truth.with_values(
            {k: float(v) for k, v in _mapping(data, "truth", source).items()}
        )
        noise = NoiseModel(
            **_checked_values(
                _section(data, "noise", NoiseModel, source), "noise", NoiseModel, source
            )
        )
        tracker = TrackerOptions(
            **_checked_values(
                _section(data, "tracker", TrackerOptions, source),
                "tracker",
                TrackerOptions,
                source,
            )
        )
        tracker = replace(
            tracker,
            drift_m_per_s=_triple(tracker.drift_m_per_s, f"{source}: tracker.drift_m_per_s"),
            drift_rad_per_s=_triple(tracker.drift_rad_per_s, f"{source}: tracker.drift_rad_per_s"),
        )
        reads = tracker.reads_per_pose
        if isinstance(reads, bool) or not isinstance(reads, int) or not 1 <= reads <= MAX_READS:
            raise InputError(
                f"{source}: tracker.reads_per_pose: a whole number 1-{MAX_READS}, got {reads!r}"
            )
        noise = replace(
            noise,
            point_sigma_range_m=_pair(
                noise.point_sigma_range_m, f"{source}: noise.point_sigma_range_m"
            ),
        )
        low, high = noise.point_sigma_range_m
        if high > 0 and (
            noise.anisotropic
            or not noise.base_sigma_m <= low <= high
            or reads > 1
            or model.oriented
        ):
            raise InputError(
                f"{source}: noise.point_sigma_range_m [{low:g}, {high:g}]: needs "
                f"{noise.base_sigma_m:.3g} (the tracker and target noise) <= low <= high, "
                "isotropic noise, one read per pose and no six_dof probe"
            )
        if reads > 1 and model.oriented:
            raise InputError(
                f"{source}: tracker.reads_per_pose {reads} with six_dof probes: "
                "not simulated (one read per pose)"
            )
        references = _targets(data.get("references"), source, "references")
        clash = sorted(set(references) & set(extra))
        if clash:
            raise InputError(f"{source}: references.{clash[0]}: also a target's name")
        events_data = data.get("events", []) or []
        if not isinstance(events_data, list):
            raise InputError(f"{source}: events: expected a list of mappings, got {events_data!r}")
        events = tuple(_event(e, source) for e in events_data)
        _check_magnitudes(noise, tracker, references, events, source)
        if not tracker.dropout_probability < 1.0:
            raise InputError(
                f"{source}: tracker.dropout_probability {tracker.dropout_probability}: must be "
                "in [0, 1) (1 would record no point)"
            )
        timing_data = _checked_values(
            _section(data, "timing", Timing, source), "timing", Timing, source
        )
        n = robot.n_joints
        if "max_joint_speed_deg_s" in timing_data:
            speeds = _speeds(
                timing_data.pop("max_joint_speed_deg_s"),
                n,
                f"{source}: timing.max_joint_speed_deg_s",
            )
            timing_data["max_joint_speed_rad_s"] = tuple(np.radians(speeds))
        elif "max_joint_speed_rad_s" in timing_data:
            timing_data["max_joint_speed_rad_s"] = _speeds(
                timing_data["max_joint_speed_rad_s"], n, f"{source}: timing.max_joint_speed_rad_s"
            )
        timing = Timing(**timing_data)
        seed = _seed(data.get("seed", 0), source)
        temperature = None
        if data.get("temperature") is not None:
            temperature = TemperatureProfile(
                **_checked_values(
                    _section(data, "temperature", TemperatureProfile, source),
                    "temperature",
                    TemperatureProfile,
                    source,
                )
            )
            if temperature.tau_s <= 0 or temperature.period_s <= 0:
                raise InputError(f"{source}: temperature.tau_s and period_s must be > 0")
    except RobotCalibError as exc:  # name the file once (a description's names its own)
        named = str(exc).startswith(
            (source, str(data.get("robot", "")).partition("#")[0] or source)
        )
        raise InputError(str(exc) if named else f"{source}: {exc}") from None
    except (TypeError, KeyError, ValueError) as exc:
        raise InputError(f"{source}: malformed world ({type(exc).__name__}: {exc})") from None
    return World(
        model, truth, noise, tracker, timing, seed, source, temperature, references, events
    )


def world_to_dict(world: World) -> dict[str, Any]:
    """A world-file mapping that rebuilds `world` exactly (every true value under `truth`)."""
    effects = [effect.to_dict() for effect in world.effects]
    timing = asdict(world.timing)
    timing.pop("max_joint_speed_rad_s")
    speeds = world.timing.speeds(world.model.robot.n_joints)
    timing["max_joint_speed_deg_s"] = np.degrees(speeds).tolist()
    robot = world.model.robot
    probes = {
        t or FIRST_TARGET_KEY: np.degrees(
            matrix_to_rpy(world.model.tool_rotations(world.truth)[world.model.targets.index(t)])
        )
        for t in world.model.oriented
    }
    payload = {"mass_kg": robot.payload_kg, "com_m": list(robot.payload_com_m)}
    return {
        **({"six_dof": {k: v.tolist() for k, v in probes.items()}} if probes else {}),
        **({"payload": payload} if robot.payload_kg else {}),
        **({"temperature": asdict(world.temperature)} if world.temperature else {}),
        "robot": robot.reference(),
        "seed": world.seed,
        "geometry": "nominal",
        "effects": effects,
        "targets": {
            t: [world.truth[k] for k in target_parameters(t)] for t in world.model.targets[1:]
        },
        "truth": {n: float(v) for n, v in zip(world.truth.names, world.truth.values)},
        "noise": _yaml_fields(world.noise),
        "tracker": _yaml_fields(world.tracker),
        **(
            {"references": {k: list(v) for k, v in world.references.items()}}
            if world.references
            else {}
        ),
        **(
            {
                "events": [
                    {"kind": e.kind, "poses": [e.first, e.last], "offset_m": list(e.offset_m)}
                    for e in world.events
                ]
            }
            if world.events
            else {}
        ),
        "timing": timing,
    }


def _yaml_fields(section: NoiseModel | TrackerOptions) -> dict[str, Any]:
    """A world section's fields as YAML takes them (tuples as lists)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(section).items()}


def save_world(world: World, path: Path) -> None:
    """Write `world` as a world YAML file (the ground truth of a simulated recording)."""
    header = f"# robot_calib world (complete truth), from {world.source}\n"
    path.write_text(header + yaml.safe_dump(world_to_dict(world), sort_keys=False))


def load_world(path: str | Path | None = None) -> World:
    """The world of a YAML file, or the built-in default world (`worlds/default.yaml`)."""
    path = Path(path) if path else WORLDS_DIR / "default.yaml"
    if not path.is_file():
        raise InputError(f"{path}: no such world file")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    return build_world(data, str(path))


def with_effect(world: World, effect: Effect, values: dict[str, float] | None = None) -> World:
    """The world with one more effect switched on (default magnitudes unless given)."""
    model = world.model.with_effects(effect)
    truth = model.parameters().with_values(dict(zip(world.truth.names, world.truth.values)))
    truth = truth.with_values(values or effect.default_values(world.model.robot))
    return replace(world, model=model, truth=truth)


def parse_sim_effect(text: str, n_joints: int) -> tuple[Effect, float | None]:
    """An effect of `simulate --effects`: its text form (`parse_effect`, e.g. 'backlash:4',
    'eccentricity:1,2', 'thermal_drift') with an optional '=VALUE' [SI] for all its terms,
    e.g. 'compliance:2=2e-5'."""
    value = None
    spec, sep, raw = text.rpartition("=")
    last = spec.split(":")[-1]
    # '=VALUE' follows the name or the joints ('thermal_drift=3e-7', 'compliance:2=2e-5');
    # after anything else it is an option's 'key=value' (parse_effect checks the key).
    if sep and (":" not in spec or last.replace(",", "").isdigit() or last == ""):
        try:
            value = float(raw)
        except ValueError:
            raise InputError(f"{param('effects', [text])}: value must be a number (SI)") from None
        if not math.isfinite(value):
            raise InputError(f"{param('effects', [text])}: value must be finite")
        text = spec
    return parse_effect(text, n_joints), value
