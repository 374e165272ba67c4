"""`robot-calib export`: a calibration as a URDF, a DH table, a Universal Robots
calibration file and a flat JSON. The URDF's forward kinematics, computed from the file as
parsed by ROS's own URDF parser (urdf_parser_py) and chained here joint by joint, equals
the calibrated geometric model to < 1 um at random poses."""

from __future__ import annotations

import csv
import io
import json
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation
from urdf_parser_py.urdf import URDF

from robot_calib.accuracy import Accuracy
from robot_calib.effects import make_effect
from robot_calib.errors import InputError
from robot_calib.export import FORMATS
from robot_calib.identify.calibration import Calibration
from robot_calib.kinematics.loader import load_robot
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.model import KinematicModel
from robot_calib.poses import Poses
from robot_calib.sim.plans import random_plan

N_POSES = 50
FK_TOLERANCE_M = 1e-6
DATA = Path(__file__).parents[1] / "data"


def calibration(
    robot_name: str, seed: int = 0, effects: tuple[str, ...] = (), offset: bool = False
) -> Calibration:
    """A calibration of `robot_name` with every free geometric and frame parameter perturbed
    (about 1 mm / 1 mrad, the tracker ~2 m away and turned), two targets, the second a 6-DoF
    probe; `offset`: the robot's readings offset from its joint variables too."""
    robot = load_robot(robot_name)
    if offset:
        robot = replace(robot, reading_offset=np.radians([3.0, -2.0, 5.0, 1.0, -4.0, 2.0]))
    model = KinematicModel(
        robot,
        tuple(make_effect(e, (4,)) for e in effects),
        targets=("", "probe"),
        oriented=("probe",),
    )
    rng = np.random.default_rng(seed)
    nominal = model.parameters(
        base2tracker=(2.0, -0.5, 0.3, 0.02, -0.03, 2.5),
        target_in_flange=(0.01, 0.02, 0.1),
        offsets={"probe": (-0.03, 0.0, 0.15)},
    )
    scale = np.array([1e-3 if p.unit in ("m", "rad") else 1e-4 for p in nominal.parameters])
    values = nominal.values + nominal.free * scale * rng.standard_normal(len(nominal))
    values[nominal.index("target_probe_rx") : nominal.index("target_probe_rz") + 1] = [
        0.3,
        -0.2,
        1.1,
    ]
    params = ParameterVector(nominal.parameters, values)
    std = np.where(params.free, 1e-5, 0.0)
    accuracy = Accuracy(0, 0.0, 0.0, 0.0, 0.0, 0.0)
    return Calibration("geometric", model, params, std, accuracy, np.zeros((0, 3)))


def urdf_frames(text: str, q: np.ndarray) -> dict[str, np.ndarray]:
    """Every link's pose (n, 4, 4) in the root link, chained from the URDF's joints as
    urdf_parser_py reads them: origin (xyz, fixed-axis rpy), then the turn about the axis
    by the joint's position (q[:, k] for the k-th revolute joint in file order)."""
    robot = URDF.from_xml_string(text)
    revolute = [j.name for j in robot.joints if j.type == "revolute"]
    by_child = {j.child: j for j in robot.joints}
    n = len(q)
    frames: dict[str, np.ndarray] = {robot.get_root(): np.tile(np.eye(4), (n, 1, 1))}

    def frame(link: str) -> np.ndarray:
        if link not in frames:
            joint = by_child[link]
            origin = np.eye(4)
            origin[:3, :3] = Rotation.from_euler("xyz", joint.origin.rpy).as_matrix()
            origin[:3, 3] = joint.origin.xyz
            out = frame(joint.parent) @ origin
            if joint.type == "revolute":
                angle = q[:, revolute.index(joint.name)]
                turn = np.tile(np.eye(4), (n, 1, 1))
                turn[:, :3, :3] = Rotation.from_rotvec(
                    angle[:, None] * np.asarray(joint.axis)[None, :]
                ).as_matrix()
                out = out @ turn
            frames[link] = out
        return frames[link]

    for link in robot.link_map:
        frame(link)
    return frames


