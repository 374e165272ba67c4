"""The parameters as one flat JSON mapping, for a controller script: name -> value (SI),
unit, 1-sigma and whether it was estimated; with the robot, the model and its effects.

Names are PARAMS.json's (msgs_doc/parameters.md): thetaJ, dJ, aJ, alphaJ, betaJ,
base2tracker_*, target_*; effect parameters keep their effect's names."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from robot_calib.export.base import Exporter, correction_lines

if TYPE_CHECKING:
    from robot_calib.identify.calibration import Calibration

FORMAT = "robot_calib.export/1"


def render(cal: Calibration, source: str) -> str:
    """The JSON text of calibration `cal` read from `source`."""
    params = cal.parameters
    doc: dict[str, Any] = {
        "format": FORMAT,
        "source": source,
        "robot": cal.model.robot.name,
        "model": cal.name,
        "effects": [e.label for e in cal.model.effects],
        "parameters": {
            p.name: {
                "value": float(value),
                "unit": p.unit,
                "std": float(std) if free else 0.0,
                "estimated": bool(free),
            }
            for p, value, std, free in zip(params.parameters, params.values, cal.std, params.free)
        },
    }
    if cal.correction is not None:  # not a parameter: only PARAMS.json holds it
        doc["warnings"] = correction_lines(cal)
    return json.dumps(doc, indent=2) + "\n"


EXPORTER = Exporter("json", ".json", "every parameter: value (SI), unit, 1-sigma", render)
