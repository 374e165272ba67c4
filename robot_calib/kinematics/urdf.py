"""A URDF as robot description: the joint axes at the zero configuration -> DH/Hayati.

`--robot robot.urdf` (any verb) loads the serial chain from a base link to a tip link:

- the revolute/continuous joints on the way, in order, are the model's joints (names,
  limits from `<limit>`; a continuous joint gets [-pi, pi]); fixed joints fold into the
  next transform; a prismatic, floating, planar or mimic joint on the chain is an error;
- each joint's axis line at the zero configuration (the joint frame's origin and its
  `<axis>`, in the base link frame) -> DH/Hayati links by the same line geometry as CPA
  (`kinematics/axes.py`): a Hayati link (beta used, d dropped) wherever two consecutive
  axes are within `PARALLEL_RAD` of parallel; alpha in [0, pi] and a >= 0 on Hayati links
  (the conversion's sign conventions: the DH table can differ from a manufacturer's by such
  signs and matching theta offsets; the kinematics are the same);
- DH frame 0 is on axis 1: the base link frame itself when its z is axis 1 (the usual
  case), else the frame at the foot of the base origin on axis 1 (`dh02base`);
- the flange (DH frame J) is on the last axis at the foot of the tip origin, x along the
  tip's x (its y if the tip's x is within ~25 deg of the axis): it is the tip link frame
  when that has z along the last axis and its origin on it (ROS-Industrial `tool0`);
  otherwise the rest is `tip2flange` (a target offset is measured from the flange anyway);
- link masses and centres of mass from `<inertial>` (every link a chain joint carries up
  to the next one, fixed branches included; zero where absent), in DH frame j.

Defaults: base = the root link, tip = `tool0`, else `flange`, else the last link of the
chain with the most moving joints. `--base-link`/`--tip-link` choose others; the base link
may be any link rigidly attached to the chain's root side (e.g. ROS-Industrial `base`, the
controller's base frame on UR descriptions). The parser is urdfdom_py's `urdf_parser_py`
(ROS's own URDF parser; pure Python on lxml), imported only when a URDF is loaded.
"""

from __future__ import annotations

import contextlib
import re
import warnings as python_warnings
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from robot_calib.errors import InputError, RobotDescriptionError, param
from robot_calib.kinematics.axes import AxisLine, angle_about, dh_from_axes, link_transform, wrap
from robot_calib.kinematics.description import RobotDescription, parse_robot
from robot_calib.kinematics.frames import Array, homogeneous, rpy_to_matrix
from robot_calib.kinematics.masses import checked_mass_model

URDF_SUFFIX = ".urdf"
PARALLEL_RAD = np.radians(1.0)  # consecutive axes closer to parallel: a Hayati link
MOVING = ("revolute", "continuous")
DEFAULT_TIPS = ("tool0", "flange")
_TIP_X_MAX_COS = 0.9  # tip x within ~25 deg of the last axis: the flange x from tip y


@dataclass(frozen=True)
class UrdfJoint:
    """One URDF joint: type, parent and child link, `origin` (4, 4) child-at-zero in the
    parent frame [m], unit `axis` (3,) in the child frame, `limits` [rad] or None, mimic."""

    name: str
    type: str
    parent: str
    child: str
    origin: Array
    axis: Array
    limits: tuple[float, float] | None
    mimic: bool


@dataclass(frozen=True)
class UrdfModel:
    """What the conversion reads from a URDF: its name, joints, and per link the inertial
    (mass [kg], centre of mass (3,) [m] in the link frame) where one is given."""

    name: str
    joints: tuple[UrdfJoint, ...]
    links: tuple[str, ...]
    inertials: dict[str, tuple[float, Array]]


@dataclass(frozen=True)
class UrdfRobot:
    """A URDF converted: the description, the chosen links, `dh02base` (4, 4) DH frame 0 in
    the base link frame and `tip2flange` (4, 4) the tip link frame in DH frame J (both the
    identity on ROS-Industrial descriptions with a z-up base and `tool0` as the tip)."""

    description: RobotDescription
    base_link: str
    tip_link: str
    dh02base: Array
    tip2flange: Array


def is_urdf_reference(name_or_path: str | Path) -> bool:
    """Whether a `--robot` value names a URDF (PATH.urdf, optionally #base_link=..&..)."""
    return str(name_or_path).split("#", 1)[0].lower().endswith(URDF_SUFFIX)


