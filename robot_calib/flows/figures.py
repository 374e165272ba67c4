"""The figures of a diagnosis drawn in other processes while this one writes the reports
(`FiguresAside`): matplotlib is single-threaded, a second process is the only way to use
the second core (half of a diagnosis of 2773 poses was figures). The figures themselves,
and the cache that draws them here, are `robot_calib.diagnosis.figures`."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import TYPE_CHECKING

from robot_calib.diagnosis.figures import FigureCache, pyplot, render_png, warm_up
from robot_calib.forked import Aside, Helper, can_fork

if TYPE_CHECKING:
    from matplotlib.figure import Figure


class FiguresAside(FigureCache):
    """PNG bytes of the figures of one report set, each drawn once: the Markdown report
    and the HTML page show the same figures (drawing them twice cost seconds).

    `draw_aside` draws them in other processes while this one writes the reports
    (`robot_calib.forked`: matplotlib is single-threaded, a second process is the only
    way to use the second core; half of a diagnosis of 2773 poses was figures): by the
    helper of `started` (forked when the run began, matplotlib imported and its fonts
    loaded by the time the figures are asked for) and the twin it forks then, else by a
    child forked then. `png` of a figure drawn aside waits for it, and draws it here if no
    other process could (it died, or fork is not available): the bytes are the same."""

    def __init__(self, dpi: int = 100, helpers: Sequence[Helper] = ()) -> None:
        super().__init__(dpi)
        self._asides: list[Aside[bytes | None]] = []  # the processes drawing figures
        self._helpers = list(helpers)

    @classmethod
    def started(cls, dpi: int = 100) -> FiguresAside:
        """A cache whose helper process starts now, importing matplotlib and loading its
        fonts (`warm_up`; the modules the pickled figures need it inherits: import them
        before); it draws with a twin it forks then (no helper without fork: then drawn as
        `draw_aside` says). Close it (`close`), or use it as a context manager."""
        return cls(dpi, [Helper(_get_ready)])

    def png(self, key: str, draw: Callable[[], Figure | None]) -> bytes | None:
        """The PNG of figure `key`, drawn by `draw` the first time (None: no figure)."""
        if key not in self._png:
            aside = next((a for a in self._asides if key in a), None)
            self._png[key] = aside.result(key) if aside is not None else render_png(draw, self.dpi)
        return self._png[key]

    def draw_aside(self, *groups: Sequence[tuple[str, Callable[[], Figure | None]]]) -> None:
        """Draw the figures of `groups` ((key, draw) each, as `png` takes them) in other
        processes while the caller goes on: the first two groups by the helper of `started`
        and its twin (their draws picklable: module-level functions and partials), any
        other here when asked; without a helper the first group in a child forked now, the
        others here when asked. Once only."""
        if self._asides:
            return
        helpers, self._helpers = self._helpers, []
        tasks = [
            [
                (key, partial(render_png, draw, self.dpi))
                for key, draw in group
                if key not in self._png
            ]
            for group in groups
        ]
        if helpers and tasks:
            both = tasks[0] + (tasks[1] if len(tasks) > 1 else [])
            self._asides.append(
                Aside(both, ASIDE_TIMEOUT_S, helper=helpers[0], split=len(tasks[0]))
            )
        elif tasks and tasks[0] and can_fork():
            warm_up(pyplot())  # imported and fonts loaded before the fork: both inherit
            self._asides.append(Aside(tasks[0], ASIDE_TIMEOUT_S))
        for helper in helpers:
            helper.close()  # unused (one that took its batch: nothing to do)

    def close(self, abort: bool = False) -> None:
        """Reap the processes drawing: after their last figure, or at once (`abort`:
        killed, on an error or an interruption here, their figures unused); unused helpers
        are killed."""
        for aside in self._asides:
            aside.close(abort)
        for helper in self._helpers:
            helper.close()
        self._asides, self._helpers = [], []


def _get_ready() -> None:
    """A helper's preparation: matplotlib imported, its fonts loaded."""
    warm_up(pyplot())


#: seconds a figure drawn aside may take at most (they take tenths): then the child is
#: killed and the figures it did not send are drawn here
ASIDE_TIMEOUT_S = 60.0