@pytest.mark.parametrize(
    ("robot_name", "offset"),
    [("kr5_sixx_r650", False), ("ur10", False), ("kr16_2", False), ("kr16_2", True)],
)
def test_the_urdf_forward_kinematics_is_the_calibrated_model(
    robot_name: str, offset: bool
) -> None:
    cal = calibration(robot_name, offset=offset)
    model, params = cal.model, cal.parameters
    text = FORMATS["urdf"].render(cal, "p.json")
    q = random_plan(model.robot, N_POSES, np.random.default_rng(1)).q
    frames = urdf_frames(text, q)
    poses = Poses.from_readings(q)
    flange2base = model.flange2base(params, poses)
    assert np.abs(frames["flange"][:, :3, 3] - flange2base[:, :3, 3]).max() < FK_TOLERANCE_M
    assert np.abs(frames["flange"][:, :3, :3] - flange2base[:, :3, :3]).max() < 1e-9
    tracker2base = frames["laser_tracker"]
    for k, link in enumerate(("tcp", "tcp_probe")):
        target2tracker = np.linalg.inv(tracker2base) @ frames[link]
        at = replace(poses, target=np.full(N_POSES, k))
        error = np.linalg.norm(target2tracker[:, :3, 3] - model.target_points(params, at), axis=1)
        assert error.max() < FK_TOLERANCE_M, (link, error.max())
    probe = model.probe_orientations(params, replace(poses, target=np.ones(N_POSES, dtype=int)))
    assert (
        np.abs((np.linalg.inv(tracker2base) @ frames["tcp_probe"])[:, :3, :3] - probe).max() < 1e-9
    )
    robot = URDF.from_xml_string(text)
    joints = [j for j in robot.joints if j.type == "revolute"]
    assert [j.name for j in joints] == list(model.robot.joint_names)
    signs = np.diag(model.robot.reading_matrix) if model.robot.reading_matrix is not None else 1
    assert np.array_equal([j.axis[2] for j in joints], np.ones(6) * signs)
    assert [[j.limit.lower, j.limit.upper] for j in joints] == model.robot.limits.tolist()
    assert "no effects beyond the geometry" in text


def test_the_urdf_header_lists_the_effects_it_cannot_hold_and_their_size() -> None:
    cal = calibration("kr5_sixx_r650", effects=("backlash",))
    name = cal.model.effects[0].parameter_names(cal.model.robot)[0]
    cal = replace(cal, parameters=cal.parameters.with_values({name: 2e-4}))
    text = FORMATS["urdf"].render(cal, "p.json")
    header = text.split("-->")[0]
    assert f"(largest parameter |{name}| = 200.0 urad)" in header
    # what it adds at the tool: 200 urad of play on joint 4, about a 0.1-0.4 m lever
    size = float(header.split("backlash[4]: moves the tool by ")[1].split(" mm rms")[0])
    assert 0.01 < size < 0.1
    assert "p.json" in header and "kr5_sixx_r650" in header
    # The geometry is still the model's without its effects.
    q = random_plan(cal.model.robot, 5, np.random.default_rng(2)).q
    geometric = replace(cal.model, effects=())
    flange = geometric.flange2base(cal.parameters, Poses.from_readings(q))
    assert np.abs(urdf_frames(text, q)["flange"] - flange).max() < 1e-9


def test_a_robot_with_coupled_joints_is_refused_for_urdf() -> None:
    cal = calibration("m20ia")
    with pytest.raises(
        InputError, match="couples joints .*3<-2.*`format='dh'` or `format='json'`"
    ):
        FORMATS["urdf"].render(cal, "p.json")