def urdf_reference(path: str | Path, base_link: str | None, tip_link: str | None) -> str:
    """The robot reference of a URDF with chosen links: PATH.urdf#base_link=B&tip_link=T."""
    if not is_urdf_reference(path):
        raise InputError(
            f"{param('base_link')}/{param('tip_link')} need {param('robot', 'FILE.urdf')}, "
            + (f"not {str(path)!r}" if str(path) else "none given")
        )
    file, _, fragment = str(path).partition("#")
    options = dict(_fragment(fragment, file))
    options.update({k: v for k, v in (("base_link", base_link), ("tip_link", tip_link)) if v})
    return file + ("#" + "&".join(f"{k}={v}" for k, v in options.items()) if options else "")


def _fragment(fragment: str, file: str) -> Iterator[tuple[str, str]]:
    for item in filter(None, fragment.split("&")):
        key, eq, value = item.partition("=")
        if key not in ("base_link", "tip_link") or not eq or not value:
            raise RobotDescriptionError(
                f"{file}: bad link choice {item!r} (use #base_link=LINK&tip_link=LINK)"
            )
        yield key, value


def load_urdf_reference(reference: str | Path) -> RobotDescription:
    """The description of a URDF robot reference (what `load_robot` dispatches here)."""
    file, _, fragment = str(reference).partition("#")
    options = dict(_fragment(fragment, file))
    robot = load_urdf(file, options.get("base_link"), options.get("tip_link"))
    return robot.description


def load_urdf(
    path: str | Path, base_link: str | None = None, tip_link: str | None = None
) -> UrdfRobot:
    """Read a URDF file and convert the chain base_link -> tip_link (defaults above)."""
    model = read_urdf(path)
    robot = urdf_to_description(model, base_link, tip_link, str(path))
    reference = urdf_reference(Path(path).resolve(), robot.base_link, robot.tip_link)
    return replace(robot, description=replace(robot.description, path=reference))


def description_from_text(
    kind: str, text: str, reference: str, where: str, quiet: bool = True
) -> RobotDescription:
    """A robot description from its own text, as a PARAMS.json carries it: `kind`
    'urdf' (the chain of `reference`'s #base_link=..&tip_link=.. choice, else the defaults),
    'yaml' (a robot YAML file's text) or 'csv' (a DH table, kinematics/dh_csv.py); the
    result's path is `reference`, the original file's, so it is written back unchanged.
    Errors name `where`; `quiet`: the loading warnings were said already (not again)."""
    import yaml

    from robot_calib.kinematics.dh_csv import dh_csv_mapping

    if kind not in ("urdf", "yaml", "csv"):
        raise RobotDescriptionError(f"{where}: description format {kind!r}: urdf, yaml or csv")
    with python_warnings.catch_warnings():
        if quiet:
            python_warnings.simplefilter("ignore", UserWarning)
        if kind == "urdf":
            options = dict(_fragment(reference.partition("#")[2], where))
            found = urdf_to_description(
                parse_urdf(text, where), options.get("base_link"), options.get("tip_link"), where
            )
            return replace(found.description, path=reference)
        if kind == "csv":
            data = dh_csv_mapping(text, Path(reference.partition("#")[0]).stem, where)
        else:
            try:
                data = yaml.safe_load(text)
            except yaml.YAMLError as exc:
                first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                raise RobotDescriptionError(f"{where}: not valid YAML ({first})") from None
        return replace(checked_mass_model(parse_robot(data, where), where), path=reference)


@contextlib.contextmanager
def _quiet_parser() -> Iterator[list[str]]:
    """urdf_parser_py prints what it does not know to stderr: collect it instead (yields
    the list). Extras at the top level (ros2_control, gazebo, ...) are not ours to judge;
    an unknown tag or attribute inside a joint or link (a typo such as `<axs>`) is, since
    the parser would silently fall back to a default axis or limit."""
    from urdf_parser_py.xml_reflection import core

    saved = core.on_error
    messages: list[str] = []
    core.on_error = messages.append
    try:
        yield messages
    finally:
        core.on_error = saved


def read_urdf(path: str | Path) -> UrdfModel:
    """Parse a URDF file into a `UrdfModel`; any problem is one RobotDescriptionError line
    naming the file."""
    path = Path(path)
    if not path.is_file():
        raise RobotDescriptionError(f"{path}: no such robot description file")
    try:
        text = path.read_bytes()
    except OSError as exc:
        raise RobotDescriptionError(f"{path}: cannot read ({exc.strerror})") from None
    return parse_urdf(text, str(path))


XACRO_NAMESPACES = ("http://www.ros.org/wiki/xacro", "http://ros.org/wiki/xacro")
"""xacro's namespace and the older one without www (both still in use)."""


