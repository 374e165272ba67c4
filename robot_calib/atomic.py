"""Files written whole or not at all: a temporary file beside the target, then a rename
(atomic on POSIX), so a crash, Ctrl-C or a full disk never leaves a half-written output.

- `write_text_atomic`: one text file (JSON, CSV, YAML).
- `staged_outputs`: several files written together (a bag and its world file, a diagnosis
  and its report + plots) into a hidden folder beside the targets, moved in at the end.

A failed write (OSError: full disk, read-only folder, ...) removes what it wrote and raises
InputError naming the file. Existing targets are replaced only with `force`; the caller
checks inputs (`output_path`, the overwrite policy of every verb), which are never
overwritten.

A target checked to be new (`claim_new`, called by `output_path` without
`--force`) is created exclusively at the final rename: a file that appeared there
meanwhile (a second command writing the same output) is never replaced, the command fails
with "exists" instead and the other's result stays.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import tempfile
import threading
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from robot_calib.errors import EXISTS, InputError, param

_NEW: set[Path] = set()
"""Targets checked to be new (absolute): created exclusively, never replaced."""

#: the interrupting signals a command received (its handler notes them here, `cli`): one
#: that a C extension's call back into Python swallowed (scipy's MINPACK around a fit
#: function, say) must still keep the outputs out, so every final rename checks this first
INTERRUPTS: list[int] = []


def _refuse_if_interrupted() -> None:
    """KeyboardInterrupt if the command was interrupted (`INTERRUPTS`): outputs of an
    interrupted command are never moved in, even when the interruption was swallowed."""
    if INTERRUPTS:
        raise KeyboardInterrupt


def claim_new(path: str | Path) -> None:
    """`path` was checked not to exist and may not be replaced (no `--force`): writing it
        by `write_text_atomic` fails if it exists by the final rename (`staged_outputs` moves
    in without replacing whenever it is not forced)."""
    _NEW.add(Path(os.path.abspath(path)))


def must_be_new(path: str | Path) -> bool:
    """True if `path` was claimed new (`claim_new`)."""
    return Path(os.path.abspath(path)) in _NEW


def write_text_atomic(path: str | Path, text: str, *, rewrite: bool = False) -> None:
    """Write `text` to `path` via a temporary `.<name>.<random>.tmp` in the same folder and
    a rename; on any failure the temporary file is removed and the target is untouched
    (InputError). A target claimed new (`claim_new`) is refused if it exists by then,
    unless `rewrite` (the command rewrites a file it wrote itself)."""
    path = Path(path)
    try:
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None
    tmp = Path(name)
    try:
        with os.fdopen(fd, "w") as file:
            file.write(text)
        os.chmod(tmp, 0o666 & ~_umask())
        _refuse_if_interrupted()
        if must_be_new(path) and not rewrite:
            _move_new(tmp, path)
        else:
            os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _umask() -> int:
    """The process's umask (mkstemp creates 0600; outputs get the usual mode)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


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
        stage = _named_folder(folder, ".robot-calib-", ".partial")  # who stages here
    except OSError as exc:
        raise InputError(f"{folder}: cannot write there: {exc.strerror or exc}") from None
    _remove_dead_stages(folder, stage)
    moved: list[Path] = []
    deferred = False
    journal = folder / f"{JOURNAL_PREFIX}{stage.name}.txt"
    try:
        yield stage
        files = sorted(f for f in stage.iterdir() if f.name != OWNER_FILE)
        stale = _interrupted_sets(folder, {f.name for f in files})
        if not force:
            _refuse_incomplete(folder, stale)
        if not force:
            for staged in files:
                if (folder / staged.name).exists():
                    raise InputError(f"{folder / staged.name}: {EXISTS}")
        deferred = _defer_signals(True)  # the set moves in as one: no signal between renames
        _refuse_if_interrupted()
        # what a SIGKILL between the renames (which no handler can hold) would leave part of:
        # the next write of any of these names finds it and says so
        write_text_atomic(journal, f"{_writer_id()}\n" + "".join(f"{f.name}\n" for f in files))
        for staged in files:
            target = folder / staged.name
            if force:
                os.replace(staged, target)
            else:
                _move_new(staged, target)
            moved.append(target)
            _pause_between_renames()
        journal.unlink(missing_ok=True)
        for old_journal in stale:  # the incomplete sets are replaced by a whole one
            killed = old_journal.name[len(JOURNAL_PREFIX) : -len(".txt")]  # its staging folder
            if killed.startswith(".robot-calib-") and killed.endswith(".partial"):
                shutil.rmtree(folder / killed, ignore_errors=True)
            old_journal.unlink(missing_ok=True)
        if not force and deferred:  # a signal that came meanwhile: the new set taken back
            deferred = _defer_signals(False)
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
        journal.unlink(missing_ok=True)
        if deferred:  # with force the old set is replaced: a signal comes after, set whole
            _defer_signals(False)


