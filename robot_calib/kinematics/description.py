"""Robot descriptions as data: the nominal DH/Hayati table, limits and an approximate mass model.

Built-ins live in `robots/*.yaml`; a user passes a YAML file of the same format. Lengths
are in m; angles in rad unless the file says ``angle_unit: deg`` (converted on load).
See `robots/kr5_sixx_r650.yaml` for a commented example. Keys outside `ROBOT_KEYS` (top
level), `JOINT_KEYS` (each joint) and `MAPPING_KEYS` (`reading_to_joint`) are rejected, so a
misspelt key is not silently ignored.

Readings to joint variables (msgs_doc/specification.md, "Joint and model conventions";
msgs_doc/robots.md):
the DH joint variable is ``theta_j = theta_j(table) + (M q + offset)_j`` with q the readings
and ``M = diag(sign) + coupling``; without a `reading_to_joint` section M = I and offset = 0
(the contract's default), and `joint_variables` returns the readings themselves.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robot_calib.errors import InputError, RobotDescriptionError, check_keys
from robot_calib.kinematics.dh import DHTable, chain
from robot_calib.kinematics.frames import Array
from robot_calib.kinematics.modified_dh import (
    MAX_BASE_OFFSET,
    base_offset,
    com_to_standard,
    standard_from_modified,
)

ROBOTS_DIR = Path(__file__).resolve().parent / "robots"
DH_FIELDS = ("theta", "d", "a", "alpha")
# top level of a robot YAML file
ROBOT_KEYS = ("name", "source", "angle_unit", "convention", "reading_to_joint", "joints")
#: the DH conventions a robot YAML file may give its table in (`convention`): standard
#: (theta_i, d_i, a_i, alpha_i) or modified / Craig (alpha_{i-1}, a_{i-1}, theta_i, d_i:
#: `kinematics.modified_dh`)
CONVENTIONS = ("dh", "modified_dh")
JOINT_KEYS = ("name", *DH_FIELDS, "beta", "hayati", "limits", "mass", "com")  # each joint
MAPPING_KEYS = ("sign", "offset", "coupling")  # the `reading_to_joint` section
LIMIT_TOLERANCE_RAD = 1e-9
"""How far beyond a joint limit a reading may lie [rad]: the rounding of a reading written
at its limit (a PLAN.yaml, a CSV); the one tolerance of `RobotDescription.check_joints`."""
JOINT_UNITS = {"rad": 1.0, "deg": np.pi / 180}


class JointLimitError(InputError):
    """Joint readings outside the robot's limits, not finite, or in the wrong unit (degrees
    given as rad): `RobotDescription.check_joints`, the one check of `compensate`, the
    compensator node, `capture`, `sim_robot` and `plan`. Its message names where (file,
    topic), the pose, the joint, the reading in rad and deg and the limits in deg."""


def joint_violations(
    q: Array,
    limits: Array,
    joint_names: Sequence[str],
    unit: str = "rad",
    tolerance: float = LIMIT_TOLERANCE_RAD,
) -> list[str | None]:
    """Per pose of q (n, J) (or one pose (J,)) in `unit` ('rad' or 'deg'): None when
    every reading is finite and within `limits` (J, 2) [rad] (+- `tolerance` [rad]), else
    what is wrong with its first bad joint (one in degrees first), as text: "joint_3 = 95
    rad is beyond any reading of this joint in rad (|q| <= 6.28): degrees? joint readings
    take rad" or
    "joint_2 = 2.1 rad (120.32 deg) outside its limits [-190.0, 45.0] deg".

    A reading in rad beyond `poses.beyond_reach` (2 pi, or 1.5 x the joint's largest
    |limit|) is no reading of that joint: degrees given as rad, most likely."""
    from robot_calib.poses import beyond_reach

    if unit not in JOINT_UNITS:
        raise InputError(f"joint unit {unit!r}: one of {sorted(JOINT_UNITS)}")
    given = np.atleast_2d(np.asarray(q, dtype=float))
    if given.shape[1] != len(joint_names):
        raise JointLimitError(
            f"{given.shape[1]} joint readings per pose for {len(joint_names)} joints"
        )
    rad = given * JOINT_UNITS[unit]
    lo, hi = limits.T
    finite = np.isfinite(rad)
    degrees, reach = beyond_reach(np.where(finite, rad, 0.0), limits)
    degrees &= unit == "rad"
    outside = ~finite | (rad < lo - tolerance) | (rad > hi + tolerance)
    out: list[str | None] = [None] * len(rad)
    for k in np.flatnonzero((outside | degrees).any(axis=1)).tolist():
        j = int(np.flatnonzero(degrees[k] if degrees[k].any() else outside[k])[0])
        value = f"{joint_names[j]} = {rad[k, j]:.6g} rad"
        if not finite[k, j]:
            out[k] = f"{joint_names[j]} = {given[k, j]} (not a finite number)"
        elif degrees[k, j]:
            out[k] = (
                f"{value} is beyond any reading of this joint in rad (|q| <= "
                f"{reach[j]:.2f}): degrees? joint readings take rad"
            )
        else:
            out[k] = (
                f"{value} ({np.degrees(rad[k, j]):.2f} deg) outside its limits "
                f"[{np.degrees(lo[j]):.1f}, {np.degrees(hi[j]):.1f}] deg"
            )
    return out


@dataclass(frozen=True)
class RobotDescription:
    """Nominal kinematics of a serial robot with revolute joints.

    theta, d, a, alpha, beta : shape (J,), nominal DH table [rad, m, m, rad, rad]
    hayati : shape (J,) bool — beta_j used and d_j dropped (axes j, j+1 nominally parallel)
    limits : shape (J, 2), [min, max] joint readings [rad]
    link_mass : shape (J,) [kg], mass of the link moved by joint j (approximate)
    link_com : shape (J, 3) [m], its centre of mass in DH frame j (approximate)
    reading_matrix : shape (J, J) or None — M of the joint variables M q + offset (None: M = I)
    reading_offset : shape (J,) [rad] or None — offset of the joint variables (None: 0)
    payload_kg, payload_com_m : a payload on the flange [kg] and its centre of mass in the
      flange frame (DH frame J) [m], already included in the last link's mass and centre
      of mass (`with_payload`); 0 and the origin without one
    """

    name: str
    joint_names: tuple[str, ...]
    theta: Array
    d: Array
    a: Array
    alpha: Array
    beta: Array
    hayati: Array
    limits: Array
    link_mass: Array
    link_com: Array
    source: str = ""
    path: str = ""  # absolute path of the YAML file it was loaded from ('' if built in code)
    reading_matrix: Array | None = None
    reading_offset: Array | None = None
    payload_kg: float = 0.0
    payload_com_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # why the description's own mass model is not used ('' when it is: `kinematics.masses`)
    mass_note: str = ""

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def has_mapping(self) -> bool:
        """True when the joint variables differ from the readings (a `reading_to_joint`)."""
        return self.reading_matrix is not None or self.reading_offset is not None

    def joint_variables(self, q: Array) -> Array:
        """Joint variables M q + offset, shape (n, J) [rad], of readings q (n, J) [rad]: what
        the DH table's theta_j adds to its nominal value. The readings themselves (the same
        array) when the robot declares no mapping."""
        if not self.has_mapping:
            return q
        out = np.asarray(q, dtype=float)
        if self.reading_matrix is not None:
            out = out @ self.reading_matrix.T
        if self.reading_offset is not None:
            out = out + self.reading_offset
        return out

    def nominal_frames(self, q: Array) -> Array:
        """(n, J + 1, 4, 4) the nominal DH frames in the base frame at readings q (n, J)
        [rad]: frame 0 the base, frame j moved by joint j (the frame of link j's mass)."""
        dh = DHTable(self.theta + self.joint_variables(q), self.d, self.a, self.alpha, self.beta)
        return chain(dh)

    def readings(self, joint_variables: Array) -> Array:
        """Readings q (n, J) [rad] of joint variables (n, J) [rad]: the inverse of
        `joint_variables` (the same array when the robot declares no mapping)."""
        if not self.has_mapping:
            return joint_variables
        out = np.asarray(joint_variables, dtype=float)
        if self.reading_offset is not None:
            out = out - self.reading_offset
        if self.reading_matrix is not None:
            out = np.linalg.solve(self.reading_matrix, out.T).T
        return out

    def joint_violations(
        self, q: Array, unit: str = "rad", tolerance: float = LIMIT_TOLERANCE_RAD
    ) -> list[str | None]:
        """Per pose of q (n, J) (or one pose (J,)) in `unit`: `joint_violations` with this
        robot's limits and joint names."""
        return joint_violations(q, self.limits, self.joint_names, unit, tolerance)

    def check_joints(
        self,
        q: Array,
        where: str,
        unit: str = "rad",
        tolerance: float = LIMIT_TOLERANCE_RAD,
        what: str = "pose",
    ) -> None:
        """JointLimitError "WHERE: WHAT k: <joint_violations text> (m of n WHATs
        outside)" for the first pose of q (n, J) in `unit` with a reading that is not
        finite, outside the limits (+- `tolerance` [rad]) or in degrees where rad is due;
        nothing when every pose is fine."""
        found = self.joint_violations(q, unit, tolerance)
        bad = [k for k, text in enumerate(found) if text is not None]
        if bad:
            more = f" ({len(bad)} of {len(found)} {what}s)" if len(found) > 1 else ""
            raise JointLimitError(f"{where}: {what} {bad[0]}: {found[bad[0]]}{more}")

    def fingerprint(self, with_names: bool = False) -> str:
        """SHA-256 of what the model uses from this description (the DH/Hayati table,
        limits, masses, the reading-to-joint mapping): PARAMS.json stores it, so a
        description file edited or replaced after the calibration is noticed on reading.
        The joint names are left out: they only say how bags name the joints (a calibration
        made with --joint-names is of the same robot); `with_names` gives the digest that
        files written before that rule store."""
        digest = hashlib.sha256("\n".join(self.joint_names).encode() if with_names else b"")
        for array in (
            self.theta,
            self.d,
            self.a,
            self.alpha,
            self.beta,
            self.hayati,
            self.limits,
            self.link_mass,
            self.link_com,
            self.reading_matrix,
            self.reading_offset,
        ):
            if array is not None:
                digest.update(np.ascontiguousarray(array, dtype=float).tobytes())
        return digest.hexdigest()

    def reference(self) -> str:
        """What `load_robot` needs to load it again: the built-in name, else the absolute
        path of its YAML file (what PARAMS.json and world files store)."""
        builtin = (ROBOTS_DIR / f"{self.name}.yaml").resolve()
        if not self.path or Path(self.path) == builtin:
            return self.name
        return self.path


# The home pose [deg] of joints 1-6 (0 beyond): wrist bent so that every joint's circle has a
# radius of several cm at a target on the flange; where simulated controllers start, dry
# runs plan from and the compensator's alternative solutions are sought near.
HOME_DEG = (0.0, -90.0, 90.0, 0.0, 45.0, 0.0)


def home_variables(n_joints: int) -> Array:
    """(J,) joint variables [rad] of the home pose: HOME_DEG, 0 for joints beyond it."""
    out = np.zeros(n_joints)
    k = min(len(HOME_DEG), n_joints)
    out[:k] = np.radians(HOME_DEG[:k])
    return out


def home_pose(robot: RobotDescription) -> Array:
    """(J,) readings [rad] of the home pose (`home_variables`, through the robot's
    reading-to-joint mapping)."""
    return np.asarray(robot.readings(home_variables(robot.n_joints)[None, :])[0], dtype=float)


def random_readings(
    robot: RobotDescription, n: int, rng: np.random.Generator, margin: float = 0.05
) -> Array:
    """(n, J) readings [rad] drawn uniformly in the joint limits shrunk by `margin` of each
    range (general poses: for checks at random poses, and the `random` plan)."""
    lo, hi = robot.limits.T
    span = hi - lo
    return rng.uniform(lo + margin * span, hi - margin * span, (n, robot.n_joints))


def available_robots() -> list[str]:
    """Names of the built-in descriptions."""
    return sorted(p.stem for p in ROBOTS_DIR.glob("*.yaml"))


MAX_PAYLOAD_KG = 5000.0  # beyond any industrial robot's rated payload


def with_payload(
    robot: RobotDescription, mass_kg: float, com_m: Sequence[float] = (0.0, 0.0, 0.0)
) -> RobotDescription:
    """`robot` carrying a payload of `mass_kg` [kg] with its centre of mass at `com_m` (3,)
    in the flange frame (DH frame J) [m]: the last link's mass and centre of mass become
    those of link and payload together (what gravity acts on, `effects.compliance`).
    Replaces a payload the description already carries. RobotDescriptionError unless
    0 <= mass_kg <= MAX_PAYLOAD_KG and the centre is finite and within 5 m."""
    com = np.asarray(com_m, dtype=float)
    if not (np.isfinite(mass_kg) and 0.0 <= mass_kg <= MAX_PAYLOAD_KG):
        raise RobotDescriptionError(f"payload {mass_kg} kg: need 0 .. {MAX_PAYLOAD_KG:g} kg")
    if com.shape != (3,) or not np.all(np.isfinite(com)) or np.linalg.norm(com) > 5.0:
        raise RobotDescriptionError(
            f"payload centre of mass {com.tolist()} m: three finite coordinates in the "
            "flange frame, within 5 m"
        )
    mass, centre = robot.link_mass.copy(), robot.link_com.copy()
    old = np.asarray(robot.payload_com_m)
    link = mass[-1] - robot.payload_kg  # the bare last link
    bare = centre[-1] if link <= 0 else (mass[-1] * centre[-1] - robot.payload_kg * old) / link
    mass[-1] = link + mass_kg
    centre[-1] = bare if mass[-1] <= 0 else (link * bare + mass_kg * com) / mass[-1]
    return replace(
        robot,
        link_mass=mass,
        link_com=centre,
        payload_kg=float(mass_kg),
        payload_com_m=(float(com[0]), float(com[1]), float(com[2])),
    )


@functools.cache
def _builtin_joint_names() -> dict[str, tuple[str, ...]]:
    """{built-in robot: its JointState names}, read once per process."""
    return {
        name: load_robot_yaml(ROBOTS_DIR / f"{name}.yaml").joint_names
        for name in available_robots()
    }


def robots_with_joint_names(names: Sequence[str]) -> list[str]:
    """The built-in robots (sorted) all of whose JointState names are among `names` (e.g. a
    message's): the robots a recording with these names may be of."""
    given = set(names)
    return [r for r, joints in _builtin_joint_names().items() if given.issuperset(joints)]


def with_joint_names(robot: RobotDescription, names: Sequence[str] | str) -> RobotDescription:
    """`robot` with the JointState names of its joints 1..J replaced by `names` (a sequence
    or 'a,b,c,...'), e.g. for a bag written with another naming (`--joint-names`).
    Raises RobotDescriptionError unless there is one distinct, non-empty name per joint."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",")]
    names = tuple(str(n) for n in names)
    where = f"joint names {','.join(names)}"
    if len(names) != robot.n_joints:
        raise RobotDescriptionError(
            f"{where}: {len(names)} names for robot {robot.name} with {robot.n_joints} joints "
            f"({', '.join(robot.joint_names)}); give one per joint, in joint order"
        )
    if not all(names):
        raise RobotDescriptionError(f"{where}: empty name")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise RobotDescriptionError(f"{where}: names must be distinct; {repeated} repeated")
    return replace(robot, joint_names=names)


def load_robot_yaml(path: Path) -> RobotDescription:
    """The description in a robot YAML file (the format of robots/*.yaml); its `path` is the
    file's absolute path. RobotDescriptionError naming the file when it is missing, not
    YAML or not a valid description. A built-in robot, a YAML or a URDF by one name:
    `kinematics.loader.load_robot`."""
    if not path.is_file():
        raise RobotDescriptionError(f"{path}: no such robot description file")
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise RobotDescriptionError(f"{path}: not valid YAML ({first})") from None
    return replace(parse_robot(data, str(path)), path=str(path.resolve()))


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise RobotDescriptionError(f"{where}: expected a number, got {value!r}")
    if not np.isfinite(value):
        raise RobotDescriptionError(f"{where}: not finite ({value!r})")
    return float(value)


def parse_robot(data: Any, source: str) -> RobotDescription:
    """Validate a loaded YAML mapping and build the description; errors name `source`."""
    if not isinstance(data, dict):
        raise RobotDescriptionError(f"{source}: expected a mapping with 'name' and 'joints'")
    check_keys(data, ROBOT_KEYS, source, RobotDescriptionError)
    joints = data.get("joints")
    if not isinstance(joints, list) or len(joints) < 2:
        raise RobotDescriptionError(f"{source}: 'joints' must be a list of >= 2 joint entries")
    unit = data.get("angle_unit", "rad")
    if unit not in ("rad", "deg"):
        raise RobotDescriptionError(f"{source}: angle_unit must be 'rad' or 'deg', got {unit!r}")
    to_rad = np.pi / 180.0 if unit == "deg" else 1.0

    table: dict[str, list[float]] = {k: [] for k in (*DH_FIELDS, "beta")}
    names, limits, mass, com, hayati = [], [], [], [], []
    for j, entry in enumerate(joints, start=1):
        where = f"{source}: joint {j}"
        if not isinstance(entry, dict):
            raise RobotDescriptionError(f"{where}: expected a mapping")
        check_keys(entry, JOINT_KEYS, where, RobotDescriptionError)
        for key in DH_FIELDS:
            if key not in entry:
                raise RobotDescriptionError(f"{where}: missing '{key}'")
            scale = to_rad if key in ("theta", "alpha") else 1.0
            table[key].append(_number(entry[key], f"{where} {key}") * scale)
        table["beta"].append(_number(entry.get("beta", 0.0), f"{where} beta") * to_rad)
        names.append(str(entry.get("name", f"joint_a{j}")))
        lim = entry.get("limits")
        if lim is None:
            limits.append([-np.pi, np.pi])
        elif isinstance(lim, list) and len(lim) == 2:
            lo, hi = (_number(v, f"{where} limits") * to_rad for v in lim)
            if lo >= hi:
                raise RobotDescriptionError(f"{where}: limits must be [min, max], got {lim}")
            limits.append([lo, hi])
        else:
            raise RobotDescriptionError(f"{where}: limits must be [min, max]")
        mass.append(_number(entry.get("mass", 0.0), f"{where} mass"))
        c = entry.get("com", [0.0, 0.0, 0.0])
        if not (isinstance(c, list) and len(c) == 3):
            raise RobotDescriptionError(f"{where}: com must be [x, y, z] in m")
        com.append([_number(v, f"{where} com") for v in c])
        hayati.append(entry.get("hayati"))

    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise RobotDescriptionError(
            f"{source}: joint names must be distinct; {repeated} given more than once"
        )
    convention = data.get("convention", "dh")
    if convention not in CONVENTIONS:
        raise RobotDescriptionError(
            f"{source}: convention must be one of {', '.join(CONVENTIONS)}, got {convention!r}"
        )
    alpha, a, com_array = np.array(table["alpha"]), np.array(table["a"]), np.array(com)
    if convention == "modified_dh":
        alpha0, a0 = base_offset(alpha, a)
        if abs(alpha0) > MAX_BASE_OFFSET or abs(a0) > MAX_BASE_OFFSET:
            raise RobotDescriptionError(
                f"{source}: joint 1's alpha ({alpha0 / to_rad:g}) and a ({a0:g} m) of a "
                "modified-DH table must be 0: the base frame's z is joint 1's axis (move "
                "the base frame onto it)"
            )
        alpha, a = standard_from_modified(alpha, a)
        com_array = com_to_standard(com_array, alpha, a)
        # a Hayati beta belongs to the pair of axes whose common normal its row gives:
        # modified row i + 1 (axes i, i + 1), standard joint i
        table["beta"] = [*table["beta"][1:], 0.0]
        hayati = [*hayati[1:], None]
    # Default: beta wherever axes j and j+1 are nominally parallel (alpha_j = 0 or pi).
    hayati = [
        bool(h) if h is not None else j < len(joints) - 1 and abs(np.sin(alpha[j])) < 1e-9
        for j, h in enumerate(hayati)
    ]
    matrix, offset = _reading_to_joint(data.get("reading_to_joint"), len(joints), to_rad, source)
    return RobotDescription(
        name=str(data.get("name", Path(source).stem)),
        joint_names=tuple(names),
        theta=np.array(table["theta"]),
        d=np.array(table["d"]),
        a=a,
        alpha=alpha,
        beta=np.array(table["beta"]),
        hayati=np.array(hayati, dtype=bool),
        limits=np.array(limits),
        link_mass=np.array(mass),
        link_com=com_array,
        source=str(data.get("source", source)),
        reading_matrix=matrix,
        reading_offset=offset,
    )


def _reading_to_joint(
    section: Any, n_joints: int, to_rad: float, source: str
) -> tuple[Array | None, Array | None]:
    """M (J, J) and offset (J,) [rad] of a `reading_to_joint` section, None for identity
    parts. `sign`: J values +1/-1; `offset`: J angles (angle_unit); `coupling`: a mapping
    {j: {k: c}} (1-based: joint variable j += c * reading k) or a J x J list with a zero
    diagonal (the diagonal is `sign`)."""
    where = f"{source}: reading_to_joint"
    if section is None:
        return None, None
    if not isinstance(section, dict):
        raise RobotDescriptionError(f"{where}: expected a mapping with {', '.join(MAPPING_KEYS)}")
    check_keys(section, MAPPING_KEYS, where, RobotDescriptionError)

    def vector(key: str) -> Array:
        values = section[key]
        if not (isinstance(values, list) and len(values) == n_joints):
            raise RobotDescriptionError(f"{where}: {key} must be a list of {n_joints} numbers")
        return np.array([_number(v, f"{where} {key}") for v in values])

    sign = vector("sign") if "sign" in section else np.ones(n_joints)
    if not np.all(np.abs(sign) == 1.0):
        raise RobotDescriptionError(f"{where}: sign must be +1 or -1 per joint, got {sign}")
    offset = vector("offset") * to_rad if "offset" in section else np.zeros(n_joints)
    coupling = np.zeros((n_joints, n_joints))
    raw = section.get("coupling")
    if isinstance(raw, dict):
        for j, row in raw.items():
            if not (isinstance(j, int) and 1 <= j <= n_joints and isinstance(row, dict)):
                raise RobotDescriptionError(
                    f"{where}: coupling must map joints 1..{n_joints} to {{reading: factor}}"
                    f", got {j!r}: {row!r}"
                )
            for k, c in row.items():
                if not (isinstance(k, int) and 1 <= k <= n_joints and k != j):
                    raise RobotDescriptionError(
                        f"{where}: coupling of joint {j}: reading {k!r} must be another "
                        f"joint in 1..{n_joints}"
                    )
                coupling[j - 1, k - 1] = _number(c, f"{where} coupling {j}.{k}")
    elif isinstance(raw, list):
        if len(raw) != n_joints or not all(
            isinstance(r, list) and len(r) == n_joints for r in raw
        ):
            raise RobotDescriptionError(f"{where}: coupling must be {n_joints} x {n_joints}")
        coupling = np.array([[_number(v, f"{where} coupling") for v in r] for r in raw])
        if np.any(np.diag(coupling) != 0.0):
            raise RobotDescriptionError(
                f"{where}: the coupling's diagonal must be 0 (each joint's own factor is sign)"
            )
    elif raw is not None:
        raise RobotDescriptionError(f"{where}: coupling must be {{j: {{k: c}}}} or a matrix")
    matrix = np.diag(sign) + coupling
    if np.linalg.cond(matrix) > 1e8:
        raise RobotDescriptionError(
            f"{where}: the mapping diag(sign) + coupling is singular: readings could not be "
            "recovered from joint variables"
        )
    identity = np.array_equal(matrix, np.eye(n_joints))
    return (None if identity else matrix), (None if not offset.any() else offset)
