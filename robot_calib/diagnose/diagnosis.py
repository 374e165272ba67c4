"""`robot-calib diagnose`: the ladder, the dominant effect, where the rest lies, as the
DIAGNOSIS.json document of CONTRACT.md section 4 (extended: msgs_doc/diagnosis.md)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from robot_calib.diagnose.ladder import AT_FLOOR, N_FOLDS, Ladder, run_ladder
from robot_calib.diagnose.noise import NoiseLevel, refine_with_model
from robot_calib.diagnose.signatures import where_it_lies
from robot_calib.kinematics.description import RobotDescription
from robot_calib.measurements import Recording

FORMAT = "robot_calib.diagnosis/1"
#: geometric within this factor of the noise floor on held-out data: nothing to diagnose
NULL_FACTOR = 1.5


def dominant_effect(
    ladder: Ladder, where: dict[str, Any], noise: NoiseLevel
) -> dict[str, Any] | None:
    """The effect that removed most of what `geometric` left (with its joints); None when
    geometric is already at the noise level; 'unknown' with the joints of the strongest
    residual signature when structure remains that no candidate explains."""
    rungs = ladder.rungs
    floor_mm = noise.floor_rms_m * 1e3
    gains: dict[str, float] = {}
    joints: dict[str, set[int]] = {}
    for before, rung in zip(rungs, rungs[1:]):
        added = rung.effects[-1]
        gain = before.heldout.absolute_rms_mm - rung.heldout.absolute_rms_mm
        gains[added.name] = gains.get(added.name, 0.0) + gain
        joints.setdefault(added.name, set()).update(added.joints)
    if gains:
        name = max(gains, key=gains.__getitem__)
        return {"effect": name, "joints": sorted(joints[name])}
    if rungs[0].heldout.absolute_rms_mm <= NULL_FACTOR * floor_mm or not noise.independent:
        return None  # at the noise level, or (noise unknown) no candidate helps
    strongest = where.get("strongest_signature")
    return {"effect": "unknown", "joints": [strongest["joint"]] if strongest else []}


def diagnose(
    recording: Recording,
    robot: RobotDescription,
    holdout: Recording | None = None,
    log: Callable[[str], None] | None = None,
) -> tuple[dict[str, Any], Ladder]:
    """The diagnosis document and the ladder behind it."""
    ladder = run_ladder(recording, robot, holdout, log)
    best = ladder.rungs[-1]
    geo = ladder.rungs[0].calibration
    where = where_it_lies(geo.model, geo.parameters, recording, geo.residuals,
                          ladder.noise.sigma_m)  # fmt: skip
    after = where if len(ladder.rungs) == 1 else where_it_lies(
        best.calibration.model, best.calibration.parameters, recording,
        best.calibration.residuals, ladder.noise.sigma_m,
    )  # fmt: skip
    noise = refine_with_model(ladder.noise, best.calibration.residuals,
                              int(best.calibration.parameters.free.sum()))  # fmt: skip
    dominant = dominant_effect(ladder, where, noise)
    floor_mm = noise.floor_rms_m * 1e3
    ratio = best.heldout.absolute_rms_mm / floor_mm
    if not noise.independent:
        note = (
            "noise level not known independently of the model (no repeat poses or circle "
            f"sweeps): the floor is the geometric model's own residual; held-out rms {ratio:.2f}"
            " x that"
            + (
                f"; strongest structure: {after['strongest_signature']['text']}"
                if after["strongest_signature"]
                else ""
            )  # fmt: skip
        )
    elif ratio <= AT_FLOOR:
        note = f"at the noise level: held-out rms {ratio:.2f} x the noise floor"
    else:
        sig = after["strongest_signature"]
        note = (
            f"held-out rms {ratio:.2f} x the noise floor remains; no effect of the vocabulary "
            "reduces it further" + (f"; strongest structure: {sig['text']}" if sig else "")
        )
    doc: dict[str, Any] = {
        "format": FORMAT,
        "dominant_effect": dominant,
        "ladder": [
            {
                "model": r.model,
                "holdout_mean_mm": r.heldout.pairwise_mean_mm,
                "holdout_max_mm": r.heldout.pairwise_max_mm,
                "holdout_abs_mean_mm": r.heldout.absolute_mean_mm,
                "holdout_abs_max_mm": r.heldout.absolute_max_mm,
                "holdout_abs_rms_mm": r.heldout.absolute_rms_mm,
                "insample_mean_mm": r.calibration.accuracy.pairwise_mean_mm,
                "insample_abs_rms_mm": r.calibration.accuracy.absolute_rms_mm,
                "free_parameters": int(r.calibration.parameters.free.sum()),
            }
            for r in ladder.rungs
        ],
        "unexplained": {
            "holdout_mean_mm": best.heldout.pairwise_mean_mm,
            "holdout_abs_rms_mm": best.heldout.absolute_rms_mm,
            "noise_floor_abs_rms_mm": floor_mm,
            "ratio_to_noise_floor": ratio,
            "note": note,
            "where": after,
        },
        "noise": {
            "sigma_mm": noise.sigma_m * 1e3,
            "source": noise.source,
            "n": noise.n,
            "floor_abs_rms_mm": floor_mm,
            "floor_abs_mean_mm": noise.floor_mean_m * 1e3,
            "ladder_sigma_mm": ladder.noise.sigma_m * 1e3,
            "ladder_source": ladder.noise.source,
        },
        "scored_on": ladder.scored_on,
        "selected_on": f"{N_FOLDS}-fold CV over poses"
        + (" + hold-out bags (equal weight)" if holdout is not None else ""),
        "where": where,
        "candidates": [
            [{"model": m, "linearised_holdout_rms_mm": s * 1e3} for m, s in rnd]
            for rnd in ladder.candidates
        ],
        "recordings": list(recording.sources),
        "holdout": [] if holdout is None else list(holdout.sources),
    }
    return doc, ladder


def diagnosis_summary(doc: dict[str, Any]) -> str:
    """A few human lines: the verdict, the ladder (held-out, seed criterion), what remains."""
    dom = doc["dominant_effect"]
    verdict = (
        "null (geometric reaches the noise level)"
        if dom is None
        else f"{dom['effect']} on joints {dom['joints']}"
    )
    rungs = "; ".join(
        f"{r['model']} {r['holdout_mean_mm']:.4f}/{r['holdout_max_mm']:.4f} mm"
        for r in doc["ladder"]
    )
    return (
        f"dominant effect: {verdict}. Ladder (held-out seed criterion mean/max, "
        f"{doc['scored_on']}): {rungs}. Noise floor {doc['noise']['floor_abs_rms_mm']:.4f} mm "
        f"rms. {doc['unexplained']['note']}."
    )
