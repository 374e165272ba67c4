"""The simulated world: true robot (nominal + geometric deviations + effects), tracker pose,
target offset, noise models and timing. One YAML format describes it (see
`worlds/default.yaml`); a seed makes every draw reproducible.

Default world: the true geometry is the seed's Table 3 "Avg. 2-6" column, the tracker
about 2.5 m from the base, an active target on a bracket off the flange axis.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robot_calib.effects import Effect, make_effect
from robot_calib.errors import InputError, RobotCalibError
from robot_calib.kinematics.description import load_robot
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel

WORLDS_DIR = Path(__file__).resolve().parent / "worlds"
DEG = np.pi / 180.0

# Seed Table 3, column "Avg. 2-6" (circle point parameters of the real KR5) [mm, deg].
SEED_TABLE3_AVG_2_6 = {
    "d1": 335.2389, "d3": -0.3457, "d4": 295.2779, "d5": 0.0063,
    "theta1": 0.0803, "theta2": -0.0288, "theta3": 89.9488, "theta4": 0.2123, "theta5": 180.0611,
    "a1": 74.8367, "a2": 270.3405, "a3": 90.2756, "a4": -0.0318, "a5": -0.0003,
    "alpha1": 90.0171, "alpha2": 0.0077, "alpha3": 89.9702, "alpha4": 90.0290, "alpha5": 90.0182,
    "beta2": 0.0541,
}  # fmt: skip

# Seed Tables 5-6: eccentricity offsets D and amplitudes A per joint, order dx, dy, dz [mm],
# ex, ey (read as deg: the tables label them "mm", which cannot be a tilt). Phases (Table 7)
# are all below 3e-4 rad, so the series is D + A cos(q).
SEED_TABLE5_D = [
    [-0.00894432, -0.00044766, -0.09097568, -2.8886e-05, 9.9299e-05],
    [0.00225915, -0.05434195, -0.00171799, -0.00027847, 0.00043006],
    [0.16801637, 0.00185002, -0.03888246, -0.00021782, -0.0004381],
    [0.00982289, 0.03792663, 0.00545861, 9.5836e-05, -0.00014458],
    [-0.00465192, 0.00250222, 0.31343338, 0.00324521, -0.00115391],
    [-0.03546433, -0.02386418, -0.13111638, 0.00084781, 0.00031983],
]
SEED_TABLE6_A = [
    [-0.09438893, -0.010266, -0.1214897, -0.0056238, 0.0062345],
    [-0.01861644, -0.11436569, -0.00977474, 0.02706514, -0.02377566],
    [0.14699369, -0.02192545, -0.00973498, 0.00430838, 0.02144104],
    [0.24364125, -0.00971577, -0.02075261, -0.01180938, 0.00267801],
    [-0.1641385, -0.02075231, 0.0408056, -0.00131996, -0.14413296],
    [0.00374365, 0.04081512, 0.02455266, 0.01901011, 0.04791811],
]

# Realistic default magnitude of each effect's parameters (SI units of the parameter):
# a joint-4 play of 2 mrad moves the target ~0.25 mm between approach directions (the seed
# reports 250 um); the others give tenths of a mm over the workspace.
DEFAULT_MAGNITUDE = {
    "backlash": 2.0e-3,  # rad, total play
    "encoder_scale": 3e-4,  # 1
    "compliance": 2.0e-5,  # rad/(N m)
    "thermal_drift_rate": 3e-7,  # 1/s: 0.03 % strain per 1000 s of warm-up
    "joint_ripple": 3e-4,  # rad
}


@dataclass(frozen=True)
class NoiseModel:
    """Measurement noise (1 sigma).

    tracker_sigma_m : isotropic tracker noise [m] (seed: +-3.75 um at 2.5 m), or with
    anisotropic=True: tracker_radial_sigma_m along the line of sight (ADM) and
    tracker_transverse_sigma_rad x range across it (angle encoders), as tracker MPE specs give.
    target_sigma_m : target centring noise [m] (seed: active target +-3 um).
    joint_sigma_rad : robot repeatability noise on the physical joint angle [rad].
    """

    tracker_sigma_m: float = 3.75e-6
    anisotropic: bool = False
    tracker_radial_sigma_m: float = 2.5e-6
    tracker_transverse_sigma_rad: float = 2.0e-6
    target_sigma_m: float = 3.0e-6
    joint_sigma_rad: float = 5.0e-6


@dataclass(frozen=True)
class TrackerOptions:
    """latency_max_s: the joint-state stamp lags the tracker's measurement by U(0, max) [s];
    dropout_probability: chance that a point is lost (line of sight) [1]."""

    latency_max_s: float = 0.002
    dropout_probability: float = 0.0


@dataclass(frozen=True)
class Timing:
    """Realistic timing between poses: joint-interpolated move at `speed_fraction` of each
    joint's max speed, plus acceleration overhead, settling and the measurement itself."""

    max_joint_speed_rad_s: tuple[float, ...] = tuple(
        np.radians([375, 300, 375, 410, 410, 660])
    )  # KR5 sixx R650 data sheet
    accel_overhead_s: float = 0.3
    settle_s: float = 0.5
    measure_s: float = 0.2


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

    @property
    def effects(self) -> tuple[Effect, ...]:
        return self.model.effects


