"""A calibrated URDF written into the user's own nominal URDF (`export --nominal-urdf`).

The user's file keeps everything the calibration does not know: link names, meshes,
inertials, limits, `<ros2_control>` and `<gazebo>` tags, comments. What changes:

- the `<origin>` of each of the robot's J moving joints, and of every joint hanging from
  the last moving joint's child link (`flange`, `tool0`, a gripper's mount): the flange
  moves with the calibrated last link;
- links are added for the calibrated target frames (``tcp``, ``tcp_NAME``) under the last
  moving joint's child and ``laser_tracker`` under the root (``calibrated_`` in front
  where the file already has a link of that name);
- a comment at the top names the source, the nominal-vs-model agreement and the effects no
  URDF holds.

How (frames at the zero configuration, all 4 x 4):
- the file's chain: its J moving joints are the robot's joint names in order where they
  all appear, else the moving joints from the root to the default tip (`tool0`,
  `flange`, ...); J_j is joint j's frame (parent link * origin) in the root frame, a_j its
  axis in that frame;
- the model's: E_j, the DH frame joint j turns about (DH frame j-1; its z is the axis,
  times the reading's sign s_j), E_{J+1} the flange;
- the file's root frame and the model's base frame differ by B (root <- base), fitted to
  the J axis lines (rotation: scipy's `Rotation.align_vectors`; translation: least
  squares of the lines' distances); the nominal file must then agree with the robot's
  nominal model at random poses (`NOMINAL_TOLERANCE_*`), else it is another robot (or
  other zero positions) and the export is refused;
- each joint frame is attached rigidly to its DH frame: C_j = (B E_j)^-1 J_j, made exact
  (C_j's rotation takes a_j onto s_j z, its translation lies on z: the file's joint turns
  exactly as the DH joint); the calibrated J'_j = B E'_j C_j, so the file's joint j turns
  about the calibrated axis j with the same reading.

The written file is parsed again and its forward kinematics checked against the
calibrated geometry at random poses before anything is written (`_verify`).
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robot_calib.errors import RobotDescriptionError
from robot_calib.export.base import (
    ExportError,
    correction_lines,
    effect_lines,
    joint_signs,
    number,
    rpy,
)
from robot_calib.export.urdf import TRACKER, comment_text, target_link
from robot_calib.kinematics.dh import chain
from robot_calib.kinematics.frames import Array, homogeneous
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.kinematics.urdf import (
    MOVING,
    UrdfJoint,
    UrdfModel,
    default_tip,
    joints_up,
    parse_urdf,
    refuse_xacro,
    zero_frames,
)
from robot_calib.model import KinematicModel, target_parameters

if TYPE_CHECKING:
    from robot_calib.identify.calibration import Calibration

NOMINAL_TOLERANCE_M = 1e-3  # the nominal file's axes farther from the model's: refused
NOMINAL_TOLERANCE_RAD = 1e-3
VERIFY_TOLERANCE_M = 1e-9  # the written file vs the calibrated geometry (a self-check)
CHECK_POSES = 20  # random poses of both checks (seeded: the same file, the same result)


@dataclass(frozen=True)
class FileChain:
    """The robot's chain in a URDF: `path` the joints from the root to the last moving
    joint in order (fixed ones included), `moving` its J moving joints, `zero` every
    link's frame (4, 4) in the root frame at the zero configuration."""

    root: str
    path: tuple[UrdfJoint, ...]
    moving: tuple[UrdfJoint, ...]
    zero: dict[str, Array]


def file_chain(urdf: UrdfModel, names: tuple[str, ...], source: str) -> FileChain:
    """The chain of the robot whose joints are `names` in `urdf` (module docstring)."""
    root, zero = zero_frames(urdf, source)
    by_name = {j.name: j for j in urdf.joints}
    if all(n in by_name and by_name[n].type in MOVING for n in names):
        tip = by_name[names[-1]].child
    else:
        tip = default_tip(urdf)
    path = list(reversed(joints_up(urdf, tip)))
    moving = [j for j in path if j.type in MOVING]
    if [j.name for j in moving] != list(names) and len(moving) != len(names):
        raise ExportError(
            f"{source}: the chain {root} -> {tip} has {len(moving)} moving joints "
            f"({', '.join(j.name for j in moving)}); the calibrated robot has {len(names)} "
            f"({', '.join(names)})"
        )
    bad = [j for j in path if j.mimic or j.type not in (*MOVING, "fixed")]
    if bad:
        raise ExportError(
            f"{source}: joint {bad[0].name} on the robot's chain is "
            f"{'mimic' if bad[0].mimic else bad[0].type}"
        )
    last = path.index(moving[-1])
    return FileChain(root, tuple(path[: last + 1]), tuple(moving), zero)


