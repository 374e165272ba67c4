"""Robot descriptions as data: the nominal DH/Hayati table, limits and an approximate mass model.

Built-ins live in `robots/*.yaml`; a user passes a YAML file of the same format. Lengths
are in m; angles in rad unless the file says ``angle_unit: deg`` (converted on load).
See `robots/kr5_sixx_r650.yaml` for a commented example. Keys outside `ROBOT_KEYS` (top
level) and `JOINT_KEYS` (each joint) are rejected, so a misspelt key is not silently ignored.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robot_calib.errors import RobotDescriptionError, check_keys
from robot_calib.kinematics.frames import Array

ROBOTS_DIR = Path(__file__).resolve().parent / "robots"
DH_FIELDS = ("theta", "d", "a", "alpha")
ROBOT_KEYS = ("name", "source", "angle_unit", "joints")  # top level of a robot YAML file
JOINT_KEYS = ("name", *DH_FIELDS, "beta", "hayati", "limits", "mass", "com")  # each joint


@dataclass(frozen=True)
class RobotDescription:
    """Nominal kinematics of a serial robot with revolute joints.

    theta, d, a, alpha, beta : shape (J,), nominal DH table [rad, m, m, rad, rad]
    hayati : shape (J,) bool — beta_j used and d_j dropped (axes j, j+1 nominally parallel)
    limits : shape (J, 2), [min, max] joint readings [rad]
    link_mass : shape (J,) [kg], mass of the link moved by joint j (approximate)
    link_com : shape (J, 3) [m], its centre of mass in DH frame j (approximate)
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

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    def reference(self) -> str:
        """What `load_robot` needs to load it again: the built-in name, else the absolute
        path of its YAML file (what PARAMS.json and world files store)."""
        builtin = (ROBOTS_DIR / f"{self.name}.yaml").resolve()
        if not self.path or Path(self.path) == builtin:
            return self.name
        return self.path


def available_robots() -> list[str]:
    """Names of the built-in descriptions."""
    return sorted(p.stem for p in ROBOTS_DIR.glob("*.yaml"))


def load_robot(name_or_path: str | Path) -> RobotDescription:
    """A built-in robot by name, a robot YAML file by path, or a URDF (kinematics/urdf.py)."""
    from robot_calib.kinematics import urdf  # imports this module: loaded on use

    if urdf.is_urdf_reference(name_or_path):
        return urdf.load_urdf_reference(name_or_path)
    path = Path(name_or_path)
    if not path.suffix:
        path = ROBOTS_DIR / f"{name_or_path}.yaml"
        if not path.is_file():
            raise RobotDescriptionError(
                f"unknown robot {str(name_or_path)!r} (built-in: {', '.join(available_robots())}"
                "; or give a YAML file)"
            )
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
        # Default: beta wherever axes j and j+1 are nominally parallel (alpha_j = 0 or pi).
        parallel = j < len(joints) and abs(np.sin(table["alpha"][-1])) < 1e-9
        hayati.append(bool(entry.get("hayati", parallel)))

    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise RobotDescriptionError(
            f"{source}: joint names must be distinct; {repeated} given more than once"
        )
    return RobotDescription(
        name=str(data.get("name", Path(source).stem)),
        joint_names=tuple(names),
        theta=np.array(table["theta"]),
        d=np.array(table["d"]),
        a=np.array(table["a"]),
        alpha=np.array(table["alpha"]),
        beta=np.array(table["beta"]),
        hayati=np.array(hayati, dtype=bool),
        limits=np.array(limits),
        link_mass=np.array(mass),
        link_com=np.array(com),
        source=str(data.get("source", source)),
    )
