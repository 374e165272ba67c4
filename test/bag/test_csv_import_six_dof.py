"""`robot-calib import` of a 6-DoF probe's orientation (quaternion or roll-pitch-yaw columns)
and of the tracker's per-point standard deviations (msgs_doc/import.md): a
simulated KR5 with a probe is exported as a semicolon / decimal-comma CSV in mm, deg, um and
mdeg with the columns in another order, imported through the command line, read back and
calibrated. Known answers: the simulated frames and the stated values, the true probe frame.
"""

from __future__ import annotations

import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli
from scipy.spatial.transform import Rotation

from robot_calib.bag.read import read_recording
from robot_calib.cli import main
from robot_calib.identify.calibrate import calibrate
from robot_calib.kinematics.frames import matrix_to_rpy, rpy_to_matrix
from robot_calib.model import absorb_base_offsets, tool_rotation_parameters
from robot_calib.sim.measure import measure_every_target
from robot_calib.sim.plans import plan_times, random_plan
from robot_calib.sim.world import World, build_world

WORLD = build_world({"seed": 3, "six_dof": {"first": [20, 35, -30]}})
ROBOT = WORLD.model.robot
JOINTS = ("A1", "A2", "A3", "A4", "A5", "A6")
N = 150
POSITION_SIGMA = float(np.hypot(WORLD.noise.tracker_sigma_m, WORLD.noise.target_sigma_m))
NO_ORIENTATION, NO_SR, NO_SP = 10, 11, 12  # rows with some 6-DoF cells left empty
CSV_OPTIONS = (
    "--sep",
    ";",
    "--decimal-comma",
    "--angle-unit",
    "deg",
    "--length-unit",
    "mm",
    "--joints",
    ",".join(JOINTS),
    "--point",
    "X,Y,Z",
)