def is_xacro_tag(tag: object) -> bool:
    """True for an element of xacro (`{namespace}name` with either xacro namespace, in
    http or https)."""
    if not isinstance(tag, str) or not tag.startswith("{"):
        return False
    namespace = tag[1 : tag.find("}")].replace("https://", "http://").rstrip("/")
    return namespace in XACRO_NAMESPACES


def refuse_xacro(root: Any, source: str, error: type[Exception]) -> None:  # noqa: ANN401
    """`error` naming `source` with a hint to run xacro when the XML tree `root` (lxml or
    ElementTree) holds xacro elements or `${...}` expressions: an unexpanded xacro file
    read as a URDF loses its includes and macros (a gripper, a tool) without a word."""
    for element in root.iter():
        attributes = " ".join(str(v) for v in element.attrib.values())
        if is_xacro_tag(element.tag) or "${" in attributes:
            raise error(
                f"{source}: a xacro file, not a URDF: expand it first "
                f"(xacro {Path(source).name} > robot.urdf)"
            )


def parse_urdf(text: bytes | str, source: str) -> UrdfModel:
    """Parse URDF text (named `source` in errors) into a `UrdfModel`; an unexpanded xacro
    file is refused with the hint to expand it."""
    import xml.etree.ElementTree as ET

    from urdf_parser_py.urdf import URDF

    # blank lines before the XML declaration: urdfdom (TinyXML2) skips them, so the
    # robot_state_publisher and RViz load such a file; lxml would refuse it
    text = text.lstrip()
    bom = b"\xef\xbb\xbf" if isinstance(text, bytes) else "\ufeff"
    if text.startswith(bom):  # type: ignore[arg-type]  # bytes or str, matched
        text = text[len(bom) :].lstrip()
    with contextlib.suppress(ET.ParseError):  # if so, the URDF parser says what is wrong
        refuse_xacro(ET.fromstring(text), source, RobotDescriptionError)

    try:
        with _quiet_parser() as messages:
            urdf = URDF.from_xml_string(text)
    except Exception as exc:  # noqa: BLE001 - the parser raises bare Exception and others
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise RobotDescriptionError(f"{source}: not a valid URDF ({first})") from None
    unused = [m for m in messages if _in_unused_element(m)]
    typos = [m for m in messages if ("/joint[" in m or "/link[" in m) and m not in unused]
    if typos:
        raise RobotDescriptionError(f"{source}: {typos[0]} (a typo? the parser would ignore it)")
    if unused:
        python_warnings.warn(
            f"{source}: {len(unused)} element(s) of links or of their visual or collision "
            "geometry ignored, as ROS's URDF parser ignores them (the calibration reads only "
            "a link's inertial): "
            + "; ".join(_element_words(m) for m in unused[:MAX_LISTED])
            + ("; ..." if len(unused) > MAX_LISTED else ""),
            UserWarning,
            stacklevel=2,
        )
    return _model(urdf, source)


#: what the URDF parser says of a link's own elements (the calibration reads only its
#: `<inertial>`) or of anything inside its `<visual>` or `<collision>` (an unknown or
#: misplaced element: `<material>` inside `<collision>`, pybullet's `<contact>`) changes no
#: kinematics: ignored with one warning, as urdfdom ignores it; inside a joint it is a typo
UNUSED_ELEMENT = re.compile(r"/link\[@name='[^']*'\](/(visual|collision)\[\d+\].*)?$")
MAX_LISTED = 4  # elements named in that warning


def _in_unused_element(message: str) -> bool:
    """True when a parser message is about a link's own element or one inside its visual
    or collision geometry (`UNUSED_ELEMENT`, matched on the element's path)."""
    where = message.rsplit(" in ", 1)[-1]
    return bool(UNUSED_ELEMENT.search(where))


def _element_words(message: str) -> str:
    """'link base, collision: "material"' of the parser's 'Unknown tag "material" in
    /robot[@name='q']/link[@name='base']/collision[1]'."""
    what, _, where = message.rpartition(" in ")
    tag = what.split()[-1] if what else message
    parts = [p for p in where.split("/") if p and not p.startswith("robot[")]
    words = [
        p.split("[@name='")[0] + " " + p.split("[@name='")[1].rstrip("']")
        if "[@name='" in p
        else p.split("[")[0]
        for p in parts
    ]
    return f"{', '.join(words)}: {tag}"