def test_the_dh_table_holds_every_row_with_its_sigma_in_si_and_mm_deg() -> None:
    cal = calibration("kr5_sixx_r650")
    params = cal.parameters
    rows = list(csv.DictReader(io.StringIO(FORMATS["dh"].render(cal, "p.json"))))
    assert len(rows) == 6
    assert rows[0]["name"] == "joint_a1"
    assert float(rows[1]["a_m"]) == params["a2"]
    assert float(rows[1]["a_mm"]) == pytest.approx(params["a2"] * 1e3, abs=1e-6)
    assert float(rows[1]["beta_rad"]) == params["beta2"]  # joint 2: Hayati
    assert float(rows[1]["beta_std_rad"]) == 1e-5
    assert float(rows[2]["alpha_deg"]) == pytest.approx(np.degrees(params["alpha3"]), abs=1e-6)
    assert rows[3]["beta_rad"] == "0" or float(rows[3]["beta_rad"]) == 0.0  # no beta4 (written 0)
    # Fixed parameters: sigma 0, named.
    assert rows[0]["fixed"] == "theta1 d1" and float(rows[0]["d_std_m"]) == 0.0
    assert rows[1]["fixed"] == "d2"
    assert rows[5]["fixed"] == "theta6 d6 a6 alpha6"
    # Every column is labelled with its unit.
    units = ("_rad", "_m", "_mm", "_deg")
    assert all(c.endswith(units) for c in rows[0] if c not in ("joint", "name", "fixed"))


def test_the_json_export_is_a_flat_mapping_with_units_and_sigma() -> None:
    cal = calibration("ur10", effects=("backlash",))
    doc = json.loads(FORMATS["json"].render(cal, "p.json"))
    assert doc["robot"] == "ur10" and doc["effects"] == ["backlash[4]"]
    assert list(doc["parameters"]) == list(cal.parameters.names)
    a2 = doc["parameters"]["a2"]
    assert a2 == {"value": cal.parameters["a2"], "unit": "m", "std": 1e-5, "estimated": True}
    assert doc["parameters"]["theta1"]["std"] == 0.0  # 0 is the "fixed" flag, exact
    assert doc["parameters"]["theta1"]["estimated"] is False


def ur_chain(kinematics: dict[str, dict[str, float]], q: np.ndarray) -> np.ndarray:
    """wrist_3_link in base_link_inertia (n, 4, 4): each entry's origin then Rz(q_j)."""
    out = np.tile(np.eye(4), (len(q), 1, 1))
    for j, entry in enumerate(
        ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
    ):
        e = kinematics[entry]
        origin = np.eye(4)
        origin[:3, :3] = Rotation.from_euler("xyz", [e["roll"], e["pitch"], e["yaw"]]).as_matrix()
        origin[:3, 3] = [e["x"], e["y"], e["z"]]
        turn = np.tile(np.eye(4), (len(q), 1, 1))
        turn[:, :3, :3] = Rotation.from_euler("z", q[:, j, None]).as_matrix()
        out = out @ origin @ turn
    return out


def test_the_ur_file_of_the_nominal_ur10_is_ur_descriptions_default() -> None:
    cal = calibration("ur10")
    cal = replace(cal, parameters=ParameterVector(cal.parameters.parameters))  # nominal
    kin = yaml.safe_load(FORMATS["ur"].render(cal, "p.json"))["kinematics"]
    # ur_description config/ur10/default_kinematics.yaml (wrist_3's rpy (pi/2, pi, pi) is
    # this (-pi/2, 0, 0)).
    expected = {
        "shoulder": (0, 0, 0.1273, 0, 0, 0),
        "upper_arm": (0, 0, 0, np.pi / 2, 0, 0),
        "forearm": (-0.612, 0, 0, 0, 0, 0),
        "wrist_1": (-0.5723, 0, 0.163941, 0, 0, 0),
        "wrist_2": (0, -0.1157, 0, np.pi / 2, 0, 0),
        "wrist_3": (0, 0.0922, 0, -np.pi / 2, 0, 0),
    }
    for name, values in expected.items():
        got = [kin[name][k] for k in ("x", "y", "z", "roll", "pitch", "yaw")]
        assert got == pytest.approx(values, abs=1e-12), name
    assert kin["hash"].startswith("calib_")


def test_the_ur_file_chains_to_the_calibrated_flange() -> None:
    cal = calibration("ur10", seed=4)
    text = FORMATS["ur"].render(cal, "p.json")
    assert text.startswith("# Universal Robots calibration of ur10")
    kin = yaml.safe_load(text)["kinematics"]
    q = random_plan(cal.model.robot, N_POSES, np.random.default_rng(3)).q
    flange2base = cal.model.flange2base(cal.parameters, Poses.from_readings(q))
    assert np.abs(ur_chain(kin, q) - flange2base).max() < FK_TOLERANCE_M