def chain_frames(chain: FileChain, q: Array) -> Array:
    """Each moving joint's frame (before its turn) in the root frame at readings q (n, J):
    shape (n, J, 4, 4), the file's origins and axes as parsed."""
    from scipy.spatial.transform import Rotation

    n = len(q)
    frame = np.tile(np.eye(4), (n, 1, 1))
    out = np.empty((n, len(chain.moving), 4, 4))
    k = 0
    for joint in chain.path:
        frame = frame @ joint.origin
        if joint.type in MOVING:
            out[:, k] = frame
            turn = np.tile(np.eye(4), (n, 1, 1))
            turn[:, :3, :3] = Rotation.from_rotvec(q[:, k, None] * joint.axis).as_matrix()
            frame = frame @ turn
            k += 1
    return out


def _lines(frames: Array, axes: Array) -> tuple[Array, Array]:
    """Axis lines: points (..., 3) and unit directions (..., 3) of frames (..., 4, 4) with
    axes (..., 3) in their own frame."""
    return frames[..., :3, 3], np.einsum("...ab,...b->...a", frames[..., :3, :3], axes)


def fit_base(points: Array, directions: Array, dh_points: Array, dh_dirs: Array) -> Array:
    """B (4, 4), the root frame <- the model's base frame, that puts the model's axis lines
    (J, 3) each onto the file's: rotation by the directions, translation by least squares
    of the points' distances from the file's lines."""
    import warnings

    from scipy.spatial.transform import Rotation

    with warnings.catch_warnings():  # degenerate directions: the tolerance check reports it
        warnings.simplefilter("ignore", UserWarning)
        rotation = Rotation.align_vectors(directions, dh_dirs)[0].as_matrix()
    projectors = np.eye(3) - np.einsum("ja,jb->jab", directions, directions)  # (J, 3, 3)
    lhs = projectors.reshape(-1, 3)
    rhs = np.einsum("jab,jb->ja", projectors, points - dh_points @ rotation.T).reshape(-1)
    translation = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return homogeneous(rotation, translation)


def _mismatch(file_frames: Array, axes: Array, dh_frames: Array, signs: Array) -> Array:
    """(2,): the largest distance [m] and angle [rad] between the file's axis lines and
    the model's (already in the root frame), over every pose and joint."""
    points, dirs = _lines(file_frames, np.broadcast_to(axes, file_frames.shape[:-2] + (3,)))
    dh_points, dh_dirs = dh_frames[..., :3, 3], dh_frames[..., :3, 2] * signs[:, None]
    offset = dh_points - points
    off_line = offset - np.einsum("...a,...a->...", offset, dirs)[..., None] * dirs
    cos = np.clip(np.einsum("...a,...a->...", dirs, dh_dirs), -1.0, 1.0)
    return np.array([np.linalg.norm(off_line, axis=-1).max(), np.arccos(cos).max()])


def _attach(joint_frame: Array, dh_frame: Array, axis: Array, sign: float) -> Array:
    """C (4, 4) = dh_frame^-1 joint_frame made exact: its rotation takes `axis` onto
    sign * z and its translation has no x, y (module docstring)."""
    from scipy.spatial.transform import Rotation

    c = np.linalg.inv(dh_frame) @ joint_frame
    turned = c[:3, :3] @ axis
    fix = Rotation.align_vectors([[0.0, 0.0, sign]], [turned])[0].as_matrix()
    return homogeneous(fix @ c[:3, :3], np.array([0.0, 0.0, c[2, 3]]))


def _at(model: KinematicModel, params: ParameterVector, q: Array) -> Array:
    """E_1..E_{J+1} (n, J + 1, 4, 4) of the model's geometry (no effects) at readings q
    (n, J): DH frames 0..J in the base frame, E_j = DH frame j-1, E_{J+1} the flange."""
    return chain(model.dh_table(params, q))


