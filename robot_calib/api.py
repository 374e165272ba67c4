"""The public Python API: a calibration from a script or a notebook in a few calls.

    import robot_calib as rc

    robot = rc.load_robot("kr5_sixx_r650")
    sim = rc.simulate("run.mcap", plan="paper-test2", effects=["backlash:4"])
    recording = rc.read_recording("run.mcap", robot=robot)
    cal = rc.calibrate(recording, robot, model="geometric+backlash:4")
    print(cal.score(recording).lines("in-sample"))
    cal.save("params.json", recording)
    again = rc.Calibration.load("params.json")
    diagnosis = rc.diagnose(recording, robot)
    print(diagnosis.summary())
    commands = rc.compensate(again, q)  # nominal joint commands (n, J) [rad] -> corrected
    done = rc.compensate_program(again, "pick_place.src")  # a KUKA program, compensated

The science runs on this process alone unless the caller installs a runner: `with
robot_calib.parallel.using(robot_calib.forked.FORKED): rc.diagnose(...)` puts its
independent work (folds, joints' scans) on the other core, as the command line does.

Every function here is one call into the same core the command line and the nodes use
(`flows/`, `identify/`, `diagnosis/`, `compensation/`), with keyword-only options and SI units
(rad, m, s). Errors are `robot_calib.errors.RobotCalibError` subclasses (InputError for bad
input) with one line naming the file or value. Importing `robot_calib` stays light: these
functions load numpy, scipy and the rest when first called (`robot_calib.__getattr__`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from robot_calib.errors import InputError, param
from robot_calib.log import Log

if TYPE_CHECKING:
    from robot_calib.compensation import Compensation
    from robot_calib.compensation.program import ProgramCompensation
    from robot_calib.flows.reportable import ReportableDiagnosis
    from robot_calib.flows.simulate import Simulation
    from robot_calib.identify.calibration import Calibration
    from robot_calib.kinematics.description import RobotDescription
    from robot_calib.kinematics.frames import Array
    from robot_calib.measurements import Recording
    from robot_calib.programs.source import Frame


def _robot(robot: object) -> RobotDescription:
    """`robot` as a description: one already loaded, or a name or path `load_robot` reads;
    anything else an InputError naming the keyword."""
    from robot_calib.kinematics.description import RobotDescription

    if isinstance(robot, RobotDescription):
        return robot
    if isinstance(robot, str | Path):
        return load_robot(robot)
    raise InputError(f"{param('robot')}: a robot description (rc.load_robot) or its name")


def _number(name: str, value: object) -> float:
    """`value` as a float, else an InputError naming the keyword `name`."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{param(name, value)}: a number")
    return float(value)


def _recording(name: str, value: object) -> Recording:
    """`value` if it is a Recording (rc.read_recording), else an InputError naming `name`."""
    from robot_calib.measurements import Recording

    if not isinstance(value, Recording):
        raise InputError(
            f"{param(name)}: a recording (rc.read_recording), not {type(value).__name__}"
        )
    return value


def load_robot(name_or_path: str | Path) -> RobotDescription:
    """A robot description: a built-in name (e.g. 'kr5_sixx_r650', 'ur10'), a robot YAML,
    a DH table CSV or a URDF (msgs_doc/robots.md)."""
    from robot_calib.kinematics.loader import load_robot as load

    return load(name_or_path)


def read_recording(
    *bags: str | Path | Sequence[str | Path],
    robot: RobotDescription | str,
    pair_tolerance: float | None = None,
    log: Log | None = None,
) -> Recording:
    """The paired measurements of one or more MCAP bags (msgs_doc/specification.md): each
    tracker point with the joint state nearest in stamp (within `pair_tolerance` [s],
    default 0.05), reference reflectors' drift removed (msgs_doc/references.md). `bags`:
    paths, or one list of them; `robot`: a description or its name."""
    from robot_calib.bag.read import read_recording as read
    from robot_calib.measurements import PAIR_TOLERANCE_S

    paths = [p for b in bags for p in ([b] if isinstance(b, str | Path) else b)]
    if not paths:
        raise InputError("read_recording: no bag given")
    tolerance = PAIR_TOLERANCE_S if pair_tolerance is None else pair_tolerance
    tolerance = _number("pair_tolerance", tolerance)
    if not 0.0 < tolerance <= 10.0:  # NaN included
        raise InputError(f"{param('pair_tolerance', tolerance)}: seconds, above 0 and at most 10")
    return read([Path(p) for p in paths], _robot(robot), tolerance, log)


def recording_from_arrays(
    q: Array,
    points: Array,
    *,
    time: Array | None = None,
    robot: RobotDescription | None = None,
    source: str = "arrays",
) -> Recording:
    """A recording of measurements already paired in memory: joint readings q (n, J) [rad]
    and the tracker's points (n, 3) [m, tracker frame] in the order measured, their times
    (n,) [s] if known; circle sweeps are found on `robot`'s joints when given."""
    from robot_calib.measurements import recording_from_arrays as make

    return make(q, points, time, robot=robot, source=source)


def simulate(
    output: str | Path,
    *,
    plan: str = "paper-test2",
    world: str | Path | None = None,
    robot: str | None = None,
    effects: Sequence[str] = (),
    seed: int | None = None,
    n_random: int = 20,
    force: bool = False,
) -> Simulation:
    """Simulate a measurement campaign (robot, tracker and recorder nodes, in-process) and
    write the bag `output` with its world file (the truth) beside it. `plan`: a built-in
    plan or a PLAN.yaml; `world`: a world YAML (default: the built-in KR5 world, or `robot`'s
    nominal geometry); `effects`: e.g. ['backlash:4', 'compliance:2=2e-5']."""
    from robot_calib.flows.simulate import simulate as run
    from robot_calib.flows.simulate import simulation_world
    from robot_calib.nodes.simulate import simulate_bag

    built = simulation_world(world, robot, effects, seed)  # robot None: the world's
    return run(output, plan, built, seed, n_random, force=force, record=simulate_bag)