def eccentricity_from_seed(joints: tuple[int, ...]) -> dict[str, float]:
    """Order-1 eccentricity values of the seed's Tables 5-6 for `joints` [SI]."""
    values = {}
    for j in joints:
        for e, err in enumerate(("dx", "dy", "dz", "ex", "ey")):
            scale = 1e-3 if err[0] == "d" else DEG
            values[f"ecc{j}_{err}_D"] = SEED_TABLE5_D[j - 1][e] * scale
            values[f"ecc{j}_{err}_c1"] = SEED_TABLE6_A[j - 1][e] * scale
    return values


def default_effect_values(effect: Effect, robot_name: str) -> dict[str, float]:
    """Realistic default values for an effect's parameters (see DEFAULT_MAGNITUDE)."""
    if effect.name == "eccentricity":
        if robot_name == "kr5_sixx_r650" and getattr(effect, "order", 1) >= 1:
            return eccentricity_from_seed(effect.joints)
        raise InputError("eccentricity values must be given for robots other than the KR5")
    if effect.name == "thermal_drift":
        return {"thermal_drift_rate": DEFAULT_MAGNITUDE["thermal_drift_rate"]}
    if effect.name == "joint_ripple":
        return {f"ripple_cos{j}": DEFAULT_MAGNITUDE["joint_ripple"] for j in effect.joints}
    return {f"{effect.name}{j}": DEFAULT_MAGNITUDE[effect.name] for j in effect.joints}


def _mapping(data: dict[str, Any], key: str, source: str) -> dict[str, Any]:
    value = data.get(key, {}) or {}
    if not isinstance(value, dict):
        raise InputError(f"{source}: '{key}' must be a mapping")
    return value


def build_world(data: dict[str, Any], source: str = "built-in default") -> World:
    """A world from a parsed world-file mapping; errors name `source`."""
    if not isinstance(data, dict):
        raise InputError(f"{source}: a world file is a mapping (see worlds/default.yaml)")
    try:
        robot = load_robot(data.get("robot", "kr5_sixx_r650"))
        effects = []
        effect_values: dict[str, float] = {}
        for spec in data.get("effects", []) or []:
            spec = dict(spec)
            name, joints = spec.pop("name"), spec.pop("joints", [])
            values = spec.pop("values", None)
            effect = make_effect(name, joints, **spec)
            effects.append(effect)
            effect_values.update(values or default_effect_values(effect, robot.name))
        model = KinematicModel(robot, tuple(effects))
        frame = _mapping(data, "base2tracker", source)
        xyz = frame.get("xyz_m", [2.2, 1.0, -0.3])
        rpy = np.radians(frame.get("rpy_deg", [0.0, 0.0, 200.0]))
        target = data.get("target_in_flange_m", [0.06, 0.0, 0.05])
        truth = model.parameters(tuple(xyz) + tuple(rpy), tuple(target))
        geometry = data.get("geometry", "seed_table3_avg_2_6")
        if geometry == "seed_table3_avg_2_6":
            if robot.name != "kr5_sixx_r650":
                raise InputError(f"{source}: geometry {geometry} is for the kr5_sixx_r650")
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
        noise = NoiseModel(**_mapping(data, "noise", source))
        tracker = TrackerOptions(**_mapping(data, "tracker", source))
        timing_data = _mapping(data, "timing", source)
        if "max_joint_speed_deg_s" in timing_data:
            speeds = np.radians(timing_data.pop("max_joint_speed_deg_s"))
            timing_data["max_joint_speed_rad_s"] = tuple(speeds)
        timing = Timing(**timing_data)
    except RobotCalibError as exc:
        raise InputError(f"{source}: {exc}") from None
    except (TypeError, KeyError, ValueError) as exc:
        raise InputError(f"{source}: malformed world ({type(exc).__name__}: {exc})") from None
    return World(model, truth, noise, tracker, timing, int(data.get("seed", 0)), source)


def world_to_dict(world: World) -> dict[str, Any]:
    """A world-file mapping that rebuilds `world` exactly (every true value under `truth`)."""
    effects = []
    for effect in world.effects:
        spec: dict[str, Any] = {"name": effect.name, "joints": list(effect.joints)}
        spec.update(
            {f.name: getattr(effect, f.name) for f in fields(effect) if f.name != "joints"}
        )
        effects.append(spec)
    timing = asdict(world.timing)
    timing["max_joint_speed_deg_s"] = np.degrees(timing.pop("max_joint_speed_rad_s")).tolist()
    robot = world.model.robot
    return {
        "robot": robot.reference(),
        "seed": world.seed,
        "geometry": "nominal",
        "effects": effects,
        "truth": {n: float(v) for n, v in zip(world.truth.names, world.truth.values)},
        "noise": asdict(world.noise),
        "tracker": asdict(world.tracker),
        "timing": timing,
    }


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
    truth = truth.with_values(values or default_effect_values(effect, world.model.robot.name))
    return replace(world, model=model, truth=truth)
