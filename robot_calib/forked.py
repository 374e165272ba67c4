"""Work done by a forked child process on the machine's other core while this process goes
on: the only way to use a second core for Python-heavy work (matplotlib's figures, the
hyperparameter searches and fits of a k-fold's folds: threads share one interpreter lock,
and two threads of those ran at 1.1 cores).

`Aside` forks one child that computes its tasks in order and writes each result (pickled)
to a file of a private temporary folder as it is done, then its number to a pipe (a
result through the pipe itself would block the child as soon as it passed the pipe's
64 KiB until this process read it: the child stood idle). `result(key)` waits for the
child's. A task the child could not deliver (it raised, died, or sent nothing within the
timeout), and every task of an `Aside` that could not fork (no os.fork, other Python
threads running), is computed here when asked: the caller gets the same value either
way, only later. The child leaves with os._exit: no exit handler, no buffered output of
this process written twice.

`Helper` forks its child early, before the tasks exist: it gets ready meanwhile (imports
matplotlib and loads its fonts, 0.4 s on the core this process leaves idle while it reads
and fits) and then takes one batch of tasks, pickled (so only module-level functions and
partials of them), for an `Aside`, sharing it with a twin it forks then. `Mailbox`
carries one value this process finds later to the tasks of an `Aside`'s child.

Every child leads a process group of its own (a helper's twin belongs to its helper's),
which an abort kills whole: Ctrl-C at the terminal reaches this process only, which ends
them. A child whose parent was killed removes its folder itself; a folder whose child
ended before its parent was killed is removed by the next process making one (it names
its writer).
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
from typing import Any, Generic, TypeVar

from robot_calib.atomic import owned_folder

T = TypeVar("T")
V = TypeVar("V")

FOLDER_PREFIX = "robot_calib-aside-"  # the private temporary folders' names start so
#: seconds the child may take for one task (they take tenths to seconds): then it is
#: killed and what it did not send is computed here
TIMEOUT_S = 120.0

#: a helper prepares (and draws) at this niceness: the cores go first to this process and
#: the children it forks to share its work
HELPER_NICENESS = 10
#: this process's ends of its helpers' pipes: closed in every child forked after them (a
#: child holding a helper's batch pipe open would keep an orphaned helper waiting)
_HELPER_FDS: set[int] = set()


def _close_helper_fds() -> None:
    for fd in list(_HELPER_FDS):
        with contextlib.suppress(OSError):
            os.close(fd)
    _HELPER_FDS.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_close_helper_fds)


def _private_folder() -> str:
    """A new private folder for a child's results in the temporary directory, naming this
    process as its writer: the next one removes it if this process was killed first."""
    return str(owned_folder(tempfile.gettempdir(), FOLDER_PREFIX))


def can_fork() -> bool:
    """True when a forked child is safe and useful: os.fork exists and this is the only
    Python thread (a fork copies only the calling thread: a lock another Python thread
    holds, a thread pool's or an rclpy executor's, would stay held in the child for ever).
    Threads outside Python (DDS) are not seen here; the child never calls into them."""
    return hasattr(os, "fork") and threading.active_count() == 1


def _start_child(body: Callable[[], object], parent: int, folder: str) -> int:
    """Fork a child that leads its own process group, runs `body` and leaves (`_leave`:
    exit status 1 when `body` raised); this process gets its pid."""
    pid = os.fork()
    if pid == 0:
        code = 0
        try:
            os.setpgid(0, 0)
            body()
        except BaseException:  # noqa: BLE001 - the parent computes what did not come
            code = 1
        finally:
            _leave(code, parent, folder)
    return pid


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


def _read_exactly(fd: int, size: int) -> bytes:
    """`size` bytes of the pipe `fd` (fewer only at its end), unbuffered: what select
    reports ready is what is read, none kept in a buffer select cannot see."""
    out = b""
    while len(out) < size:
        chunk = os.read(fd, size - len(out))
        if not chunk:
            break
        out += chunk
    return out


def _compute(
    tasks: Sequence[tuple[int, tuple[Hashable, Callable[[], object]]]], folder: str, write: int
) -> None:
    """In a child: each (number, task)'s result pickled to `folder`/<number>, then the
    number (8 bytes, written at once: a pipe never splits so few) to the pipe `write`."""
    with os.fdopen(write, "wb") as pipe:
        for number, (_, task) in tasks:
            with open(os.path.join(folder, str(number)), "wb") as file:
                pickle.dump(task(), file, protocol=pickle.HIGHEST_PROTOCOL)
            pipe.write(number.to_bytes(8, "little"))
            pipe.flush()


class Mailbox(Generic[V]):
    """One value this process sends, once it has it, to the tasks of an `Aside` (made
    with this mailbox): `put` here, `get` in a task, which waits for it in the child and
    has it at once here (a task the child could not deliver runs here after the `put`).
    The value is pickled through a pipe (keep it small: a pipe holds 64 KiB unread), and
    only when a child was forked to read it. Close it (or use it as a context manager)."""

    def __init__(self) -> None:
        self._creator = os.getpid()
        self._read, self._write = os.pipe()
        self._forked = False
        self._value: V | None = None
        self._put = False

    def forked(self) -> None:
        """In the Aside's child: only the reading end kept (this process gone: end of file)."""
        os.close(self._write)
        self._write = -1

    def forking_done(self) -> None:
        """Here, once the child is forked: only the writing end kept."""
        os.close(self._read)
        self._read = -1
        self._forked = True

    def put(self, value: V) -> None:
        """Send `value` (here, once)."""
        self._value, self._put = value, True
        if self._forked and self._write >= 0:
            body = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
            with contextlib.suppress(BrokenPipeError):  # the child died: computed here
                os.write(self._write, len(body).to_bytes(8, "little") + body)
        self.close()

    def get(self) -> V:
        """The value put: here at once (after `put`), in the child when it comes (an
        EOFError when this process closed the mailbox without a value)."""
        if not self._put and os.getpid() != self._creator:
            head = _read_exactly(self._read, 8)
            if len(head) != 8:
                raise EOFError("the mailbox was closed before a value was put")
            self._value = pickle.loads(_read_exactly(self._read, int.from_bytes(head, "little")))
            self._put = True
        if not self._put:
            raise RuntimeError("Mailbox.get before put")
        return self._value  # type: ignore[return-value]  # V once put (V may be None)

    def close(self) -> None:
        """Close what is left of the pipe here (a child waiting in `get` reads its end)."""
        for fd in (self._read, self._write):
            if fd >= 0:
                os.close(fd)
        self._read = self._write = -1

    def __enter__(self) -> Mailbox[V]:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()