#: a set's journal in the target folder while its files are renamed in: the writer's pid,
#: then one file name per line; removed once the set is whole (or taken back)
JOURNAL_PREFIX = ".robot-calib-set-"


def _interrupted_sets(folder: Path, names: set[str]) -> dict[Path, list[str]]:
    """The journals in `folder` of writers that died between their renames (a process
    that no longer runs; SIGKILL, power loss) listing any of `names`, each with the files
    of its set present now (the incomplete set)."""
    out: dict[Path, list[str]] = {}
    for journal in folder.glob(f"{JOURNAL_PREFIX}*.txt"):
        try:
            writer, *listed = journal.read_text().split("\n")
        except OSError:
            continue
        listed = [name for name in listed if name]
        if _gone(writer) and names.intersection(listed):
            out[journal] = [name for name in listed if (folder / name).exists()]
    return out


def refuse_incomplete(path: str | Path) -> None:
    """InputError when `path` is a file of a set whose writer was killed between its
    renames (`staged_outputs`' journal): an incomplete set, replaced only with --force."""
    path = Path(path)
    if path.parent.is_dir():
        _refuse_incomplete(path.parent, _interrupted_sets(path.parent, {path.name}))


def _refuse_incomplete(folder: Path, stale: dict[Path, list[str]]) -> None:
    for journal, partial in stale.items():
        if partial:
            raise InputError(
                f"{folder}: {', '.join(partial)}: left by a write that was killed between the "
                f"renames of its files (journal {journal.name}): an incomplete set; use "
                f"{param('force', True)} to replace it"
            )


#: in a staging folder: who stages there (`_writer_id`); never moved in
OWNER_FILE = ".owner"


def _writer_id() -> str:
    """'host pid start': this process, told apart from a later one given the same pid (its
    start time in clock ticks since boot, where /proc has it)."""
    return f"{socket.gethostname()} {os.getpid()} {_start_time(os.getpid())}"


