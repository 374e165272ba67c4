"""Work done by a forked child process on the machine's other core while this process goes
on: the only way to use a second core for Python-heavy work (matplotlib's figures, the
hyperparameter searches and fits of a k-fold's folds: threads share one interpreter lock,
and two threads of those ran at 1.1 cores).

`Aside` forks one child that computes its tasks in order and writes each result (pickled)
to a file of a private temporary folder as it is done, then its number to a pipe (a
result through the pipe itself would block the child as soon as it passed the pipe's
64 KiB until this process read it: the child stood idle). `result(key)` waits for the
child's; a task
the child could not deliver (it raised, died, sent a cut message or nothing within the
timeout) or an `Aside` that could not fork (no os.fork, other Python threads running, the
tasks run here at once) is computed here when asked: the caller gets the same value either
way, only later. The child leaves with os._exit: no exit handler, no buffered output of
this process written twice.

`Helper` forks its child early, before the tasks exist: it gets ready meanwhile (imports
matplotlib and loads its fonts, 0.4 s on the core this process leaves idle while it reads
and fits) and then takes one batch of tasks, pickled (so only module-level functions and
partials of them), for an `Aside`, sharing it with a twin it forks then.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import select
import shutil
import signal
import tempfile
import threading
from collections.abc import Callable, Hashable, Sequence
from types import TracebackType
from typing import IO, Generic, TypeVar

T = TypeVar("T")

FOLDER_PREFIX = "robot_calib-aside-"  # the private temporary folders' names start so
#: seconds the child may take for one task (they take tenths to seconds): then it is
#: killed and what it did not send is computed here
TIMEOUT_S = 120.0


def can_fork() -> bool:
    """True when a forked child is safe and useful: os.fork exists and this is the only
    Python thread (a fork copies only the calling thread: a lock another thread holds, an
    rclpy executor's or a thread pool's, would stay held in the child for ever)."""
    return hasattr(os, "fork") and threading.active_count() == 1


class Aside(Generic[T]):
    """`tasks` ((key, zero-argument callable) each; the results picklable) computed in
    order by a forked child while the caller goes on; `result(key)` gives each. Use as a
    context manager (or call `close`): leaving reaps the child, killed at once when an
    exception (Ctrl-C included) leaves the block.

    A task is computed twice at most (in the child, then here when the child did not send
    it), so tasks must not change the state they share with the caller: the child's
    changes are lost, the result is what counts. A `mailbox` (`Mailbox`) carries one value
    this process finds later to the child's tasks. With a `helper` (`Helper`, not yet used)
    its child computes the tasks instead of a new fork, when they can be pickled; `split`:
    the tasks from that index on by a twin it forks (both cores), the others by itself.

    Every child leads a process group of its own (a helper's twin belongs to it), which an
    abort kills whole; so Ctrl-C at the terminal reaches this process only, which ends them."""

    def __init__(self, tasks: Sequence[tuple[Hashable, Callable[[], T]]],
                 timeout_s: float = TIMEOUT_S, helper: Helper | None = None,
                 split: int | None = None, mailbox: Mailbox | None = None) -> None:  # fmt: skip
        self._tasks = dict(tasks)
        self._results: dict[Hashable, T] = {}
        self._timeout_s = timeout_s
        self._received = 0
        self._keys = [key for key, _ in tasks]
        self._child: tuple[int, IO[bytes], str] | None = None  # pid, pipe, folder
        if not self._tasks:
            return
        if helper is not None:
            self._child = helper.take(list(tasks), split)
        if self._child is None and can_fork():
            self._fork(list(tasks), mailbox)

    def _fork(self, tasks: list[tuple[Hashable, Callable[[], T]]],
              mailbox: Mailbox | None) -> None:  # fmt: skip
        folder = tempfile.mkdtemp(prefix=FOLDER_PREFIX)
        read, write = os.pipe()
        parent = os.getpid()
        pid = os.fork()
        if pid == 0:  # the child: compute, send, and leave without running any exit handler
            code = 0
            try:
                os.setpgid(0, 0)
                os.close(read)
                if mailbox is not None:
                    mailbox.forked()
                _compute(list(enumerate(tasks)), folder, write)
            except BaseException:  # noqa: BLE001 - the parent computes what did not come
                code = 1
            finally:
                _leave(code, parent, folder)
        os.close(write)
        if mailbox is not None:
            mailbox.forking_done()
        self._child = (pid, os.fdopen(read, "rb"), folder)

    @property
    def forked(self) -> bool:
        """True while a child computes the tasks not yet received."""
        return self._child is not None

    @property
    def received(self) -> int:
        """How many results came from the child so far."""
        return self._received

    def __contains__(self, key: Hashable) -> bool:
        return key in self._tasks

    def result(self, key: Hashable) -> T:
        """The result of task `key`: the child's when it sends it, else computed here."""
        while key not in self._results and self._receive():
            pass
        if key not in self._results:
            self._results[key] = self._tasks[key]()
        return self._results[key]

    def _receive(self) -> bool:
        """One result from the child; False (the child reaped) at its end, or when it sends
        nothing within the timeout or a message cut short (it died)."""
        if self._child is None:
            return False
        _, pipe, folder = self._child
        if select.select([pipe], [], [], self._timeout_s)[0]:
            head = pipe.read(8)
            number = int.from_bytes(head, "little") if len(head) == 8 else len(self._keys)
            if number < len(self._keys):
                path = os.path.join(folder, str(number))
                try:
                    with open(path, "rb") as file:
                        self._results[self._keys[number]] = pickle.load(file)
                    self._received += 1
                    return True
                except (OSError, pickle.UnpicklingError, EOFError, ValueError, AttributeError):
                    pass
                finally:
                    with contextlib.suppress(OSError):
                        os.unlink(path)
        self.close(abort=True)
        return False

    def close(self, abort: bool = False) -> None:
        """Reap the child: after its last result, or at once (`abort`: killed, what it did
        not send yet computed here when asked)."""
        if self._child is None:
            return
        pid, pipe, folder = self._child
        self._child = None
        try:
            if abort:
                _kill(pid)
            else:
                while chunk := pipe.read(1 << 16):  # what it still sends: unused
                    del chunk
            pipe.close()
            os.waitpid(pid, 0)
        finally:
            shutil.rmtree(folder, ignore_errors=True)

    def __enter__(self) -> Aside[T]:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:  # fmt: skip
        self.close(abort=kind is not None)


class Mailbox:
    """One value this process sends, once it has it, to the tasks of an `Aside` (made
    with this mailbox): `put` here, `get` in a task, which waits for it in the child and
    has it at once here (a task the child could not deliver runs here after the `put`).
    The value is pickled through a pipe (keep it small: a pipe holds 64 KiB unread)."""

    _UNSET = object()

    def __init__(self) -> None:
        self._creator = os.getpid()
        self._read, self._write = os.pipe()
        self._value: object = self._UNSET

    def forked(self) -> None:
        """In the Aside's child: only the reading end kept (this process gone: end of file)."""
        os.close(self._write)
        self._write = -1

    def forking_done(self) -> None:
        """Here, once the child is forked: only the writing end kept."""
        os.close(self._read)
        self._read = -1

    def put(self, value: object) -> None:
        """Send `value` (here, once)."""
        self._value = value
        if self._write >= 0:
            body = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
            with contextlib.suppress(BrokenPipeError):  # the child died: computed here
                os.write(self._write, len(body).to_bytes(8, "little") + body)
            os.close(self._write)
            self._write = -1

    def get(self) -> object:
        """The value put: here at once (after `put`), in the child when it comes."""
        if self._value is self._UNSET and os.getpid() != self._creator:
            with os.fdopen(self._read, "rb", closefd=False) as pipe:
                head = pipe.read(8)
                if len(head) != 8:
                    raise EOFError("the mailbox was closed before a value was put")
                self._value = pickle.loads(pipe.read(int.from_bytes(head, "little")))
        if self._value is self._UNSET:
            raise RuntimeError("Mailbox.get before put")
        return self._value

    def close(self) -> None:
        """Close what is left of the pipe here."""
        for fd in (self._read, self._write):
            if fd >= 0:
                os.close(fd)
        self._read = self._write = -1

    def __enter__(self) -> Mailbox:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:  # fmt: skip
        self.close()


def _leave(code: int, parent: int, folder: str) -> None:
    """A child's end: its folder removed when the process that forked it is gone (killed:
    nobody else will), then os._exit (no exit handler of the parent's runs twice)."""
    try:
        if os.getppid() != parent:
            shutil.rmtree(folder, ignore_errors=True)
    finally:
        os._exit(code)


def _kill(pid: int) -> None:
    """SIGKILL to the process group `pid` leads (a child and its twin), else to `pid`."""
    with contextlib.suppress(ProcessLookupError):
        try:
            os.killpg(pid, signal.SIGKILL)
        except ProcessLookupError:  # not (yet) leading a group: the process itself
            os.kill(pid, signal.SIGKILL)


def _compute(tasks: Sequence[tuple[int, tuple[Hashable, Callable[[], object]]]], folder: str,
             write: int) -> None:  # fmt: skip
    """In a child: each (number, task)'s result pickled to `folder`/<number>, then the
    number (8 bytes, written at once: a pipe never splits so few) to the pipe `write`."""
    with os.fdopen(write, "wb") as pipe:
        for number, (_, task) in tasks:
            with open(os.path.join(folder, str(number)), "wb") as file:
                pickle.dump(task(), file, protocol=pickle.HIGHEST_PROTOCOL)
            pipe.write(number.to_bytes(8, "little"))
            pipe.flush()


class Helper:
    """A child forked now (when `can_fork`) that runs `prepare` (e.g. imports) while this
    process goes on, then waits for one batch of tasks (`take`, by an `Aside`), which it
    may share with a twin it forks then (both prepared: the preparation is paid once).
    The batch goes through a file of the helper's private folder (the pipe only signals
    it), so `take` never blocks.

    A helper never given a batch must be closed (`close`): it is killed and reaped. One
    that outlives this process (killed) ends when its batch pipe reads end-of-file."""

    def __init__(self, prepare: Callable[[], object]) -> None:
        self._child: tuple[int, int, int, str] | None = None  # pid, results, batch, folder
        if not can_fork():
            return
        folder = tempfile.mkdtemp(prefix=FOLDER_PREFIX)
        results, batch = os.pipe(), os.pipe()
        parent = os.getpid()
        pid = os.fork()
        if pid == 0:  # the child
            code = 0
            try:
                os.setpgid(0, 0)
                os.close(results[0])
                os.close(batch[1])
                prepare()
                if os.read(batch[0], 1):  # end of file: this process ended without a batch
                    with open(os.path.join(folder, "batch"), "rb") as file:
                        tasks, split = pickle.load(file)
                    _share(list(enumerate(tasks)), split, folder, results[1])
            except BaseException:  # noqa: BLE001 - the parent computes what did not come
                code = 1
            finally:
                _leave(code, parent, folder)
        os.close(results[1])
        os.close(batch[0])
        self._child = (pid, results[0], batch[1], folder)

    def take(self, tasks: Sequence[tuple[Hashable, Callable[[], T]]], split: int | None = None
             ) -> tuple[int, IO[bytes], str] | None:  # fmt: skip
        """Hand `tasks` to the child (from index `split` on to its twin): its pid, results
        pipe and folder (for `Aside`), or None when it cannot (no child, already given a
        batch, tasks not picklable: it is then closed)."""
        if self._child is None:
            return None
        pid, results, batch, folder = self._child
        try:
            with open(os.path.join(folder, "batch"), "wb") as file:
                pickle.dump((list(tasks), split), file, protocol=pickle.HIGHEST_PROTOCOL)
            os.write(batch, b"1")
        except (pickle.PicklingError, AttributeError, TypeError, OSError):
            self.close()
            return None
        os.close(batch)
        self._child = None
        return pid, os.fdopen(results, "rb"), folder

    def close(self) -> None:
        """Kill and reap the child if it never took a batch; remove its folder."""
        if self._child is None:
            return
        pid, results, batch, folder = self._child
        self._child = None
        _kill(pid)
        os.close(results)
        os.close(batch)
        os.waitpid(pid, 0)
        shutil.rmtree(folder, ignore_errors=True)


def _share(tasks: list[tuple[int, tuple[Hashable, Callable[[], object]]]], split: int | None,
           folder: str, write: int) -> None:  # fmt: skip
    """In a helper: `tasks` computed (`_compute`), those from index `split` on by a twin
    forked now (it writes to the same pipe and folder; reaped here before returning)."""
    if split is None or not 0 < split < len(tasks):
        _compute(tasks, folder, write)
        return
    twin = os.fork()
    if twin == 0:
        code = 0
        try:
            _compute(tasks[split:], folder, write)
        except BaseException:  # noqa: BLE001 - the parent computes what did not come
            code = 1
        finally:
            os._exit(code)
    try:
        _compute(tasks[:split], folder, write)
    finally:
        os.waitpid(twin, 0)