def test_the_ur_file_is_only_for_ur_robots() -> None:
    with pytest.raises(InputError, match="kr5_sixx_r650 is not a Universal Robots arm"):
        FORMATS["ur"].render(calibration("kr5_sixx_r650"), "p.json")


def test_the_export_verb_writes_every_format_and_keeps_the_overwrite_policy(
    tmp_path: Path,
) -> None:
    from cli_runner import cli

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return cli(*args, cwd=tmp_path)

    # a UR10 bag simulated in-process (the ROS graph's simulate is tested elsewhere)
    from robot_calib.bag.write import write_measurement_bag
    from robot_calib.sim.measure import measure_every_target
    from robot_calib.sim.plans import paper_test_plan, plan_times
    from robot_calib.sim.world import build_world

    world = build_world({"robot": "ur10", "geometry": "nominal", "seed": 2})
    plan = paper_test_plan(3)
    poses, points = measure_every_target(
        world, plan.q, plan_times(plan, world.timing), np.random.default_rng(2)
    )
    write_measurement_bag(
        tmp_path / "x.mcap", poses.q, points, world.model.robot.joint_names, poses.time
    )
    assert run("calibrate", "x.mcap", "--robot", "ur10", "-o", "p.json").returncode == 0
    for fmt, name in (("urdf", "r.urdf"), ("dh", "r.csv"), ("ur", "r.yaml"), ("json", "r.json")):
        proc = run("export", "p.json", "--format", fmt, "-o", name)
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout.startswith(f"{name}: ")
    URDF.from_xml_string((tmp_path / "r.urdf").read_text())
    assert "shoulder" in yaml.safe_load((tmp_path / "r.yaml").read_text())["kinematics"]
    for args, message in (
        (("--format", "dh", "-o", "r.csv"), "r.csv: exists; will not overwrite it (use --force)"),
        (("--format", "json", "-o", "p.json", "--force"), "is an input of this command"),
        (("--format", "dh", "-o", "r.csv", "--robot", "ur5"), "identified for robot ur10"),
    ):
        proc = run("export", "p.json", *args)
        assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [
            f"robot-calib export: error: {proc.stderr.split('error: ', 1)[1].strip()}"
        ]
        assert message in proc.stderr, proc.stderr
    assert run("export", "p.json", "--format", "dh", "-o", "r.csv", "--force").returncode == 0
    for name in ("ur10.urdf", "kr16_2.urdf"):
        (tmp_path / name).write_bytes((DATA / name).read_bytes())
    proc = run(
        "export", "p.json", "--format", "urdf", "--nominal-urdf", "ur10.urdf", "-o", "n.urdf"
    )
    assert (
        proc.returncode == 0
        and "ur10" in URDF.from_xml_string((tmp_path / "n.urdf").read_bytes()).name
    ), proc.stderr
    for args, message in (
        (("--format", "dh", "--nominal-urdf", "ur10.urdf", "-o", "d.csv"), "for --format urdf"),
        (("--nominal-urdf", "kr16_2.urdf", "-o", "k.urdf"), "not robot ur10's nominal"),
        (("--nominal-urdf", "ur10.urdf", "-o", "ur10.urdf", "--force"), "is an input"),
        (("--nominal-urdf", "none.urdf", "-o", "z.urdf"), "none.urdf: no such nominal URDF"),
    ):
        args = args if "--format" in args else ("--format", "urdf", *args)
        proc = run("export", "p.json", *args)
        assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
        assert message in proc.stderr, proc.stderr
    assert not (tmp_path / "k.urdf").exists() and not (tmp_path / "d.csv").exists()


def _with_meshes(name: str) -> bytes:
    """Fixture URDF `name` with a visual mesh on every link and a ros2_control tag: what a
    vendor's URDF carries and the export must keep."""
    text = (DATA / name).read_text()
    text = text.replace("/>", "/>", 0)
    import re

    text = re.sub(
        r'<link name="([^"]+)"/>',
        r'<link name="\1"><visual><geometry><mesh filename="package://m/\1.dae"/></geometry>'
        r"</visual></link>",
        text,
    )
    return text.replace("</robot>", '<ros2_control name="hw" type="system"/></robot>').encode()


