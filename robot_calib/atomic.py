"""Files written whole or not at all: a temporary file beside the target, then a rename
(atomic on POSIX), so a crash, Ctrl-C or a full disk never leaves a half-written output.

- `write_text_atomic`: one text file (JSON, CSV, YAML).
- `staged_outputs`: several files written together (a bag and its world file, a diagnosis
  and its report + plots) into a hidden folder beside the targets, moved in at the end.

A failed write (OSError: full disk, read-only folder, ...) removes what it wrote and raises
InputError naming the file. Existing targets are replaced only with `force`; the caller
checks inputs (`pipeline.output_path`), which are never overwritten.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from robot_calib.errors import InputError


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write `text` to `path` via `.<name>.tmp` in the same folder and a rename; on any
    failure the temporary file is removed and the target is untouched (InputError)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def staged_outputs(folder: str | Path, force: bool = False) -> Iterator[Path]:
    """A hidden staging folder inside `folder`: write the outputs there under their final
    names; on a normal exit every file in it moves into `folder` (an existing file there is
    refused, InputError naming it, unless `force`), on any exception nothing is kept.

    Files keep their names while staged, so a bag's metadata names the right file.

    Yields
    ------
    stage : Path
        The staging folder (`folder/.robot-calib-XXXX.partial`), removed on exit.
    """
    folder = Path(folder)
    try:
        stage = Path(tempfile.mkdtemp(prefix=".robot-calib-", suffix=".partial", dir=folder))
    except OSError as exc:
        raise InputError(f"{folder}: cannot write there: {exc.strerror or exc}") from None
    moved: list[Path] = []
    try:
        yield stage
        files = sorted(stage.iterdir())
        if not force:
            for staged in files:
                if (folder / staged.name).exists():
                    raise InputError(
                        f"{folder / staged.name}: exists; will not overwrite it (use --force)"
                    )
        for staged in files:
            target = folder / staged.name
            if force:
                os.replace(staged, target)
            else:
                _move_new(staged, target)
            moved.append(target)
    except OSError as exc:
        for target in moved:
            target.unlink(missing_ok=True)
        raise InputError(f"{folder}: cannot write the outputs: {exc.strerror or exc}") from None
    except BaseException:
        for target in moved:
            target.unlink(missing_ok=True)
        raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def _move_new(staged: Path, target: Path) -> None:
    """Move `staged` to `target`, which must not exist (a hard link refuses an existing
    target atomically; where links are not supported, checked just before a rename)."""
    try:
        os.link(staged, target)
    except FileExistsError:
        raise InputError(f"{target}: exists; will not overwrite it (use --force)") from None
    except OSError:  # e.g. a file system without hard links
        if target.exists():
            raise InputError(f"{target}: exists; will not overwrite it (use --force)") from None
        os.replace(staged, target)
        return
    staged.unlink()
