"""The calibration flow: a model identified from paired measurements, from bags, or from
one stream bag (`robot-calib calibrate`, the calibrator node, `run`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from robot_calib.errors import InputError, param
from robot_calib.flows.bags import read_bags
from robot_calib.identify import DEFAULT_ECC_ORDER, DEFAULT_MODEL
from robot_calib.identify.model_spec import ModelSpec
from robot_calib.kinematics.description import RobotDescription
from robot_calib.log import Log
from robot_calib.measurements import PAIR_TOLERANCE_S

if TYPE_CHECKING:
    from robot_calib.identify.calibration import Calibration
    from robot_calib.identify.latency import StreamCalibration
    from robot_calib.measurements import Recording


def calibrate_recording(
    recording: Recording,
    robot: RobotDescription,
    model: str = DEFAULT_MODEL,
    ecc_order: int = DEFAULT_ECC_ORDER,
    objective: str = "absolute",
    log: Log | None = None,
) -> Calibration:
    """Identify `model` from paired measurements (a bag's, or live topics').

    Returns
    -------
    calibration : Calibration
        As `robot_calib.identify.calibrate.calibrate`.
    """
    from robot_calib.identify.calibrate import calibrate, model_notes

    for note in model_notes(model, robot, ecc_order):
        (log or (lambda _line: None))(note)
    if objective == "seed":
        check_seed_objective_memory(len(recording), robot, model, ecc_order)
    cal = calibrate(recording, robot, model, ecc_order, log=log, objective=objective)
    return replace(cal, recordings=tuple(recording.sources))  # what it was fitted on


SEED_OBJECTIVE_MEMORY_LIMIT = 2 * 1024**3  # bytes of pairwise rows `--objective seed` may take


def seed_objective_bytes(n_points: int, n_params: int) -> int:
    """Memory [bytes] of the seed objective's pairwise rows for `n_points` and `n_params`
    parameters: per pair of points, the two points' Jacobians, their difference (3 x P
    each) and the distance row (P), float64; O(n_points^2)."""
    pairs = n_points * (n_points - 1) // 2
    return pairs * (3 * 3 * n_params + n_params) * 8


def check_seed_objective_memory(
    n_points: int, robot: RobotDescription, model: str, ecc_order: int = DEFAULT_ECC_ORDER
) -> None:
    """InputError when `--objective seed` on `n_points` would need more than
    SEED_OBJECTIVE_MEMORY_LIMIT, naming the largest number of points that fits."""
    from robot_calib.identify.calibrate import parse_model
    from robot_calib.model import KinematicModel

    _, effects = parse_model(model, robot, ecc_order)
    n_params = len(KinematicModel(robot, tuple(effects)).parameters().names)
    need = seed_objective_bytes(n_points, n_params)
    if need <= SEED_OBJECTIVE_MEMORY_LIMIT:
        return
    allowed = n_points
    while seed_objective_bytes(allowed, n_params) > SEED_OBJECTIVE_MEMORY_LIMIT:
        allowed = int(allowed * 0.99)
    while seed_objective_bytes(allowed + 1, n_params) <= SEED_OBJECTIVE_MEMORY_LIMIT:
        allowed += 1
    gib = 1024**3
    raise InputError(
        f"{param('objective', 'seed')} on {n_points} points needs {need / gib:.1f} GiB for "
        f"its pairwise rows (limit {SEED_OBJECTIVE_MEMORY_LIMIT / gib:.0f} GiB: at most "
        f"{allowed} points with {n_params} parameters); use "
        f"{param('objective', 'absolute')} (O(N)) or fewer points"
    )


def calibrate_bags(
    bags: Sequence[str | Path],
    robot: RobotDescription,
    model: str = DEFAULT_MODEL,
    ecc_order: int = DEFAULT_ECC_ORDER,
    objective: str = "absolute",
    pair_tolerance: float = PAIR_TOLERANCE_S,
    log: Log | None = None,
) -> tuple[Calibration, Recording]:
    """Identify `model` from `bags`. A bad model name fails before any bag is read.

    Returns
    -------
    calibration : Calibration
        As `robot_calib.identify.calibrate.calibrate`: parameters (P) with their 1-sigma,
        in-sample accuracy [mm], residuals (n, 3) [m], identifiability, solver report.
    recording : Recording
        The paired measurements of `bags` it was identified from (as `read_bags`).
    """
    from robot_calib.identify.calibrate import parse_model

    parse_model(model, robot, ecc_order)
    recording = read_bags(bags, robot, pair_tolerance, log)
    cal = calibrate_recording(recording, robot, model, ecc_order, objective, log)
    return cal, recording


def calibrate_stream_bag(
    bags: Sequence[str | Path],
    robot: RobotDescription,
    model: str = DEFAULT_MODEL,
    ecc_order: int = DEFAULT_ECC_ORDER,
    latency_s: float | None = None,
    max_points: int | None = None,
    max_gap_s: float | None = None,
    log: Log | None = None,
) -> StreamCalibration:
    """Identify `model` from one stream bag (continuous tracking, msgs_doc/stream.md): the
    joint readings interpolated to the point stamps + `latency_s` [s] (None: identified);
    at most `max_points` points fitted (None: STREAM_MAX_POINTS), points in joint-state gaps
    longer than `max_gap_s` [s] (None: STREAM_MAX_GAP_S) dropped. A bad model name fails
    before the bag is read; more than one bag is an InputError (one latency per bag).

    Returns
    -------
    stream_calibration : StreamCalibration
        As `robot_calib.identify.latency.calibrate_stream`: the calibration, the paired
        points it was fitted on, the pairing, the latency used and how it was found.
    """
    from robot_calib.bag.read import read_stream
    from robot_calib.identify.calibrate import parse_model
    from robot_calib.identify.latency import calibrate_stream
    from robot_calib.measurements.stream import STREAM_MAX_GAP_S, STREAM_MAX_POINTS

    parse_model(model, robot, ecc_order)
    if len(bags) != 1:
        raise InputError(
            f"{param('stream', True)} calibrates one bag (its own latency); got {len(bags)}"
        )
    if ModelSpec.parse(model).base == "cpa":
        raise InputError(
            f"{param('stream', True)} {param('model', model)}: a stream has no "
            "circle sweeps; use an "
            "LM model (nominal, geometric, geometric+EFFECT)"
        )
    stream = read_stream(Path(bags[0]), robot)
    return calibrate_stream(
        stream,
        robot,
        model,
        latency_s,
        max_points=STREAM_MAX_POINTS if max_points is None else max_points,
        max_gap_s=STREAM_MAX_GAP_S if max_gap_s is None else max_gap_s,
        ecc_order=ecc_order,
        log=log,
    )