class Aside(Generic[T]):
    """`tasks` ((key, zero-argument callable) each; the results picklable) computed in
    order by a forked child while the caller goes on; `result(key)` gives each. Use as a
    context manager (or call `close`): leaving ends the child (killed when it still runs:
    what it had not sent is not wanted, or an exception, Ctrl-C included, left the block).

    A task is computed twice at most (in the child, then here when the child did not send
    it), so tasks must not change the state they share with the caller: the child's
    changes are lost, the result is what counts. `mailbox` carries one value this process
    finds later to the child's tasks. `helper`: a `Helper` that has not taken a batch yet
    computes the tasks instead of a new child (when they can be pickled; no mailbox
    then), with `split` the tasks from that index on by a twin it forks (both cores)."""

    def __init__(
        self,
        tasks: Sequence[tuple[Hashable, Callable[[], T]]],
        timeout_s: float = TIMEOUT_S,
        helper: Helper | None = None,
        split: int | None = None,
        mailbox: Mailbox[Any] | None = None,
    ) -> None:
        if helper is not None and mailbox is not None:
            raise ValueError("Aside: a helper's batch takes no mailbox")
        self._tasks = dict(tasks)
        self._results: dict[Hashable, T] = {}
        self._timeout_s = timeout_s
        self._received = 0
        self._keys = [key for key, _ in tasks]
        self._child: tuple[int, int, str] | None = None  # pid, results pipe, folder
        if not self._tasks:
            return
        if helper is not None:
            self._child = helper.take(list(tasks), split)
        if self._child is None and can_fork():
            self._fork(list(tasks), mailbox)

    def _fork(
        self, tasks: list[tuple[Hashable, Callable[[], T]]], mailbox: Mailbox[Any] | None
    ) -> None:
        folder = _private_folder()
        read, write = os.pipe()

        def body() -> None:
            os.close(read)
            if mailbox is not None:
                mailbox.forked()
            _compute(list(enumerate(tasks)), folder, write)

        pid = _start_child(body, os.getpid(), folder)
        os.close(write)
        if mailbox is not None:
            mailbox.forking_done()
        self._child = (pid, read, folder)

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
        nothing within the timeout or an unreadable result (it died)."""
        if self._child is None:
            return False
        _, pipe, folder = self._child
        if select.select([pipe], [], [], self._timeout_s)[0]:
            head = _read_exactly(pipe, 8)
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
        """End the child and remove its folder: reaped when it is done, else killed first
        (`abort`, or results it had not sent yet: they are not wanted). Safe against an
        interruption in the middle: the child is then killed and reaped all the same."""
        if self._child is None:
            return
        pid, pipe, folder = self._child
        try:
            done = not abort and os.waitpid(pid, os.WNOHANG)[0] == pid
            if not done:
                _kill(pid)
                os.waitpid(pid, 0)
        except ChildProcessError:  # reaped already
            pass
        except BaseException:
            _kill(pid)
            with contextlib.suppress(ChildProcessError):
                os.waitpid(pid, 0)
            raise
        finally:
            self._child = None
            os.close(pipe)
            shutil.rmtree(folder, ignore_errors=True)

    def __enter__(self) -> Aside[T]:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close(abort=kind is not None)


class Helper:
    """A child forked now (when `can_fork`) that runs `prepare` (e.g. imports) while this
    process goes on, then waits for one batch of tasks (`take`, by an `Aside`), which it
    may share with a twin it forks then (both prepared: the preparation is paid once).
    The batch goes through a file of the helper's private folder (the pipe only signals
    it), so `take` never blocks.

    A helper never given a batch must be closed (`close`): it is killed and reaped. One
    that outlives this process (killed) ends when its batch pipe reads end-of-file (no
    other child keeps it open: `_HELPER_FDS`)."""

    def __init__(self, prepare: Callable[[], object]) -> None:
        self._child: tuple[int, int, int, str] | None = None  # pid, results, batch, folder
        if not can_fork():
            return
        folder = _private_folder()
        results, batch = os.pipe(), os.pipe()

        def body() -> None:
            os.close(results[0])
            os.close(batch[1])
            os.nice(HELPER_NICENESS)  # prepared in the gaps of this process's work
            prepare()
            if _read_exactly(batch[0], 1):  # end of file: this process ended without a batch
                with open(os.path.join(folder, "batch"), "rb") as file:
                    tasks, split = pickle.load(file)
                _share(list(enumerate(tasks)), split, folder, results[1])

        pid = _start_child(body, os.getpid(), folder)
        os.close(results[1])
        os.close(batch[0])
        _HELPER_FDS.update((results[0], batch[1]))
        self._child = (pid, results[0], batch[1], folder)

    def take(
        self, tasks: Sequence[tuple[Hashable, Callable[[], T]]], split: int | None = None
    ) -> tuple[int, int, str] | None:
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
        _HELPER_FDS.difference_update((results, batch))
        self._child = None
        return pid, results, folder

    def close(self) -> None:
        """Kill and reap the child if it never took a batch; remove its folder."""
        if self._child is None:
            return
        pid, results, batch, folder = self._child
        self._child = None
        _HELPER_FDS.difference_update((results, batch))
        _kill(pid)
        os.close(results)
        os.close(batch)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(pid, 0)
        shutil.rmtree(folder, ignore_errors=True)


def _share(
    tasks: list[tuple[int, tuple[Hashable, Callable[[], object]]]],
    split: int | None,
    folder: str,
    write: int,
) -> None:
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


class Forked:
    """The runner of `robot_calib.parallel` that computes `aside`'s tasks in a forked child
    (`Aside`, `Mailbox`): what `flows/` install for the command line and the nodes."""

    def aside(
        self, tasks: Sequence[tuple[Hashable, Callable[[], T]]], mailbox: Any = None
    ) -> Aside[T]:
        return Aside(tasks, mailbox=mailbox)

    def mailbox(self) -> Mailbox[Any]:
        return Mailbox()


FORKED = Forked()