@dataclass(frozen=True)
class NominalFit:
    """How the file sits on the model: B (4, 4) root <- base, C (J, 4, 4) each joint frame
    in its DH frame, the nominal flange (4, 4) at the zero pose in the base frame, and the
    largest nominal disagreement: metres and radians."""

    base: Array
    attach: Array
    nominal_flange: Array
    distance_m: float
    angle_rad: float


def fit_nominal(cal: Calibration, chain: FileChain, source: str) -> NominalFit:
    """Fit B and the C_j of the nominal file to the robot's nominal model; ExportError when
    they disagree by more than the tolerances at random poses."""
    model = KinematicModel(cal.model.robot, (), cal.model.targets, cal.model.oriented)
    nominal = model.parameters()
    from robot_calib.kinematics.description import random_readings

    signs = joint_signs(cal, "a URDF")
    zero_q = np.zeros((1, len(chain.moving)))
    q = np.vstack([zero_q, random_readings(model.robot, CHECK_POSES, np.random.default_rng(0))])
    frames = _at(model, nominal, q)  # the zero pose first
    dh = frames[0]
    file_frames = chain_frames(chain, q)
    file0 = file_frames[0]
    axes = np.array([j.axis for j in chain.moving])
    points, dirs = _lines(file0, axes)
    base = fit_base(points, dirs, dh[:-1, :3, 3], dh[:-1, :3, 2] * signs[:, None])
    distance, angle = _mismatch(file_frames, axes, base @ frames[:, :-1], signs)
    if distance > NOMINAL_TOLERANCE_M or angle > NOMINAL_TOLERANCE_RAD:
        raise ExportError(
            f"{source}: not robot {model.robot.name}'s nominal kinematics: its joint axes are "
            f"up to {distance * 1e3:.3f} mm / {np.degrees(angle):.4f} deg off the model's at "
            f"random poses (tolerance {NOMINAL_TOLERANCE_M * 1e3:g} mm / "
            f"{np.degrees(NOMINAL_TOLERANCE_RAD):.3f} deg): another robot, other zero "
            "positions, or joint directions?"
        )
    attach = np.stack(
        [_attach(file0[j], base @ dh[j], axes[j], signs[j]) for j in range(len(axes))]
    )
    return NominalFit(base, attach, dh[-1], float(distance), float(angle))


def _xml(text: bytes, source: str):  # type: ignore[no-untyped-def] # lxml's element
    from lxml import etree

    try:
        tree = etree.parse(io.BytesIO(text), etree.XMLParser(remove_blank_text=False))
    except etree.XMLSyntaxError as exc:
        raise RobotDescriptionError(f"{source}: not valid XML ({exc})") from None
    refuse_xacro(tree.getroot(), source, ExportError)  # either xacro namespace
    return tree


def _set_origin(element, transform: Array) -> None:  # type: ignore[no-untyped-def]
    from lxml import etree

    origin = element.find("origin")
    if origin is None:
        origin = etree.Element("origin")
        element.insert(0, origin)
    origin.set("xyz", " ".join(number(v) for v in transform[:3, 3]))
    origin.set("rpy", " ".join(number(v) for v in rpy(transform[:3, :3])))