def calibrate(
    recording: Recording,
    robot: RobotDescription | str,
    *,
    model: str = "geometric",
    ecc_order: int = 1,
    log: Log | None = None,
) -> Calibration:
    """Identify `model` ('nominal', 'cpa', 'geometric', 'geometric+EFFECT[:joints]...',
    msgs_doc/effects.md) from `recording`: CPA, then Levenberg-Marquardt; tracker blunders
    left out and listed (`Calibration.outliers`), an implausible result marked
    (`Calibration.plausible`). `log` (e.g. `print`) gets its progress and notes."""
    from robot_calib.flows.calibrate import calibrate_recording

    if isinstance(ecc_order, bool) or not isinstance(ecc_order, int) or ecc_order < 1:
        raise InputError(f"{param('ecc_order', ecc_order)}: a Fourier order, an integer >= 1")
    if not isinstance(model, str):
        raise InputError(f"{param('model', model)}: a model name, e.g. 'geometric+backlash:4'")
    recording = _recording("recording", recording)
    return calibrate_recording(recording, _robot(robot), model, ecc_order, log=log)


def diagnose(
    recording: Recording,
    robot: RobotDescription | str,
    *,
    holdout: Recording | None = None,
    tracker_sigma_m: float | None = None,
    log: Log | None = None,
) -> ReportableDiagnosis:
    """The sim-to-real gap diagnosis (msgs_doc/diagnosis.md): the ladder of models scored
    on `holdout` (else k-fold over poses), the noise floor, the dominant effect and what
    remains. `Diagnosis.summary()` in words, `.to_dict()` the DIAGNOSIS.json document,
    `.save(path)` writes it, `.report(path)` writes it with the Markdown and HTML reports
    and the best model's PARAMS.json beside it (as `robot-calib diagnose -o path`)."""
    from robot_calib.flows.diagnose import diagnose_recordings
    from robot_calib.flows.reportable import ReportableDiagnosis

    recording = _recording("recording", recording)
    holdout = None if holdout is None else _recording("holdout", holdout)
    sigma = None if tracker_sigma_m is None else _number("tracker_sigma_m", tracker_sigma_m)
    diagnosis, ladder = diagnose_recordings(
        recording, _robot(robot), holdout, log=log, tracker_sigma_m=sigma
    )
    return ReportableDiagnosis.of(diagnosis, ladder, recording)


def compensate(
    calibration: Calibration,
    q: Array,
    *,
    directions: Array | None = None,
    time: Array | None = None,
) -> Compensation:
    """The joint commands (n, J) [rad] the nominal controller must be given so that the
    calibrated robot reaches where the nominal model puts commands q (n, J) [rad]
    (`Compensation.q`; `.converged`, `.error_m` per command). `directions` (n, J) +-1: each
    joint's approach direction (default: from the motion between consecutive commands);
    `time` (n,) [s] for models that follow time."""
    import numpy as np

    from robot_calib.compensation import compensate_commands
    from robot_calib.poses import Poses, approach_directions

    try:
        q = np.asarray(q, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{param('q')}: joint commands, numbers [rad]") from None
    n_joints = calibration.model.robot.n_joints
    if q.ndim != 2 or q.shape[1] != n_joints:
        raise InputError(
            f"{param('q')}: joint commands of shape (n, {n_joints}) [rad], got {q.shape}"
        )
    if not np.isfinite(q).all():
        raise InputError(f"{param('q')}: joint commands must be finite numbers [rad]")
    commands = Poses.from_readings(
        q, approach_directions(q) if directions is None else directions, time
    )
    return compensate_commands(calibration, commands)


def compensate_program(
    calibration: Calibration,
    program: str | Path,
    *,
    language: str | None = None,
    tools: dict[str, Sequence[float]] | None = None,
    bases: dict[str, Sequence[float]] | None = None,
) -> ProgramCompensation:
    """A robot program (KUKA .src with its .dat, ABB .mod, FANUC .ls, URScript .script;
    `language` 'krl', 'rapid', 'fanuc_tp' or 'urscript' where the suffix does not say)
    compensated for `calibration` (msgs_doc/programs.md): `.texts` (file name -> the
    compensated text; write it in the file's encoding, `.program.encoding(name)`) and
    `.rows` (per target: status, values written, mm and deg moved, why). `tools`, `bases`:
    frames the program names but does not declare (FANUC's UT/UF), by their number or name
    ('*' for every target), in the language's own pose notation (KRL X,Y,Z,A,B,C [mm, deg],
    RAPID x,y,z,q1..q4, FANUC X,Y,Z,W,P,R, URScript x,y,z,rx,ry,rz [m, rad])."""
    from robot_calib.compensation.program import compensate_program as compensate_it
    from robot_calib.programs.registry import check_robot, language_for

    lang = language_for(program, language)
    check_robot(lang, calibration.model.robot.name, "calibration")
    given: list[dict[str, Frame]] = [{}, {}]
    for kind, (keyword, frames) in enumerate((("tools", tools), ("bases", bases))):
        for key, values in (frames or {}).items():
            frame = lang.frame(kind, str(key), values, f"{param(keyword)}: {key}")
            given[kind][frame.key] = frame
    return compensate_it(calibration, lang.read(Path(program)), lang, given[0], given[1])