def _pose(origin: Any) -> Array:  # noqa: ANN401 - urdf_parser_py's Pose (untyped)
    if origin is None:
        return np.eye(4)
    xyz = [float(v) for v in (origin.xyz or (0.0, 0.0, 0.0))]
    rpy = [float(v) for v in (origin.rpy or (0.0, 0.0, 0.0))]
    return homogeneous(rpy_to_matrix(*rpy), np.array(xyz))


def _model(urdf: Any, source: str) -> UrdfModel:  # noqa: ANN401 - urdf_parser_py's Robot
    joints = []
    for joint in urdf.joints:
        axis = np.array([float(v) for v in (joint.axis or (1.0, 0.0, 0.0))])
        norm = float(np.linalg.norm(axis))
        if joint.type in MOVING and not norm > 0:
            raise RobotDescriptionError(f"{source}: joint {joint.name}: zero axis")
        limits = None
        if joint.type == "revolute" and joint.limit is not None:
            limits = (float(joint.limit.lower or 0.0), float(joint.limit.upper or 0.0))
        joints.append(
            UrdfJoint(
                str(joint.name),
                str(joint.type),
                str(joint.parent),
                str(joint.child),
                _pose(joint.origin),
                axis / (norm or 1.0),
                limits,
                joint.mimic is not None,
            )
        )
    inertials = {}
    for link in urdf.links:
        inertial = link.inertial
        if inertial is not None and inertial.mass:
            inertials[str(link.name)] = (float(inertial.mass), _pose(inertial.origin)[:3, 3])
    links = tuple(str(link.name) for link in urdf.links)
    return UrdfModel(str(urdf.name or Path(source).stem), tuple(joints), links, inertials)


def zero_frames(model: UrdfModel, source: str) -> tuple[str, dict[str, Array]]:
    """The root link and every link's frame in the root frame at the zero configuration."""
    children = {j.child for j in model.joints}
    roots = [name for name in model.links if name not in children]
    if len(roots) != 1:
        raise RobotDescriptionError(
            f"{source}: a URDF tree needs exactly one root link, found {roots or 'none'}"
        )
    frames = {roots[0]: np.eye(4)}
    below: dict[str, list[UrdfJoint]] = {}
    for joint in model.joints:
        below.setdefault(joint.parent, []).append(joint)
    todo = [roots[0]]
    while todo:
        for joint in below.get(todo.pop(), []):
            frames[joint.child] = frames[joint.parent] @ joint.origin
            todo.append(joint.child)
    return roots[0], frames


def joints_up(model: UrdfModel, link: str) -> list[UrdfJoint]:
    """The joints from `link` up to the root, nearest first."""
    parent = {j.child: j for j in model.joints}
    out = []
    while link in parent:
        out.append(parent[link])
        link = parent[link].parent
    return out


def default_tip(model: UrdfModel) -> str:
    for name in DEFAULT_TIPS:
        if name in model.links:
            return name
    parents = {j.parent for j in model.joints}
    leaves = [name for name in model.links if name not in parents]
    return max(leaves, key=lambda n: sum(j.type in MOVING for j in joints_up(model, n)))