def render_on_nominal(cal: Calibration, source: str, nominal_path: str | Path) -> str:
    """The calibrated URDF written into the nominal URDF at `nominal_path` (module
    docstring); ExportError / RobotDescriptionError (one line) for a file that cannot
    take it."""
    from lxml import etree

    nominal_path = Path(nominal_path)
    name = str(nominal_path)
    if not nominal_path.is_file():
        raise RobotDescriptionError(f"{name}: no such nominal URDF")
    text = nominal_path.read_bytes()
    tree = _xml(text, name)
    urdf = parse_urdf(text, name)
    model, params = cal.model, cal.parameters
    robot = model.robot
    chain = file_chain(urdf, robot.joint_names, name)
    fit = fit_nominal(cal, chain, name)
    zero = np.zeros((1, model.robot.n_joints))
    dh = _at(model, params, zero)[0]  # calibrated E'_1..E'_{J+1}
    n = len(chain.moving)
    new_joint = np.stack([fit.base @ dh[j] @ fit.attach[j] for j in range(n)])  # J'_j
    old_joint = np.stack([chain.zero[j.child] for j in chain.moving])  # J_j
    origins: dict[str, Array] = {}
    for j, joint in enumerate(chain.moving):
        parent = chain.zero[joint.parent]
        if j > 0:  # the fixed joints between keep their transforms
            parent = new_joint[j - 1] @ np.linalg.inv(old_joint[j - 1]) @ parent
        origins[joint.name] = np.linalg.inv(parent) @ new_joint[j]
    last_link = chain.moving[-1].child
    flange = fit.base @ dh[n]
    move = (
        np.linalg.inv(new_joint[-1])
        @ flange
        @ np.linalg.inv(fit.base @ fit.nominal_flange)
        @ old_joint[-1]
    )
    for joint in urdf.joints:
        if joint.parent == last_link:
            origins[joint.name] = move @ joint.origin
    root_element = tree.getroot()
    for element in root_element.findall("joint"):
        if element.get("name") in origins:
            _set_origin(element, origins[element.get("name")])
    links = set(urdf.links)

    def fresh(link: str) -> str:
        return link if link not in links else f"calibrated_{link}"

    added: list[tuple[str, str, Array]] = []
    rotations = model.tool_rotations(params)
    for k, target in enumerate(model.targets):
        offset = np.array([params[p] for p in target_parameters(target)])
        tool = np.linalg.inv(new_joint[-1]) @ flange @ homogeneous(rotations[k], offset)
        added.append((last_link, fresh(target_link(target)), tool))
    base2tracker = model.base2tracker(params)
    added.append((chain.root, fresh(TRACKER), fit.base @ np.linalg.inv(base2tracker)))
    if len(root_element):
        root_element[-1].tail = "\n  "
    for holder, link, transform in added:
        etree.SubElement(root_element, "link", name=link).tail = "\n  "
        joint = etree.SubElement(root_element, "joint", name=f"{holder}-{link}", type="fixed")
        etree.SubElement(joint, "parent", link=holder)
        etree.SubElement(joint, "child", link=link)
        _set_origin(joint, transform)
        etree.indent(joint, space="  ", level=1)
        joint.tail = "\n  "
    root_element[-1].tail = "\n"
    header = [
        f"Calibrated by robot-calib export from {source} (model {cal.name}), written into",
        f"the nominal URDF {nominal_path.name}. The calibrated geometry is in the origins of",
        f"joints {', '.join(j.name for j in chain.moving)}",
        f"and of the joints under {last_link}; links added: "
        f"{', '.join(a[1] for a in added)} (the calibrated targets and the laser tracker).",
        f"The nominal file agreed with robot {robot.name}'s nominal model to "
        f"{fit.distance_m * 1e3:.4f} mm / {np.degrees(fit.angle_rad):.5f} deg (axis lines).",
    ]
    effects = effect_lines(cal)
    if effects:
        header.append("Effects identified that no URDF can hold (compensate them separately):")
        header += [f"  {line}" for line in effects]
    elif cal.correction is None:
        header.append("The model has no effects beyond the geometry: the URDF holds it whole.")
    header += correction_lines(cal)
    comment = etree.Comment("\n" + "".join(f"  {comment_text(h)}\n" for h in header))
    comment.tail = root_element.text  # first inside <robot>, the file's indentation kept
    root_element.text = "\n  "
    root_element.insert(0, comment)
    out = etree.tostring(tree, xml_declaration=True, encoding="utf-8")
    out = out.replace(b"--><robot", b"-->\n<robot", 1)  # lxml drops the prolog's line breaks
    _verify(cal, out, fit, name)
    return out.decode() + "\n"


def _verify(cal: Calibration, text: bytes, fit: NominalFit, source: str) -> None:
    """The written file's joint frames at random poses vs B E'_j(q) C_j: ExportError (a
    bug, never a silent wrong file) when they differ by more than VERIFY_TOLERANCE_M."""
    from robot_calib.kinematics.description import random_readings

    model = cal.model
    chain = file_chain(parse_urdf(text, source), model.robot.joint_names, source)
    q = random_readings(model.robot, CHECK_POSES, np.random.default_rng(1))
    expected = fit.base @ _at(model, cal.parameters, q)[:, :-1] @ fit.attach
    error = np.abs(chain_frames(chain, q) - expected).max()
    if not error < VERIFY_TOLERANCE_M:
        raise ExportError(
            f"{source}: the written URDF's joints are {error:.3g} m off the calibrated "
            "geometry (a bug: please report it with this file)"
        )