def _start_time(pid: int) -> str:
    """Process `pid`'s start time (/proc/<pid>/stat field 22), '' where not known."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return ""


def _gone(writer: str) -> bool:
    """True when the writer `_writer_id` gave is surely no longer running: on this host,
    its pid runs no more or runs a process started at another time. A writer of another
    host (a shared folder) or an unreadable id counts as running: nothing of it is
    removed or called incomplete."""
    host, _, rest = writer.partition(" ")
    pid, _, start = rest.partition(" ")
    if host != socket.gethostname() or not pid.isdigit():
        return False
    if not _running(int(pid)):
        return True
    return bool(start) and _start_time(int(pid)) not in ("", start)


def owned_folder(parent: str | Path, prefix: str) -> Path:
    """A new private folder `parent/<prefix>XXXX` naming its writer (`OWNER_FILE`), after
    the folders of that prefix whose writers are gone (killed before they could remove
    theirs) are removed (`remove_dead_folders`)."""
    folder = _named_folder(parent, prefix)
    remove_dead_folders(Path(parent), f"{prefix}*", folder)
    return folder


#: the signals an interruption arrives by (held while a folder gets its writer's name)
_HELD = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _named_folder(parent: str | Path, prefix: str, suffix: str = "") -> Path:
    """A new folder `parent/<prefix>XXXX<suffix>` with its writer's name in it
    (`OWNER_FILE`), made with Ctrl-C, SIGTERM and SIGHUP held until both are done (they
    are handled right after): a folder without its writer's name is never swept, and one
    interrupted between the two stayed for ever."""
    hold = hasattr(signal, "pthread_sigmask")
    held = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD) if hold else set()
    try:
        folder = Path(tempfile.mkdtemp(prefix=prefix, suffix=suffix, dir=parent))
        try:
            (folder / OWNER_FILE).write_text(_writer_id())
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
    finally:
        if hold:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)
    return folder


def _remove_dead_stages(folder: Path, own: Path) -> None:
    """Remove the staging folders in `folder` (not `own`) whose writer is gone (killed
    before it moved its set in: nothing of them reached the folder's outputs)."""
    remove_dead_folders(folder, ".robot-calib-*.partial", own)


def remove_dead_folders(folder: Path, pattern: str, own: Path) -> None:
    """Remove the folders `pattern` in `folder` (not `own`) that name a writer
    (`OWNER_FILE`) no longer running (`_gone`)."""
    for stage in folder.glob(pattern):
        owner = stage / OWNER_FILE
        if stage == own or not stage.is_dir() or not owner.is_file():
            continue
        with contextlib.suppress(OSError):
            if _gone(owner.read_text()):
                shutil.rmtree(stage, ignore_errors=True)


def _running(pid: int) -> bool:
    """True if a process `pid` runs (this one included)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


_DEFERRED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
_held: list[tuple[dict[int, Any], list[int]]] = []


def _defer_signals(hold: bool) -> bool:
    """Hold (`hold`) or release Ctrl-C, SIGTERM and SIGHUP: while held they are recorded,
    not handled; on release the handlers are restored and each recorded signal is raised
    again (the command's handler: 'interrupted', exit 130). True if now held. Only in the
    main thread (where Python runs its signal handlers); ignored signals stay ignored.
    SIGKILL cannot be held: a set is then left part-moved."""
    if threading.current_thread() is not threading.main_thread():
        return False
    if hold:
        caught: list[int] = []
        previous: dict[int, Any] = {}
        for sig in _DEFERRED:
            handler = signal.getsignal(sig)
            if handler not in (signal.SIG_IGN, None):
                previous[sig] = handler
                signal.signal(sig, lambda signum, _frame: caught.append(signum))
        _held.append((previous, caught))
        return True
    if _held:
        restore, pending = _held.pop()
        for number, handler in restore.items():
            signal.signal(number, handler)
        for number in dict.fromkeys(pending):
            signal.raise_signal(number)
    return False


def _pause_between_renames() -> None:
    """Tests: ROBOT_CALIB_TEST_RENAME_PAUSE_S seconds between the renames of a set (the
    window a signal must not split; 0 / unset in use)."""
    pause = os.environ.get("ROBOT_CALIB_TEST_RENAME_PAUSE_S")
    if pause:
        time.sleep(float(pause))


def _move_new(staged: Path, target: Path) -> None:
    """Move `staged` to `target`, which must not exist (a hard link refuses an existing
    target atomically; where links are not supported, checked just before a rename)."""
    try:
        os.link(staged, target)
    except FileExistsError:
        raise InputError(f"{target}: {EXISTS}") from None
    except OSError:  # e.g. a file system without hard links
        if target.exists():
            raise InputError(f"{target}: {EXISTS}") from None
        os.replace(staged, target)
        return
    staged.unlink()


def refuse_input(path: Path, inputs: Sequence[str | Path]) -> None:
    """InputError if `path` is one of `inputs` (an existing file, any spelling or link)."""
    if path.exists() and any(
        Path(p).exists() and path.resolve() == Path(p).resolve() for p in inputs
    ):
        raise InputError(f"{path}: is an input of this command; will not overwrite it")


def output_path(
    raw: str | Path, what: str, inputs: Sequence[str | Path] = (), force: bool = False
) -> Path:
    """The path of a file to write (the overwrite policy of every verb): its folder must
    exist and be writable, it must not be a folder, it must not be one of the command's
    `inputs` (an input is never overwritten, even with `force`), and it must not exist
    unless `force`; InputError naming the path otherwise.

    Returns
    -------
    path : Path
        `raw` as a Path.
    """
    path = Path(raw)
    if not path.parent.is_dir():
        raise InputError(f"{path.parent}: no such folder for {what}")
    if path.is_dir():
        raise InputError(f"{path}: is a folder; give a file name for {what}")
    refuse_input(path, inputs)
    if not os.access(path.parent, os.W_OK | os.X_OK):
        raise InputError(f"{path.parent}: folder not writable; cannot write {what} there")
    if not force:
        refuse_incomplete(path)  # a set killed half-moved: said as such, not "exists"
    if path.exists() and not force:
        raise InputError(f"{path}: {EXISTS}")
    if not force:  # still new at the final rename, or refused (a second command wrote it)
        claim_new(path)
    return path
