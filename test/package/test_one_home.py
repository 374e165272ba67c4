"""One home per concept, read from the source: PARAMS.json is parsed by
`Calibration.from_dict` alone, a learned correction is applied to points by
`model.corrected` alone (and to tool frames by the compensation's solver), a model name is
split by `ModelSpec` alone, and a line-taking callable is `log.Log`."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import robot_calib

PACKAGE = Path(robot_calib.__file__).parent

# (what, pattern of a use, the modules allowed to use it)
HOMES = [
    ("PARAMS.json parsed", r"\bparams_from_dict\(|\bread_document\(", {"identify/calibration.py"}),
    (
        "a learned correction applied",
        r"correction\.predict\(",
        {"model.py", "compensation/solve.py"},
    ),
    # sim/blind.py: the names of the harness's world classes ('backlash+thermal_warmup'),
    # not model names
    ("a model name split", r"\.split\(\"\+\"\)", {"identify/model_spec.py", "sim/blind.py"}),
    ("a line-taking callable", r"Callable\[\[str\], None\]", {"log.py"}),
]


def uses(pattern: str) -> set[str]:
    found = set()
    for path in PACKAGE.rglob("*.py"):
        text = re.sub(r"(?m)^\s*(def|#).*$", "", path.read_text())  # definitions, comments
        if re.search(pattern, text):
            found.add(str(path.relative_to(PACKAGE)))
    return found


@pytest.mark.parametrize(("what", "pattern", "homes"), HOMES, ids=[h[0] for h in HOMES])
def test_one_home(what: str, pattern: str, homes: set[str]) -> None:
    found = uses(pattern)
    found = {f for f in found if not f.startswith("identify/correction")}  # its own models
    assert found <= homes, f"{what} outside its home: {sorted(found - homes)}"
    assert found, f"{what}: the pattern finds nothing (stale test)"
