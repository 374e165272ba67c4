"""What lies outside the vocabulary, read from the hybrid rung's learned correction.

When the physical model the ladder's hybrid rung extends (its last physical rung) stays
well above what a learned correction of its residuals reaches held out (the hybrid rung
won by OUTSIDE_FACTOR or more), most of the remaining error is physical structure the
vocabulary cannot express. The correction's load-driven geometry
(`identify.correction_structured`: each joint housing's six small motions, changing with
the gravity load it carries) says where: the motions that explain most of it that no
other motion explains (each left out of the fit in turn: collinear motions that cancel
each other count only what is their own), in words a robotics engineer reads ("joint 2's
angle changes with its gravity load": play or a compliance whose side the load chooses;
"joint 4's axis tilts with the load": the link before it bending or twisting out of the
arm plane). Scored on the held-out data of the rungs, never in-sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from robot_calib.diagnosis.ladder import Ladder
from robot_calib.identify.correction_structured import LoadMotion, StructuredCorrection
from robot_calib.measurements import Recording
from robot_calib.records import Record

#: the hybrid rung's held-out rms at most 1 / OUTSIDE_FACTOR of that of the physical rung
#: it extends: most of what the physical model leaves is structure outside the vocabulary
OUTSIDE_FACTOR = 2.0
#: load-driven motions reported (the strongest first)
MOTIONS_REPORTED = 3


@dataclass(frozen=True)
class OutsideVocabulary(Record):
    """DIAGNOSIS.json `outside_vocabulary` (msgs_doc/diagnosis.md): the held-out rms [mm]
    of the physical model the hybrid extends and of the hybrid model, and the strongest
    load-driven motions of the learned correction (`LoadMotion`; empty when the correction
    has no load-driven part: a Gaussian process alone, or a PARAMS.json of format 1)."""

    physical_model: str
    physical_abs_rms_mm: float
    hybrid_abs_rms_mm: float
    motions: list[LoadMotion] = field(default_factory=list)

    @property
    def joints(self) -> list[int]:
        """The joints of the reported motions, strongest first, each once."""
        return list(dict.fromkeys(m.joint for m in self.motions))

    def line(self) -> str:
        where = "; ".join(f"{m.meaning} ({m.rms_um:.0f} um rms)" for m in self.motions)
        return (
            f"outside the vocabulary: {self.physical_model} leaves {self.physical_abs_rms_mm:.4f}"
            f" mm rms held-out, a learned correction of it {self.hybrid_abs_rms_mm:.4f} mm"
            + (f"; where: {where}" if where else "")
        )


def outside_vocabulary(ladder: Ladder, recording: Recording) -> OutsideVocabulary | None:
    """The finding when the ladder ends with a hybrid rung at most 1 / OUTSIDE_FACTOR of the
    held-out rms of the physical rung it extends (the last rung before it, as the ladder's
    `_learn_the_rest` takes), else None; the motions from its correction at the calibration
    poses of `recording` (`StructuredCorrection.strongest`)."""
    if not ladder.rungs or not ladder.rungs[-1].learned:
        return None
    hybrid = ladder.rungs[-1]
    extended = [r for r in ladder.rungs[:-1] if not r.learned]
    if not extended:
        return None
    physical = extended[-1]
    if hybrid.heldout.absolute_rms_mm * OUTSIDE_FACTOR > physical.heldout.absolute_rms_mm:
        return None
    correction = hybrid.calibration.correction
    motions: list[LoadMotion] = []
    if isinstance(correction, StructuredCorrection):
        motions = correction.strongest(recording.poses, MOTIONS_REPORTED)
    return OutsideVocabulary(
        physical.model, physical.heldout.absolute_rms_mm, hybrid.heldout.absolute_rms_mm, motions
    )
