"""A compensated program's per-target table, `NAME.targets.csv` beside the program
(msgs_doc/programs.md): one row per target in program order, what was done to it and why."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from robot_calib.atomic import write_text_atomic
from robot_calib.compensation.program import TargetRow
from robot_calib.programs.source import EVERY, Frame

#: the columns of a compensated program's per-target table (msgs_doc/programs.md)
TABLE_HEADER = (
    "target,file,line,kind,status,moved_mm,turned_deg,error_um,used_on_lines,tool,base,reason"
)


def write_program_table(
    path: str | Path,
    rows: Sequence[TargetRow],
    tools: Mapping[str, Frame] | None = None,
    bases: Mapping[str, Frame] | None = None,
) -> None:
    """A compensated program's per-target table (TABLE_HEADER), one row per target in
    program order, atomically; `error_um` empty where the target was not solved; `tool`,
    `base`: the frame's key and, where an option gave it (`tools`, `bases`), that option
    (EVERY: the frame of every target)."""
    lines = [TABLE_HEADER]
    for row in rows:
        target = row.target
        error = "" if not np.isfinite(row.error_m) else f"{row.error_m * 1e6:.3f}"
        fields = [
            target.name,
            target.file,
            str(target.line),
            target.kind,
            row.status,
            f"{row.moved_mm:.4f}",
            f"{row.turned_deg:.5f}",
            error,
            " ".join(map(str, target.used)),
            _frame(target.tool, tools or {}, "flange"),
            _frame(target.base, bases or {}, "robot base"),
            row.reason,
        ]
        lines.append(",".join(_quoted(f) for f in fields))
    write_text_atomic(path, "\n".join(lines) + "\n")


def _frame(key: str | None, given: Mapping[str, Frame], default: str) -> str:
    """A target's frame as the table names it: its key (or `default`), and the option
    that gave its value."""
    if EVERY in given:
        return f"{key or default} as {given[EVERY].where}"
    if key is not None and key in given:
        return f"{key} as {given[key].where}"
    return key or default


def _quoted(field: str) -> str:
    """A CSV field, quoted where it holds a comma or a quote."""
    if any(c in field for c in ',"\n'):
        return '"' + field.replace('"', '""') + '"'
    return field
