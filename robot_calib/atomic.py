"""Files written whole or not at all: a temporary file beside the target, then a rename
(atomic on POSIX), so a crash or Ctrl-C never leaves a half-written output."""

from __future__ import annotations

import os
from pathlib import Path


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write `text` to `path` via `.<name>.tmp` in the same folder and a rename."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