def urdf_to_description(
    model: UrdfModel, base_link: str | None, tip_link: str | None, source: str
) -> UrdfRobot:
    """Convert the chain base_link -> tip_link of a parsed URDF (module docstring)."""
    root, zero = zero_frames(model, source)
    base = base_link or root
    tip = tip_link or default_tip(model)
    for role, name in (("base", base), ("tip", tip)):
        if name not in zero:
            raise RobotDescriptionError(f"{source}: no {role} link {name!r} in the URDF")
    up_tip, up_base = joints_up(model, tip), joints_up(model, base)
    common = {j.name for j in up_tip} & {j.name for j in up_base}
    moving_above_base = [j.name for j in up_base if j.name not in common and j.type != "fixed"]
    if moving_above_base:
        raise RobotDescriptionError(
            f"{source}: base link {base!r} is not fixed to the chain to {tip!r} "
            f"(joint {moving_above_base[0]} moves between them)"
        )
    chain = [j for j in reversed(up_tip) if j.name not in common]
    for joint in chain:
        if joint.type not in (*MOVING, "fixed") or joint.mimic:
            kind = "mimic" if joint.mimic else joint.type
            raise RobotDescriptionError(
                f"{source}: joint {joint.name} is {kind}; only revolute, continuous and "
                "fixed joints can be on the chain"
            )
    moving = [j for j in chain if j.type in MOVING]
    if len(moving) < 2:
        raise RobotDescriptionError(
            f"{source}: the chain {base!r} -> {tip!r} has {len(moving)} moving joint(s); "
            f"it needs >= 2 (choose {param('base_link')}/{param('tip_link')})"
        )
    root2base_inv = np.linalg.inv(zero[base])
    in_base = {name: root2base_inv @ frame for name, frame in zero.items()}

    axes = [AxisLine(in_base[j.child][:3, 3], in_base[j.child][:3, :3] @ j.axis) for j in moving]
    n = len(axes)
    hayati = np.zeros(n, dtype=bool)
    for j in range(n - 1):
        u, v = axes[j].direction, axes[j + 1].direction
        if np.linalg.norm(np.cross(u, v)) < np.sin(PARALLEL_RAD):
            offset = axes[j + 1].point - axes[j].point
            if np.linalg.norm(offset - (offset @ u) * u) < 1e-9:
                raise RobotDescriptionError(
                    f"{source}: the axes of {moving[j].name} and {moving[j + 1].name} coincide"
                )
            hayati[j] = True

    dh02base = _frame_on_axis(axes[0], np.eye(4))
    links = dh_from_axes(axes, dh02base, hayati, np.full(n, np.pi / 2), np.ones(n))
    last = links.frames[-1]
    tip_frame = in_base[tip]
    flange_x = _flange_x(last[:3, 2], tip_frame)
    d_last = float((tip_frame[:3, 3] - last[:3, 3]) @ last[:3, 2])
    theta_last = angle_about(last[:3, 2], last[:3, 0], flange_x)
    flange = last @ link_transform(theta_last, d_last, 0.0, 0.0, 0.0)
    frames = np.concatenate([links.frames[1:], flange[None]])  # DH frames 1..J in base

    mass, com = _mass_model(model, moving, frames, in_base)
    limits = [
        j.limits if j.limits is not None else (-np.pi, np.pi) for j in moving
    ]  # continuous (or unlimited) joints: one turn
    for joint, (lo, hi) in zip(moving, limits):
        if not lo < hi:
            raise RobotDescriptionError(
                f"{source}: joint {joint.name}: limit lower {lo} must be below upper {hi}"
            )
    description = RobotDescription(
        name=model.name,
        joint_names=tuple(j.name for j in moving),
        theta=np.array([wrap(t) for t in (*links.theta, theta_last)]),
        d=np.append(links.d, d_last),
        a=np.append(links.a, 0.0),
        alpha=np.append(links.alpha, 0.0),
        beta=np.append(links.beta, 0.0),
        hayati=hayati,
        limits=np.array(limits, dtype=float),
        link_mass=mass,
        link_com=com,
        source=f"URDF {Path(source).name}, chain {base} -> {tip}",
    )
    description = checked_mass_model(description, source)
    return UrdfRobot(description, base, tip, dh02base, np.linalg.inv(flange) @ tip_frame)


def _frame_on_axis(axis: AxisLine, hint: Array) -> Array:
    """A frame with z along `axis`, origin at the foot of hint's origin on it, x along
    hint's x made perpendicular to the axis (its y if x is too close to the axis)."""
    z = axis.direction
    origin = axis.point + ((hint[:3, 3] - axis.point) @ z) * z
    x = _flange_x(z, hint)
    return homogeneous(np.column_stack([x, np.cross(z, x), z]), origin)


def _flange_x(z: Array, frame: Array) -> Array:
    """frame's x (or y, if x lies within ~25 deg of z) made perpendicular to unit z."""
    v = frame[:3, 0] if abs(frame[:3, 0] @ z) < _TIP_X_MAX_COS else frame[:3, 1]
    v = v - (v @ z) * z
    return v / np.linalg.norm(v)


def _mass_model(
    model: UrdfModel,
    moving: list[UrdfJoint],
    frames: Array,
    in_base: dict[str, Array],
) -> tuple[Array, Array]:
    """link_mass (J,) [kg] and link_com (J, 3) [m] in DH frame j: every link with an
    inertial belongs to the nearest chain joint above it (none: fixed to the base)."""
    index = {j.name: k for k, j in enumerate(moving)}
    n = len(moving)
    mass, moment = np.zeros(n), np.zeros((n, 3))
    for link, (m, com_in_link) in model.inertials.items():
        owner = next((index[j.name] for j in joints_up(model, link) if j.name in index), None)
        if owner is None:
            continue  # on the base side of joint 1
        mass[owner] += m
        moment[owner] += m * (in_base[link][:3, :3] @ com_in_link + in_base[link][:3, 3])
    com = np.zeros((n, 3))
    for j in np.flatnonzero(mass > 0):
        centre = moment[j] / mass[j]
        com[j] = frames[j][:3, :3].T @ (centre - frames[j][:3, 3])
    return mass, com
