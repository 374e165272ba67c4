"""PARAMS.json, the format (msgs_doc/parameters.md): the document <-> forward model and
parameters, its checks (finite SI values, plausibility re-checked on reading, the robot
description it carries) and the helpers of its human summary. Light on purpose: no scipy.

The `Calibration` object as a document and back, and the summary itself, live in
`identify.calibration`, above this module. Values are SI (m, rad); what is printed for
people is in mm and deg, labelled.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from robot_calib.accuracy import Accuracy
from robot_calib.atomic import write_text_atomic
from robot_calib.effects import effect_from_dict
from robot_calib.errors import InputError, ParameterError, RobotCalibError, param
from robot_calib.identify.correction_structured import LearnedCorrection, correction_from_dict
from robot_calib.kinematics.description import RobotDescription, with_payload
from robot_calib.kinematics.loader import load_robot
from robot_calib.kinematics.parameters import ParameterVector
from robot_calib.kinematics.urdf import description_from_text, is_urdf_reference
from robot_calib.model import KinematicModel
from robot_calib.poses import PRIMARY_TARGET

if TYPE_CHECKING:
    from robot_calib.identify.outliers import Outlier

FORMAT = "robot_calib.params/1"
#: Beyond these a result is no robot of its table at all, but nonsense (PARAMS.json
#: `plausible: false`, `calibrate` exit 3; re-checked whenever a PARAMS.json is read): a
#: geometric parameter this far from nominal (identify.plausibility)
PHYSICAL_LENGTH_M = 0.5
PHYSICAL_ANGLE_RAD = math.radians(30.0)
SI_UNITS = (
    "m",
    "rad",
    "1",
    "1/s",
    "1/K",
    "s",
    "rad/m",
    "rad/(N m)",
)  # units parameters are stored in


def human_value(name: str, unit: str, value: float) -> tuple[float, str]:
    """A value in the units people read: m -> mm, rad -> deg (others unchanged)."""
    if unit == "m":
        return value * 1e3, "mm"
    if unit == "rad":
        return float(np.degrees(value)), "deg"
    return value, unit


def write_json_atomic(doc: dict[str, Any], path: Path) -> None:
    """Write JSON via a temporary file and rename: never a half-written file."""
    write_text_atomic(path, json.dumps(doc, indent=2) + "\n")


def read_document(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise InputError(f"{path}: no such parameter file")
    try:
        doc = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        if Path(path).suffix.lower() in (".mcap", ".db3"):  # arguments swapped
            raise InputError(
                f"{path}: a bag, not a parameter file: the parameter file "
                "(PARAMS.json) comes first, then the bags"
            ) from None
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise InputError(f"{path}: not a robot_calib parameter file (format {FORMAT})")
    return doc


#: the descriptions read from PARAMS.json sections, by (reference, fingerprint): a result
#: written again from a model read on another machine carries its section on
_SECTIONS: dict[tuple[str, str], dict[str, str]] = {}


def description_section(robot: RobotDescription) -> dict[str, str] | None:
    """PARAMS.json's own copy of the robot description (the result is portable,
    it needs no file of the machine it was made on): `format` (urdf | yaml), `text` (the
    file's), None for a built-in robot (its name is enough) or a description whose file no
    longer reads back as `robot` (edited since it was loaded: the path alone, as before)."""
    reference = robot.reference()
    if reference == robot.name:
        return None
    known = _SECTIONS.get((reference, robot.fingerprint()))
    if known is not None:
        return known
    kind = (
        "urdf"
        if is_urdf_reference(reference)
        else "csv"
        if reference.lower().endswith(".csv")
        else "yaml"
    )
    try:
        text = Path(reference.partition("#")[0]).read_text(encoding="utf-8")
        section = {"format": kind, "text": text}
        back = robot_from_section(section, reference, reference)
    except (OSError, UnicodeDecodeError, RobotCalibError):
        return None
    if robot.payload_kg:
        back = with_payload(back, robot.payload_kg, robot.payload_com_m)
    return section if back.fingerprint() == robot.fingerprint() else None


def robot_from_section(section: Any, reference: str, where: str) -> RobotDescription:
    """The robot of a PARAMS.json `robot_description` section (`description_section`),
    named `reference` (the file's `robot`); errors name `where`."""
    if not isinstance(section, dict) or not all(
        isinstance(section.get(k), str) for k in ("format", "text")
    ):
        raise InputError(f"{where}: 'robot_description' must hold 'format' and 'text' strings")
    robot = description_from_text(
        section["format"], section["text"], reference, f"{where}: robot_description"
    )
    _SECTIONS[(reference, robot.fingerprint())] = {
        "format": section["format"],
        "text": section["text"],
    }
    return robot


def params_from_dict(
    doc: Mapping[str, Any], where: str = "PARAMS.json"
) -> tuple[KinematicModel, ParameterVector]:
    """The forward model and parameters of a PARAMS.json document; errors name `where`."""
    try:
        section = doc.get("robot_description")
        robot = (
            load_robot(doc["robot"])
            if section is None
            else robot_from_section(section, str(doc["robot"]), where)
        )
        payload = doc.get("payload")
        if payload is not None:  # the calibration's payload (--payload), masses and all
            try:
                mass, centre = float(payload["mass_kg"]), [float(v) for v in payload["com_m"]]
            except (ValueError, TypeError) as exc:
                raise InputError(f"{where}: malformed payload ({exc})") from None
            robot = with_payload(robot, mass, centre)
        stored = doc.get("robot_fingerprint")
        if stored is not None and stored not in (robot.fingerprint(), robot.fingerprint(True)):
            raise InputError(
                f"robot description {doc['robot']} is not the one it was calibrated "
                "with (edited or replaced since): its joints or kinematics differ"
            )
        records = doc.get("effects", [])
        if not isinstance(records, list):
            raise InputError(f"{where}: 'effects' must be a list of effect records")
        effects = tuple(effect_from_dict(e) for e in records)
        targets = doc.get("targets", [{"name": PRIMARY_TARGET}])
        if not isinstance(targets, list) or not targets:
            raise InputError(f"{where}: 'targets' must be a non-empty list of target records")
        model = KinematicModel(
            robot,
            effects,
            tuple(str(t["name"]) for t in targets),
            tuple(str(t["name"]) for t in targets if t.get("six_dof")),
        )
        params = ParameterVector.from_dict(doc["parameters"])
        expected = model.parameters().names
        if params.names != expected:
            missing = sorted(set(expected) - set(params.names))
            raise ParameterError(f"parameters do not match the model (missing {missing[:5]})")
    except (KeyError, TypeError) as exc:
        raise InputError(f"{where}: malformed parameter file ({exc})") from None
    except RobotCalibError as exc:
        raise InputError(f"{where}: {exc}") from None
    check_params_document(doc, model.parameters(), where)
    return model, params


def check_params_document(
    doc: Mapping[str, Any], params: ParameterVector, where: str | Path
) -> None:
    """InputError (one line, naming `where` and the parameter) when a PARAMS.json record
    has a value, nominal or 1-sigma that is not a finite number, or a unit other than the
    SI unit the model declares for it (m, rad, 1, 1/s, rad/(N m)): such a file was edited
    or written by another tool, and predicting from it would be silently wrong."""
    units = {p.name: p.unit for p in params.parameters}
    for record in doc.get("parameters", []):
        name = record.get("name")
        for key in ("value", "nominal", "std"):
            value = record.get(key, 0.0)
            if not isinstance(value, int | float) or not math.isfinite(value):
                raise InputError(f"{where}: parameter {name} {key} {value!r} is not finite")
        unit = record.get("unit")
        if unit != units.get(name) or unit not in SI_UNITS:
            raise InputError(
                f"{where}: parameter {name} has unit {unit!r}, expected {units.get(name)!r}: "
                f"parameter files are in SI ({', '.join(SI_UNITS)})"
            )


def far_from_nominal_values(
    params: ParameterVector,
    length_m: float,
    angle_rad: float,
    free_only: bool = False,
    deg_digits: int = 1,
    nominal: ParameterVector | None = None,
) -> list[str]:
    """'a2 +882.0 mm', 'theta4 +64.6 deg', ...: the geometric parameters of `params` (free
    ones only with `free_only`) more than `length_m` [m] or `angle_rad` [rad] from nominal
    (the nominal values of `nominal`, by name, else those `params` carries)."""
    reference = params if nominal is None else nominal
    out = []
    for p, value in zip(params.parameters, params.values):
        if p.group != "geometric" or (free_only and not p.free):
            continue
        base = reference.nominal[reference.index(p.name)] if p.name in reference else p.nominal
        deviation = value - base
        if p.unit == "m" and abs(deviation) > length_m:
            out.append(f"{p.name} {deviation * 1e3:+.1f} mm")
        elif p.unit == "rad" and abs(deviation) > angle_rad:
            out.append(f"{p.name} {np.degrees(deviation):+.{deg_digits}f} deg")
    return out


def beyond_physics(robot_name: str, far: Sequence[str]) -> str:
    """The implausibility reason for geometric parameters `far` ('a2 +5000.0 mm', ...)
    beyond PHYSICAL_LENGTH_M / PHYSICAL_ANGLE_RAD of nominal; '' when there are none."""
    if not far:
        return ""
    return (
        f"geometric parameters beyond physics ({robot_name}; more than "
        f"{PHYSICAL_LENGTH_M * 1e3:.0f} mm or {math.degrees(PHYSICAL_ANGLE_RAD):.0f} deg from "
        f"nominal): {', '.join(far)}"
    )


def implausible_of(
    doc: Mapping[str, Any],
    where: str | Path,
    model: KinematicModel,
    params: ParameterVector,
) -> tuple[str, ...]:
    """Why the calibration of a PARAMS.json document is nonsense (`plausible: false`, its
    `implausible` reasons), empty when it is plausible; InputError naming `where` when they
    are malformed or disagree. A file that says `plausible: true`, or says nothing (it
    predates the fields, or was written by hand), is re-checked: geometric parameters beyond
    PHYSICAL_LENGTH_M / PHYSICAL_ANGLE_RAD of the robot's nominal make it implausible all
    the same (`model`, `params`: the file's, as `params_from_dict` read them)."""
    plausible, reasons = doc.get("plausible", True), doc.get("implausible", [])
    if not isinstance(plausible, bool) or not (
        isinstance(reasons, list) and all(isinstance(r, str) for r in reasons)
    ):
        raise InputError(
            f"{where}: 'plausible' must be true or false, 'implausible' a list of reasons"
        )
    if plausible and reasons:
        raise InputError(f"{where}: 'plausible' is true but 'implausible' gives reasons")
    if not plausible:
        return tuple(reasons) or ("marked plausible: false",)
    far = far_from_nominal_values(
        params, PHYSICAL_LENGTH_M, PHYSICAL_ANGLE_RAD, nominal=model.parameters()
    )
    if far:
        said = "says plausible: true" if "plausible" in doc else "has no 'plausible' field"
        return (
            f"{beyond_physics(model.robot.name, far)} (re-checked on reading: the file "
            f"{said}; edited by hand?)",
        )
    return ()


def check_plausible(reasons: Sequence[str], where: str | Path, force: bool) -> str | None:
    """None for a plausible calibration (no `reasons`, `implausible_of`); for one marked
    `plausible: false` (file `where`), InputError (exit 2) naming the file and its reasons,
    or with `force` the warning line to print: predicting, compensating or exporting from
    nonsense must be asked for."""
    if not reasons:
        return None
    why = "; ".join(reasons)
    if not force:
        raise InputError(
            f"{where}: fitted, implausible ({why}); {param('force', True)} to use it anyway"
        )
    return f"warning: {where}: fitted, implausible ({why}); used because of {param('force', True)}"


def in_sample_accuracy(
    doc: Mapping[str, Any], where: str | Path, key: str = "residuals"
) -> Accuracy | None:
    """The calibration's in-sample figures (PARAMS.json `residuals`, mm; `key`
    'hybrid_residuals': the hybrid model's, physical model minus learned correction), None
    when the file has none; InputError naming `where` when they are not finite numbers >= 0."""
    if key not in doc:
        return None
    try:
        figures = Accuracy.from_dict(doc[key])
    except InputError as exc:
        raise InputError(f"{where}: {key}: {exc}") from None
    for name, value in figures.to_dict().items():
        if isinstance(value, bool) or not isinstance(value, int | float) or not value >= 0:
            raise InputError(f"{where}: {key}: {name} {value!r} is not a number >= 0")
        if not math.isfinite(value):
            raise InputError(f"{where}: {key}: {name} {value!r} is not finite")
    return figures


def correction_of(
    doc: Mapping[str, Any], model: KinematicModel, parameters: ParameterVector, where: str | Path
) -> LearnedCorrection | None:
    """The learned correction of a PARAMS.json document (its `correction` section,
    msgs_doc/parameters.md; format 2, structured, or 1, the Gaussian process alone), None
    when it has none (the physical model alone); InputError naming `where` when the
    section is malformed or was fitted on another number of joints or targets than `model`
    has, or (format 2) was fitted at other parameters than the file's `parameters`."""
    if "correction" not in doc:
        return None
    section = f"{where}: correction"
    if doc["correction"] is None:
        raise InputError(f"{section}: null (leave the section out for no correction)")
    correction = correction_from_dict(doc["correction"], model, section, parameters)
    if correction.n_joints != model.robot.n_joints or correction.n_targets != len(model.targets):
        raise InputError(
            f"{section}: fitted on {correction.n_joints} joints and {correction.n_targets} "
            f"target(s), the model has {model.robot.n_joints} and {len(model.targets)}"
        )
    return correction


def outlier_lines(outliers: Sequence[Outlier]) -> list[str]:
    """Human lines for the flagged measurements (none: no line)."""
    if not outliers:
        return []
    from robot_calib.identify.outliers import outlier_counts

    head = (
        f"outliers: {len(outliers)} measurement(s) flagged ({outlier_counts(outliers)}), "
        "left out of the fit (hold-out ones: not scored):"
    )
    return [head] + [f"  {o.line()}" for o in outliers]


def fixed_reasons(parameters: ParameterVector) -> dict[str, list[str]]:
    """The fixed parameters' names by the reason they are fixed, in vector order; the
    per-term reasons of the identifiability analysis ('...: moves the points like ...')
    grouped under their common head."""
    reasons: dict[str, list[str]] = {}
    for p in parameters.parameters:
        if p.free:
            continue
        many = "moves the points like" in p.fixed_reason  # one per term: group them
        key = p.fixed_reason.split(":")[0] if many else p.fixed_reason
        reasons.setdefault(key, []).append(p.name)
    return reasons