@pytest.mark.parametrize(("robot_name", "file"), [("ur5", "ur5.urdf"), ("kr16_2", "kr16_2.urdf")])
def test_the_calibration_written_into_the_nominal_urdf_keeps_it_and_is_the_model(
    tmp_path: Path, robot_name: str, file: str
) -> None:
    from robot_calib.export.urdf_nominal import render_on_nominal

    nominal_file = tmp_path / file
    nominal_file.write_bytes(_with_meshes(file))
    cal = calibration(robot_name)
    model = cal.model
    # the nominal calibration written into the nominal file gives its origins back (to 1 nm:
    # the fixture rounds its roll to 1.570796327 and has 1e-11 m terms)
    nominal_params = model.parameters().with_values(
        {
            p.name: cal.parameters[p.name]
            for p in model.parameters().parameters
            if p.group == "frames"
        }
    )
    same = render_on_nominal(replace(cal, parameters=nominal_params), "p.json", nominal_file)
    before = {j.name: j for j in URDF.from_xml_string(nominal_file.read_bytes()).joints}
    after = URDF.from_xml_string(same.encode())
    for joint in after.joints:
        if joint.name in before:
            old = before[joint.name].origin
            assert np.allclose(joint.origin.xyz, old.xyz, atol=1e-9), joint.name
            assert np.allclose(
                Rotation.from_euler("xyz", joint.origin.rpy).as_matrix(),
                Rotation.from_euler("xyz", old.rpy).as_matrix(),
                atol=1e-9,
            ), joint.name
    # the calibration: the file's tcp seen from its laser_tracker is the model's point
    text = render_on_nominal(cal, "p.json", nominal_file)
    q = random_plan(model.robot, N_POSES, np.random.default_rng(3)).q
    frames = urdf_frames(text.encode(), q)
    poses = Poses.from_readings(q)
    tracker = np.linalg.inv(frames["laser_tracker"])
    error = np.linalg.norm(
        (tracker @ frames["tcp"])[:, :3, 3] - model.target_points(cal.parameters, poses), axis=1
    )
    assert error.max() < FK_TOLERANCE_M
    # tool0 moves with the calibrated flange: rigid to the tcp at every pose
    tool_in_tcp = np.linalg.inv(frames["tcp"]) @ frames["tool0"]
    assert np.abs(tool_in_tcp - tool_in_tcp[0]).max() < 1e-12
    # what the calibration does not know is kept: links, limits, meshes, other tags
    kept = URDF.from_xml_string(text.encode())
    original = URDF.from_xml_string(nominal_file.read_bytes())
    assert set(original.link_map) <= set(kept.link_map)
    assert [(j.name, j.limit.lower, j.limit.upper) for j in kept.joints if j.limit] == [
        (j.name, j.limit.lower, j.limit.upper) for j in original.joints if j.limit
    ]
    assert text.count("<mesh ") == nominal_file.read_text().count("<mesh ") > 0
    assert "<ros2_control" in text and "no effects beyond the geometry" in text


def test_a_xacro_or_another_robots_urdf_is_refused_as_nominal(tmp_path: Path) -> None:
    from robot_calib.export.urdf_nominal import render_on_nominal

    cal = calibration("ur5")
    xacro = tmp_path / "ur.urdf.xacro"
    xacro.write_text(
        (DATA / "ur5.urdf")
        .read_text()
        .replace(
            '<robot name="ur5">',
            '<robot name="ur5" xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:property '
            'name="d1" value="0.1"/>',
        )
    )
    with pytest.raises(InputError, match="a xacro file, not a URDF: expand it first"):
        render_on_nominal(cal, "p.json", xacro)
    with pytest.raises(InputError, match=r"not robot ur5's nominal kinematics: .* mm"):
        render_on_nominal(cal, "p.json", DATA / "ur10.urdf")