def measure(world: World, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint readings (n, 6) [rad], points (n T, 3) [m] and frames (n T, 3, 3) of every
    target of `world` at n random poses."""
    plan = random_plan(ROBOT, n, np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 1)
    poses, points = measure_every_target(world, plan.q, plan_times(plan, world.timing), rng)
    assert poses.rotation is not None
    return plan.q, points, poses.rotation


def export(path: Path, columns: dict[str, np.ndarray]) -> Path:
    """A CSV as the tracker software writes it: ';', decimal commas, the header in dict
    order; NaN: an empty cell."""
    lines = [";".join(columns)]
    for k in range(len(next(iter(columns.values())))):
        cells = (
            "" if np.isnan(v[k]) else f"{v[k]:.17g}".replace(".", ",") for v in columns.values()
        )
        lines.append(";".join(cells))
    path.write_text("\n".join(lines) + "\n")
    return path


Q, POINTS, FRAMES = measure(WORLD, N, seed=1)
# stated per point: the simulated noise give or take 10 % [m per coordinate, rad per axis]
_FACTORS = np.random.default_rng(7).uniform(0.9, 1.1, (N, 2))
SIGMA = _FACTORS * [POSITION_SIGMA, WORLD.noise.orientation_sigma_rad]
QUAT = Rotation.from_matrix(FRAMES).as_quat()  # x, y, z, w
QUAT[::2] *= -1.0  # q and -q are one rotation: the sign is the exporter's choice


def first_target_columns(orientation: str = "quaternion") -> dict[str, np.ndarray]:
    """The first target's export: an index, the quaternion's w first and x, y, z reversed
    (or roll, pitch, yaw in rad), joints [deg], points [mm], sigmas [um, mdeg] or
    [mm, rad], a temperature; a few 6-DoF cells empty."""
    columns = {"Index": np.arange(N, dtype=float)}
    if orientation == "quaternion":
        columns |= {"QW": QUAT[:, 3]}
    columns |= {j: np.degrees(Q[:, k]) for k, j in enumerate(JOINTS)}
    columns |= {c: POINTS[:, k] * 1e3 for k, c in enumerate("XYZ")}
    if orientation == "quaternion":
        columns |= {"QZ": QUAT[:, 2], "QY": QUAT[:, 1], "QX": QUAT[:, 0]}
        columns |= {"SP": SIGMA[:, 0] * 1e6, "SR": np.degrees(SIGMA[:, 1]) * 1e3}
    else:
        rpy = np.array([matrix_to_rpy(f) for f in FRAMES])  # the package's convention
        columns |= {"Roll": rpy[:, 0], "Pitch": rpy[:, 1], "Yaw": rpy[:, 2]}
        columns |= {"SP": SIGMA[:, 0] * 1e3, "SR": SIGMA[:, 1]}
    columns["Temp"] = np.full(N, 21.5)
    columns = {c: v.copy() for c, v in columns.items()}
    for c in ("QW", "QX", "QY", "QZ", "Roll", "Pitch", "Yaw"):
        if c in columns:
            columns[c][NO_ORIENTATION] = np.nan  # orientation not measured at this pose
    columns["SR"][NO_SR] = np.nan  # not stated
    columns["SP"][NO_SP] = np.nan
    return columns


QUATERNION_ARGS = (
    "--orientation",
    "QX,QY,QZ,QW",
    "--sigma",
    "SP,SR",
    "--sigma-unit",
    "um",
    "--sigma-angle-unit",
    "mdeg",
)
# roll-pitch-yaw in rad while the joints are in deg; sigmas in the defaults: --length-unit
# (mm) and the orientation unit (rad)
RPY_ARGS = ("--orientation-rpy", "Roll,Pitch,Yaw", "--orientation-unit", "rad", "--sigma", "SP,SR")


def expected_six_dof() -> tuple[np.ndarray, np.ndarray]:
    """What the bag should hold: the frames (NaN where not measured) and the sigmas (NaN
    where not stated; an orientation sigma is dropped where no orientation was measured)."""
    rotation, sigma = FRAMES.copy(), SIGMA.copy()
    rotation[NO_ORIENTATION] = np.nan
    sigma[[NO_ORIENTATION, NO_SR], 1] = np.nan
    sigma[NO_SP, 0] = np.nan
    return rotation, sigma


def run_all(*commands: tuple[str, ...]) -> list[subprocess.CompletedProcess[str]]:
    """Several `robot-calib` commands, one after another in this process (cli: main() is
    not thread-safe: it redirects this process's stdout/stderr and working directory)."""
    return [cli(*args) for args in commands]


def test_quaternion_and_rpy_columns_round_trip_and_calibrate(tmp_path: Path) -> None:
    quaternion_csv = export(tmp_path / "quaternion.csv", first_target_columns("quaternion"))
    rpy_csv = export(tmp_path / "rpy.csv", first_target_columns("rpy"))
    bags = tmp_path / "quaternion.mcap", tmp_path / "rpy.mcap"
    procs = run_all(
        ("import", str(quaternion_csv), *CSV_OPTIONS, *QUATERNION_ARGS, "-o", str(bags[0])),
        ("import", str(rpy_csv), *CSV_OPTIONS, *RPY_ARGS, "-o", str(bags[1])),
    )
    for proc in procs:
        assert proc.returncode == 0, proc.stderr
        assert "warning" not in proc.stderr, proc.stderr
        assert f"the first target: {N - 1} orientations, {N} rows with stated" in proc.stdout
        assert f"/laser_tracker/pose={N}" in proc.stdout  # PoseWithCovarianceStamped
    rotation, sigma = expected_six_dof()
    recordings = [read_recording([bag], ROBOT) for bag in bags]
    for recording in recordings:
        assert recording.oriented_targets == ("",) and len(recording) == N
        assert recording.poses.rotation is not None and recording.poses.sigma is not None
        np.testing.assert_allclose(recording.poses.q, Q, atol=1e-12)
        np.testing.assert_allclose(recording.points, POINTS, atol=1e-12)
        assert np.isnan(recording.poses.rotation[NO_ORIENTATION]).all()
        np.testing.assert_allclose(recording.poses.rotation, rotation, atol=1e-9)
        np.testing.assert_allclose(recording.poses.sigma, sigma, rtol=1e-9)
    # the package's roll-pitch-yaw convention, R = Rz(yaw) Ry(pitch) Rx(roll), by hand
    np.testing.assert_allclose(rpy_to_matrix(*matrix_to_rpy(FRAMES[0])), FRAMES[0], atol=1e-12)
    # the imported bag identifies the probe frame in the flange frame
    truth = absorb_base_offsets(ROBOT, WORLD.truth)
    cal = calibrate(recordings[0], ROBOT, "geometric")
    for name in tool_rotation_parameters(""):
        assert abs(cal.parameters[name] - truth[name]) < 2e-5, name


def test_a_further_target_takes_its_own_orientation_and_sigma(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    world = build_world(
        {"seed": 3, "targets": {"smr2": [0.03, -0.02, 0.12]}, "six_dof": {"smr2": [10, -20, 40]}}
    )
    n, missing, point_only = 20, 3, 5
    q, points, frames = measure(world, n, seed=4)
    points, frames = points.reshape(n, 2, 3) * 1e3, frames.reshape(n, 2, 3, 3)[:, 1]
    rpy = np.degrees(Rotation.from_matrix(frames).as_euler("xyz"))  # extrinsic: Rz Ry Rx
    columns = {j: np.degrees(q[:, k]) for k, j in enumerate(JOINTS)}
    columns |= {c: points[:, 0, k] for k, c in enumerate("XYZ")}
    columns |= {c: points[:, 1, k] for k, c in enumerate(("X2", "Y2", "Z2"))}
    columns |= {c: rpy[:, k].copy() for k, c in enumerate(("R2", "P2", "W2"))}
    columns["S2"] = np.linspace(0.004, 0.008, n)  # mm
    for c in ("X2", "Y2", "Z2", "R2", "P2", "W2", "S2"):
        columns[c][missing] = np.nan  # smr2 not seen at this pose
    for c in ("R2", "P2", "W2"):
        columns[c][point_only] = np.nan  # seen, but the orientation not measured
    csv = export(tmp_path / "two.csv", columns)
    bag = tmp_path / "two.mcap"
    proc = cli(
        "import",
        str(csv),
        *CSV_OPTIONS,
        "--target",
        "smr2:X2,Y2,Z2",
        "--orientation-rpy",
        "smr2:R2,P2,W2",
        "--sigma",
        "smr2:S2",
        "-o",
        str(bag),
    )
    assert proc.returncode == 0, proc.stderr
    assert "target smr2: 18 orientations, 19 rows with stated" in proc.stdout
    recording = read_recording([bag], ROBOT)
    assert recording.target_names == ("", "smr2") and recording.oriented_targets == ("smr2",)
    assert recording.poses.rotation is not None and recording.poses.sigma is not None
    smr2 = recording.poses.target_index == 1
    seen = np.arange(n) != missing
    rotation = recording.poses.rotation[smr2]
    assert np.isnan(rotation[point_only - 1]).all()  # the row after `missing` moved up
    oriented = seen & (np.arange(n) != point_only)
    np.testing.assert_allclose(rotation[oriented[seen]], frames[oriented], atol=1e-9)
    np.testing.assert_allclose(recording.poses.sigma[smr2, 0], columns["S2"][seen] * 1e-3)
    assert np.isnan(recording.poses.rotation[~smr2]).all()  # the first target: points only
    # an orientation where the target's point is missing, or half an orientation: errors
    for cells, row, message in [
        (("R2", "P2", "W2"), missing, "target smr2 has an orientation but no point"),
        (("P2",), point_only, "target smr2 has some of its orientation cells (R2,P2,W2) empty"),
    ]:
        broken = {c: v.copy() for c, v in columns.items()}
        for column in cells:
            broken[column][row] = 1.0
        bad = export(tmp_path / "bad.csv", broken)
        status, stderr = main_in_process(
            capsys,
            "import",
            str(bad),
            *CSV_OPTIONS,
            "--target",
            "smr2:X2,Y2,Z2",
            "--orientation-rpy",
            "smr2:R2,P2,W2",
            "-o",
            str(tmp_path / "bad.mcap"),
        )
        assert status == 2 and f"{bad}:{row + 2}: {message}" in stderr, stderr
        assert not (tmp_path / "bad.mcap").exists()


def main_in_process(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    """`robot-calib ARGS` through the command line's own main() in this process (parse,
    core, error -> one line and exit status; no Python start-up per call): exit status and
    stderr. main() installs signal handlers; they are put back."""
    signals = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    handlers = {s: signal.getsignal(s) for s in signals}
    try:
        status = main(list(args))
    finally:
        for s, handler in handlers.items():
            signal.signal(s, handler)
    return status, capsys.readouterr().err


def test_bad_six_dof_input_is_one_line_exit_2_and_no_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = first_target_columns("quaternion")

    def broken(name: str, column: str, row: int, value: float) -> str:
        columns = {c: v.copy() for c, v in good.items()}
        columns[column][row] = value
        return str(export(tmp_path / f"{name}.csv", columns))

    path = str(export(tmp_path / "good.csv", good))
    both = ("--orientation-rpy", "QX,QY,QZ")
    cases = [  # (CSV, options, what the message says); line = row + 2 (header, 1-based)
        (
            broken("norm", "QX", 20, QUAT[20, 0] + 0.05),
            QUATERNION_ARGS,
            ":22: quaternion QX,QY,QZ,QW (x, y, z, w) of the first target has norm",
        ),
        (
            broken("zero", "SP", 30, 0.0),
            QUATERNION_ARGS,
            ":32: position standard deviation "
            "SP of the first target is 0: need a finite number > 0",
        ),
        (
            broken("negative", "SR", 31, -2.0),
            QUATERNION_ARGS,
            ":33: orientation standard deviation SR of the first target is -2",
        ),
        (
            broken("infinite", "SP", 40, np.inf),
            QUATERNION_ARGS,
            ":42: position standard deviation SP of the first target is inf",
        ),
        (
            broken("partial", "QY", 50, np.nan),
            QUATERNION_ARGS,
            ":52: the first target has some of its orientation cells (QX,QY,QZ,QW) empty",
        ),
        (path, ("--orientation", "QX,QY,QZ,NOPE"), "no column 'NOPE'"),
        (path, ("--orientation", "QX,QY,QZ,QW", "--sigma", "NOPE"), "no column 'NOPE'"),
        (path, ("--orientation", "smr9:QX,QY,QZ,QW"), "no target smr9 among the targets"),
        (path, ("--sigma", "smr9:SP"), "no target smr9 among the targets of --target"),
        (path, ("--orientation", "QX,QY,QZ,QW", *both), "one orientation per target"),
        (path, ("--sigma", "SP,SR"), "an orientation standard deviation, but no --orientation"),
    ]
    lines = (tmp_path / "good.csv").read_text().splitlines()
    cells = lines[3].split(";")
    cells[list(good).index("SR")] = "nan"  # spelled out: not an empty cell ('not stated')
    lines[3] = ";".join(cells)
    (tmp_path / "nan.csv").write_text("\n".join(lines) + "\n")
    cases.append(
        (
            str(tmp_path / "nan.csv"),
            QUATERNION_ARGS,
            ":4: orientation standard deviation SR of the first target is nan",
        )
    )
    out = tmp_path / "out.mcap"
    for csv, options, message in cases:
        status, stderr = main_in_process(
            capsys, "import", csv, *CSV_OPTIONS, *options, "-o", str(out)
        )
        assert status == 2, (options, stderr)
        assert message in stderr and f"robot-calib import: error: {csv}" in stderr, stderr
        assert len(stderr.strip().splitlines()) == 1, stderr
        assert {f.suffix for f in tmp_path.iterdir()} == {".csv"}  # nothing written, staged
    # and as a process of its own
    csv, options, message = cases[0]
    proc = cli("import", csv, *CSV_OPTIONS, *options, "-o", str(out))
    assert proc.returncode == 2 and message in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and not out.exists()


def test_implausible_sigmas_and_empty_orientations_get_warnings(tmp_path: Path) -> None:
    """Micrometres read as millimetres (no --sigma-unit um), and orientation columns empty
    in every row: imported all the same, each with a warning."""
    columns = first_target_columns("quaternion")
    for c in ("QW", "QX", "QY", "QZ"):
        columns[c][:] = np.nan
    csv = export(tmp_path / "um.csv", columns)
    proc = cli(
        "import",
        str(csv),
        *CSV_OPTIONS,
        "--orientation",
        "QX,QY,QZ,QW",
        "--sigma",
        "SP",
        "-o",
        str(tmp_path / "um.mcap"),
    )
    assert proc.returncode == 0, proc.stderr
    assert "position standard deviations SP of the first target have a median of 0.0048" in (
        proc.stderr
    )
    assert "another unit? (--sigma-unit)" in proc.stderr
    assert "--orientation QX,QY,QZ,QW: every cell is empty" in proc.stderr
    recording = read_recording([tmp_path / "um.mcap"], ROBOT)
    assert recording.oriented_targets == () and recording.poses.sigma is not None
    np.testing.assert_allclose(recording.poses.sigma[:, 0], columns["SP"] * 1e-3)
