"""URDF robot descriptions (kinematics/urdf.py): the conversion to DH/Hayati against an
independent URDF forward kinematics and against the built-in YAML descriptions.

Fixtures: test/data/*.urdf, written by hand in ur_description's and kuka_experimental's
layouts (each file says where its numbers come from). The URDF forward kinematics here
reads the XML itself (xml.etree) and multiplies joint origins and axis rotations, so it
shares nothing with the loader but the file.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli

from robot_calib.errors import RobotDescriptionError
from robot_calib.kinematics.description import RobotDescription
from robot_calib.kinematics.dh import DHTable, chain
from robot_calib.kinematics.loader import load_robot
from robot_calib.kinematics.urdf import load_urdf

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "test" / "data"
# Points rigidly attached to the tip link, in its frame [m]: its origin and two off it.
TIP_POINTS = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]])
# The UR YAML's base is the controller's base frame: ur_description's `base` link.
BASE_LINK = {"kr5_sixx_r650": "base_link", "ur5": "base", "ur10": "base"}
N_POSES = 50
UM = 1e-6


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _origin(element: ET.Element | None) -> np.ndarray:
    out = np.eye(4)
    if element is None:
        return out
    roll, pitch, yaw = (float(v) for v in element.get("rpy", "0 0 0").split())
    out[:3, :3] = (
        _rot(np.array([0.0, 0, 1]), yaw)
        @ _rot(np.array([0.0, 1, 0]), pitch)
        @ _rot(np.array([1.0, 0, 0]), roll)
    )
    out[:3, 3] = [float(v) for v in element.get("xyz", "0 0 0").split()]
    return out


def urdf_tip2base(path: Path, base: str, tip: str, q: dict[str, float]) -> np.ndarray:
    """Tip link frame in the base link frame, shape (4, 4), for joint values q [rad]: the
    product of joint origins and rotations about their axes, up to the root and down."""
    joints = {j.find("child").get("link"): j for j in ET.parse(path).getroot().iter("joint")}  # type: ignore[union-attr]

    def link2root(link: str) -> np.ndarray:
        out = np.eye(4)
        while link in joints:
            joint = joints[link]
            motion = np.eye(4)
            if joint.get("type") != "fixed":
                axis = np.array([float(v) for v in joint.find("axis").get("xyz").split()])  # type: ignore[union-attr]
                motion[:3, :3] = _rot(axis / np.linalg.norm(axis), q[joint.get("name")])  # type: ignore[index]
            out = _origin(joint.find("origin")) @ motion @ out
            link = joint.find("parent").get("link")  # type: ignore[union-attr,assignment]
        return out

    return np.linalg.inv(link2root(base)) @ link2root(tip)


def model_flange2base(robot: RobotDescription, q: np.ndarray) -> np.ndarray:
    """Our model's flange (DH frame J) in its base frame, (n, 4, 4), for readings q (n, J)
    (through the robot's reading_to_joint mapping, if it declares one)."""
    return model_frames(robot, q)[:, -1]


def model_frames(robot: RobotDescription, q: np.ndarray) -> np.ndarray:
    """DH frames 0..J of our model in its base frame, (n, J + 1, 4, 4), for readings q."""
    dh = DHTable(robot.theta + robot.joint_variables(q), robot.d, robot.a, robot.alpha, robot.beta)
    return chain(dh)


def points(frames: np.ndarray) -> np.ndarray:
    """TIP_POINTS carried by frames (n, 4, 4) -> (n, 4, 3)."""
    return np.einsum("nij,kj->nki", frames[:, :3, :3], TIP_POINTS) + frames[:, None, :3, 3]


def random_readings(robot: RobotDescription, seed: int) -> np.ndarray:
    lo, hi = np.maximum(robot.limits[:, 0], -np.pi), np.minimum(robot.limits[:, 1], np.pi)
    return np.random.default_rng(seed).uniform(lo, hi, size=(N_POSES, robot.n_joints))


@pytest.mark.parametrize("name", ["kr5_sixx_r650", "ur5", "ur10"])
def test_urdf_model_matches_urdf_and_yaml_forward_kinematics(name: str) -> None:
    path = DATA / f"{name}.urdf"
    urdf = load_urdf(path, BASE_LINK[name], "tool0")
    robot = urdf.description
    yaml_robot = load_robot(name)
    assert robot.n_joints == 6 and robot.hayati.tolist() == yaml_robot.hayati.tolist()
    q = random_readings(robot, seed=len(name))

    # (i) our model built from the URDF-derived table vs the URDF's own kinematics
    direct = np.array(
        [
            urdf_tip2base(path, BASE_LINK[name], "tool0", dict(zip(robot.joint_names, qi)))
            for qi in q
        ]
    )
    ours = urdf.dh02base @ model_flange2base(robot, q) @ urdf.tip2flange
    gap_urdf = np.linalg.norm(points(ours) - points(direct), axis=-1).max()
    # (ii) the URDF-derived table vs the built-in YAML table: the same flange
    gap_yaml = np.linalg.norm(
        points(model_flange2base(robot, q)) - points(model_flange2base(yaml_robot, q)), axis=-1
    ).max()
    print(
        f"{name}: max |URDF FK - model| {gap_urdf / UM:.2e} um, "
        f"|URDF table - YAML table| {gap_yaml / UM:.2e} um"
    )
    assert gap_urdf < UM and gap_yaml < UM
    # tool0 is DH frame 6 and the base (z up, on axis 1) DH frame 0: no leftovers
    np.testing.assert_allclose(urdf.tip2flange, np.eye(4), atol=1e-9)
    np.testing.assert_allclose(urdf.dh02base, np.eye(4), atol=1e-9)


# Built-ins from manufacturers' URDFs: test/data/NAME.urdf is the source the YAML names,
# transcribed (joint origins, axes, limits; `base` = the manufacturer's base frame, `tool0` =
# the flange frame).
MANUFACTURER_URDFS = [
    "kr6_r900_sixx",
    "kr16_2",
    "kr210_r2700_extra",
    "irb120_3_58",
    "irb2600_12_165",
    "irb6700_200_260",
    "r2000ic_165f",
    "m20ia",
    "gp7",
    "gp8",
    "gp25",
]
# FANUC: the URDF's joint_3 (upper arm to forearm) is J2 + J3 of the controller's readings
# (ROS-Industrial's fanuc_driver, J23_factor 1); the YAML declares that coupling.
FANUC_J23 = {"r2000ic_165f", "m20ia"}


def urdf_joint_values(name: str, q: np.ndarray) -> np.ndarray:
    """The URDF's joint values (n, J) of the robot's readings q (n, J) [rad]."""
    out = q.copy()
    if name in FANUC_J23:
        out[:, 2] = q[:, 2] + q[:, 1]
    return out


@pytest.mark.parametrize("name", MANUFACTURER_URDFS)
def test_built_in_robot_is_the_manufacturers_urdf(name: str) -> None:
    """The built-in YAML's flange (DH frame 6) at readings q is the URDF's tool0 in its `base`
    at the URDF's joint values of q, to < 1 um (joint zeros, turning directions and the
    FANUC J2-J3 coupling included); the same names and limits; and the URDF converted by
    kinematics/urdf.py gives the same flange."""
    path = DATA / f"{name}.urdf"
    robot = load_robot(name)
    urdf = load_urdf(path, "base", "tool0")
    assert urdf.description.joint_names == robot.joint_names
    assert urdf.description.hayati.tolist() == robot.hayati.tolist()
    # the YAML writes the URDF's rad limits (3-6 decimals) in degrees: equal to 0.06 deg
    np.testing.assert_allclose(robot.limits, urdf.description.limits, atol=1e-3)
    q = random_readings(robot, seed=len(name))
    q_urdf = urdf_joint_values(name, q)
    direct = np.array(
        [urdf_tip2base(path, "base", "tool0", dict(zip(robot.joint_names, qi))) for qi in q_urdf]
    )
    gap_yaml = np.linalg.norm(points(model_flange2base(robot, q)) - points(direct), axis=-1)
    converted = urdf.dh02base @ model_flange2base(urdf.description, q_urdf) @ urdf.tip2flange
    gap_urdf = np.linalg.norm(points(converted) - points(direct), axis=-1)
    print(
        f"{name}: max |URDF FK - YAML model| {gap_yaml.max() / UM:.2e} um, "
        f"|URDF FK - URDF model| {gap_urdf.max() / UM:.2e} um"
    )
    assert gap_yaml.max() < UM and gap_urdf.max() < UM


def test_irb120_mass_model_is_the_urdfs_inertials() -> None:
    """irb120_3_58's masses are the URDF's link masses and its centres of mass (in DH frames
    j) sit where the URDF's are, in any pose (< 1 um)."""
    robot = load_robot("irb120_3_58")
    urdf = load_urdf(DATA / "irb120_3_58.urdf", "base", "tool0")
    np.testing.assert_allclose(robot.link_mass, urdf.description.link_mass, rtol=1e-12)
    q = random_readings(robot, seed=7)[:10]
    ours, theirs = model_frames(robot, q), urdf.dh02base @ model_frames(urdf.description, q)
    for j in range(robot.n_joints):
        mine = ours[:, j + 1, :3, :3] @ robot.link_com[j] + ours[:, j + 1, :3, 3]
        other = theirs[:, j + 1, :3, :3] @ urdf.description.link_com[j] + theirs[:, j + 1, :3, 3]
        assert np.linalg.norm(mine - other, axis=-1).max() < UM, j + 1


def test_kr5_table_is_the_seed_table_and_ur_differs_only_by_sign_conventions() -> None:
    kr5, yaml_kr5 = load_urdf(DATA / "kr5_sixx_r650.urdf").description, load_robot("kr5_sixx_r650")
    for field in ("d", "a", "alpha", "beta"):
        np.testing.assert_allclose(getattr(kr5, field), getattr(yaml_kr5, field), atol=1e-12)
    wrapped = (kr5.theta - yaml_kr5.theta + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(wrapped, 0, atol=1e-12)
    ur5 = load_urdf(DATA / "ur5.urdf", "base").description
    np.testing.assert_allclose(np.abs(ur5.a), np.abs(load_robot("ur5").a), atol=1e-9)
    assert ur5.joint_names[0] == "shoulder_pan_joint"
    np.testing.assert_allclose(np.degrees(ur5.limits[2]), [-180, 180])


def test_other_tip_and_default_base_keep_the_kinematics() -> None:
    """tip = `flange` (x along the last axis): the rest is in tip2flange; base = the root
    `base_link` (turned by pi from UR's base): the same points in that frame."""
    path = DATA / "ur10.urdf"
    urdf = load_urdf(path, tip_link="flange")
    assert urdf.base_link == "base_link" and urdf.tip_link == "flange"
    assert not np.allclose(urdf.tip2flange, np.eye(4), atol=1e-6)
    q = random_readings(urdf.description, seed=3)
    ours = urdf.dh02base @ model_flange2base(urdf.description, q) @ urdf.tip2flange
    direct = np.array(
        [
            urdf_tip2base(path, "base_link", "flange", dict(zip(urdf.description.joint_names, qi)))
            for qi in q
        ]
    )
    assert np.linalg.norm(points(ours) - points(direct), axis=-1).max() < UM


def test_masses_and_centres_of_mass_come_from_the_inertials() -> None:
    path = DATA / "ur5.urdf"
    urdf = load_urdf(path, "base")
    robot = urdf.description
    # base_link_inertia (4 kg) sits before joint 1: not part of any moving link
    np.testing.assert_allclose(robot.link_mass, [3.7, 8.393, 2.275, 1.219, 1.219, 0.1879])
    # the upper arm's centre of mass: (a2/2, 0, 0.12) in upper_arm_link, wherever the arm is
    q = random_readings(robot, seed=5)[:3]
    frames = chain(DHTable(robot.theta + q, robot.d, robot.a, robot.alpha, robot.beta))
    for qi, f in zip(q, frames):
        upper_arm = urdf_tip2base(path, "base", "upper_arm_link", dict(zip(robot.joint_names, qi)))
        expected = upper_arm[:3, :3] @ [-0.2125, 0, 0.12] + upper_arm[:3, 3]
        np.testing.assert_allclose(
            f[2, :3, :3] @ robot.link_com[1] + f[2, :3, 3], expected, atol=1e-12
        )


def _write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "bad.urdf"
    path.write_text(f'<robot name="bad">{body}</robot>')
    return path


LINKS = '<link name="a"/><link name="b"/><link name="c"/>'


def _joint(name: str, parent: str, child: str, kind: str = "continuous", extra: str = "") -> str:
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
        f'<child link="{child}"/><axis xyz="0 0 1"/>{extra}</joint>'
    )


@pytest.mark.parametrize(
    ("body", "options", "message"),
    [
        ("<robot", {}, "not a valid URDF"),
        (LINKS + _joint("j1", "a", "b"), {}, "exactly one root link"),
        (
            LINKS + _joint("j1", "a", "b") + _joint("j2", "b", "c", "prismatic"),
            {},
            "j2 is prismatic",
        ),
        (LINKS + _joint("j1", "a", "b") + _joint("j2", "b", "c"), {}, "coincide"),
        (
            LINKS + _joint("j1", "a", "b") + _joint("j2", "b", "c"),
            {"tip_link": "x"},
            "no tip link 'x'",
        ),
        (
            LINKS + _joint("j1", "a", "b") + _joint("j2", "b", "c"),
            {"base_link": "c"},
            "0 moving joint",
        ),
    ],
)
def test_bad_urdf_is_one_error_naming_the_file(
    tmp_path: Path, body: str, options: dict[str, str], message: str
) -> None:
    with pytest.raises(RobotDescriptionError, match=message) as info:
        load_urdf(_write(tmp_path, body), **options)
    assert "bad.urdf" in str(info.value) and "\n" not in str(info.value)


def test_cli_calibrate_then_predict_with_a_urdf(tmp_path: Path) -> None:
    """`--robot x.urdf` through calibrate; PARAMS.json keeps the URDF reference, so predict
    reloads it; a broken URDF is one line and exit 2."""
    urdf = DATA / "kr5_sixx_r650.urdf"
    params = tmp_path / "params.json"
    proc = cli(
        "calibrate",
        str(ROOT / "bags" / "paper_test3.mcap"),
        "--model",
        "cpa",
        "--robot",
        str(urdf),
        "--tip-link",
        "tool0",
        "-o",
        str(params),
    )
    assert proc.returncode == 0, proc.stderr
    reference = json.loads(params.read_text())["robot"]
    assert reference == f"{urdf}#base_link=base_link&tip_link=tool0"
    joints = tmp_path / "joints.csv"
    joints.write_text("q1,q2,q3,q4,q5,q6\n0,-1.5,1.5,0,0.5,0\n")
    points = tmp_path / "points.csv"
    proc = cli("predict", str(params), "--joints", str(joints), "-o", str(points))
    assert proc.returncode == 0, proc.stderr
    assert np.loadtxt(points, delimiter=",", skiprows=1).shape == (3,)

    bad = _write(tmp_path, "<link")
    proc = cli("calibrate", "x.mcap", "--robot", str(bad), "-o", "p.json")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert "bad.urdf: not a valid URDF" in proc.stderr
    proc = cli("calibrate", "x.mcap", "--base-link", "base", "-o", "p.json")
    assert proc.returncode == 2 and "--base-link/--tip-link need --robot FILE.urdf" in proc.stderr


def test_a_typo_inside_a_joint_is_an_error(tmp_path: Path) -> None:
    """`<axs>` for `<axis>`: the parser would fall back to the default axis silently."""
    from robot_calib.errors import RobotDescriptionError
    from robot_calib.kinematics.loader import load_robot

    text = (DATA / "kr5_sixx_r650.urdf").read_text().replace("<axis ", "<axs ", 1)
    bad = tmp_path / "typo.urdf"
    bad.write_text(text)
    with pytest.raises(RobotDescriptionError, match='Unknown tag "axs"'):
        load_robot(str(bad))
    named = tmp_path / "named.urdf"  # a name that looks like a path does not hide it
    named.write_text(re.sub(r'<robot name="[^"]*"', '<robot name="arm/collision[1]"', text))
    with pytest.raises(RobotDescriptionError, match='Unknown tag "axs"'):
        load_robot(str(named))


def test_a_urdf_as_it_ships_loads_as_ros_loads_it(tmp_path: Path) -> None:
    """A URDF as one ships (the ABB IRB 120's of a public repository): a byte-order mark and
    a blank line before the XML declaration, `<material>` and `<inertial>` inside
    `<collision>`, pybullet's `<contact>` in a link. urdfdom, and so
    robot_state_publisher and RViz, take it; so does this tool, with one warning naming
    what it ignores, and the same kinematics and masses as the clean file."""
    import warnings

    clean = DATA / "irb120_3_58.urdf"
    text = clean.read_text()
    collision = (
        '<collision><geometry><box size="0.1 0.1 0.1"/></geometry>'
        '<material name="grey"/><inertial><mass value="99"/></inertial></collision>'
    )
    for link in ("link_1", "link_4"):
        text = text.replace(f'<link name="{link}">', f'<link name="{link}">{collision}', 1)
    text = "\ufeff\n\n  " + text.replace(
        '<link name="link_2">',
        '<link name="link_2"><contact><lateral_friction value="1"/></contact>',
        1,
    )
    assert text.lstrip("\ufeff \n").startswith("<?xml")
    shipped = tmp_path / "irb120_as_shipped.urdf"
    shipped.write_text(text)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        robot = load_robot(f"{shipped}#base_link=base&tip_link=tool0")
    said = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    assert len(said) == 1 and "5 element(s) of links or of their visual" in said[0], said
    assert '"material"' in said[0] and '"inertial"' in said[0], said
    reference = load_urdf(clean, "base", "tool0").description
    q = random_readings(reference, seed=3)
    gap = points(model_flange2base(robot, q)) - points(model_flange2base(reference, q))
    assert np.abs(gap).max() < 1e-12
    np.testing.assert_array_equal(robot.link_mass, reference.link_mass)  # not the 99 kg


def test_a_mass_model_beyond_physics_is_named_and_replaced(tmp_path: Path) -> None:
    """The shipped IRB 120 URDF puts link 4's centre of mass 500.22 m from its frame (the
    ROS-Industrial description: 0.22 m); a YAML robot may say 1e6 kg, or leave a link at
    0 kg. Each is named in one warning and never used: the gravity effects use the masses of
    the built-in description of the same arm (found by its kinematics, the centres carried
    into the file's own frames), so the gravity torques are those of the sane file; an arm
    that is no built-in gets a default from its geometry."""
    import warnings

    from robot_calib.effects.compliance import gravity_joints, gravity_torques
    from robot_calib.kinematics.masses import DEFAULT_DENSITY_KG_M3, mass_model_line, reach_m

    def loaded(reference: str) -> tuple[RobotDescription, list[str]]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            robot = load_robot(reference)
        return robot, [str(w.message) for w in caught]

    text = (DATA / "irb120_3_58.urdf").read_text()
    sane_com = '<origin xyz="0.2247 0.00015 0.00041"/>'
    text = text.replace(sane_com, sane_com.replace("0.2247", "500.2247"))
    shipped = tmp_path / "irb120_absurd_com.urdf"
    shipped.write_text(text)
    robot, said = loaded(f"{shipped}#base_link=base&tip_link=tool0")
    assert len(said) == 1 and "mass model beyond physics" in said[0], said
    assert "the link of joint_4: centre of mass 499.9 m from its frame" in said[0], said
    assert "the built-in irb120_3_58's masses" in said[0], said
    line = mass_model_line(robot)
    assert line.startswith("the built-in irb120_3_58's masses (the same arm by its kinematics)")
    assert "not the description's" in line and "centre of mass 499.9 m" in line
    sane = load_robot(f"{DATA / 'irb120_3_58.urdf'}#base_link=base&tip_link=tool0")
    assert mass_model_line(sane).startswith("the description's (URDF irb120_3_58.urdf")
    np.testing.assert_array_equal(robot.a, sane.a)  # the geometry is not touched
    q = random_readings(sane, seed=5)
    torque, truth = gravity_torques(robot, q), gravity_torques(sane, q)
    assert np.abs(torque - truth).max() < 1e-3 * np.abs(truth).max()  # the arm's own
    assert gravity_joints(robot) == gravity_joints(sane) != ()
    kr5 = (ROOT / "robot_calib/kinematics/robots/kr5_sixx_r650.yaml").read_text()
    builtin = load_robot("kr5_sixx_r650")
    for name, doc, value in (
        (
            "heavy",
            kr5.replace("mass: 9.0,", "mass: 1000000.0,", 1),
            "1e+06 kg in all for a reach of 1.15 m",
        ),
        ("massless", kr5.replace("mass: 9.0,", "mass: 0.0,", 1), "mass 0 kg"),
    ):
        path = tmp_path / f"{name}.yaml"
        path.write_text(doc)
        robot, said = loaded(str(path))
        assert len(said) == 1 and value in said[0], said
        assert "the built-in kr5_sixx_r650's masses" in said[0], said
        np.testing.assert_allclose(robot.link_mass, builtin.link_mass)
    # not a built-in arm (link 2 5 cm longer), link 2 left at 0 kg: a default from its size
    other = tmp_path / "other.yaml"
    other.write_text(kr5.replace("mass: 6.0,", "mass: 0.0,", 1).replace("a: 0.270,", "a: 0.320,"))
    robot, said = loaded(str(other))
    assert len(said) == 1 and "a default from the geometry" in said[0], said
    assert float(robot.link_mass.sum()) == pytest.approx(
        DEFAULT_DENSITY_KG_M3 * reach_m(robot) ** 3
    )
    assert 2 in gravity_joints(robot) and np.all(robot.link_mass > 0)


def test_the_verdict_is_the_same_with_an_absurd_urdf_and_the_builtin_arm(tmp_path: Path) -> None:
    """A simulated IRB 120 whose joint 2 bends under gravity (1e-4 rad/(N m)), diagnosed
    with its URDF as shipped (link 4's centre of mass 500 m off) and with the built-in
    description of the same arm: one verdict, compliance on joint 2, because the absurd
    masses are replaced by the arm's own. (Without masses, as before, the same data read as
    a transmission error.)"""
    import warnings

    from robot_calib.flows.diagnose import diagnose_recordings
    from robot_calib.sim.measure import record_plan
    from robot_calib.sim.plans import random_plan
    from robot_calib.sim.world import build_world

    sane_com = '<origin xyz="0.2247 0.00015 0.00041"/>'
    shipped = tmp_path / "irb120_absurd_com.urdf"
    shipped.write_text(
        (DATA / "irb120_3_58.urdf")
        .read_text()
        .replace(sane_com, sane_com.replace("0.2247", "500.2247"))
    )
    world = build_world(
        {
            "robot": "irb120_3_58",
            "seed": 4,
            "geometry": "nominal",
            "deviations": {"a2": 0.0004, "d4": -0.0003, "theta3": 0.001},
            "effects": [
                {"name": "compliance", "joints": [2], "values": {"compliance2": 1.0e-4}},
                {"name": "backlash", "joints": [1], "values": {"backlash1": 0.001}},
            ],
        },
        "IRB 120 bending at joint 2",
    )
    rng = np.random.default_rng(1)
    recording = record_plan(world, random_plan(world.model.robot, 240, rng), rng)
    verdicts = []
    for reference in ("irb120_3_58", f"{shipped}#base_link=base&tip_link=tool0"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the absurd model's warning: tested above
            robot = load_robot(reference)
        diagnosis, _ = diagnose_recordings(recording, robot)
        verdicts.append(diagnosis.verdict)
    assert verdicts[0] == verdicts[1] == "compliance on joints [2]", verdicts
