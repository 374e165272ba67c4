"""Independent work the science may run beside its own, on a runner its caller owns.

The science names a few independent tasks (the second half of the joints' frequency scans,
the other folds' fits, half of a sum over poses) with `aside(tasks)`, goes on with its own
work, then asks `result(key)` of each; a task may wait for one value the science finds
meanwhile (`mailbox()`: `put` here, `get` in the task). What runs the tasks is the
caller's choice, installed for a block with `using(runner)`:

- `SEQUENTIAL` (nothing installed: a library call, a notebook): each task is computed here
  when its result is asked; no process is forked, no thread started;
- `robot_calib.forked.FORKED`: a forked child on the machine's other core (what the
  command line's `diagnose` and `run` install; a script may too:
  `with using(FORKED): rc.diagnose(...)`). A
  process with other Python threads (a notebook's kernel, a node's executor) never forks:
  its tasks are computed here all the same.

The results are the same either way; only when they arrive differs.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Hashable, Iterator, Sequence
from contextvars import ContextVar
from types import TracebackType
from typing import Any, Generic, Protocol, TypeVar

T = TypeVar("T")
V = TypeVar("V")

Tasks = Sequence[tuple[Hashable, Callable[[], T]]]


class Results(Protocol[T]):
    """The tasks of one `aside` call: `result(key)` waits for (or computes) each; leaving
    the block ends whatever still runs."""

    def result(self, key: Hashable) -> T: ...

    def __enter__(self) -> Results[T]: ...

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None: ...


class Box(Protocol[V]):
    """One value found here (`put`) that a task waits for (`get`)."""

    def put(self, value: V) -> None: ...

    def get(self) -> V: ...

    def __enter__(self) -> Box[V]: ...

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None: ...


class Runner(Protocol):
    """What runs the tasks of `aside` (see the module docstring)."""

    def aside(self, tasks: Tasks[T], mailbox: Box[Any] | None = None) -> Results[T]: ...

    def mailbox(self) -> Box[Any]: ...


class _Later(Generic[T]):
    """`SEQUENTIAL`'s results: each task computed here when first asked."""

    def __init__(self, tasks: Tasks[T]) -> None:
        self._tasks = dict(tasks)
        self._done: dict[Hashable, T] = {}

    def result(self, key: Hashable) -> T:
        if key not in self._done:
            self._done[key] = self._tasks[key]()
        return self._done[key]

    def __enter__(self) -> _Later[T]:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self._tasks.clear()


class _Held(Generic[V]):
    """`SEQUENTIAL`'s mailbox: the value put, for the task computed after it."""

    def __init__(self) -> None:
        self._value: list[V] = []

    def put(self, value: V) -> None:
        self._value[:] = [value]

    def get(self) -> V:
        if not self._value:
            raise RuntimeError("a task asked for a value not found yet")
        return self._value[0]

    def __enter__(self) -> _Held[V]:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self._value.clear()


class Sequential:
    """Every task computed here, when its result is asked."""

    def aside(self, tasks: Tasks[T], mailbox: Box[Any] | None = None) -> Results[T]:
        del mailbox  # its value is put before any task that gets it is computed
        return _Later(tasks)

    def mailbox(self) -> Box[Any]:
        return _Held()


SEQUENTIAL = Sequential()

_runner: ContextVar[Runner | None] = ContextVar("robot_calib_runner", default=None)


def aside(tasks: Tasks[T], mailbox: Box[Any] | None = None) -> Results[T]:
    """`tasks` (key, function of no arguments) run by the installed runner (SEQUENTIAL when
    none is); `mailbox` one of `mailbox()`, whose value some of the tasks wait for."""
    return (_runner.get() or SEQUENTIAL).aside(tasks, mailbox)


def mailbox() -> Box[Any]:
    """A mailbox of the installed runner, for one `aside` call."""
    return (_runner.get() or SEQUENTIAL).mailbox()


@contextlib.contextmanager
def using(runner: Runner) -> Iterator[None]:
    """Run the tasks of `aside` within this block on `runner`."""
    token = _runner.set(runner)
    try:
        yield
    finally:
        _runner.reset(token)
